#pragma once

// The status LEDs: the daemon's state as a blink pattern on one GPIO line, and
// an optional heartbeat line that blinks while the pipeline is alive.
//
//   pattern       status line                         daemon state
//   starting      100 ms on, 900 ms off               before the pipeline runs
//   initialising  two 100 ms flashes per second       initialising, tracking (no scale yet)
//   converging    slow blink: 500 ms on, 500 ms off   converging
//   converged     solid on                            converged
//   lost          fast blink: 100 ms on, 100 ms off   lost, fault
//   off           off                                 stopped
// heartbeat line: 500 ms on, 500 ms off while setAlive(true), else off.
// Every period begins "on": starting is on for [0, 100) ms of each second,
// initialising for [0, 100) and [200, 300), converging for [0, 500), lost for
// [0, 100) of each 200 ms; the heartbeat's phase starts when it becomes alive.
//
// The levels are a pure function of the pattern and the time since it began
// (patternLevel), so tests can check them at chosen instants with render();
// the thread started by start() calls render() at each edge.
//
// Errors (a line that cannot be set) are returned by render() and kept for
// takeError(), which gives each new error once: the caller logs it once, not
// at every blink.

#include <array>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include <scaled/core/result.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/report.h>
#include <scaled/drivers/gpio/gpio_lines.h>

namespace scaled::daemon {

enum class LightPattern : std::uint8_t {
    kOff,
    kStarting,
    kInitialising,
    kConverging,
    kConverged,
    kLost
};
const char* toString(LightPattern p);

LightPattern patternFor(DaemonState state);
// The status line's level `t_ns` after the pattern began (t_ns >= 0; earlier
// times count as 0).
bool patternLevel(LightPattern p, std::int64_t t_ns);
// The first instant after `t_ns` (same time base: since the pattern began) at
// which the level changes: the level is patternLevel(p, t_ns) on [t_ns, edge)
// and differs at the edge. Patterns that never change: t_ns + one hour.
std::int64_t nextEdgeNs(LightPattern p, std::int64_t t_ns);

class StatusLights {
public:
    // config.chip empty: nullptr (no LEDs; the caller logs that once). An
    // error when the chip or a line cannot be had (gpio.chip set but neither
    // line: kInvalidArgument); the caller logs it and runs on without LEDs.
    // Lines: status first, heartbeat second (each when set, i.e. not -1).
    static core::Result<std::unique_ptr<StatusLights>> open(const GpioConfig& config);
    // The same on outputs the caller opened (tests: a fake). `outputs` must
    // hold the configured lines in open()'s order; config.chip is not used.
    static core::Result<std::unique_ptr<StatusLights>> create(
        std::unique_ptr<drivers::gpio::GpioOutputs> outputs, const GpioConfig& config);
    ~StatusLights();  // stop()
    StatusLights(const StatusLights&) = delete;
    StatusLights& operator=(const StatusLights&) = delete;
    StatusLights(StatusLights&&) = delete;
    StatusLights& operator=(StatusLights&&) = delete;

    // Thread-safe. A new pattern restarts its phase at the current time; the
    // pattern already shown keeps its phase.
    void setPattern(LightPattern p);
    // Thread-safe. Becoming alive starts the heartbeat's phase.
    void setAlive(bool alive);
    [[nodiscard]] LightPattern pattern() const;

    // Drives the lines for time `now_ns` (CLOCK_MONOTONIC, i.e.
    // std::chrono::steady_clock). A line is set only when its level changed
    // (the first render sets every line); no allocation unless it fails.
    // Used by the thread; tests call it directly with chosen times (without
    // start()). After stop(): kUnavailable.
    core::Status render(std::int64_t now_ns);
    // Same as setPattern / setAlive, with the phase starting at `now_ns` (tests).
    void setPatternAt(LightPattern p, std::int64_t now_ns);
    void setAliveAt(bool alive, std::int64_t now_ns);

    // Thread-safe. The last render error not taken yet; an error equal to the
    // one taken before is not given again until a render succeeds.
    std::optional<std::string> takeError();

    // The blink thread: renders at each edge and after each change. start()
    // and stop() are called by the owner's thread; once stopped the lights
    // do not start again.
    void start();
    // Ends the thread, drives the lines inactive and releases them.
    void stop();

    // "gpiochip1 [scaled-leds] lines 2,3: status line 2, heartbeat line 3".
    [[nodiscard]] std::string describe() const;

private:
    StatusLights(std::unique_ptr<drivers::gpio::GpioOutputs> outputs, const GpioConfig& config,
                 std::int64_t now_ns);
    void run();
    core::Status renderLocked(std::int64_t now_ns);
    // When the thread must render next, at or after `now_ns`.
    [[nodiscard]] std::int64_t nextWakeLocked(std::int64_t now_ns) const;
    void noteErrorLocked(const core::Error& error);

    static constexpr int kNoLine = -1;
    // Level not driven yet (or its set failed): the next render sets it.
    static constexpr std::int8_t kUnknown = -1;

    std::unique_ptr<drivers::gpio::GpioOutputs> outputs_;  // null once stopped
    GpioConfig config_;
    std::string description_;
    int status_index_ = kNoLine;                                 // index into outputs_
    int heartbeat_index_ = kNoLine;                              // index into outputs_
    std::array<std::int8_t, 2> last_level_{kUnknown, kUnknown};  // per output index
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    LightPattern pattern_ = LightPattern::kStarting;
    std::int64_t pattern_start_ns_ = 0;
    bool alive_ = false;
    std::int64_t alive_start_ns_ = 0;
    bool wake_ = false;  // a change the thread has not rendered yet
    bool stop_ = false;
    std::string last_error_;  // the error of the last failed render ("" after a success)
    std::optional<std::string> pending_error_;
    std::thread thread_;
};

}  // namespace scaled::daemon
