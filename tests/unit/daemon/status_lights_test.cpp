// The status LEDs: the patterns (levels and edges), the state mapping, and
// StatusLights on a fake GpioOutputs (which lines it sets and when, errors,
// the thread, stop). The real driver under StatusLights is tested in the VM
// (tests/vm/gpio_vm_test.cpp).

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/status_lights.h>

#include "allocation_counter.h"

namespace scaled::daemon {
namespace {

using core::ErrorCode;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kHourNs = 3600LL * 1000 * kMs;

constexpr std::array<LightPattern, 6> kAllPatterns = {
    LightPattern::kOff,        LightPattern::kStarting,  LightPattern::kInitialising,
    LightPattern::kConverging, LightPattern::kConverged, LightPattern::kLost};

// --- patterns ----------------------------------------------------------------

TEST(LightPatternTest, PatternForEveryState) {
    EXPECT_EQ(patternFor(DaemonState::kInitialising), LightPattern::kInitialising);
    EXPECT_EQ(patternFor(DaemonState::kTracking), LightPattern::kInitialising);
    EXPECT_EQ(patternFor(DaemonState::kConverging), LightPattern::kConverging);
    EXPECT_EQ(patternFor(DaemonState::kConverged), LightPattern::kConverged);
    EXPECT_EQ(patternFor(DaemonState::kLost), LightPattern::kLost);
    EXPECT_EQ(patternFor(DaemonState::kFault), LightPattern::kLost);
}

TEST(LightPatternTest, Names) {
    EXPECT_STREQ(toString(LightPattern::kOff), "off");
    EXPECT_STREQ(toString(LightPattern::kStarting), "starting");
    EXPECT_STREQ(toString(LightPattern::kInitialising), "initialising");
    EXPECT_STREQ(toString(LightPattern::kConverging), "converging");
    EXPECT_STREQ(toString(LightPattern::kConverged), "converged");
    EXPECT_STREQ(toString(LightPattern::kLost), "lost");
}

struct LevelAt {
    std::int64_t t_ns;
    bool level;
};

// The table of status_lights.h at its phase points and on both sides of
// every edge (1 ns before, at), over more than one period.
std::vector<LevelAt> expectedLevels(LightPattern p) {
    switch (p) {
        case LightPattern::kOff:
            return {{0, false}, {100 * kMs, false}, {999 * kMs, false}, {5000 * kMs, false}};
        case LightPattern::kConverged:
            return {{0, true}, {100 * kMs, true}, {999 * kMs, true}, {5000 * kMs, true}};
        case LightPattern::kStarting:  // 100 ms on, 900 ms off
            return {{0, true},          {50 * kMs, true},       {100 * kMs - 1, true},
                    {100 * kMs, false}, {500 * kMs, false},     {1000 * kMs - 1, false},
                    {1000 * kMs, true}, {1100 * kMs - 1, true}, {1100 * kMs, false},
                    {2000 * kMs, true}};
        case LightPattern::kInitialising:  // on 0-100, off 100-200, on 200-300, off 300-1000
            return {{0, true},          {100 * kMs - 1, true},   {100 * kMs, false},
                    {150 * kMs, false}, {200 * kMs - 1, false},  {200 * kMs, true},
                    {250 * kMs, true},  {300 * kMs - 1, true},   {300 * kMs, false},
                    {650 * kMs, false}, {1000 * kMs - 1, false}, {1000 * kMs, true},
                    {1200 * kMs, true}, {1300 * kMs, false}};
        case LightPattern::kConverging:  // 500 ms on, 500 ms off
            return {{0, true},          {250 * kMs, true},  {500 * kMs - 1, true},
                    {500 * kMs, false}, {750 * kMs, false}, {1000 * kMs - 1, false},
                    {1000 * kMs, true}, {1500 * kMs, false}};
        case LightPattern::kLost:  // 100 ms on, 100 ms off
            return {{0, true},          {50 * kMs, true},   {100 * kMs - 1, true},
                    {100 * kMs, false}, {150 * kMs, false}, {200 * kMs - 1, false},
                    {200 * kMs, true},  {300 * kMs, false}, {1000 * kMs, true},
                    {1100 * kMs, false}};
    }
    return {};
}

TEST(LightPatternTest, LevelsAtPhasePointsAndEdges) {
    for (const LightPattern p : kAllPatterns) {
        for (const LevelAt& at : expectedLevels(p)) {
            EXPECT_EQ(patternLevel(p, at.t_ns), at.level)
                << toString(p) << " at " << at.t_ns << " ns";
        }
    }
}

TEST(LightPatternTest, EdgesOfTheFirstTwoSeconds) {
    const auto edges = [](LightPattern p) {
        std::vector<std::int64_t> out;
        for (std::int64_t t = 0; t < 2000 * kMs; t = nextEdgeNs(p, t)) {
            out.push_back(t);
        }
        return out;
    };
    using V = std::vector<std::int64_t>;
    EXPECT_EQ(edges(LightPattern::kStarting), (V{0, 100 * kMs, 1000 * kMs, 1100 * kMs}));
    EXPECT_EQ(edges(LightPattern::kInitialising), (V{0, 100 * kMs, 200 * kMs, 300 * kMs, 1000 * kMs,
                                                     1100 * kMs, 1200 * kMs, 1300 * kMs}));
    EXPECT_EQ(edges(LightPattern::kConverging), (V{0, 500 * kMs, 1000 * kMs, 1500 * kMs}));
    EXPECT_EQ(edges(LightPattern::kLost),
              (V{0,          100 * kMs,  200 * kMs,  300 * kMs,  400 * kMs,  500 * kMs,  600 * kMs,
                 700 * kMs,  800 * kMs,  900 * kMs,  1000 * kMs, 1100 * kMs, 1200 * kMs, 1300 * kMs,
                 1400 * kMs, 1500 * kMs, 1600 * kMs, 1700 * kMs, 1800 * kMs, 1900 * kMs}));
}

TEST(LightPatternTest, NextEdgeIsWhereTheLevelChanges) {
    for (const LightPattern p : kAllPatterns) {
        const bool constant = p == LightPattern::kOff || p == LightPattern::kConverged;
        // Every millisecond of three seconds, and 1 ns either side of each.
        for (std::int64_t ms = 0; ms < 3000; ++ms) {
            for (const std::int64_t t : {ms * kMs, ms * kMs + 1, ms * kMs + kMs - 1}) {
                const std::int64_t edge = nextEdgeNs(p, t);
                const bool level = patternLevel(p, t);
                ASSERT_GT(edge, t) << toString(p) << " at " << t;
                if (constant) {
                    ASSERT_EQ(edge, t + kHourNs) << toString(p);
                    ASSERT_EQ(patternLevel(p, edge), level) << toString(p);
                    continue;
                }
                ASSERT_LE(edge - t, 900 * kMs) << toString(p) << " at " << t;
                ASSERT_EQ(patternLevel(p, (t + edge) / 2), level) << toString(p) << " at " << t;
                ASSERT_EQ(patternLevel(p, edge - 1), level) << toString(p) << " at " << t;
                ASSERT_NE(patternLevel(p, edge), level) << toString(p) << " at " << t;
            }
        }
    }
}

// --- StatusLights on a fake ---------------------------------------------------

struct Call {
    std::size_t index;
    bool active;
};

// What the fake saw, shared with the test (it outlives the fake). Fixed
// storage: recording a call does not allocate.
struct FakeLog {
    std::mutex mutex;
    std::condition_variable changed;
    std::array<Call, 16384> calls{};
    std::size_t count = 0;
    std::array<int, 2> level{-1, -1};  // last set per index; -1: never set
    bool fail = false;
    bool destroyed = false;
    std::size_t count_at_destruction = 0;

