#include <algorithm>
#include <chrono>
#include <limits>
#include <system_error>
#include <utility>

#include <scaled/daemon/status_lights.h>

namespace scaled::daemon {
namespace {

using core::ErrorCode;
using core::makeError;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kHourNs = 3600LL * 1000 * kMs;
// After a failed set, the thread tries again this soon even when no edge is due
// (a solid pattern would otherwise wait an hour).
constexpr std::int64_t kRetryNs = 1000 * kMs;

// A periodic blink: on at each even boundary, off at each odd one. Every
// period starts on and ends off (an even number of boundaries, the first 0),
// so the level also changes at the period's end.
struct Blink {
    std::int64_t period_ns;
    std::array<std::int64_t, 4> boundaries_ns;
    std::size_t count;
};

constexpr Blink kStartingBlink{1000 * kMs, {0, 100 * kMs, 0, 0}, 2};
constexpr Blink kInitialisingBlink{1000 * kMs, {0, 100 * kMs, 200 * kMs, 300 * kMs}, 4};
constexpr Blink kSlowBlink{1000 * kMs, {0, 500 * kMs, 0, 0}, 2};
constexpr Blink kFastBlink{200 * kMs, {0, 100 * kMs, 0, 0}, 2};
constexpr const Blink& kHeartbeatBlink = kSlowBlink;

// nullptr for the patterns that never change.
const Blink* blinkOf(LightPattern p) {
    switch (p) {
        case LightPattern::kStarting:
            return &kStartingBlink;
        case LightPattern::kInitialising:
            return &kInitialisingBlink;
        case LightPattern::kConverging:
            return &kSlowBlink;
        case LightPattern::kLost:
            return &kFastBlink;
        case LightPattern::kOff:
        case LightPattern::kConverged:
            return nullptr;
    }
    return nullptr;
}

std::int64_t phaseOf(const Blink& blink, std::int64_t t_ns) {
    return std::max<std::int64_t>(t_ns, 0) % blink.period_ns;
}

bool blinkLevel(const Blink& blink, std::int64_t t_ns) {
    const std::int64_t phase = phaseOf(blink, t_ns);
    std::size_t passed = 0;
    while (passed < blink.count && blink.boundaries_ns[passed] <= phase) {
        ++passed;
    }
    return passed % 2 == 1;
}

std::int64_t blinkNextEdge(const Blink& blink, std::int64_t t_ns) {
    const std::int64_t t = std::max<std::int64_t>(t_ns, 0);
    const std::int64_t phase = t % blink.period_ns;
    const std::int64_t period_start = t - phase;
    for (std::size_t i = 0; i < blink.count; ++i) {
        if (blink.boundaries_ns[i] > phase) {
            return period_start + blink.boundaries_ns[i];
        }
    }
    return period_start + blink.period_ns;  // the next period's first boundary
}

std::int64_t plusHour(std::int64_t t_ns) {
    return t_ns > std::numeric_limits<std::int64_t>::max() - kHourNs
               ? std::numeric_limits<std::int64_t>::max()
               : t_ns + kHourNs;
}

std::int64_t steadyNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

std::chrono::steady_clock::time_point steadyTimePoint(std::int64_t t_ns) {
    return std::chrono::steady_clock::time_point(
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
            std::chrono::nanoseconds(t_ns)));
}

core::Status checkLines(const GpioConfig& config) {
    if (config.status_line < -1 || config.heartbeat_line < -1) {
        return makeError(ErrorCode::kInvalidArgument,
                         "gpio: a line offset must be >= 0, or -1 for none (got status_line " +
                             std::to_string(config.status_line) + ", heartbeat_line " +
                             std::to_string(config.heartbeat_line) + ")");
    }
    if (config.status_line == -1 && config.heartbeat_line == -1) {
        return makeError(ErrorCode::kInvalidArgument,
                         "gpio.chip is set but no line is (set gpio.status_line and/or "
                         "gpio.heartbeat_line)");
    }
    if (config.status_line == config.heartbeat_line) {
        return makeError(ErrorCode::kInvalidArgument,
                         "gpio: status_line and heartbeat_line are the same line (" +
                             std::to_string(config.status_line) + ")");
    }
    return {};
}

}  // namespace

