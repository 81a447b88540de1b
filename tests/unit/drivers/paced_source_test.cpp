// PacedFrameSource with a fake clock: no test sleeps.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/source/paced_source.h>

namespace scaled::drivers::source {
namespace {

using core::ErrorCode;

constexpr int64_t kMs = 1000000;
constexpr int64_t kStart = 5000 * kMs;  // the fake clock's time when a test starts

// Time stands still unless a test advances it; sleepUntil() jumps to the target.
class FakeClock final : public PacingClock {
public:
    int64_t nowNs() override { return now_ns; }
    void sleepUntil(int64_t t_ns) override {
        sleeps.push_back(t_ns);
        now_ns = std::max(now_ns, t_ns);
    }
    int64_t now_ns = kStart;
    std::vector<int64_t> sleeps;
};

// Frames with the given timestamps; reading one takes `read_ns` on the clock.
class ListSource final : public FrameSource {
public:
    ListSource(std::vector<int64_t> t_ns, std::shared_ptr<FakeClock> clock, int64_t read_ns = 0)
        : t_ns_(std::move(t_ns)), clock_(std::move(clock)), read_ns_(read_ns) {
        info_.name = "list";
        info_.frame_count = t_ns_.size();
        info_.listed_count = t_ns_.size();
    }
    [[nodiscard]] const SequenceInfo& info() const override { return info_; }
    core::Result<bool> next(Frame& frame) override {
        if (cursor_ >= t_ns_.size()) {
            return false;
        }
        clock_->now_ns += read_ns_;
        frame = Frame{};
        frame.id = static_cast<int64_t>(cursor_);
        frame.t_ns = t_ns_[cursor_++];
        frame.gray = cv::Mat(1, 1, CV_8UC1, cv::Scalar(0));
        frame.color = cv::Mat(1, 1, CV_8UC3, cv::Scalar(0, 0, 0));
        return true;
    }
    core::Result<bool> seek(std::size_t index) override {
        if (index > t_ns_.size()) {
            return core::makeError(ErrorCode::kInvalidArgument, "list: seek beyond the end");
        }
        cursor_ = index;
        return index < t_ns_.size();
    }

private:
    std::vector<int64_t> t_ns_;
    std::shared_ptr<FakeClock> clock_;
    int64_t read_ns_;
    SequenceInfo info_;
    std::size_t cursor_ = 0;
};

// t_i = t0 + i * period.
std::vector<int64_t> evenTimes(int n, int64_t period_ns, int64_t t0 = 1700000000LL * 1000000000LL) {
    std::vector<int64_t> t;
    t.reserve(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
        t.push_back(t0 + i * period_ns);
    }
    return t;
}

std::unique_ptr<PacedFrameSource> paced(std::vector<int64_t> t,
                                        const std::shared_ptr<FakeClock>& clock,
                                        const PacingOptions& opt, int64_t read_ns = 0) {
    auto src = PacedFrameSource::create(std::make_unique<ListSource>(std::move(t), clock, read_ns),
                                        opt, clock);
    EXPECT_TRUE(src) << src.error().message;
    return src ? std::move(*src) : nullptr;
}

PacingOptions realTime(double speed = 1.0, bool drop = false) {
    PacingOptions opt;
    opt.mode = PacingMode::kRealTime;
    opt.speed = speed;
    opt.drop_late = drop;
    return opt;
}

// Reads everything; after each frame the consumer works for `work_ns`.
std::vector<int64_t> consume(PacedFrameSource& src, FakeClock& clock, int64_t work_ns) {
    std::vector<int64_t> ids;
    Frame f;
    while (true) {
        auto r = src.next(f);
        EXPECT_TRUE(r);
        if (!r || !*r) {
            break;
        }
        ids.push_back(f.id);
        clock.now_ns += work_ns;
    }
    return ids;
}

TEST(DatasetPacing, AsFastAsPossibleNeverWaits) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(5, 33 * kMs), clock, PacingOptions{});
    ASSERT_TRUE(src);
    EXPECT_EQ(consume(*src, *clock, 0).size(), 5U);
    EXPECT_TRUE(clock->sleeps.empty());
    EXPECT_EQ(clock->now_ns, kStart);
    EXPECT_EQ(src->stats().released, 5U);
    EXPECT_EQ(src->stats().late, 0U);
    EXPECT_EQ(src->info().name, "list");  // the inner source's info
}