    std::vector<Call> callsSince(std::size_t first) {
        const std::lock_guard lock(mutex);
        return {calls.begin() + static_cast<std::ptrdiff_t>(first),
                calls.begin() + static_cast<std::ptrdiff_t>(count)};
    }
    std::size_t callCount() {
        const std::lock_guard lock(mutex);
        return count;
    }
    // Waits (on the fake's condition variable, not a sleep) until `done`; the
    // timeout only bounds a failing test.
    template <typename Pred>
    bool waitFor(Pred done) {
        std::unique_lock lock(mutex);
        return changed.wait_for(lock, std::chrono::seconds(30), [&] { return done(*this); });
    }
};

class FakeOutputs final : public drivers::gpio::GpioOutputs {
public:
    FakeOutputs(std::shared_ptr<FakeLog> log, std::size_t lines)
        : log_(std::move(log)), lines_(lines) {}
    FakeOutputs(const FakeOutputs&) = delete;
    FakeOutputs& operator=(const FakeOutputs&) = delete;
    FakeOutputs(FakeOutputs&&) = delete;
    FakeOutputs& operator=(FakeOutputs&&) = delete;
    ~FakeOutputs() override {
        {
            const std::lock_guard lock(log_->mutex);
            log_->destroyed = true;
            log_->count_at_destruction = log_->count;
        }
        log_->changed.notify_all();
    }