const char* toString(LightPattern p) {
    switch (p) {
        case LightPattern::kOff:
            return "off";
        case LightPattern::kStarting:
            return "starting";
        case LightPattern::kInitialising:
            return "initialising";
        case LightPattern::kConverging:
            return "converging";
        case LightPattern::kConverged:
            return "converged";
        case LightPattern::kLost:
            return "lost";
    }
    return "?";
}

LightPattern patternFor(DaemonState state) {
    switch (state) {
        case DaemonState::kInitialising:
        case DaemonState::kTracking:
            return LightPattern::kInitialising;
        case DaemonState::kConverging:
            return LightPattern::kConverging;
        case DaemonState::kConverged:
            return LightPattern::kConverged;
        case DaemonState::kLost:
        case DaemonState::kFault:
            return LightPattern::kLost;
    }
    return LightPattern::kLost;
}

bool patternLevel(LightPattern p, std::int64_t t_ns) {
    if (const Blink* blink = blinkOf(p)) {
        return blinkLevel(*blink, t_ns);
    }
    return p == LightPattern::kConverged;
}

std::int64_t nextEdgeNs(LightPattern p, std::int64_t t_ns) {
    if (const Blink* blink = blinkOf(p)) {
        return blinkNextEdge(*blink, t_ns);
    }
    return plusHour(t_ns);
}

// --- StatusLights ------------------------------------------------------------

core::Result<std::unique_ptr<StatusLights>> StatusLights::open(const GpioConfig& config) {
    if (config.chip.empty()) {
        return std::unique_ptr<StatusLights>();
    }
    if (auto ok = checkLines(config); !ok) {
        return ok.error();
    }
    drivers::gpio::GpioOutputOptions options;
    options.chip = config.chip;
    for (const int line : {config.status_line, config.heartbeat_line}) {
        if (line >= 0) {
            options.offsets.push_back(static_cast<unsigned>(line));
        }
    }
    options.active_low = config.active_low;
    options.consumer = config.consumer;
    auto outputs = drivers::gpio::openGpioOutputs(options);
    if (!outputs) {
        return outputs.error();
    }
    return create(std::move(*outputs), config);
}

core::Result<std::unique_ptr<StatusLights>> StatusLights::create(
    std::unique_ptr<drivers::gpio::GpioOutputs> outputs, const GpioConfig& config) {
    if (!outputs) {
        return makeError(ErrorCode::kInvalidArgument, "status LEDs: no GPIO outputs given");
    }
    if (auto ok = checkLines(config); !ok) {
        return ok.error();
    }
    return std::unique_ptr<StatusLights>(
        new StatusLights(std::move(outputs), config, steadyNowNs()));
}

StatusLights::StatusLights(std::unique_ptr<drivers::gpio::GpioOutputs> outputs,
                           const GpioConfig& config, std::int64_t now_ns)
    : outputs_(std::move(outputs)), config_(config), pattern_start_ns_(now_ns) {
    int next = 0;
    std::string lines;
    if (config_.status_line >= 0) {
        status_index_ = next++;
        lines += "status line " + std::to_string(config_.status_line);
    }
    if (config_.heartbeat_line >= 0) {
        heartbeat_index_ = next++;
        lines += (lines.empty() ? "" : ", ") + std::string("heartbeat line ") +
                 std::to_string(config_.heartbeat_line);
    }
    description_ = outputs_->describe() + ": " + lines;
}

StatusLights::~StatusLights() {
    stop();
}

void StatusLights::setPattern(LightPattern p) {
    setPatternAt(p, steadyNowNs());
}

void StatusLights::setPatternAt(LightPattern p, std::int64_t now_ns) {
    {
        const std::lock_guard lock(mutex_);
        if (p == pattern_) {
            return;
        }
        pattern_ = p;
        pattern_start_ns_ = now_ns;
        wake_ = true;
    }
    changed_.notify_one();
}

void StatusLights::setAlive(bool alive) {
    setAliveAt(alive, steadyNowNs());
}

void StatusLights::setAliveAt(bool alive, std::int64_t now_ns) {
    {
        const std::lock_guard lock(mutex_);
        if (alive == alive_) {
            return;
        }
        alive_ = alive;
        alive_start_ns_ = now_ns;
        wake_ = true;
    }
    changed_.notify_one();
}

LightPattern StatusLights::pattern() const {
    const std::lock_guard lock(mutex_);
    return pattern_;
}

