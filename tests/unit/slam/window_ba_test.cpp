// The window bundle adjustment (core/slam/window_ba.h) on a synthetic scene:
// a filter whose unit shrinks by 30% over 10 s, the adjusted trajectory that
// holds it, no allocation once running.

#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/slam/quaternion.h>
#include <scaled/core/slam/window_ba.h>

#include "allocation_counter.h"
#include "scene.h"

namespace scaled::core::slam {
namespace {

constexpr int kFrames = 300;
constexpr Scalar kPi = Scalar(3.14159265358979);

// Uniform draws in [lo, hi) from a 64-bit LCG: the scenes are the same on
// every platform.
class Uniform {
public:
    explicit Uniform(std::uint64_t seed) : rng_(seed) {}
    Scalar operator()(Scalar lo, Scalar hi) {
        rng_ = rng_ * 6364136223846793005ULL + 1442695040888963407ULL;
        return lo + (hi - lo) * Scalar(rng_ >> 11) / Scalar(1ULL << 53);
    }

private:
    std::uint64_t rng_;
};

// Point i seen in frame k at px: kept when inside the 640x480 image, with a
// deterministic +-0.5 px error.
void pushObserved(size_t i, int k, const std::optional<Vec2>& px,
                  std::vector<FeatureObservation>& out) {
    if (!px || px->x() < 0 || px->y() < 0 || px->x() > 639 || px->y() > 479) {
        return;
    }
    const auto h = static_cast<Scalar>((i * 2654435761U + static_cast<size_t>(k) * 97U) % 1000);
    const Scalar e = (h / 1000 - Scalar(0.5));
    out.push_back({i + 1, *px + Vec2(e, -e)});
}

struct Scene {
    std::vector<Vec3> points;
    std::vector<CameraPose> truth;
    std::vector<CameraPose> filter;  // the truth with a shrinking unit
};

// 400 points 3-6 units ahead; the camera slides 2 units sideways and 0.6
// forward while turning +-0.15 rad; the filter's unit shrinks linearly from 1
// to 0.7 along the way (its steps are the true steps times that factor).
Scene makeScene() {
    Scene s;
    Uniform uniform(12345);
    for (int i = 0; i < 400; ++i) {
        s.points.emplace_back(uniform(-4, 4), uniform(-1.5, 1.5), uniform(3, 6));
    }
    Vec3 p_filter = Vec3::Zero();
    for (int k = 0; k < kFrames; ++k) {
        const Scalar u = Scalar(k) / Scalar(kFrames - 1);
        CameraPose T;
        T.p_CinW = Vec3(-1 + 2 * u, Scalar(0.1) * std::sin(Scalar(6.28) * u), Scalar(0.6) * u);
        T.R_CtoW =
            Eigen::AngleAxis<Scalar>(Scalar(0.15) * std::sin(Scalar(9.42) * u), Vec3::UnitY())
                .toRotationMatrix();
        if (k > 0) {
            const Scalar unit = 1 - Scalar(0.3) * u;
            p_filter += unit * (T.p_CinW - s.truth.back().p_CinW);
        }
        CameraPose F = T;
        F.p_CinW = p_filter;
        s.truth.push_back(T);
        s.filter.push_back(F);
    }
    return s;
}

// The features a frame sees (at most 160), with pushObserved()'s error.
void observe(const Scene& s, const PinholeRadialCamera& cam, int k,
             std::vector<FeatureObservation>& out) {
    out.clear();
    for (size_t i = 0; i < s.points.size() && out.size() < 160; ++i) {
        const CameraPose& T = s.truth[static_cast<size_t>(k)];
        const Vec3 p_C = T.R_CtoW.transpose() * (s.points[i] - T.p_CinW);
        pushObserved(i, k, cam.project(p_C), out);
    }
}

Scalar windowRange(const std::vector<CameraPose>& poses, const Scene& s) {
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    for (size_t k = 0; k < poses.size(); ++k) {
        est.push_back(poses[k].p_CinW);
        gt.push_back(s.truth[k].p_CinW);
    }
    const auto w = slidingWindowScales(est, gt, 150);
    EXPECT_TRUE(w.ok());
    return w.ok() ? w->range : Scalar(0);
}

TEST(WindowBa, ValidateNamesTheField) {
    WindowBaConfig c;
    c.fixed_keyframes = c.window_keyframes - 1;
    const auto r = validate(c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("window_ba.fixed_keyframes"), std::string::npos);
    c = WindowBaConfig{};
    c.huber_px = 0;
    EXPECT_FALSE(WindowBa::create(test::makeCamera(), c).ok());
}

TEST(WindowBa, HoldsTheUnitTheFilterLoses) {
    const Scene s = makeScene();
    const auto cam = test::makeCamera();
    WindowBaConfig config;
    config.enabled = true;
    auto ba = WindowBa::create(cam, config);
    ASSERT_TRUE(ba.ok()) << ba.error().message;
    std::vector<FeatureObservation> obs;
    obs.reserve(160);
    std::vector<CameraPose> served;
    int optimisations = 0;
    Scalar rms_after = 0;
    Scalar max_unit = 0;
    std::int64_t allocations = -1;
    EXPECT_TRUE(ba->adjustedFromFilter().isIdentity()) << "no keyframe yet";
    Sim3 last_T;
    int steps_checked = 0;
    for (int k = 0; k < kFrames; ++k) {
        observe(s, cam, k, obs);
        const std::int64_t before = test::allocationCount();
        const WindowBaReport r = ba->addFrame(s.filter[static_cast<size_t>(k)], obs);
        if (optimisations > 0) {
            allocations = std::max<std::int64_t>(allocations, 0) + test::allocationCount() - before;
        }
        if (r.optimised) {
            ++optimisations;
            rms_after = r.rms_after_px;
            EXPECT_GT(r.points, 100);
        }
        served.push_back(ba->adjustedPose(s.filter[static_cast<size_t>(k)]));
        // Between keyframes the served camera moves as the filter's, its
        // translation times the unit ratio: the similarity's scale.
        const Sim3 T = ba->adjustedFromFilter();
        if (k > 0 && T.scale == last_T.scale && T.R == last_T.R && T.t == last_T.t) {
            const CameraPose& f0 = s.filter[static_cast<size_t>(k - 1)];
            const CameraPose& f1 = s.filter[static_cast<size_t>(k)];
            const CameraPose& s0 = served[served.size() - 2];
            const CameraPose& s1 = served.back();
            const Vec3 filter_step = f0.R_CtoW.transpose() * (f1.p_CinW - f0.p_CinW);
            const Vec3 served_step = s0.R_CtoW.transpose() * (s1.p_CinW - s0.p_CinW);
            EXPECT_LT((served_step - T.scale * filter_step).norm(),
                      Scalar(1e-4) * std::max(Scalar(1), filter_step.norm()))
                << "frame " << k;
            const Mat3 served_turn = s0.R_CtoW.transpose() * s1.R_CtoW;
            const Mat3 filter_turn = f0.R_CtoW.transpose() * f1.R_CtoW;
            EXPECT_LT((served_turn - filter_turn).norm(), Scalar(1e-4)) << "frame " << k;
            ++steps_checked;
        }
        last_T = T;
        if (optimisations > 0) {
            max_unit = std::max(max_unit, std::abs(T.scale - 1));
        }
    }
    EXPECT_GT(max_unit, Scalar(0.05)) << "the served unit never left the filter's";
    EXPECT_GT(steps_checked, kFrames / 2);
    EXPECT_GE(optimisations, 5);
    EXPECT_LT(rms_after, Scalar(0.6));
    EXPECT_EQ(allocations, 0) << "addFrame allocated once running";
    const Scalar filter_range = windowRange(s.filter, s);
    const Scalar served_range = windowRange(served, s);
    EXPECT_GT(filter_range, Scalar(1.15));
    EXPECT_LT(served_range, Scalar(1.05)) << "the filter's: " << filter_range;
}

TEST(WindowBa, HandsTheFilterTheScaleItLostWithFeedback) {
    const Scene s = makeScene();
    const auto cam = test::makeCamera();
    WindowBaConfig config;
    config.enabled = true;
    config.scale_feedback = true;
    config.max_scale_step = 1;
    auto ba = WindowBa::create(cam, config);
    ASSERT_TRUE(ba.ok());
    std::vector<FeatureObservation> obs;
    Scalar last_scale = 1;
    for (int k = 0; k < kFrames; ++k) {
        observe(s, cam, k, obs);
        const WindowBaReport r = ba->addFrame(s.filter[static_cast<size_t>(k)], obs);
        if (r.optimised) {
            last_scale = r.scale;
        }
    }
    // The synthetic filter is not rescaled, so the last optimisation sees the
    // whole shrink of its window: units 0.70-0.86 against the held ~0.9.
    EXPECT_GT(last_scale, Scalar(1.1));
    EXPECT_LT(last_scale, Scalar(1.5));
}

TEST(WindowBa, ADeferredOptimisationIsTheSameOneTakenLater) {
    // defer_frames = 2: addFrame() only says an optimisation is due; run as
    // the tracker runs it (runDue() now, finishDue() two frames later, the
    // frames in between not given to the window), it gives the same adjusted
    // keyframes to the bit, and the served pose is the immediate run's from
    // the frame the result is taken on until the next one is due.
    const Scene s = makeScene();
    const auto cam = test::makeCamera();
    WindowBaConfig now_config;
    WindowBaConfig later_config;
    later_config.defer_frames = 2;
    auto now = WindowBa::create(cam, now_config);
    auto later = WindowBa::create(cam, later_config);
    ASSERT_TRUE(now.ok() && later.ok());
    std::vector<FeatureObservation> obs;
    int due_at = -1;
    int optimisations = 0;
    int same = 0;
    WindowBaReport done;
    for (int k = 0; k < kFrames; ++k) {
        observe(s, cam, k, obs);
        const CameraPose& F = s.filter[static_cast<size_t>(k)];
        const WindowBaReport r_now = now->addFrame(F, obs);
        EXPECT_FALSE(r_now.due);
        if (due_at >= 0 && k - due_at < later_config.defer_frames) {
            continue;  // running: the tracker gives the window nothing
        }
        if (due_at >= 0) {
            later->finishDue(k - due_at - 1);
            due_at = -1;
            EXPECT_TRUE(done.optimised);
        }
        const WindowBaReport r_later = later->addFrame(F, obs);
        EXPECT_FALSE(r_later.optimised) << "frame " << k;
        if (r_later.due) {
            EXPECT_TRUE(r_now.optimised) << "frame " << k;
            done = later->runDue();
            EXPECT_EQ(done.rms_after_px, r_now.rms_after_px);
            ++optimisations;
            due_at = k;
            continue;
        }
        const Sim3 a = now->adjustedFromFilter();
        const Sim3 b = later->adjustedFromFilter();
        EXPECT_TRUE(a.scale == b.scale && a.R == b.R && a.t == b.t) << "frame " << k;
        ++same;
    }
    EXPECT_GE(optimisations, 5);
    EXPECT_GT(same, kFrames - 3 * optimisations - 1);

    WindowBaConfig bad;
    bad.defer_frames = bad.keyframe_every;
    const auto r = validate(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("window_ba.defer_frames"), std::string::npos);
}

// A camera with a rolling shutter, turning fast (0.3 rad about y at 0.5 Hz:
// up to 0.94 rad/s, a handheld pan) while it slides: each row of a frame is
// seen from the true camera at its own time, 30 ms from the first row to the
// last. The filter's poses and velocities are the truth at the frame's time.
struct RollingShutterScene {
    std::vector<Vec3> points;
    std::vector<CameraPose> truth;
    std::vector<Vec3> v_W;
    std::vector<Vec3> w_C;
};

CameraPose rollingTruth(Scalar t) {
    CameraPose T;
    T.p_CinW = Vec3(Scalar(0.2) * t, Scalar(0.05) * std::sin(2 * kPi * Scalar(0.3) * t), 0);
    T.R_CtoW =
        Eigen::AngleAxis<Scalar>(Scalar(0.3) * std::sin(kPi * t), Vec3::UnitY()).toRotationMatrix();
    return T;
}

RollingShutterScene makeRollingShutterScene() {
    RollingShutterScene s;
    Uniform uniform(777);
    for (int i = 0; i < 600; ++i) {
        s.points.emplace_back(uniform(-5, 7), uniform(-1.5, 1.5), uniform(3, 6));
    }
    for (int k = 0; k < kFrames; ++k) {
        const Scalar t = Scalar(k) / 30;
        s.truth.push_back(rollingTruth(t));
        s.v_W.emplace_back(
            Scalar(0.2), Scalar(0.05) * 2 * kPi * Scalar(0.3) * std::cos(2 * kPi * Scalar(0.3) * t),
            0);
        s.w_C.emplace_back(0, Scalar(0.3) * kPi * std::cos(kPi * t), 0);
    }
    return s;
}

// The features frame k sees (at most 160), each from the camera at its row's
// time (three fixed-point passes: the row is where the point lands), with
// pushObserved()'s error.
void observeRolling(const RollingShutterScene& s, const PinholeRadialCamera& cam, int k,
                    Scalar readout_s, std::vector<FeatureObservation>& out) {
    out.clear();
    for (size_t i = 0; i < s.points.size() && out.size() < 160; ++i) {
        Scalar row = Scalar(cam.height() - 1) / 2;
        std::optional<Vec2> px;
        for (int pass = 0; pass < 3; ++pass) {
            const CameraPose T =
                rollingTruth(Scalar(k) / 30 + readout_s * row / Scalar(cam.height() - 1));
            px = cam.project(T.R_CtoW.transpose() * (s.points[i] - T.p_CinW));
            if (!px) {
                break;
            }
            row = px->y();
        }
        pushObserved(i, k, px, out);
    }
}

struct RollingShutterRun {
    Scalar rms_after_px = 0;
    Scalar max_position_error = 0;  // served keyframe positions against the truth
    Scalar max_rotation_error_rad = 0;
    int optimisations = 0;
    std::int64_t allocations = 0;  // by addFrame() once it has optimised
    Scalar readout_s = 0;          // the last optimisation's
    Scalar focal_scale = 1;        // the last optimisation's
    Scalar k1 = 0;                 // the last optimisation's
};

// The window given model_readout_s (estimating it from there with
// sigma_s > 0) on images whose rows are read in true_readout_s.
// With focal_factor != 1 the window is given a camera whose focal length is
// that factor times the images' (estimating it from there with
// focal_sigma_rel > 0). The images' radial distortion is true_k1; the
// window is given none (estimating it with k1_sigma > 0), or true_k1 with
// give_k1.
RollingShutterRun runRolling(Scalar model_readout_s, Scalar true_readout_s = Scalar(0.03),
                             Scalar sigma_s = 0, Scalar max_s = Scalar(0.05),
                             Scalar focal_factor = 1, Scalar focal_sigma_rel = 0,
                             Scalar true_k1 = 0, Scalar k1_sigma = 0, bool give_k1 = false,
                             Scalar focal_max_rel = Scalar(0.3)) {
    const RollingShutterScene s = makeRollingShutterScene();
    const auto cam = test::makeCamera(true_k1);
    WindowBaConfig config;
    config.rolling_shutter_s = model_readout_s;
    config.rolling_shutter_sigma_s = sigma_s;
    config.rolling_shutter_max_s = max_s;
    config.focal_sigma_rel = focal_sigma_rel;
    config.k1_sigma = k1_sigma;
    config.focal_max_rel = focal_max_rel;
    CameraIntrinsics model_k = cam.intrinsics();
    model_k.k1 = give_k1 ? true_k1 : 0;
    model_k.fx *= focal_factor;
    model_k.fy *= focal_factor;
    auto ba = WindowBa::create(PinholeRadialCamera::create(model_k).value(), config);
    RollingShutterRun out;
    if (!ba.ok()) {
        ADD_FAILURE() << ba.error().message;
        return out;
    }
    std::vector<FeatureObservation> obs;
    obs.reserve(160);
    for (int k = 0; k < kFrames; ++k) {
        observeRolling(s, cam, k, true_readout_s, obs);
        const size_t ks = static_cast<size_t>(k);
        const std::int64_t before = test::allocationCount();
        const WindowBaReport r = ba->addFrame(s.truth[ks], obs, s.v_W[ks], s.w_C[ks]);
        if (out.optimisations > 0) {
            out.allocations += test::allocationCount() - before;
        }
        if (r.optimised) {
            ++out.optimisations;
            out.rms_after_px = r.rms_after_px;
            out.readout_s = r.rolling_shutter_s;
            out.focal_scale = r.focal_scale;
            out.k1 = r.k1;
        }
        if (out.optimisations > 0 && k % config.keyframe_every == 0) {
            const CameraPose served = ba->adjustedPose(s.truth[ks]);
            out.max_position_error =
                std::max(out.max_position_error, (served.p_CinW - s.truth[ks].p_CinW).norm());
            out.max_rotation_error_rad =
                std::max(out.max_rotation_error_rad,
                         rotationError(served.R_CtoW, s.truth[ks].R_CtoW).norm());
        }
    }
    return out;
}

TEST(WindowBa, ARollingShutterIsSeenFromEachRowsCamera) {
    // Given the readout time, the window explains the rows as the noise
    // allows and keeps the true trajectory (0.41 px, 3.4 mm, 1.8 mrad); told
    // a global shutter, the shear (up to 14 px from the first row to the last
    // at the fastest turn) stays in its residuals and bends the keyframes
    // (1.90 px, 45 mm, 19.5 mrad).
    const RollingShutterRun modelled = runRolling(Scalar(0.03));
    const RollingShutterRun global = runRolling(0);
    EXPECT_GE(modelled.optimisations, 5);
    EXPECT_EQ(modelled.optimisations, global.optimisations);
    EXPECT_LT(modelled.rms_after_px, Scalar(0.6));
    EXPECT_GT(global.rms_after_px, 2 * modelled.rms_after_px);
    EXPECT_LT(modelled.max_position_error, Scalar(0.02));
    EXPECT_GT(global.max_position_error, 3 * modelled.max_position_error);
    EXPECT_LT(modelled.max_rotation_error_rad, Scalar(0.003));
    EXPECT_GT(global.max_rotation_error_rad, 3 * modelled.max_rotation_error_rad);
    EXPECT_EQ(modelled.allocations, 0) << "addFrame allocated once running";

    WindowBaConfig bad;
    bad.rolling_shutter_s = Scalar(1.5);
    const auto r = validate(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("window_ba.rolling_shutter_s"), std::string::npos);
}

TEST(WindowBa, EstimatesTheReadoutTime) {
    // Told a global shutter with a prior of 30 ms around it, the window finds
    // the 30 ms of the images (0.03000 s) and ends where it would given them
    // (0.41 px, 3.4 mm, 1.8 mrad).
    const RollingShutterRun estimated = runRolling(0, Scalar(0.03), Scalar(0.03));
    const RollingShutterRun given = runRolling(Scalar(0.03));
    EXPECT_GE(estimated.optimisations, 5);
    EXPECT_EQ(estimated.optimisations, given.optimisations);
    EXPECT_NEAR(estimated.readout_s, Scalar(0.03), Scalar(0.002));
    EXPECT_LT(estimated.rms_after_px, Scalar(1.1) * given.rms_after_px);
    EXPECT_LT(estimated.max_position_error, Scalar(2) * given.max_position_error);
    EXPECT_LT(estimated.max_rotation_error_rad, Scalar(2) * given.max_rotation_error_rad);
    EXPECT_EQ(estimated.allocations, 0) << "addFrame allocated once running";

    // On a global shutter, from a prior at 20 ms, it comes down to 0.00003 s.
    const RollingShutterRun global = runRolling(Scalar(0.02), 0, Scalar(0.03));
    EXPECT_EQ(global.optimisations, given.optimisations);
    EXPECT_LT(global.readout_s, Scalar(0.005));
    // Rows read from the bottom up (-30 ms: the sensor upside down, or the
    // sequence played backwards): -0.02999 s.
    const RollingShutterRun upwards = runRolling(0, Scalar(-0.03), Scalar(0.03));
    EXPECT_EQ(upwards.optimisations, given.optimisations);
    EXPECT_NEAR(upwards.readout_s, Scalar(-0.03), Scalar(0.002));
    // An 80 ms shutter with the estimate kept within 50 ms: held at the
    // bound, the poses stepping for the bound's time (1.94 px).
    const RollingShutterRun clamped = runRolling(0, Scalar(0.08), Scalar(0.03), Scalar(0.05));
    EXPECT_EQ(clamped.optimisations, given.optimisations);
    EXPECT_EQ(clamped.readout_s, Scalar(0.05));
    EXPECT_EQ(clamped.allocations, 0) << "addFrame allocated once running";

    WindowBaConfig bad;
    bad.rolling_shutter_s = Scalar(0.06);
    bad.rolling_shutter_sigma_s = Scalar(0.01);
    auto r = validate(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("rolling_shutter_max_s"), std::string::npos);
    bad.rolling_shutter_s = Scalar(-0.06);
    EXPECT_FALSE(validate(bad).ok());
    bad.rolling_shutter_sigma_s = 0;  // given, not estimated: any max
    EXPECT_TRUE(validate(bad).ok());
    bad = WindowBaConfig{};
    bad.rolling_shutter_sigma_s = Scalar(1e-6);  // a prior that tight is a given value
    r = validate(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("window_ba.rolling_shutter_sigma_s"), std::string::npos);
}

TEST(WindowBa, EstimatesTheFocalLengthAndDistortion) {
    // Given a focal length 10% long (the 7-Scenes camera.txt is about 11%
    // long for its colour images) on a global shutter, the window's factor
    // comes to 1 / 1.1 (0.90909) and the trajectory to what the right camera
    // gives (0.403 px against 0.988 px with the long focal length, 2.0 mm).
    const RollingShutterRun right = runRolling(0, 0);
    const RollingShutterRun wrong = runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1));
    const RollingShutterRun estimated = runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1), Scalar(0.2));
    EXPECT_GE(estimated.optimisations, 5);
    EXPECT_EQ(estimated.optimisations, right.optimisations);
    EXPECT_EQ(wrong.optimisations, right.optimisations);
    EXPECT_NEAR(estimated.focal_scale, 1 / Scalar(1.1), Scalar(0.005));
    EXPECT_GT(wrong.rms_after_px, Scalar(1.5) * right.rms_after_px);
    EXPECT_LT(estimated.rms_after_px, Scalar(1.1) * right.rms_after_px);
    EXPECT_LT(estimated.max_position_error, Scalar(2) * right.max_position_error + Scalar(0.005));
    EXPECT_EQ(estimated.allocations, 0) << "addFrame allocated once running";
    // With a 30 ms rolling shutter, both estimated together (0.90977, 29.98 ms).
    const RollingShutterRun both =
        runRolling(0, Scalar(0.03), Scalar(0.03), Scalar(0.05), Scalar(1.1), Scalar(0.2));
    EXPECT_NEAR(both.focal_scale, 1 / Scalar(1.1), Scalar(0.005));
    EXPECT_NEAR(both.readout_s, Scalar(0.03), Scalar(0.002));
    EXPECT_EQ(both.allocations, 0) << "addFrame allocated once running";

    // A barrel distortion (k1 = -0.1) not given: estimated with the focal
    // length (0.90959, k1 -0.0999; 0.403 px as given both, 1.003 px given
    // neither).
    const RollingShutterRun distorted_right =
        runRolling(0, 0, 0, Scalar(0.05), 1, 0, Scalar(-0.1), 0, true);
    const RollingShutterRun distorted_given_none =
        runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1), 0, Scalar(-0.1));
    const RollingShutterRun distorted =
        runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1), Scalar(0.2), Scalar(-0.1), Scalar(0.2));
    // The focal length alone cannot explain the distortion (0.682 px, the
    // factor stays at 1.099).
    const RollingShutterRun distorted_focal_only =
        runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1), Scalar(0.2), Scalar(-0.1));
    EXPECT_EQ(distorted.optimisations, distorted_right.optimisations);
    EXPECT_EQ(distorted_focal_only.optimisations, distorted_right.optimisations);
    EXPECT_NEAR(distorted.focal_scale, 1 / Scalar(1.1), Scalar(0.005));
    EXPECT_NEAR(distorted.k1, Scalar(-0.1), Scalar(0.01));
    EXPECT_GT(distorted_given_none.rms_after_px, Scalar(1.5) * distorted_right.rms_after_px);
    EXPECT_GT(distorted_focal_only.rms_after_px, Scalar(1.5) * distorted_right.rms_after_px);
    EXPECT_LT(distorted.rms_after_px, Scalar(1.1) * distorted_right.rms_after_px);
    EXPECT_LT(distorted.max_position_error,
              Scalar(2) * distorted_right.max_position_error + Scalar(0.005));
    EXPECT_EQ(distorted.allocations, 0) << "addFrame allocated once running";
    // All three at once, with a 30 ms shutter (0.90735, -0.1011, 30.06 ms).
    const RollingShutterRun all = runRolling(0, Scalar(0.03), Scalar(0.03), Scalar(0.05),
                                             Scalar(1.1), Scalar(0.2), Scalar(-0.1), Scalar(0.2));
    EXPECT_NEAR(all.focal_scale, 1 / Scalar(1.1), Scalar(0.005));
    EXPECT_NEAR(all.k1, Scalar(-0.1), Scalar(0.01));
    EXPECT_NEAR(all.readout_s, Scalar(0.03), Scalar(0.002));
    // The focal factor kept within [1 / 1.05, 1.05]: held at the bound.
    const RollingShutterRun bounded =
        runRolling(0, 0, 0, Scalar(0.05), Scalar(1.1), Scalar(0.2), 0, 0, false, Scalar(0.05));
    EXPECT_EQ(bounded.optimisations, right.optimisations);
    EXPECT_NEAR(bounded.focal_scale, 1 / Scalar(1.05), Scalar(1e-6));

    WindowBaConfig bad;
    bad.focal_sigma_rel = Scalar(1e-5);
    const auto r = validate(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("window_ba.focal_sigma_rel"), std::string::npos);
    bad = WindowBaConfig{};
    bad.k1_sigma = Scalar(1e-5);
    const auto r1 = validate(bad);
    ASSERT_FALSE(r1.ok());
    EXPECT_NE(r1.error().message.find("window_ba.k1_sigma"), std::string::npos);
}

TEST(WindowBa, AResetStartsOver) {
    const Scene s = makeScene();
    const auto cam = test::makeCamera();
    WindowBaConfig config;
    config.enabled = true;
    auto ba = WindowBa::create(cam, config);
    ASSERT_TRUE(ba.ok());
    std::vector<FeatureObservation> obs;
    for (int k = 0; k < 30; ++k) {
        observe(s, cam, k, obs);
        (void)ba->addFrame(s.filter[static_cast<size_t>(k)], obs);
    }
    EXPECT_EQ(ba->keyframeCount(), 10);
    ba->reset();
    EXPECT_EQ(ba->keyframeCount(), 0);
    const CameraPose p = ba->adjustedPose(s.filter[5]);
    EXPECT_TRUE(p.p_CinW.isApprox(s.filter[5].p_CinW));
}

}  // namespace
}  // namespace scaled::core::slam