    core::Status set(std::size_t index, bool active) override {
        {
            const std::lock_guard lock(log_->mutex);
            if (index >= lines_) {
                return core::makeError(ErrorCode::kInvalidArgument, "fake: no such line");
            }
            if (log_->fail) {
                return core::makeError(ErrorCode::kIo, "fake line: cannot set");
            }
            if (log_->count < log_->calls.size()) {
                log_->calls[log_->count] = Call{index, active};
            }
            ++log_->count;
            log_->level[index] = active ? 1 : 0;
        }
        log_->changed.notify_all();
        return {};
    }
    [[nodiscard]] std::string describe() const override { return "fakechip [fake] lines 2,3"; }

private:
    std::shared_ptr<FakeLog> log_;
    std::size_t lines_;
};

GpioConfig twoLines() {
    GpioConfig config;
    config.chip = "fake";
    config.status_line = 2;
    config.heartbeat_line = 3;
    return config;
}

std::unique_ptr<StatusLights> makeLights(const std::shared_ptr<FakeLog>& log,
                                         const GpioConfig& config, std::size_t lines = 2) {
    auto lights = StatusLights::create(std::make_unique<FakeOutputs>(log, lines), config);
    EXPECT_TRUE(lights.ok()) << (lights.ok() ? "" : lights.error().message);
    return lights.ok() ? std::move(*lights) : nullptr;
}

constexpr std::size_t kStatus = 0;
constexpr std::size_t kHeartbeat = 1;

TEST(StatusLightsTest, OpenWithoutChipGivesNoLights) {
    GpioConfig config;
    config.status_line = 3;
    auto lights = StatusLights::open(config);
    ASSERT_TRUE(lights.ok()) << lights.error().message;
    EXPECT_EQ(*lights, nullptr);
}

TEST(StatusLightsTest, OpenWithChipButNoLineIsInvalid) {
    GpioConfig config;
    config.chip = "scaled-leds";
    auto lights = StatusLights::open(config);
    ASSERT_FALSE(lights.ok());
    EXPECT_EQ(lights.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(lights.error().message.find("gpio.chip is set but no line is"), std::string::npos)
        << lights.error().message;
}

TEST(StatusLightsTest, OpenMissingChipIsNotFoundAndSaysWhatChipsThereAre) {
    GpioConfig config;
    config.chip = "scaled-leds-missing";
    config.status_line = 0;
    auto lights = StatusLights::open(config);
    ASSERT_FALSE(lights.ok());
    EXPECT_EQ(lights.error().code, ErrorCode::kNotFound);
    EXPECT_NE(lights.error().message.find("'scaled-leds-missing'"), std::string::npos)
        << lights.error().message;
    bool host_has_chips = false;
    std::error_code ec;
    for (std::filesystem::directory_iterator it("/dev", ec);
         !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        host_has_chips = host_has_chips || it->path().filename().string().starts_with("gpiochip");
    }
    const std::string listed =
        host_has_chips ? "chips found: " : "there are no GPIO chips on this system";
    EXPECT_NE(lights.error().message.find(listed), std::string::npos) << lights.error().message;
}

TEST(StatusLightsTest, CreateRejectsBadLines) {
    const auto log = std::make_shared<FakeLog>();
    GpioConfig same = twoLines();
    same.heartbeat_line = same.status_line;
    auto a = StatusLights::create(std::make_unique<FakeOutputs>(log, 2), same);
    ASSERT_FALSE(a.ok());
    EXPECT_EQ(a.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(a.error().message.find("same line"), std::string::npos) << a.error().message;

    GpioConfig negative = twoLines();
    negative.status_line = -2;
    auto b = StatusLights::create(std::make_unique<FakeOutputs>(log, 2), negative);
    ASSERT_FALSE(b.ok());
    EXPECT_EQ(b.error().code, ErrorCode::kInvalidArgument);

    GpioConfig none = twoLines();
    none.status_line = -1;
    none.heartbeat_line = -1;
    auto c = StatusLights::create(std::make_unique<FakeOutputs>(log, 2), none);
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.error().message.find("no line is"), std::string::npos) << c.error().message;

    auto d = StatusLights::create(nullptr, twoLines());
    ASSERT_FALSE(d.ok());
    EXPECT_EQ(d.error().code, ErrorCode::kInvalidArgument);
}

TEST(StatusLightsTest, DescribeNamesTheOutputsAndTheLines) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    EXPECT_EQ(lights->describe(), "fakechip [fake] lines 2,3: status line 2, heartbeat line 3");
}

TEST(StatusLightsTest, FirstRenderSetsEveryLineThenOnlyChanges) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverging, 0);
    ASSERT_TRUE(lights->render(10 * kMs).ok());
    auto calls = log->callsSince(0);
    ASSERT_EQ(calls.size(), 2U);  // both, although the heartbeat is off (inactive)
    EXPECT_EQ(calls[0].index, kStatus);
    EXPECT_TRUE(calls[0].active);
    EXPECT_EQ(calls[1].index, kHeartbeat);
    EXPECT_FALSE(calls[1].active);

