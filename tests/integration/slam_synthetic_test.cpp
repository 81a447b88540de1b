// The tracker on rendered images of a textured room (drivers/synth): real
// pixels, exact ground truth. Trajectory accuracy, and the consistency (NEES)
// of the camera pose over Monte-Carlo runs with the scale fixed by known
// depths of the first map's features. Figures: docs/accuracy.md.

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/slam/quaternion.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled {
namespace {

using core::Scalar;
using core::Vec2;
using core::Vec3;

core::PinholeRadialCamera syntheticCamera() {
    core::CameraIntrinsics k;
    k.fx = 500;
    k.fy = 500;
    k.cx = 320;
    k.cy = 240;
    k.width_px = 640;
    k.height_px = 480;
    return core::PinholeRadialCamera::create(k).value();
}

struct SyntheticRun {
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    std::vector<double> nees;   // per frame (0 for the first)
    std::vector<bool> tracked;  // health ok on the frame
    int lost_frames = 0;
    int new_maps = 0;
    int relocalisations = 0;
    int gyro_frames = 0;              // predicted with the gyro
    Vec3 gyro_bias_C = Vec3::Zero();  // the tracker's estimate at the end
    double mean_measured = 0;
};

// Frames of the rendered sequence: its rate, and a range rendered black (a
// covered lens) that the tracker must come back from.
struct SyntheticFrames {
    double fps = drivers::synth::kDefaultFps;
    int blank_first = -1;
    int blank_end = -1;
    double speed_scale = 1;    // drivers::synth::TrajectoryConfig::speed_scale
    double shake_rms_rad = 0;  // drivers::synth::TrajectoryConfig::shake_rms_rad
    // A simulated gyro at this rate (0: none): the trajectory's angular rate
    // (camera frame) plus white noise of gyro_noise_density and a constant
    // bias of gyro_bias_radps per axis.
    double gyro_hz = 0;
    double gyro_noise_density = 2e-4;
    double gyro_bias_radps = 0;
};

// The gyro samples of a trajectory from 0 to duration_s: the body rate over
// each sample period from the poses at its ends.
std::vector<core::ImuSample> simulateGyro(const drivers::synth::Trajectory& traj, double duration_s,
                                          const SyntheticFrames& f, std::uint64_t seed) {
    std::vector<core::ImuSample> out;
    std::mt19937 rng(static_cast<std::uint32_t>(seed + 77));
    std::normal_distribution<double> white(0, f.gyro_noise_density * std::sqrt(f.gyro_hz));
    const double h = 1.0 / f.gyro_hz;
    for (double t = 0; t <= duration_s + h; t += h) {
        const core::Mat3 R0 = traj.poseAt(t - h / 2).R_CtoW;
        const core::Mat3 R1 = traj.poseAt(t + h / 2).R_CtoW;
        const Eigen::AngleAxis<Scalar> aa(R0.transpose() * R1);
        core::ImuSample s;
        s.t_ns = static_cast<std::int64_t>(std::llround(t * 1e9));
        s.accel_mps2 = Vec3(0, 0, Scalar(9.81));
        s.gyro_radps = Vec3(aa.axis() * aa.angle() / Scalar(h));
        for (int a = 0; a < 3; ++a) {
            (*s.gyro_radps)(a) += Scalar(white(rng) + f.gyro_bias_radps);
        }
        out.push_back(s);
    }
    return out;
}

// Renders and tracks n frames. known_depth: the first map's features get their
// true depth (scale fixed, metric) with a 2% prior.
SyntheticRun runSynthetic(int n_frames, std::uint64_t seed, bool known_depth,
                          const drivers::vision::TrackerConfig& base = {},
                          Scalar tracker_focal_scale = 1, const SyntheticFrames& frames = {}) {
    SyntheticRun out;
    const auto cam = syntheticCamera();
    // The camera the tracker believes in (the renderer always uses cam).
    core::CameraIntrinsics believed = cam.intrinsics();
    believed.fx *= tracker_focal_scale;
    believed.fy *= tracker_focal_scale;
    const auto tracker_cam = core::PinholeRadialCamera::create(believed).value();
    auto scene = drivers::synth::Scene::create();
    EXPECT_TRUE(scene.ok());
    drivers::synth::RenderOptions ro;
    ro.noise_sigma = 2.0;
    ro.noise_seed = seed;
    drivers::synth::Renderer renderer(*scene, ro);
    drivers::synth::TrajectoryConfig tc;
    tc.speed_scale = frames.speed_scale;
    tc.shake_rms_rad = frames.shake_rms_rad;
    auto traj = drivers::synth::Trajectory::create(tc);
    EXPECT_TRUE(traj.ok());
    const auto seq = traj->makeSequence(n_frames, frames.fps);
    std::vector<core::ImuSample> gyro;
    if (frames.gyro_hz > 0) {
        gyro = simulateGyro(*traj, double(n_frames) / frames.fps, frames, seed);
    }
    core::slam::ImuWindow imu;
    imu.samples = gyro;

    drivers::vision::TrackerConfig config = base;
    config.slam.seed = seed;
    auto tracker = drivers::vision::MonoTracker::create(tracker_cam, config);
    EXPECT_TRUE(tracker.ok());
    const core::CameraPose T0 = seq.front().pose_CtoW;
    tracker->setGravityDownC(T0.R_CtoW.transpose() * drivers::synth::gravityDirectionW());
    cv::Mat gray;
    cv::Mat depth;
    if (known_depth) {
        tracker->setDepthPrior(
            [&](const Vec2& px) -> std::optional<Scalar> {
                const float z = depth.at<float>(static_cast<int>(std::lround(px.y())),
                                                static_cast<int>(std::lround(px.x())));
                const auto ray = cam.unproject(px);
                if (!(z > 0) || !ray) {
                    return std::nullopt;
                }
                return Scalar(z) * ray->norm();
            },
            Scalar(0.02));
    }
    double measured = 0;
    for (std::size_t k = 0; k < seq.size(); ++k) {
        renderer.render(cam, seq[k].pose_CtoW, gray, &depth, k);
        const auto ki = static_cast<int>(k);
        if (ki >= frames.blank_first && ki < frames.blank_end) {
            gray.setTo(0);
        }
        const auto stats =
            tracker->processFrame(seq[k].t_ns, gray, frames.gyro_hz > 0 ? &imu : nullptr);
        out.gyro_frames += stats.gyro == core::slam::GyroCoverage::kOk ? 1 : 0;
        const bool ok = stats.health == core::slam::SlamHealth::kOk;
        out.tracked.push_back(ok);
        out.lost_frames += ok ? 0 : 1;
        out.new_maps += stats.new_map ? 1 : 0;
        out.relocalisations += stats.relocalised ? 1 : 0;
        if (!ok && stats.health != core::slam::SlamHealth::kRelocalising) {
            tracker->reset();  // what every caller does: a new map next frame
        }
        measured += stats.inliers + stats.rescued;
        // Ground truth in the first camera's frame.
        core::CameraPose truth;
        truth.R_CtoW = T0.R_CtoW.transpose() * seq[k].pose_CtoW.R_CtoW;
        truth.p_CinW = T0.R_CtoW.transpose() * (seq[k].pose_CtoW.p_CinW - T0.p_CinW);
        const core::CameraPose est = tracker->filter().pose();
        out.est.push_back(est.p_CinW);
        out.gt.push_back(truth.p_CinW);
        Eigen::Matrix<Scalar, 6, 1> e;
        e.head<3>() = truth.p_CinW - est.p_CinW;
        e.tail<3>() = core::slam::rotationError(est.R_CtoW, truth.R_CtoW);
        const auto P = tracker->filter().poseCovariance();
        out.nees.push_back(k == 0 ? 0.0 : static_cast<double>(e.dot(P.ldlt().solve(e))));
    }
    out.mean_measured = measured / double(seq.size());
    out.gyro_bias_C = tracker->gyroBiasC();
    return out;
}

TEST(SlamSynthetic, TrajectoryErrorBelowOnePercentOfThePath) {
    const auto r = runSynthetic(300, 1, false);
    EXPECT_EQ(r.lost_frames, 0);
    const auto a = core::alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok()) << a.error().message;
    const Scalar len = core::pathLength(r.gt);
    std::printf("synthetic: path %.3f m, ATE %.4f m (%.2f%%), scale %.3f, %.1f measured/frame\n",
                double(len), double(a->ate_rmse), double(100 * a->ate_rmse / len), double(a->scale),
                r.mean_measured);
    EXPECT_GT(len, 2.0);
    EXPECT_LT(a->ate_rmse, Scalar(0.01) * len);
}

// Issue 21: a covered lens for 12 frames (0.4 s of this room's brisk path)
// in the middle of the run. The filter is lost after
// tracker.slam.lost_after_frames bad frames; the tracker keeps the map and
// finds the camera in it again (the features' descriptors against the
// frame's corners, RANSAC PnP) when the image comes back: no new map, and
// one trajectory in one frame and scale before and after. (After 15 frames
// here the view has turned too far for the descriptors; redkitchen's 20-frame
// outage is in slam_redkitchen_test.cpp.)
TEST(SlamSynthetic, RelocalisesAfterACoveredLensAndKeepsTheMap) {
    SyntheticFrames frames;
    frames.blank_first = 150;
    frames.blank_end = 162;
    const auto r = runSynthetic(300, 1, false, {}, 1, frames);
    EXPECT_EQ(r.new_maps, 1) << "the first map only";
    EXPECT_EQ(r.relocalisations, 1);
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    int tracked_after = 0;
    for (std::size_t k = 0; k < r.est.size(); ++k) {
        if (r.tracked[k] &&
            (static_cast<int>(k) < frames.blank_first || static_cast<int>(k) >= frames.blank_end)) {
            est.push_back(r.est[k]);
            gt.push_back(r.gt[k]);
            tracked_after += static_cast<int>(k) >= frames.blank_end ? 1 : 0;
        }
    }
    EXPECT_GE(tracked_after, 120) << "back within a few frames of the light";
    const auto a = core::alignTrajectories(est, gt);
    ASSERT_TRUE(a.ok()) << a.error().message;
    const Scalar len = core::pathLength(gt);
    std::printf("covered lens: %d frames not tracked, ATE %.2f%% of the path over both parts\n",
                r.lost_frames, double(100 * a->ate_rmse / len));
    EXPECT_LT(a->ate_rmse, Scalar(0.02) * len);
}

// Issue 21: the same room at 10 Hz (three times the motion per frame). The
// gate ellipses outgrow the full-resolution search budget; the coarse-to-fine
// search finds the features at a pyramid level and refines them, and every
// frame is tracked in one map. Without the pyramid the same run loses the map.
TEST(SlamSynthetic, TracksATenHertzSequenceWithTheCoarseToFineSearch) {
    SyntheticFrames frames;
    frames.fps = 10;
    const auto r = runSynthetic(150, 1, false, {}, 1, frames);
    EXPECT_EQ(r.lost_frames, 0);
    EXPECT_EQ(r.new_maps, 1);
    const auto a = core::alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok()) << a.error().message;
    const Scalar len = core::pathLength(r.gt);
    std::printf("10 Hz: ATE %.2f%% of the path\n", double(100 * a->ate_rmse / len));
    EXPECT_LT(a->ate_rmse, Scalar(0.03) * len);

    drivers::vision::TrackerConfig no_pyramid;
    no_pyramid.pyramid_levels = 0;
    no_pyramid.relocalise_s = 0;
    const auto flat = runSynthetic(150, 1, false, no_pyramid, 1, frames);
    EXPECT_GT(flat.new_maps, 1) << "without the pyramid the map is lost";
}

