// The gyro motion prior (core/slam/gyro_prior.h): integration of gyro samples
// over a frame interval, the filter's prediction with it, and what it buys on
// the point-level simulation.

#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/gyro_prior.h>
#include <scaled/core/slam/quaternion.h>

#include "point_slam_sim.h"
#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core::slam {
namespace {

constexpr int64_t kMs = 1'000'000;

std::vector<ImuSample> samplesAt(int64_t from_ns, int64_t to_ns, int64_t step_ns,
                                 const std::function<Vec3(double)>& rate_at_s) {
    std::vector<ImuSample> out;
    for (int64_t t = from_ns; t <= to_ns; t += step_ns) {
        ImuSample s;
        s.t_ns = t;
        s.accel_mps2 = Vec3(0, 0, Scalar(9.81));
        s.gyro_radps = rate_at_s(double(t) * 1e-9);
        out.push_back(s);
    }
    return out;
}

Mat3 expMap(const Vec3& phi) {
    const Scalar a = phi.norm();
    if (a < Scalar(1e-12)) {
        return Mat3::Identity();
    }
    return Eigen::AngleAxis<Scalar>(a, phi / a).toRotationMatrix();
}

Vec3 logMap(const Mat3& R) {
    const Eigen::AngleAxis<Scalar> aa(R);
    return aa.axis() * aa.angle();
}

TEST(GyroPrior, AConstantRateComesOutRotatedIntoTheCameraFrameWithItsSigma) {
    const Vec3 w_I(Scalar(0.3), Scalar(-1.2), Scalar(0.5));
    const auto samples = samplesAt(0, 200 * kMs, 5 * kMs, [&](double) { return w_I; });
    GyroModel model;
    model.R_ItoC = expMap(Vec3(Scalar(0.2), Scalar(1.0), Scalar(-0.4)));
    model.noise_density = Scalar(0.001);
    model.bias_sigma_radps = Scalar(0.01);
    const GyroIntegration g = integrateGyro(samples, 50 * kMs, 83 * kMs, model);
    ASSERT_EQ(g.coverage, GyroCoverage::kOk) << toString(g.coverage);
    EXPECT_LE((g.rate.w_C_radps - model.R_ItoC * w_I).norm(), test::tolerance(1e-9, 1e-5));
    const double dt = 0.033;
    EXPECT_NEAR(g.rate.sigma_radps, std::sqrt(1e-6 / dt + 1e-4), test::tolerance(1e-12, 1e-6));
    EXPECT_EQ(g.rate.samples, 8);  // 50..85 ms at 5 ms, bounds included
    // The bias is taken off every sample.
    model.bias_I_radps = Vec3(Scalar(0.1), 0, 0);
    const GyroIntegration b = integrateGyro(samples, 50 * kMs, 83 * kMs, model);
    ASSERT_EQ(b.coverage, GyroCoverage::kOk);
    EXPECT_LE((b.rate.w_C_radps - model.R_ItoC * (w_I - model.bias_I_radps)).norm(),
              test::tolerance(1e-9, 1e-5));
}

TEST(GyroPrior, AVaryingRateIntegratesToTheTrueRotation) {
    // Body rate w(t) = (2 cos 3t, 1.5 sin 2t, 0.8 + t): the true rotation is
    // integrated on a fine grid, the gyro sampled at 200 Hz.
    const auto rate = [](double t) {
        return Vec3(Scalar(2 * std::cos(3 * t)), Scalar(1.5 * std::sin(2 * t)), Scalar(0.8 + t));
    };
    const auto samples = samplesAt(0, kMs * 1000, 5 * kMs, rate);
    const int64_t t0 = 311 * kMs;  // between samples at both ends
    const int64_t t1 = 412 * kMs;
    Mat3 R_true = Mat3::Identity();
    constexpr int kSteps = 20000;
    const double h = double(t1 - t0) * 1e-9 / kSteps;
    for (int i = 0; i < kSteps; ++i) {
        R_true = R_true * expMap(rate(double(t0) * 1e-9 + (i + 0.5) * h) * Scalar(h));
    }
    const GyroIntegration g = integrateGyro(samples, t0, t1, GyroModel{});
    ASSERT_EQ(g.coverage, GyroCoverage::kOk);
    const Vec3 phi = g.rate.w_C_radps * Scalar(0.101);
    // About 0.2 rad turned: within 1e-4 rad (the rate is linear only piecewise).
    EXPECT_LE(logMap(expMap(phi).transpose() * R_true).norm(), Scalar(1e-4));
    // Constant-velocity's guess would be the rate at t0 held: far off.
    EXPECT_GE(logMap(expMap(rate(0.311) * Scalar(0.101)).transpose() * R_true).norm(),
              Scalar(0.01));
}

TEST(GyroPrior, RefusesMissingSamplesGapsAndBadInput) {
    const Vec3 w(0, 0, 1);
    const auto samples = samplesAt(0, 100 * kMs, 10 * kMs, [&](double) { return w; });
    GyroModel model;
    model.max_gap_ns = 20 * kMs;
    EXPECT_EQ(integrateGyro(samples, 40 * kMs, 75 * kMs, model).coverage, GyroCoverage::kOk);
    // The interval runs past the last sample by more than the gap.
    EXPECT_EQ(integrateGyro(samples, 90 * kMs, 125 * kMs, model).coverage, GyroCoverage::kGap);
    // ... and by less: the last rate is held.
    EXPECT_EQ(integrateGyro(samples, 90 * kMs, 115 * kMs, model).coverage, GyroCoverage::kOk);
    // Nothing near the interval (another clock, say).
    EXPECT_EQ(integrateGyro(samples, 5000 * kMs, 5033 * kMs, model).coverage,
              GyroCoverage::kNoSamples);
    EXPECT_EQ(integrateGyro({}, 0, 33 * kMs, model).coverage, GyroCoverage::kNoSamples);
    // A hole of 50 ms inside the interval.
    std::vector<ImuSample> holed;
    for (const auto& s : samples) {
        if (s.t_ns < 30 * kMs || s.t_ns > 70 * kMs) {
            holed.push_back(s);
        }
    }
    EXPECT_EQ(integrateGyro(holed, 20 * kMs, 90 * kMs, model).coverage, GyroCoverage::kGap);
    // A hole before the interval does not matter.
    EXPECT_EQ(integrateGyro(holed, 80 * kMs, 95 * kMs, model).coverage, GyroCoverage::kOk);
    // Accelerometer-only samples are not a gyro.
    std::vector<ImuSample> accel_only = samples;
    for (auto& s : accel_only) {
        s.gyro_radps.reset();
    }
    EXPECT_EQ(integrateGyro(accel_only, 40 * kMs, 75 * kMs, model).coverage,
              GyroCoverage::kNoSamples);
    // Bad interval, bad sample, bad model.
    EXPECT_EQ(integrateGyro(samples, 40 * kMs, 40 * kMs, model).coverage,
              GyroCoverage::kBadInterval);
    std::vector<ImuSample> nan = samples;
    nan[5].gyro_radps = Vec3(std::numeric_limits<Scalar>::quiet_NaN(), 0, 0);
    EXPECT_EQ(integrateGyro(nan, 40 * kMs, 75 * kMs, model).coverage, GyroCoverage::kBadInterval);
    GyroModel zero_sigma = model;
    zero_sigma.noise_density = 0;
    zero_sigma.bias_sigma_radps = 0;
    EXPECT_EQ(integrateGyro(samples, 40 * kMs, 75 * kMs, zero_sigma).coverage,
              GyroCoverage::kBadInterval);
}

TEST(GyroPrior, PredictTakesTheGyrosRateAndCarriesItsVarianceIntoTheRotation) {
    const auto cam = test::makeCamera(0, 0, 500);
    test::PointSimOptions opt;
    test::PointSlamSim sim(cam, opt);
    SlamConfig config = test::pointSimSlamConfig();
    auto slam = EkfSlam::create(cam, config);
    ASSERT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    for (int k = 0; k < 20; ++k) {
        sim.step(*slam, k);  // a map with features and correlations
    }
    const VecX x_before = slam->state();
    GyroRate rate;
    rate.w_C_radps = Vec3(Scalar(0.4), Scalar(-0.7), Scalar(0.1));
    rate.sigma_radps = Scalar(0.02);
    const Scalar dt = Scalar(sim.timeNs(20) - sim.timeNs(19)) * Scalar(1e-9);
    ASSERT_EQ(slam->predict(sim.timeNs(20), &rate), SlamHealth::kOk);
    const VecX x = slam->state();
    const MatX P = slam->covariance();
    EXPECT_LE((x.segment<3>(kAngVel) - rate.w_C_radps).norm(), test::tolerance(1e-12, 1e-6));
    const Vec4 q_expected =
        quatMultiply(x_before.segment<4>(kQuat), quatFromRotationVector(rate.w_C_radps * dt));
    EXPECT_LE((x.segment<4>(kQuat) - q_expected).norm(), test::tolerance(1e-12, 1e-6));
    // w: the gyro's variance, uncorrelated with position, velocity and the map.
    const Scalar var = rate.sigma_radps * rate.sigma_radps;
    const Mat3 P_ww = P.block<3, 3>(kAngVel, kAngVel);
    EXPECT_LE((P_ww - Mat3::Identity() * var).cwiseAbs().maxCoeff(), test::tolerance(1e-15, 1e-9));
    const int n_features = slam->stateDim() - kCameraDim;
    EXPECT_LE(P.block(kAngVel, kCameraDim, 3, n_features).cwiseAbs().maxCoeff(), Scalar(0));
    const Mat3 P_wp = P.block<3, 3>(kAngVel, 0);
    EXPECT_LE(P_wp.cwiseAbs().maxCoeff(), Scalar(0));
    // q and w: d q' / d w * var, as the motion model's Jacobian has it.
    Mat13 F;
    Vec13 xc = x_before.head<kCameraDim>();
    xc.segment<3>(kAngVel) = rate.w_C_radps;
    (void)predictCamera(xc, dt, MotionNoise{}, &F, nullptr);
    const Mat43 expected_qw = F.block<4, 3>(kQuat, kAngVel) * var;
    const Mat43 P_qw = P.block<4, 3>(kQuat, kAngVel);
    EXPECT_LE((P_qw - expected_qw).cwiseAbs().maxCoeff(), test::tolerance(1e-12, 1e-7));

    // A rate without a positive sigma is ignored: constant velocity runs.
    GyroRate bad = rate;
    bad.sigma_radps = 0;
    const Vec3 w_before = slam->state().segment<3>(kAngVel);
    ASSERT_EQ(slam->predict(sim.timeNs(21), &bad), SlamHealth::kOk);
    EXPECT_LE((slam->state().segment<3>(kAngVel) - w_before).norm(), test::tolerance(1e-12, 1e-6));
}

// Runs the point simulation with a simulated gyro (the true rate plus white
// noise of the model's sigma) or without, and returns the mean a-priori
// rotation error (after predict, before the update) and the mean pose NEES.
struct GyroRun {
    double prior_rotation_error_rad = 0;
    double nees = 0;
    int bad_frames = 0;
};

GyroRun runWithGyro(bool use_gyro, Scalar fps, std::uint32_t seed) {
    const auto cam = test::makeCamera(0, 0, 500);
    test::PointSimOptions opt;
    opt.seed = seed;
    opt.fps = fps;
    opt.frames = static_cast<int>(8 * fps);
    opt.pixel_noise_px = 1;
    opt.known_depth_rel_sigma = Scalar(0.02);
    opt.shake_rad = Scalar(0.15);
    test::PointSlamSim sim(cam, opt);
    SlamConfig config = test::pointSimSlamConfig();
    config.seed = seed;
    auto slam = EkfSlam::create(cam, config);
    EXPECT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    std::mt19937 rng(seed + 1000);
    const Scalar sigma = Scalar(0.02);
    std::normal_distribution<double> noise(0, static_cast<double>(sigma));
    GyroRun r;
    int n = 0;
    for (int k = 0; k < opt.frames; ++k) {
        GyroRate rate;
        if (k > 0) {
            rate.w_C_radps =
                sim.trueRateC(k) + Vec3(Scalar(noise(rng)), Scalar(noise(rng)), Scalar(noise(rng)));
            rate.sigma_radps = sigma;
        }
        // The a-priori error: predict on a copy (the step predicts again).
        if (k > 0) {
            EkfSlam probe = *slam;
            probe.predict(sim.timeNs(k), use_gyro ? &rate : nullptr);
            const CameraPose truth = sim.truthInC0(Scalar(k) / opt.fps);
            r.prior_rotation_error_rad +=
                static_cast<double>(rotationError(probe.pose().R_CtoW, truth.R_CtoW).norm());
        }
        const auto report = sim.step(*slam, k, use_gyro && k > 0 ? &rate : nullptr);
        r.bad_frames += report.bad_frame ? 1 : 0;
        if (k > 0) {
            const CameraPose truth = sim.truthInC0(Scalar(k) / opt.fps);
            const CameraPose est = slam->pose();
            Eigen::Matrix<Scalar, 6, 1> e;
            e.head<3>() = truth.p_CinW - est.p_CinW;
            e.tail<3>() = rotationError(est.R_CtoW, truth.R_CtoW);
            const Mat6x6 P = slam->poseCovariance();
            r.nees += static_cast<double>(e.dot(P.ldlt().solve(e)));
            ++n;
        }
    }
    r.prior_rotation_error_rad /= n;
    r.nees /= n;
    return r;
}

TEST(GyroPrior, AtTenFramesASecondTheGyroHalvesThePriorRotationErrorAndStaysConsistent) {
    // A camera shaking by 0.15 rad at 4-5 rad/s, seen at 10 Hz. Measured
    // (seeds 1-4): the gyro's prior error is a fraction of constant
    // velocity's, and the pose NEES stays near its 6 dof.
    double cv_err = 0;
    double gyro_err = 0;
    double gyro_nees = 0;
    for (std::uint32_t seed = 1; seed <= 4; ++seed) {
        const GyroRun cv = runWithGyro(false, 10, seed);
        const GyroRun gy = runWithGyro(true, 10, seed);
        std::printf("seed %u: prior rotation error %.5f (cv) %.5f (gyro) rad; NEES %.2f %.2f\n",
                    seed, cv.prior_rotation_error_rad, gy.prior_rotation_error_rad, cv.nees,
                    gy.nees);
        cv_err += cv.prior_rotation_error_rad;
        gyro_err += gy.prior_rotation_error_rad;
        gyro_nees += gy.nees;
        EXPECT_EQ(gy.bad_frames, 0);
    }
    EXPECT_LT(gyro_err, 0.5 * cv_err);
    EXPECT_GT(gyro_nees / 4, 3.0);
    EXPECT_LT(gyro_nees / 4, 10.0);
}

}  // namespace
}  // namespace scaled::core::slam