    ASSERT_TRUE(lights->render(20 * kMs).ok());
    ASSERT_TRUE(lights->render(499 * kMs).ok());
    EXPECT_EQ(log->callCount(), 2U);  // no change, no set

    ASSERT_TRUE(lights->render(500 * kMs).ok());
    calls = log->callsSince(2);
    ASSERT_EQ(calls.size(), 1U);
    EXPECT_EQ(calls[0].index, kStatus);
    EXPECT_FALSE(calls[0].active);

    ASSERT_TRUE(lights->render(999 * kMs).ok());
    EXPECT_EQ(log->callCount(), 3U);
    ASSERT_TRUE(lights->render(1000 * kMs).ok());
    EXPECT_EQ(log->callCount(), 4U);
    EXPECT_EQ(log->level[kStatus], 1);
}

TEST(StatusLightsTest, HeartbeatBlinksWhileAliveFromWhenItBecameAlive) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverged, 0);
    lights->setAliveAt(true, 300 * kMs);
    struct Expect {
        std::int64_t t_ns;
        int heartbeat;
    };
    for (const Expect e : {Expect{300 * kMs, 1}, Expect{799 * kMs, 1}, Expect{800 * kMs, 0},
                           Expect{1299 * kMs, 0}, Expect{1300 * kMs, 1}}) {
        ASSERT_TRUE(lights->render(e.t_ns).ok());
        EXPECT_EQ(log->level[kHeartbeat], e.heartbeat) << e.t_ns;
        EXPECT_EQ(log->level[kStatus], 1);
    }
    lights->setAliveAt(true, 1400 * kMs);  // already alive: the phase stays
    ASSERT_TRUE(lights->render(1400 * kMs).ok());
    EXPECT_EQ(log->level[kHeartbeat], 1);
    lights->setAliveAt(false, 1500 * kMs);
    ASSERT_TRUE(lights->render(1500 * kMs).ok());
    EXPECT_EQ(log->level[kHeartbeat], 0);
    ASSERT_TRUE(lights->render(2300 * kMs).ok());
    EXPECT_EQ(log->level[kHeartbeat], 0);
}

TEST(StatusLightsTest, SamePatternKeepsItsPhaseAndANewOneRestartsIt) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverging, 0);
    EXPECT_EQ(lights->pattern(), LightPattern::kConverging);
    ASSERT_TRUE(lights->render(600 * kMs).ok());
    EXPECT_EQ(log->level[kStatus], 0);
    lights->setPatternAt(LightPattern::kConverging, 600 * kMs);  // no restart
    ASSERT_TRUE(lights->render(600 * kMs).ok());
    EXPECT_EQ(log->level[kStatus], 0);
    lights->setPatternAt(LightPattern::kLost, 600 * kMs);  // restarts: on at once
    EXPECT_EQ(lights->pattern(), LightPattern::kLost);
    ASSERT_TRUE(lights->render(600 * kMs).ok());
    EXPECT_EQ(log->level[kStatus], 1);
    ASSERT_TRUE(lights->render(700 * kMs).ok());
    EXPECT_EQ(log->level[kStatus], 0);
    lights->setPattern(LightPattern::kOff);
    ASSERT_TRUE(lights->render(800 * kMs).ok());
    EXPECT_EQ(log->level[kStatus], 0);
}

TEST(StatusLightsTest, HeartbeatOnlyUsesTheFirstOutput) {
    const auto log = std::make_shared<FakeLog>();
    GpioConfig config = twoLines();
    config.status_line = -1;
    auto lights = makeLights(log, config, 1);
    ASSERT_NE(lights, nullptr);
    EXPECT_EQ(lights->describe(), "fakechip [fake] lines 2,3: heartbeat line 3");
    lights->setPatternAt(LightPattern::kConverged, 0);
    lights->setAliveAt(true, 0);
    ASSERT_TRUE(lights->render(0).ok()) << "only index 0 exists in the fake";
    const auto calls = log->callsSince(0);
    ASSERT_EQ(calls.size(), 1U);
    EXPECT_EQ(calls[0].index, 0U);
    EXPECT_TRUE(calls[0].active);
}