// Issue 21, the gyro motion prior: the room walked four times as fast, seen
// at 10 Hz. Measured (seed 1, docs/slam.md "The gyro prior"): constant
// velocity loses the camera on 89 of 150 frames (ATE 3.8%; 66 on 49456a4 with
// MonoSLAM's velocity noise, 8 with the random walk); with a 200 Hz gyro
// (2e-4 rad/s/sqrt(Hz), a bias of 0.03 rad/s on each axis, beyond the 0.02
// the tracker assumes) every frame is tracked, one map, ATE 1.3% (0.6% with
// 0.01 rad/s). The on-line bias estimate moves toward the bias, slowly: 0.003,
// 0.002, 0.009 rad/s after 15 s (the map takes part of a constant bias as a
// slow turn of the whole world, which monocular SLAM cannot see).
TEST(SlamSynthetic, AGyroKeepsAFastCameraAtTenHertz) {
    SyntheticFrames frames;
    frames.fps = 10;
    frames.speed_scale = 4;
    frames.gyro_hz = 200;
    frames.gyro_bias_radps = 0.03;
    const auto r = runSynthetic(150, 1, false, {}, 1, frames);
    EXPECT_EQ(r.gyro_frames, 149);
    std::printf(
        "gyro bias estimate after 15 s: %.4f %.4f %.4f rad/s (true 0.03 each, camera "
        "frame = gyro frame)\n",
        double(r.gyro_bias_C.x()), double(r.gyro_bias_C.y()), double(r.gyro_bias_C.z()));
    for (int a = 0; a < 3; ++a) {
        EXPECT_GT(r.gyro_bias_C(a), Scalar(0)) << a << ": the estimate moves the wrong way";
        EXPECT_LT(r.gyro_bias_C(a), Scalar(0.045)) << a;
    }
    EXPECT_GT(r.gyro_bias_C.sum() / 3, Scalar(0.003));
    EXPECT_EQ(r.lost_frames, 0);
    EXPECT_EQ(r.new_maps, 1);
    const auto a = core::alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok()) << a.error().message;
    const Scalar len = core::pathLength(r.gt);
    std::printf("4x speed at 10 Hz with a gyro: ATE %.2f%% of the path\n",
                double(100 * a->ate_rmse / len));
    EXPECT_LT(a->ate_rmse, Scalar(0.02) * len);

    // The two motion models without a gyro, compared without the start check
    // (with it, MonoSLAM's noise lost 2 frames here and the random walk 8:
    // which start the check restarts decides more than the model does).
    frames.gyro_hz = 0;
    drivers::vision::TrackerConfig no_check;
    no_check.start_check_s = 0;
    drivers::vision::TrackerConfig monoslam = no_check;
    monoslam.slam.motion.reference_hz = 0;
    const auto cv = runSynthetic(150, 1, false, monoslam, 1, frames);
    EXPECT_GT(cv.lost_frames, 10) << "without the gyro, with MonoSLAM's noise, the camera is lost";
    // The velocity's noise as a random walk (the default) loses fewer.
    const auto walk = runSynthetic(150, 1, false, no_check, 1, frames);
    std::printf(
        "without a gyro: %d frames lost with MonoSLAM's velocity noise, %d with the "
        "random walk\n",
        cv.lost_frames, walk.lost_frames);
    EXPECT_LT(walk.lost_frames, cv.lost_frames);
}

