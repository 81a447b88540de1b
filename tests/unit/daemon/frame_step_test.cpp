// The frame step the daemon, scale-eval and slam-run share (frame_step.h):
// a new map's vertical asked once per map, a restart asks again, and the
// detection schedule counts the map's tracked frames.

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/daemon/frame_step.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/sim/sim_source.h>

namespace scaled::daemon {
namespace {

class FrameStepTest : public ::testing::Test {
protected:
    void SetUp() override {
        sim_.seed = 3;
        sim_.duration_s = 2.0;
        auto src = drivers::sim::openSimSource(sim_);
        ASSERT_TRUE(src.ok()) << src.error().message;
        source_ = std::move(*src);
        auto camera = core::PinholeRadialCamera::create(drivers::sim::simIntrinsics(sim_));
        ASSERT_TRUE(camera.ok()) << camera.error().message;
        auto tracker =
            drivers::vision::MonoTracker::create(*camera, defaultPipelineConfig().tracker);
        ASSERT_TRUE(tracker.ok()) << tracker.error().message;
        tracker_.emplace(std::move(*tracker));
    }

    // The next frame of the sim.
    const drivers::source::Frame& next() {
        auto got = source_->next(frame_);
        EXPECT_TRUE(got.ok() && *got);
        return frame_;
    }

    drivers::sim::SimConfig sim_;
    std::unique_ptr<drivers::source::FrameSource> source_;
    std::optional<drivers::vision::MonoTracker> tracker_;
    drivers::source::Frame frame_;
};

TEST_F(FrameStepTest, AsksForTheVerticalOncePerMapAndAgainAfterARestart) {
    FrameStep step(*tracker_);
    int asked = 0;
    const auto select = [&](const drivers::source::Frame&) {
        ++asked;
        drivers::imu::MapGravity g;
        g.down_C = core::Vec3(0, 1, 0);
        g.source = "test";
        return g;
    };
    for (int i = 0; i < 12; ++i) {
        const FrameStepResult r = step.track(next(), nullptr, select);
        ASSERT_TRUE(r.ok) << "frame " << i << ": " << core::slam::toString(r.stats.health);
        EXPECT_EQ(r.gravity != nullptr, i == 0) << "frame " << i;
        EXPECT_EQ(r.map_started, i == 0) << "frame " << i;
        EXPECT_EQ(r.frames_in_map, i + 1);
        EXPECT_FALSE(r.map_lost);
        EXPECT_GE(r.track_ms, 0.0);
    }
    ASSERT_EQ(asked, 1);
    ASSERT_EQ(step.tracker().filter().pose().p_CinW.size(), 3);

    step.restart();
    const FrameStepResult r = step.track(next(), nullptr, select);
    EXPECT_EQ(asked, 2);
    ASSERT_NE(r.gravity, nullptr);
    EXPECT_EQ(r.gravity->source, "test");
    EXPECT_TRUE(r.map_started);
    EXPECT_EQ(r.frames_in_map, 1);
}

TEST_F(FrameStepTest, DetectionIsDueOnEveryNthFrameOfTheMapButNotItsFirst) {
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.every_frames = 3;
    std::vector<std::int64_t> due;
    for (int i = 0; i < 12; ++i) {
        const drivers::source::Frame& f = next();
        const FrameStepResult r = step.track(
            f, nullptr, [](const drivers::source::Frame&) { return drivers::imu::MapGravity{}; });
        ASSERT_TRUE(r.ok);
        if (step.detectionDue(r, schedule, f.t_ns)) {
            due.push_back(r.frames_in_map);
        }
    }
    EXPECT_EQ(due, (std::vector<std::int64_t>{4, 7, 10}));
}

TEST_F(FrameStepTest, DetectionByPeriodCountsFrameTime) {
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.period_s = 0.1;  // the sim runs at 30 fps: every third or fourth frame
    std::vector<std::int64_t> due_t_ns;
    for (int i = 0; i < 15; ++i) {
        const drivers::source::Frame& f = next();
        const FrameStepResult r = step.track(
            f, nullptr, [](const drivers::source::Frame&) { return drivers::imu::MapGravity{}; });
        ASSERT_TRUE(r.ok);
        if (step.detectionDue(r, schedule, f.t_ns)) {
            due_t_ns.push_back(f.t_ns);
        }
    }
    ASSERT_GE(due_t_ns.size(), 3U);
    for (std::size_t k = 1; k < due_t_ns.size(); ++k) {
        EXPECT_GE(static_cast<double>(due_t_ns[k] - due_t_ns[k - 1]) * 1e-9, 0.1 - 1e-9);
        EXPECT_LT(static_cast<double>(due_t_ns[k] - due_t_ns[k - 1]) * 1e-9, 0.1 + 1.0 / 30 + 1e-6);
    }
}

}  // namespace
}  // namespace scaled::daemon
