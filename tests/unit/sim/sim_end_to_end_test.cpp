// The whole pipeline on the sim source: the tracker (daemon defaults) on the
// rendered frames, the sim detector and the scale estimator every 10th frame
// of the map, against the true scale of the map (Sim(3) alignment of the SLAM
// camera centres with the ground truth). Figures: docs/sim.md.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <optional>
#include <span>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/detector/object_detector.h>
#include <scaled/drivers/priors_toml.h>
#include <scaled/sim/sim_source.h>
#include <scaled/vision/mono_tracker.h>

namespace scaled::sim {
namespace {

using core::Vec3;

struct EndToEnd {
    int frames = 0;
    int epochs = 1;
    int lost_frames = 0;
    int updates = 0;
    std::optional<int> converged_frame;  // first frame of the final converged run
    double map = 0;
    double rel_width95 = 0;
    std::optional<double> truth;  // true scale of the final map
    core::ScaleState state = core::ScaleState::kNoData;
    std::optional<double> truth_first;  // over the final map's first and last 600 frames
    std::optional<double> truth_last;
    double render_ms = 0;    // per frame, thread CPU time
    double tracker_ms = 0;   // per frame
    double detector_ms = 0;  // per detection
};

// CPU time of the calling thread, ms (the machine may be shared: wall time varies).
double threadCpuMs() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

std::optional<double> truthScale(std::span<const Vec3> est, std::span<const Vec3> gt) {
    if (est.size() < 3) {
        return std::nullopt;
    }
    auto a = core::alignTrajectories(est, gt, true);
    return a ? std::optional<double>(static_cast<double>(a->scale)) : std::nullopt;
}

EndToEnd runEndToEnd(const SimConfig& config, int max_frames) {
    EndToEnd r;
    auto source = openSimSource(config);
    EXPECT_TRUE(source.ok()) << source.error().message;
    auto detector = createSimDetector(config);
    EXPECT_TRUE(detector.ok()) << detector.error().message;
    auto priors = drivers::loadPriorsFile(SCALED_SOURCE_DIR "/config/priors.toml");
    EXPECT_TRUE(priors.ok()) << priors.error().message;
    if (!source || !detector || !priors) {
        return r;
    }
    const daemon::PipelineConfig pc = daemon::defaultPipelineConfig();
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    EXPECT_TRUE(camera.ok());
    auto tracker = vision::MonoTracker::create(*camera, pc.tracker);
    EXPECT_TRUE(tracker.ok()) << tracker.error().message;
    auto estimator = core::ScaleEstimator::create(pc.estimator, *priors, *camera);
    EXPECT_TRUE(estimator.ok()) << estimator.error().message;
    if (!camera || !tracker || !estimator) {
        return r;
    }

    using Clock = std::chrono::steady_clock;
    const auto ms = [](Clock::time_point a, Clock::time_point b) {
        return std::chrono::duration<double, std::milli>(b - a).count();
    };
    std::vector<core::slam::MapPoint> points;
    std::vector<core::MapFeature> features;
    std::vector<core::Detection> dets(64);
    detector::DetectionResult boxes;
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    int frames_in_map = 0;
    bool need_gravity = true;
    drivers::Frame frame;
    for (int i = 0; i < max_frames; ++i) {
        const double c0 = threadCpuMs();
        auto got = (*source)->next(frame);
        r.render_ms += threadCpuMs() - c0;
        const auto t1 = Clock::now();
        EXPECT_TRUE(got.ok() && *got);
        if (!got || !*got) {
            break;
        }
        ++r.frames;
        if (need_gravity) {
            tracker->setGravityDownC(*frame.gravity_down_C);
            need_gravity = false;
        }
        const auto stats = tracker->processFrame(frame.t_ns, frame.gray);
        r.tracker_ms += ms(t1, Clock::now());
        const bool ok = stats.health == core::slam::SlamHealth::kOk;
        if (ok && stats.new_map) {
            frames_in_map = 0;
        }
        if (!ok) {
            ++r.lost_frames;
            tracker->reset();
            estimator->reset();
            need_gravity = true;
            ++r.epochs;
            est.clear();
            gt.clear();
            frames_in_map = 0;
            r.converged_frame.reset();
            continue;
        }
        ++frames_in_map;
        const auto& slam = tracker->filter();
        est.push_back(slam.pose().p_CinW);
        gt.push_back(frame.T_CtoW_gt->p_CinW);
        if (frames_in_map > 1 && (frames_in_map - 1) % pc.detection.every_frames == 0) {
            const auto t2 = Clock::now();
            auto det = (*detector)->detect(frame.color, frame.id, frame.t_ns, boxes);
            r.detector_ms += ms(t2, Clock::now());
            EXPECT_TRUE(det.ok());
            const std::size_t n = detector::toEstimatorDetections(boxes, dets);
            slam.mapPoints(points);
            features.clear();
            for (const auto& m : points) {
                features.push_back({m.p_FinW, m.P_FinW});
            }
            const core::FrameSnapshot snapshot{slam.pose(), slam.upW(), features};
            estimator->update(snapshot, std::span(dets.data(), n));
            ++r.updates;
            const auto s = estimator->summary();
            if (s.state == core::ScaleState::kConverged) {
                if (!r.converged_frame) {
                    r.converged_frame = static_cast<int>(frame.id);
                }
            } else {
                r.converged_frame.reset();
            }
        }
    }
    const auto s = estimator->summary();
    r.state = s.state;
    r.map = static_cast<double>(s.map);
    r.rel_width95 = static_cast<double>(s.rel_width95);
    r.truth = truthScale(est, gt);
    const std::size_t part = std::min<std::size_t>(est.size(), 300);
    r.truth_first = truthScale(std::span(est).first(part), std::span(gt).first(part));
    r.truth_last = truthScale(std::span(est).last(part), std::span(gt).last(part));
    if (r.frames > 0) {
        r.render_ms /= r.frames;
        r.tracker_ms /= r.frames;
    }
    if (r.updates > 0) {
        r.detector_ms /= r.updates;
    }
    return r;
}

// 30 s at 30 fps. The posterior must have converged (and stayed so) by
// kConvergedBy, and its final MAP must be within kTolerance of the true scale
// of the map over the whole run. The tolerance is set by the tracker's scale
// drift (the map's unit grows by 10-20% over these 30 s while the camera keeps
// turning to new walls; docs/sim.md), not by the detections.
constexpr int kFrames = 900;
constexpr int kConvergedBy = 600;
constexpr double kTolerance = 0.12;

TEST(SimEndToEnd, ScaleConvergesToTheTrueScale) {
    SimConfig config;
    config.duration_s = static_cast<double>(kFrames) / config.fps;
    const EndToEnd r = runEndToEnd(config, kFrames);
    ASSERT_EQ(r.frames, kFrames);
    ASSERT_TRUE(r.truth.has_value());
    const double err = r.map / *r.truth - 1;
    std::printf(
        "sim end to end: %d frames, %d map(s), %d lost, %d updates; converged (held to the end) "
        "from frame %d; MAP %.4f, true %.4f, error %+.2f%%, ci95 width %.1f%%; true scale of the "
        "first / last 300 frames %.4f / %.4f; render %.2f "
        "ms/frame, tracker %.2f ms/frame, detector %.3f ms/call\n",
        r.frames, r.epochs, r.lost_frames, r.updates, r.converged_frame.value_or(-1), r.map,
        *r.truth, 100 * err, 100 * r.rel_width95, r.truth_first.value_or(0),
        r.truth_last.value_or(0), r.render_ms, r.tracker_ms, r.detector_ms);
    EXPECT_EQ(r.state, core::ScaleState::kConverged);
    ASSERT_TRUE(r.converged_frame.has_value());
    EXPECT_LE(*r.converged_frame, kConvergedBy);
    EXPECT_LT(std::abs(err), kTolerance);
}

}  // namespace
}  // namespace scaled::sim