core::Status StatusLights::render(std::int64_t now_ns) {
    const std::lock_guard lock(mutex_);
    return renderLocked(now_ns);
}

core::Status StatusLights::renderLocked(std::int64_t now_ns) {
    if (!outputs_) {
        return makeError(ErrorCode::kUnavailable, "status LEDs: stopped (lines released)");
    }
    const std::array<std::pair<int, bool>, 2> wanted{{
        {status_index_, patternLevel(pattern_, now_ns - pattern_start_ns_)},
        {heartbeat_index_, alive_ && blinkLevel(kHeartbeatBlink, now_ns - alive_start_ns_)},
    }};
    core::Status result;
    for (const auto& [index, level] : wanted) {
        if (index == kNoLine) {
            continue;
        }
        const auto i = static_cast<std::size_t>(index);
        const std::int8_t value = level ? 1 : 0;
        if (last_level_[i] == value) {
            continue;
        }
        auto set = outputs_->set(i, level);
        if (!set) {
            last_level_[i] = kUnknown;
            if (result.ok()) {
                result = set.error();
            }
            continue;
        }
        last_level_[i] = value;
    }
    if (result.ok()) {
        last_error_.clear();
    } else {
        noteErrorLocked(result.error());
    }
    return result;
}

void StatusLights::noteErrorLocked(const core::Error& error) {
    if (error.message != last_error_) {
        last_error_ = error.message;
        pending_error_ = error.message;
    }
}

std::optional<std::string> StatusLights::takeError() {
    const std::lock_guard lock(mutex_);
    return std::exchange(pending_error_, std::nullopt);
}

std::int64_t StatusLights::nextWakeLocked(std::int64_t now_ns) const {
    std::int64_t wake = plusHour(now_ns);
    if (status_index_ != kNoLine) {
        const std::int64_t since = std::max<std::int64_t>(now_ns - pattern_start_ns_, 0);
        wake = std::min(wake, pattern_start_ns_ + nextEdgeNs(pattern_, since));
    }
    if (heartbeat_index_ != kNoLine && alive_) {
        const std::int64_t since = std::max<std::int64_t>(now_ns - alive_start_ns_, 0);
        wake = std::min(wake, alive_start_ns_ + blinkNextEdge(kHeartbeatBlink, since));
    }
    for (const int index : {status_index_, heartbeat_index_}) {
        if (index != kNoLine && last_level_[static_cast<std::size_t>(index)] == kUnknown) {
            wake = std::min(wake, now_ns + kRetryNs);  // its set failed: try again
        }
    }
    return wake;
}

void StatusLights::start() {
    const std::lock_guard lock(mutex_);
    if (thread_.joinable() || stop_ || !outputs_) {
        return;
    }
    try {
        thread_ = std::thread(&StatusLights::run, this);
    } catch (const std::system_error& e) {
        noteErrorLocked(
            makeError(ErrorCode::kUnavailable,
                      std::string("status LEDs: cannot start the blink thread: ") + e.what()));
    }
}

void StatusLights::run() {
    std::unique_lock lock(mutex_);
    while (!stop_) {
        const std::int64_t now_ns = steadyNowNs();
        (void)renderLocked(now_ns);  // a failure is kept for takeError()
        const std::int64_t wake_ns = nextWakeLocked(now_ns);
        wake_ = false;
        changed_.wait_until(lock, steadyTimePoint(wake_ns), [this] { return stop_ || wake_; });
    }
}

void StatusLights::stop() {
    {
        const std::lock_guard lock(mutex_);
        stop_ = true;
    }
    changed_.notify_one();
    if (thread_.joinable()) {
        thread_.join();
    }
    const std::lock_guard lock(mutex_);
    if (!outputs_) {
        return;
    }
    // Inactive before the release: once released, what a line does is up to
    // the chip's driver (many keep the last value, which would leave an LED on).
    for (const int index : {status_index_, heartbeat_index_}) {
        if (index == kNoLine) {
            continue;
        }
        if (auto set = outputs_->set(static_cast<std::size_t>(index), false); !set) {
            noteErrorLocked(set.error());
        }
    }
    outputs_.reset();
}

std::string StatusLights::describe() const {
    const std::lock_guard lock(mutex_);
    return description_;
}

}  // namespace scaled::daemon