TEST(StatusLightsTest, StatusOnlyUsesTheFirstOutput) {
    const auto log = std::make_shared<FakeLog>();
    GpioConfig config = twoLines();
    config.heartbeat_line = -1;
    auto lights = makeLights(log, config, 1);
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverged, 0);
    lights->setAliveAt(true, 0);
    ASSERT_TRUE(lights->render(0).ok());
    const auto calls = log->callsSince(0);
    ASSERT_EQ(calls.size(), 1U);
    EXPECT_EQ(calls[0].index, 0U);
    EXPECT_TRUE(calls[0].active);
}

TEST(StatusLightsTest, RenderDoesNotAllocate) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kInitialising, 0);
    lights->setAliveAt(true, 0);
    ASSERT_TRUE(lights->render(0).ok());
    const std::int64_t before = test::allocationCount();
    for (std::int64_t t = 0; t < 5000 * kMs; t += 7 * kMs) {
        const auto result = lights->render(t);
        ASSERT_TRUE(result.ok());
    }
    EXPECT_EQ(test::allocationCount(), before);
    EXPECT_GT(log->callCount(), 20U);  // the lines did change meanwhile
}

TEST(StatusLightsTest, AnErrorIsGivenOnceUntilARenderSucceeds) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kLost, 0);
    EXPECT_FALSE(lights->takeError().has_value());

    log->fail = true;
    auto r = lights->render(0);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, "fake line: cannot set");
    auto error = lights->takeError();
    ASSERT_TRUE(error.has_value());
    EXPECT_EQ(*error, "fake line: cannot set");
    EXPECT_FALSE(lights->takeError().has_value());

    EXPECT_FALSE(lights->render(100 * kMs).ok());  // the same error again: not given again
    EXPECT_FALSE(lights->takeError().has_value());

    log->fail = false;
    ASSERT_TRUE(lights->render(100 * kMs).ok());  // lines not set before are set now
    EXPECT_EQ(log->level[kStatus], 0);
    EXPECT_EQ(log->level[kHeartbeat], 0);
    log->fail = true;
    EXPECT_FALSE(lights->render(200 * kMs).ok());
    error = lights->takeError();
    ASSERT_TRUE(error.has_value()) << "a new failure after a success is new";
}

TEST(StatusLightsTest, StopDrivesTheLinesInactiveThenReleasesThem) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverged, 0);
    lights->setAliveAt(true, 0);
    ASSERT_TRUE(lights->render(0).ok());
    EXPECT_EQ(log->level, (std::array<int, 2>{1, 1}));
    const std::size_t before = log->callCount();
    lights->stop();
    ASSERT_TRUE(log->destroyed);
    const auto calls = log->callsSince(before);
    ASSERT_EQ(calls.size(), 2U);
    EXPECT_EQ(log->count_at_destruction, before + 2);  // set inactive, then released
    EXPECT_EQ(log->level, (std::array<int, 2>{0, 0}));
    auto r = lights->render(kMs);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kUnavailable);
    lights->start();  // stopped for good: no thread
    lights.reset();   // the destructor's stop() finds nothing left to do
}

TEST(StatusLightsTest, DestructorDrivesTheLinesInactiveThenReleasesThem) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPatternAt(LightPattern::kConverged, 0);
    ASSERT_TRUE(lights->render(0).ok());
    lights.reset();
    ASSERT_TRUE(log->destroyed);
    EXPECT_EQ(log->count_at_destruction, log->callCount());
    EXPECT_EQ(log->level, (std::array<int, 2>{0, 0}));
}

TEST(StatusLightsTest, ThreadRendersChangesAndStops) {
    const auto log = std::make_shared<FakeLog>();
    auto lights = makeLights(log, twoLines());
    ASSERT_NE(lights, nullptr);
    lights->setPattern(LightPattern::kOff);
    lights->start();
    ASSERT_TRUE(log->waitFor([](FakeLog& l) { return l.level[0] == 0 && l.level[1] == 0; }))
        << "the thread's first render sets both lines";

    lights->setPattern(LightPattern::kConverged);
    ASSERT_TRUE(log->waitFor([](FakeLog& l) { return l.level[0] == 1; }));
    lights->setAlive(true);  // the heartbeat starts on
    ASSERT_TRUE(log->waitFor([](FakeLog& l) { return l.level[1] == 1; }));

    lights->stop();
    EXPECT_TRUE(log->destroyed);
    EXPECT_EQ(log->level, (std::array<int, 2>{0, 0}));
    EXPECT_FALSE(lights->takeError().has_value());
}

}  // namespace
}  // namespace scaled::daemon