TEST(DatasetPacing, RealTimeSleepsUntilEachFrameIsDue) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(4, 33 * kMs), clock, realTime());
    ASSERT_TRUE(src);
    // A fast consumer (5 ms per frame); reading is instant.
    auto ids = consume(*src, *clock, 5 * kMs);
    EXPECT_EQ(ids, (std::vector<int64_t>{0, 1, 2, 3}));
    // Frame 0 sets the origin (kStart); frame i is due at kStart + 33 i ms.
    EXPECT_EQ(clock->sleeps,
              (std::vector<int64_t>{kStart + 33 * kMs, kStart + 66 * kMs, kStart + 99 * kMs}));
    EXPECT_EQ(src->stats().slept, 3U);
    EXPECT_EQ(src->stats().late, 0U);
    EXPECT_EQ(src->stats().dropped, 0U);
}

TEST(DatasetPacing, ReadTimeCountsAgainstTheSchedule) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(3, 40 * kMs), clock, realTime(), 10 * kMs);
    ASSERT_TRUE(src);
    consume(*src, *clock, 0);
    // Origin: kStart + 10 ms (after frame 0 is read). Frame 1 is read by
    // kStart + 20 ms and due at kStart + 50 ms.
    EXPECT_EQ(clock->sleeps, (std::vector<int64_t>{kStart + 50 * kMs, kStart + 90 * kMs}));
}

TEST(DatasetPacing, SpeedFactorScalesTheSchedule) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(3, 40 * kMs), clock, realTime(2.0));
    ASSERT_TRUE(src);
    consume(*src, *clock, 0);
    EXPECT_EQ(clock->sleeps, (std::vector<int64_t>{kStart + 20 * kMs, kStart + 40 * kMs}));

    auto slow_clock = std::make_shared<FakeClock>();
    auto slow = paced(evenTimes(3, 40 * kMs), slow_clock, realTime(0.5));
    ASSERT_TRUE(slow);
    consume(*slow, *slow_clock, 0);
    EXPECT_EQ(slow_clock->sleeps, (std::vector<int64_t>{kStart + 80 * kMs, kStart + 160 * kMs}));
}

TEST(DatasetPacing, LateFramesAreCountedAndNotSlept) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(5, 33 * kMs), clock, realTime());
    ASSERT_TRUE(src);
    // A slow consumer: 50 ms per frame against a 33 ms period.
    auto ids = consume(*src, *clock, 50 * kMs);
    EXPECT_EQ(ids.size(), 5U);  // nothing dropped without drop_late
    EXPECT_TRUE(clock->sleeps.empty());
    EXPECT_EQ(src->stats().late, 4U);
    EXPECT_EQ(src->stats().dropped, 0U);
    EXPECT_EQ(src->stats().released, 5U);
    // Frame 4: due at 132 ms, asked for at 200 ms.
    EXPECT_EQ(src->stats().max_late_ns, 68 * kMs);

    // Exactly on time is not late.
    auto on_time_clock = std::make_shared<FakeClock>();
    auto on_time = paced(evenTimes(3, 33 * kMs), on_time_clock, realTime());
    ASSERT_TRUE(on_time);
    consume(*on_time, *on_time_clock, 33 * kMs);
    EXPECT_EQ(on_time->stats().late, 0U);
    EXPECT_TRUE(on_time_clock->sleeps.empty());
}