// Issue 19: the map's scale holds on the rendered room when the camera model
// is right (600 frames, seeds 1 and 2: thirds within 8%, the 150-frame window
// scale within 15%), and it does not when the focal length the tracker
// believes is 12% long, the kind of error the shared redkitchen's camera.txt
// appears to carry (docs/slam.md): the same filter then drifts like it does
// on redkitchen. What the tracker's scale needs first is a right camera.
TEST(SlamSynthetic, TheMapsScaleHoldsWhenTheCameraModelIsRight) {
    for (const std::uint64_t seed : {std::uint64_t{1}, std::uint64_t{2}}) {
        const auto r = runSynthetic(600, seed, false);
        EXPECT_EQ(r.lost_frames, 0);
        const auto thirds = core::scaleDriftBetweenThirds(r.est, r.gt);
        const auto w = core::slidingWindowScales(r.est, r.gt, 150);
        ASSERT_TRUE(thirds && w);
        std::printf("synthetic seed %d: thirds %.3f, window range %.3f\n", int(seed),
                    double(*thirds), double(w->range));
        EXPECT_NEAR(*thirds, 1, 0.08) << "seed " << seed;
        EXPECT_LT(w->range, 1.15) << "seed " << seed;
    }
    const auto off = runSynthetic(600, 1, false, {}, Scalar(1.12));
    const auto w = core::slidingWindowScales(off.est, off.gt, 150);
    ASSERT_TRUE(w);
    std::printf("synthetic, focal 12%% long: window range %.3f\n", double(w->range));
    EXPECT_GT(w->range, 1.15);
}

