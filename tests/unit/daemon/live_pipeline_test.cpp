// The pipeline with a live camera that goes away: the daemon reports the fault
// (state "fault", SCALE.fault naming the camera and the cause), reopens the
// camera with its backoff until it is back, and resumes with a new map (a new
// epoch) without a restart; stop() ends a reconnect wait. The camera is a
// scripted LiveCamera over the sim's rendered frames: the kernel's loss of a
// real device is tested in the VM (tests/vm, vm.v4l2_recover and vm.daemon).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/pipeline.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>

#include "../../../daemon/src/live_source.h"
#include "hub_wait.h"

namespace scaled::daemon {
namespace {

using test::waitUntil;

using core::ErrorCode;
using core::makeError;

// Frames from the sim; after `lose_after` frames the device is "unplugged":
// next() fails with kUnavailable and reopen() fails until the test plugs it
// back in.
class ScriptedCamera final : public drivers::camera::LiveCamera {
public:
    ScriptedCamera(std::unique_ptr<drivers::source::FrameSource> inner, int lose_after)
        : inner_(std::move(inner)), lose_after_(lose_after) {}

    [[nodiscard]] const drivers::source::SequenceInfo& info() const override {
        return inner_->info();
    }
    core::Result<bool> next(drivers::source::Frame& frame) override {
        if (stopped_) {
            return false;
        }
        std::unique_lock lock(mutex_);
        if (delivered_ == lose_after_ && !lost_once_) {
            lost_once_ = true;
            present_ = false;
            changed_.notify_all();
        }
        if (!present_ || closed_) {
            closed_ = true;
            return makeError(ErrorCode::kUnavailable,
                             "/dev/video7 (scripted): device lost: No such device");
        }
        lock.unlock();
        auto got = inner_->next(frame);
        if (got && *got) {
            const std::lock_guard relock(mutex_);
            ++delivered_;
        }
        return got;
    }
    [[nodiscard]] std::string describe() const override { return "/dev/video7 (scripted)"; }
    [[nodiscard]] std::string mode() const override { return "YUYV 320x240 @ 30"; }
    core::Result<bool> reopen() override {
        const std::lock_guard lock(mutex_);
        ++reopen_calls_;
        changed_.notify_all();
        if (!present_) {
            return makeError(ErrorCode::kUnavailable, "no V4L2 capture device named \"scripted\"");
        }
        closed_ = false;
        return true;
    }
    void stop() override { stopped_ = true; }