TEST(DatasetPacing, DropModeSkipsFramesMoreThanOnePeriodLate) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(10, 33 * kMs), clock, realTime(1.0, true));
    ASSERT_TRUE(src);
    // 80 ms per frame against 33 ms: frame 1 is 47 ms late at 80 ms (dropped),
    // frame 2 14 ms (kept, late); at 160 ms frame 3 is 61 ms late (dropped),
    // frame 4 28 ms (kept); at 240 ms frames 5 (75) and 6 (42) are dropped, 7
    // (9) kept; at 320 ms frame 8 (56) is dropped, 9 (23) kept.
    auto ids = consume(*src, *clock, 80 * kMs);
    EXPECT_EQ(ids, (std::vector<int64_t>{0, 2, 4, 7, 9}));
    EXPECT_EQ(src->stats().released, 5U);
    EXPECT_EQ(src->stats().dropped, 5U);
    EXPECT_EQ(src->stats().late, 4U);
    EXPECT_TRUE(clock->sleeps.empty());

    // The same at double speed (period 16.5 ms): more frames go.
    auto fast_clock = std::make_shared<FakeClock>();
    auto fast = paced(evenTimes(10, 33 * kMs), fast_clock, realTime(2.0, true));
    ASSERT_TRUE(fast);
    auto fast_ids = consume(*fast, *fast_clock, 80 * kMs);
    EXPECT_LT(fast_ids.size(), ids.size());
    EXPECT_EQ(fast->stats().released + fast->stats().dropped, 10U);
}

TEST(DatasetPacing, SeekResetsTheOrigin) {
    auto clock = std::make_shared<FakeClock>();
    auto src = paced(evenTimes(6, 100 * kMs), clock, realTime());
    ASSERT_TRUE(src);
    Frame f;
    ASSERT_TRUE(src->next(f).ok());
    ASSERT_TRUE(src->next(f).ok());  // sleeps to kStart + 100 ms
    ASSERT_EQ(clock->sleeps.size(), 1U);
    clock->now_ns += 1000 * kMs;  // a long pause: frame 2 would be very late
    auto s = src->seek(4);
    ASSERT_TRUE(s && *s);
    ASSERT_TRUE(src->next(f).ok());  // the new origin: released at once, not late
    EXPECT_EQ(f.id, 4);
    EXPECT_EQ(src->stats().late, 0U);
    const int64_t origin = clock->now_ns;
    ASSERT_TRUE(src->next(f).ok());
    EXPECT_EQ(clock->sleeps.back(), origin + 100 * kMs);
    // Back to the start: the earlier timestamp is a new origin too.
    ASSERT_TRUE(src->seek(0).ok());
    const std::size_t sleeps = clock->sleeps.size();
    ASSERT_TRUE(src->next(f).ok());
    EXPECT_EQ(f.id, 0);
    EXPECT_EQ(clock->sleeps.size(), sleeps);
    EXPECT_FALSE(src->seek(7).ok());  // errors of the inner source pass through
}

TEST(DatasetPacing, RejectsBadOptions) {
    auto clock = std::make_shared<FakeClock>();
    for (const double speed : {0.0, -1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
        auto src = PacedFrameSource::create(std::make_unique<ListSource>(evenTimes(2, kMs), clock),
                                            realTime(speed), clock);
        ASSERT_FALSE(src) << speed;
        EXPECT_EQ(src.error().code, ErrorCode::kInvalidArgument);
    }
    auto none = PacedFrameSource::create(nullptr, PacingOptions{});
    ASSERT_FALSE(none);
    // The default clock is the steady clock (not used here: no frame is read).
    auto steady = PacedFrameSource::create(std::make_unique<ListSource>(evenTimes(2, kMs), clock),
                                           realTime());
    ASSERT_TRUE(steady) << steady.error().message;
    SteadyPacingClock real;
    const int64_t a = real.nowNs();
    real.sleepUntil(a - 1);  // in the past: returns at once
    EXPECT_GE(real.nowNs(), a);
}

}  // namespace
}  // namespace scaled::drivers::source
