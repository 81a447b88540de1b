// The frame step the daemon, scale-eval and slam-run share (frame_step.h):
// a new map's vertical asked once per map, a restart asks again, and the
// detection schedule counts the map's frames, those spent relocalising in it
// included, so a relocalisation keeps its phase.

#include <algorithm>
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
        reopen(2.0);
        auto camera = core::PinholeRadialCamera::create(drivers::sim::simIntrinsics(sim_));
        ASSERT_TRUE(camera.ok()) << camera.error().message;
        auto tracker =
            drivers::vision::MonoTracker::create(*camera, defaultPipelineConfig().tracker);
        ASSERT_TRUE(tracker.ok()) << tracker.error().message;
        tracker_.emplace(std::move(*tracker));
    }

    void reopen(double duration_s) {
        sim_.duration_s = duration_s;
        auto src = drivers::sim::openSimSource(sim_);
        ASSERT_TRUE(src.ok()) << src.error().message;
        source_ = std::move(*src);
    }

    // Tracks the next n frames (all must be tracked) and returns the map's
    // frame numbers (FrameStepResult::frames_in_map) of those due.
    std::vector<std::int64_t> dueFramesInMap(FrameStep& step, const DetectionSchedule& schedule,
                                             int n) {
        std::vector<std::int64_t> due;
        for (int i = 0; i < n; ++i) {
            const drivers::source::Frame& f = next();
            const FrameStepResult r = step.track(f, nullptr, [](const drivers::source::Frame&) {
                return drivers::imu::MapGravity{};
            });
            EXPECT_TRUE(r.ok) << "frame " << i;
            if (step.detectionDue(r, schedule, f.t_ns)) {
                due.push_back(r.frames_in_map);
            }
        }
        return due;
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
    schedule.min_map_age_s = 0;
    const std::vector<std::int64_t> due = dueFramesInMap(step, schedule, 12);
    EXPECT_EQ(due, (std::vector<std::int64_t>{4, 7, 10}));
}

TEST_F(FrameStepTest, NothingIsDueInTheMapsFirstSeconds) {
    // min_map_age_s of frame time from the map's first frame: the sim runs at
    // 30 fps, so 0.25 s is frames 0-7 (t = 0.233 s at frame 7); the schedule
    // keeps its phase (every third frame from the map's first).
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.every_frames = 3;
    schedule.min_map_age_s = 0.25;
    EXPECT_EQ(dueFramesInMap(step, schedule, 15), (std::vector<std::int64_t>{10, 13}));
}

TEST_F(FrameStepTest, ThePhaseChoosesWhichFrameOfEachPeriodIsDue) {
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.every_frames = 3;
    schedule.phase_frames = 2;
    schedule.min_map_age_s = 0;
    const std::vector<std::int64_t> due = dueFramesInMap(step, schedule, 12);
    EXPECT_EQ(due, (std::vector<std::int64_t>{3, 6, 9, 12}));
}

TEST_F(FrameStepTest, ARelocalisationKeepsTheDetectionSchedulesPhase) {
    // 60 frames tracked, 12 black (the tracker loses the camera and looks for
    // it in the same map), then the scene again: the frames due are the same
    // frames of the sequence as without the outage (every third from the
    // map's first), however many frames the relocalisation took. Counting
    // only tracked frames shifted the schedule by the outage and changed
    // which views the scale estimator got (docs/accuracy.md).
    reopen(4.0);
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.every_frames = 3;
    schedule.min_map_age_s = 0;
    std::vector<std::int64_t> due;
    std::vector<std::int64_t> tracked_after;
    int relocalising = 0;
    for (int i = 0; i < 115; ++i) {
        drivers::source::Frame f = next();
        if (i >= 60 && i < 72) {
            f.gray = cv::Mat::zeros(f.gray.size(), f.gray.type());
        }
        const FrameStepResult r = step.track(
            f, nullptr, [](const drivers::source::Frame&) { return drivers::imu::MapGravity{}; });
        ASSERT_FALSE(r.map_lost) << "frame " << i;
        ASSERT_FALSE(r.map_started && i > 0) << "frame " << i << " started a new map";
        const bool looking = r.stats.health == core::slam::SlamHealth::kRelocalising;
        if (r.ok || looking) {
            EXPECT_EQ(r.frames_in_map, i + 1) << "frame " << i;
        }
        relocalising += looking ? 1 : 0;
        if (r.ok && i >= 72) {
            tracked_after.push_back(i);
        }
        if (step.detectionDue(r, schedule, f.t_ns)) {
            ASSERT_TRUE(r.ok) << "frame " << i;
            due.push_back(i);
        }
    }
    ASSERT_GT(relocalising, 0) << "the black frames never made the tracker look for the camera";
    ASSERT_GE(tracked_after.size(), 10U) << "the camera was not found again in the map";
    for (const std::int64_t i : due) {
        EXPECT_EQ(i % 3, 0) << "frame " << i << " was due out of phase";
    }
    // Every tracked frame after the outage whose number is a multiple of 3 is due.
    for (const std::int64_t i : tracked_after) {
        EXPECT_EQ(std::find(due.begin(), due.end(), i) != due.end(), i % 3 == 0) << "frame " << i;
    }
}

TEST_F(FrameStepTest, DetectionByPeriodCountsFrameTime) {
    FrameStep step(*tracker_);
    DetectionSchedule schedule;
    schedule.period_s = 0.1;  // the sim runs at 30 fps: every third or fourth frame
    schedule.min_map_age_s = 0;
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