// A shaken camera (0.008 rad RMS per axis at 2-8 Hz: angular accelerations of
// 10-20 rad/s^2 against the motion model's sigma_alpha of 1) jolts each frame
// by up to 10 px more than the constant-velocity guess. The rotation check
// (tracker.rotation_check_radps) predicts those frames with the small images'
// rotation: one map, no frame lost. Without it the filter loses the camera
// (docs/slam.md "The rotation check").
TEST(SlamSynthetic, TheRotationCheckKeepsAShakenCamerasMap) {
    SyntheticFrames shaken;
    shaken.shake_rms_rad = 0.008;
    const auto r = runSynthetic(300, 1, false, {}, 1, shaken);
    const auto a = core::alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok());
    const Scalar len = core::pathLength(r.gt);
    std::printf("shaken, rotation check: ATE %.2f%%, %d lost, %d relocalisations, %d maps\n",
                double(100 * a->ate_rmse / len), r.lost_frames, r.relocalisations, r.new_maps);
    EXPECT_EQ(r.lost_frames, 0);
    EXPECT_EQ(r.relocalisations, 0);
    EXPECT_EQ(r.new_maps, 1);
    EXPECT_LT(a->ate_rmse, Scalar(0.015) * len);

    drivers::vision::TrackerConfig off;
    off.rotation_check_radps = 0;
    const auto o = runSynthetic(300, 1, false, off, 1, shaken);
    const auto o_a = core::alignTrajectories(o.est, o.gt);
    std::printf("shaken, no rotation check: ATE %.2f%%, %d lost, %d relocalisations, %d maps\n",
                o_a.ok() ? double(100 * o_a->ate_rmse / len) : -1.0, o.lost_frames,
                o.relocalisations, o.new_maps);
    EXPECT_GT(o.lost_frames, 0) << "the shake no longer needs the check: make it stronger";
}