    void plugIn() {
        const std::lock_guard lock(mutex_);
        present_ = true;
    }
    // Waits (bounded) until reopen() has been tried at least n times.
    bool waitReopenCalls(int n, std::chrono::seconds timeout) {
        std::unique_lock lock(mutex_);
        return changed_.wait_for(lock, timeout, [&] { return reopen_calls_ >= n; });
    }
    int reopenCalls() {
        const std::lock_guard lock(mutex_);
        return reopen_calls_;
    }

private:
    std::unique_ptr<drivers::source::FrameSource> inner_;
    std::mutex mutex_;
    std::condition_variable changed_;
    int lose_after_;
    int delivered_ = 0;
    int reopen_calls_ = 0;
    bool present_ = true;
    bool closed_ = false;
    bool lost_once_ = false;
    std::atomic<bool> stopped_{false};
};

// The errors and state changes the pipeline reports (the field log's view).
class Events final : public PipelineEvents {
public:
    void onFrame(const Frame& /*frame*/) override {}
    void onDetection(const drivers::detector::DetectionResult& /*result*/, std::uint64_t /*epoch*/,
                     double /*latency_ms*/) override {}
    void onScale(const Scale& /*scale*/) override {}
    void onPose(const Pose& /*pose*/) override {}
    void onWindowBa(const WindowBa& /*window*/) override {}
    void onState(DaemonState /*from*/, DaemonState to, std::uint64_t /*epoch*/,
                 std::int64_t /*frame_id*/, const char* reason) override {
        const std::lock_guard lock(mutex_);
        states_.push_back(std::string(toString(to)) + " (" + reason + ")");
    }
    void onError(const char* where, const std::string& message) override {
        const std::lock_guard lock(mutex_);
        errors_.push_back(std::string(where) + ": " + message);
    }
    std::vector<std::string> errors() const {
        const std::lock_guard lock(mutex_);
        return errors_;
    }
    std::vector<std::string> states() const {
        const std::lock_guard lock(mutex_);
        return states_;
    }

private:
    mutable std::mutex mutex_;
    std::vector<std::string> errors_;
    std::vector<std::string> states_;
};

struct Rig {
    Events events;
    DaemonConfig config;
    std::unique_ptr<ReportHub> hub;
    ScriptedCamera* camera = nullptr;
    std::unique_ptr<Pipeline> pipeline;
};

std::unique_ptr<Rig> makeRig(int lose_after, double retry_initial_s) {
    auto rig_ptr = std::make_unique<Rig>();
    Rig& rig = *rig_ptr;
    rig.config = defaultDaemonConfig();
    rig.config.source.kind = SourceKind::kV4l2;
    rig.config.source.device = "scripted";
    rig.config.log.frame_every = 0;
    rig.config.camera.retry_initial_s = retry_initial_s;
    rig.config.camera.retry_max_s = retry_initial_s * 4;
    rig.hub = std::make_unique<ReportHub>(
        static_cast<std::size_t>(rig.config.pipeline.estimator.posterior.grid.bins));
    drivers::sim::SimConfig sim;
    sim.duration_s = 0;  // unbounded, like a camera
    PipelineParts parts;
    auto src = drivers::sim::openSimSource(sim);
    EXPECT_TRUE(src.ok()) << src.error().message;
    auto camera = std::make_unique<ScriptedCamera>(std::move(*src), lose_after);
    rig.camera = camera.get();
    parts.live = camera.get();
    parts.source = std::move(camera);
    auto det = drivers::sim::createSimDetector(sim);
    EXPECT_TRUE(det.ok()) << det.error().message;
    parts.detector = std::move(*det);
    auto priors = drivers::priors::loadPriorsFile(SCALED_SOURCE_DIR "/config/priors.toml");
    EXPECT_TRUE(priors.ok()) << priors.error().message;
    parts.priors = std::move(*priors);
    parts.source_name = "v4l2:scripted";
    parts.lossless = true;  // every frame tracked: the run does not depend on timing
    auto p = Pipeline::create(rig.config, std::move(parts), *rig.hub, &rig.events);
    EXPECT_TRUE(p.ok()) << p.error().message;
    rig.pipeline = std::move(*p);
    return rig_ptr;
}

TEST(LivePipeline, ALostCameraIsAFaultUntilItIsBackThenANewEpoch) {
    auto rig_ptr = makeRig(60, 0.01);
    Rig& rig = *rig_ptr;
    ReportHub& hub = *rig.hub;
    ASSERT_TRUE(rig.pipeline->start().ok());
    EXPECT_TRUE(hub.status().live);
    EXPECT_EQ(hub.status().camera_device, "/dev/video7 (scripted)");
    EXPECT_EQ(hub.status().camera_mode, "YUYV 320x240 @ 30");

    // Unplugged after 60 frames: a fault naming the device and the cause, and
    // reopen attempts (several: the device stays missing meanwhile).
    ASSERT_TRUE(waitUntil(
        hub, [&] { return hub.scale().state == DaemonState::kFault; }, std::chrono::seconds(120)));
    ASSERT_TRUE(rig.camera->waitReopenCalls(3, std::chrono::seconds(60)));
    const auto camera_lost = [&] { return hub.status().camera_lost; };
    ASSERT_TRUE(waitUntil(hub, camera_lost, std::chrono::seconds(10)));
    // The latest reason is shown while it is missing; each reason is logged
    // once, not at every attempt.
    ASSERT_TRUE(waitUntil(
        hub,
        [&] { return hub.scale().fault == "camera: no V4L2 capture device named \"scripted\""; },
        std::chrono::seconds(10)));
    EXPECT_EQ(hub.scale().state, DaemonState::kFault);
    const std::vector<std::string> want_errors = {
        "camera: /dev/video7 (scripted): device lost: No such device",
        "camera: no V4L2 capture device named \"scripted\""};
    EXPECT_EQ(rig.events.errors(), want_errors);
    EXPECT_FALSE(rig.pipeline->finished());
    // Every frame before the loss was tracked; none since.
    ASSERT_TRUE(waitUntil(
        hub, [&] { return hub.status().frames_tracked == 60; }, std::chrono::seconds(60)));

    // Plugged back in: frames flow, the fault clears, a new map and epoch.
    rig.camera->plugIn();
    ASSERT_TRUE(waitUntil(
        hub,
        [&] {
            const auto st = hub.status();
            return st.frames_tracked >= 150 && st.epoch >= 2 && !st.camera_lost;
        },
        std::chrono::seconds(120)));
    const PipelineStatus st = hub.status();
    EXPECT_EQ(st.camera_reconnects, 1U);
    EXPECT_EQ(st.epoch, 2U);
    const ScaleReport back = hub.scale();
    EXPECT_NE(back.state, DaemonState::kFault);
    EXPECT_TRUE(back.fault.empty()) << back.fault;
    const auto states = rig.events.states();
    bool lost = false;
    bool returned = false;
    for (const auto& s : states) {
        lost |= s == "fault (camera lost)";
        returned |= lost && s.find("(camera back)") != std::string::npos;
    }
    EXPECT_TRUE(lost && returned) << ::testing::PrintToString(states);
    rig.pipeline->stop();
    EXPECT_FALSE(rig.pipeline->failure().has_value());
}

// Shutting down while the camera is missing ends the backoff wait and the
// capture thread (the test would hang at stop() otherwise).
TEST(LivePipeline, StopEndsTheReconnectWait) {
    auto rig_ptr = makeRig(5, 3600);  // a wait of an hour before the first attempt
    Rig& rig = *rig_ptr;
    ASSERT_TRUE(rig.pipeline->start().ok());
    ASSERT_TRUE(waitUntil(
        *rig.hub, [&] { return rig.hub->scale().state == DaemonState::kFault; },
        std::chrono::seconds(60)));
    rig.pipeline->stop();
    EXPECT_FALSE(rig.pipeline->failure().has_value());
    EXPECT_EQ(rig.camera->reopenCalls(), 0);
}

// LiveSource: a camera missing at start is not an error at start: next()
// says why, reopen() opens it once it exists, and the intrinsics come from
// the configuration meanwhile.
TEST(LiveSource, StartsWithoutTheCameraAndOpensItWhenItAppears) {
    DaemonConfig c = defaultDaemonConfig();
    c.source.kind = SourceKind::kV4l2;
    c.source.device = "usbcam";
    c.camera.fx_px = 500;
    c.camera.fy_px = 501;
    c.camera.cx_px = 320;
    c.camera.cy_px = 240;
    int attempts = 0;
    bool present = false;
    CameraOpener opener = [&](const drivers::camera::CameraOptions& o)
        -> core::Result<std::unique_ptr<drivers::camera::LiveCamera>> {
        ++attempts;
        EXPECT_EQ(o.device, "usbcam");
        EXPECT_EQ(o.width_px, 640);
        EXPECT_FLOAT_EQ(static_cast<float>(o.intrinsics.fy), 501.0F);
        if (!present) {
            return makeError(ErrorCode::kNotFound, "no V4L2 capture device named \"usbcam\"");
        }
        drivers::sim::SimConfig sim;
        sim.duration_s = 0;
        auto src = drivers::sim::openSimSource(sim);
        if (!src) {
            return src.error();
        }
        return std::unique_ptr<drivers::camera::LiveCamera>(
            std::make_unique<ScriptedCamera>(std::move(*src), 1000));
    };
    LiveSource source(opener, cameraOptions(c), "v4l2:usbcam", nullptr,
                      "no V4L2 capture device named \"usbcam\"");
    EXPECT_FALSE(source.hasCamera());
    EXPECT_TRUE(source.info().has_intrinsics);
    EXPECT_FLOAT_EQ(static_cast<float>(source.info().intrinsics.fx), 500.0F);
    EXPECT_EQ(source.describe(), "v4l2:usbcam (not found)");
    drivers::source::Frame frame;
    auto got = source.next(frame);
    ASSERT_FALSE(got.ok());
    EXPECT_EQ(got.error().code, ErrorCode::kUnavailable);
    EXPECT_EQ(got.error().message, "no V4L2 capture device named \"usbcam\"");
    auto again = source.reopen();
    ASSERT_FALSE(again.ok());
    EXPECT_EQ(again.error().code, ErrorCode::kUnavailable);  // still a fault to retry
    present = true;
    ASSERT_TRUE(source.reopen().ok());
    EXPECT_EQ(attempts, 2);
    EXPECT_TRUE(source.hasCamera());
    EXPECT_EQ(source.describe(), "/dev/video7 (scripted)");
    got = source.next(frame);
    ASSERT_TRUE(got.ok()) << got.error().message;
    EXPECT_TRUE(*got);
    EXPECT_FALSE(frame.gray.empty());
    source.stop();
    got = source.next(frame);
    ASSERT_TRUE(got.ok());
    EXPECT_FALSE(*got);
}

}  // namespace
}  // namespace scaled::daemon
