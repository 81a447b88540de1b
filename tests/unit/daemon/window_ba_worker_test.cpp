// The window adjustment's optimisations on the daemon's worker thread
// (daemon/window_ba_worker.h, tracker.window_ba_defer_frames): the same poses
// to the bit as the tracker running them itself, which is what scale-eval
// and slam-run do.

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/daemon/frame_step.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/daemon/window_ba_worker.h>
#include <scaled/drivers/sim/sim_source.h>

namespace scaled::daemon {
namespace {

struct SimRun {
    std::vector<core::CameraPose> poses;
    int optimisations = 0;
    int tracked = 0;
};

// The sim (seed 3) for duration_s and a tracker with a small window (an
// optimisation every 12 frames from frame 36 on) deferring by defer_frames.
struct SimTracker {
    std::unique_ptr<drivers::source::FrameSource> source;
    std::optional<drivers::vision::MonoTracker> tracker;
    drivers::source::Frame frame;

    // The next frame into `frame`; false at the sim's end.
    bool next() {
        auto got = source->next(frame);
        return got.ok() && *got;
    }
};

SimTracker makeSimTracker(double duration_s, int defer_frames) {
    SimTracker st;
    drivers::sim::SimConfig sim;
    sim.seed = 3;
    sim.duration_s = duration_s;
    auto source = drivers::sim::openSimSource(sim);
    EXPECT_TRUE(source.ok());
    auto camera = core::PinholeRadialCamera::create(drivers::sim::simIntrinsics(sim));
    EXPECT_TRUE(camera.ok());
    if (!source.ok() || !camera.ok()) {
        return st;
    }
    st.source = std::move(*source);
    PipelineConfig config = defaultPipelineConfig();
    auto& ba = config.tracker.window_ba;
    ba.defer_frames = defer_frames;
    ba.window_keyframes = 20;
    ba.fixed_keyframes = 8;
    ba.step_keyframes = 4;
    auto tracker = drivers::vision::MonoTracker::create(*camera, config.tracker);
    EXPECT_TRUE(tracker.ok()) << tracker.error().message;
    if (tracker.ok()) {
        st.tracker.emplace(std::move(*tracker));
    }
    return st;
}

// The sim's first 2.5 s (4 optimisations in the 75 frames), defer_frames = 2,
// and the worker or not.
SimRun runSim(bool worker) {
    SimTracker st = makeSimTracker(2.5, 2);
    SimRun run;
    if (!st.tracker) {
        return run;
    }
    std::optional<WindowBaWorker> thread;  // before the tracker's use, destroyed after it
    if (worker) {
        thread.emplace();
        st.tracker->setOptimisationRunner(&*thread);
    }
    FrameStep step(*st.tracker);
    while (st.next()) {
        const FrameStepResult r = step.track(st.frame, nullptr, [](const drivers::source::Frame&) {
            return drivers::imu::MapGravity{};
        });
        run.tracked += r.ok ? 1 : 0;
        run.optimisations += r.stats.window_ba.optimised ? 1 : 0;
        run.poses.push_back(st.tracker->pose());
    }
    return run;
}

TEST(DaemonWindowBa, TheWorkerThreadGivesTheTrackersOwnPoses) {
    const SimRun inline_run = runSim(false);
    const SimRun threaded = runSim(true);
    ASSERT_GT(inline_run.tracked, 60);
    EXPECT_GE(inline_run.optimisations, 3) << "the window was adjusted (4 when written)";
    EXPECT_EQ(threaded.optimisations, inline_run.optimisations);
    ASSERT_EQ(threaded.poses.size(), inline_run.poses.size());
    int differ = 0;
    for (std::size_t k = 0; k < threaded.poses.size(); ++k) {
        const core::CameraPose& a = threaded.poses[k];
        const core::CameraPose& b = inline_run.poses[k];
        differ += (a.p_CinW == b.p_CinW && a.R_CtoW == b.R_CtoW) ? 0 : 1;
    }
    EXPECT_EQ(differ, 0) << "frames whose pose differs";
}

TEST(DaemonWindowBa, ANewMapWaitsForTheRunningOptimisation) {
    // reset() on the frame that handed an optimisation to the worker: it waits
    // for it before the window is reset (under TSan: no race), and the next
    // map tracks and adjusts its window again.
    SimTracker st = makeSimTracker(4.0, 1);
    ASSERT_TRUE(st.tracker);
    WindowBaWorker worker;
    st.tracker->setOptimisationRunner(&worker);
    int resets = 0;
    int optimised_after = 0;
    int tracked_after = 0;
    while (st.next()) {
        const auto stats = st.tracker->processFrame(st.frame.t_ns, st.frame.gray);
        if (resets == 0 && stats.window_ba.due) {
            st.tracker->reset();
            ++resets;
        } else if (resets > 0) {
            optimised_after += stats.window_ba.optimised ? 1 : 0;
            tracked_after += stats.health == core::slam::SlamHealth::kOk ? 1 : 0;
        }
    }
    EXPECT_EQ(resets, 1) << "an optimisation was handed over";
    EXPECT_GT(tracked_after, 50);
    EXPECT_GE(optimised_after, 1) << "the new map's window was adjusted";
}

TEST(DaemonWindowBa, WaitingWithNothingStartedReturnsAtOnce) {
    WindowBaWorker worker;
    const core::slam::WindowBaReport r = worker.wait();
    EXPECT_FALSE(r.optimised);
}

}  // namespace
}  // namespace scaled::daemon