double meanPoseNees(const drivers::vision::TrackerConfig& config) {
    constexpr int kRuns = 4;
    constexpr int kFrames = 150;
    std::vector<double> sum(kFrames, 0.0);
    for (int run = 0; run < kRuns; ++run) {
        const auto r = runSynthetic(kFrames, 10 + static_cast<std::uint64_t>(run), true, config);
        EXPECT_EQ(r.lost_frames, 0);
        const auto a = core::alignTrajectories(r.est, r.gt);
        EXPECT_TRUE(a.ok());
        if (a) {
            EXPECT_NEAR(a->scale, 1, 0.1) << "the known depths fix the scale";
        }
        for (int k = 0; k < kFrames; ++k) {
            sum[static_cast<size_t>(k)] += r.nees[static_cast<size_t>(k)];
        }
    }
    double mean = 0;
    for (int k = 1; k < kFrames; ++k) {
        mean += sum[static_cast<size_t>(k)] / kRuns;
    }
    mean /= kFrames - 1;
    std::printf(
        "synthetic images: mean pose NEES %.2f over %d runs x %d frames (6 dof: 6 is "
        "consistent); sigma_a %.1f, sigma_alpha %.1f, pixel sigma %.2f\n",
        mean, kRuns, kFrames, double(config.slam.motion.sigma_a),
        double(config.slam.motion.sigma_alpha), double(config.slam.pixel_sigma_px));
    return mean;
}

TEST(SlamSynthetic, PoseNeesOverMonteCarloRuns) {
    // With the defaults (noise tuned for handheld real data: 1 px, sigma_a 8)
    // the filter is conservative on this smooth, sharp synthetic sequence:
    // NEES well below 6 (docs/accuracy.md). The filter's own consistency with
    // matching noise models is shown at point level (SlamConsistency, NEES 5.2).
    const double mean = meanPoseNees({});
    EXPECT_GT(mean, 0.01);
    EXPECT_LT(mean, 6.0);
}

}  // namespace
}  // namespace scaled
