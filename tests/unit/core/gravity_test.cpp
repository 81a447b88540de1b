// estimateGravityDown(): accelerometer logs built from a known camera-IMU
// rotation and a known gravity direction (fixed seeds), near-static windows
// accepted within a fraction of a degree, moving ones refused with a reason.

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/geometry/gravity.h>

namespace scaled::core {
namespace {

constexpr double kG = 9.80665;
constexpr int64_t kPeriodNs = 5'000'000;  // 200 Hz
constexpr double kDeg = std::numbers::pi / 180.0;

Mat3 rotation(double angle_rad, const Eigen::Vector3d& axis) {
    return Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix().cast<Scalar>();
}

// The camera-IMU rotation of these tests: an IMU mounted about 30 degrees off
// the camera's axes, about a skew axis.
Mat3 testImuToCamera() {
    return rotation(31 * kDeg, Eigen::Vector3d(0.3, -1.0, 0.4));
}

// Gravity (down) in the camera frame: a camera pitched down and rolled a bit.
Vec3 testDownInCamera() {
    return Eigen::Vector3d(0.12, 0.93, 0.34).normalized().cast<Scalar>();
}

// `n` samples of a still accelerometer at 200 Hz from t0: the specific force
// -g down, in I, plus white noise of `noise_mps2` per axis.
std::vector<ImuSample> stillLog(const Mat3& R_ItoC, const Vec3& down_inC, std::size_t n,
                                double noise_mps2, unsigned seed, int64_t t0_ns = 0) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise(0.0, noise_mps2);
    const Vec3 f_inI = -Scalar(kG) * (R_ItoC.transpose() * down_inC);
    std::vector<ImuSample> out;
    for (std::size_t k = 0; k < n; ++k) {
        ImuSample s;
        s.t_ns = t0_ns + static_cast<int64_t>(k) * kPeriodNs;
        s.accel_mps2 = f_inI + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)).cast<Scalar>();
        out.push_back(s);
    }
    return out;
}

double degrees(Scalar rad) {
    return static_cast<double>(rad) / kDeg;
}

TEST(Gravity, StillLogGivesTheKnownDirection) {
    const Mat3 R_ItoC = testImuToCamera();
    const Vec3 down_inC = testDownInCamera();
    // 0.05 m/s^2 per axis: a cheap MEMS accelerometer's noise at 200 Hz.
    const auto log = stillLog(R_ItoC, down_inC, 400, 0.05, 7);
    auto est = estimateGravityDown(log, R_ItoC);
    ASSERT_TRUE(est.ok()) << est.error().message;
    // The default window is the first 0.5 s: samples 0..100 at 200 Hz.
    EXPECT_EQ(est->samples, 101U);
    EXPECT_EQ(est->t_first_ns, 0);
    EXPECT_EQ(est->t_last_ns, 100 * kPeriodNs);
    EXPECT_NEAR(est->down_inC.norm(), 1, 1e-5);
    // The bound asked for is 2 degrees; the noise allows far less: about
    // 0.05 * sqrt(2) / (9.81 * sqrt(101)) rad = 0.04 degrees (1 sigma).
    const double err_deg = degrees(angleBetween(est->down_inC, down_inC));
    EXPECT_LT(err_deg, 2.0);
    EXPECT_LT(err_deg, 0.15);
    EXPECT_LT(err_deg, 4 * degrees(est->sigma_rad));
    EXPECT_NEAR(est->magnitude_mps2, kG, 0.05);
    EXPECT_NEAR(est->spread_mps2, 0.05 * std::sqrt(3.0), 0.02);
    // Down in I is the opposite of the mean specific force.
    EXPECT_LT(degrees(angleBetween(est->down_inI, -est->mean_accel_mps2)), 1e-3);
    EXPECT_FALSE(est->mean_rate_radps.has_value());
}

TEST(Gravity, NoiselessLogIsExact) {
    const Mat3 R_ItoC = testImuToCamera();
    const Vec3 down_inC = testDownInCamera();
    auto est = estimateGravityDown(stillLog(R_ItoC, down_inC, 20, 0.0, 1), R_ItoC);
    ASSERT_TRUE(est.ok()) << est.error().message;
    EXPECT_LT((est->down_inC - down_inC).norm(), 1e-5);
    EXPECT_NEAR(est->spread_mps2, 0, 1e-5);
}

TEST(Gravity, WindowBeforeATime) {
    // Still for 1 s with one direction, then still for 1 s with another: the
    // window before t = 1.9 s sees only the second.
    const Mat3 R_ItoC = Mat3::Identity();
    const Vec3 first = Vec3(0, 1, 0);
    const Vec3 second = rotation(20 * kDeg, Eigen::Vector3d::UnitX()) * first;
    auto log = stillLog(R_ItoC, first, 200, 0.02, 3);
    const auto later = stillLog(R_ItoC, second, 200, 0.02, 4, 200 * kPeriodNs);
    log.insert(log.end(), later.begin(), later.end());

    GravityOptions opt;
    opt.at_t_ns = 1'900'000'000;
    auto est = estimateGravityDown(log, R_ItoC, opt);
    ASSERT_TRUE(est.ok()) << est.error().message;
    EXPECT_EQ(est->t_last_ns, 1'900'000'000);
    EXPECT_EQ(est->t_first_ns, 1'400'000'000);
    EXPECT_LT(degrees(angleBetween(est->down_inC, second)), 0.15);

    auto start = estimateGravityDown(log, R_ItoC);  // the first 0.5 s
    ASSERT_TRUE(start.ok()) << start.error().message;
    EXPECT_LT(degrees(angleBetween(start->down_inC, first)), 0.15);

    // Across the change the window is not static: the two halves differ by
    // 20 degrees, 3.4 m/s^2.
    opt.at_t_ns = 1'250'000'000;
    auto across = estimateGravityDown(log, R_ItoC, opt);
    ASSERT_FALSE(across.ok());
    EXPECT_EQ(across.error().code, ErrorCode::kDegenerate);
    EXPECT_NE(across.error().message.find("spread"), std::string::npos) << across.error().message;
}

TEST(Gravity, MovingLogIsRefusedWithTheReason) {
    // A hand-held camera shaken at 2 Hz with 3 m/s^2 along x_I.
    const Mat3 R_ItoC = testImuToCamera();
    auto log = stillLog(R_ItoC, testDownInCamera(), 200, 0.05, 11);
    for (ImuSample& s : log) {
        const double t_s = static_cast<double>(s.t_ns) * 1e-9;
        s.accel_mps2.x() += Scalar(3.0 * std::sin(2 * std::numbers::pi * 2.0 * t_s));
    }
    auto est = estimateGravityDown(log, R_ItoC);
    ASSERT_FALSE(est.ok());
    EXPECT_EQ(est.error().code, ErrorCode::kDegenerate);
    const std::string& m = est.error().message;
    EXPECT_NE(m.find("gravity: not static in [0.000, 0.500] s (101 samples)"), std::string::npos)
        << m;
    EXPECT_NE(m.find("accelerometer spread"), std::string::npos) << m;
    EXPECT_NE(m.find("(moving or vibrating)"), std::string::npos) << m;
}

TEST(Gravity, WrongMagnitudeIsRefused) {
    // Still, but reading 1.3 g (an accelerating lift, or a wrong scale).
    const Mat3 R_ItoC = Mat3::Identity();
    auto log = stillLog(R_ItoC, Vec3(0, 1, 0), 200, 0.0, 5);
    for (ImuSample& s : log) {
        s.accel_mps2 *= Scalar(1.3);  // 12.7486 m/s^2
    }
    auto est = estimateGravityDown(log, R_ItoC);
    ASSERT_FALSE(est.ok());
    EXPECT_EQ(est.error().code, ErrorCode::kDegenerate);
    EXPECT_NE(est.error().message.find("mean specific force 12.749 m/s^2, expected 9.807 +- 0.800"),
              std::string::npos)
        << est.error().message;
    EXPECT_EQ(est.error().message.find("spread"), std::string::npos) << est.error().message;
}

TEST(Gravity, RotatingGyroIsRefused) {
    const Mat3 R_ItoC = Mat3::Identity();
    auto log = stillLog(R_ItoC, Vec3(0, 1, 0), 200, 0.01, 6);
    for (ImuSample& s : log) {
        s.gyro_radps = Vec3(0, 0.5, 0);
    }
    auto est = estimateGravityDown(log, R_ItoC);
    ASSERT_FALSE(est.ok());
    EXPECT_NE(est.error().message.find("mean angular rate 0.500 rad/s > 0.100 (rotating)"),
              std::string::npos)
        << est.error().message;

    for (ImuSample& s : log) {
        s.gyro_radps = Vec3(0.001, -0.002, 0.001);
    }
    auto still = estimateGravityDown(log, R_ItoC);
    ASSERT_TRUE(still.ok()) << still.error().message;
    ASSERT_TRUE(still->mean_rate_radps.has_value());
    EXPECT_NEAR(*still->mean_rate_radps, std::sqrt(6e-6), 1e-6);
}

TEST(Gravity, TooFewSamples) {
    const Mat3 R_ItoC = Mat3::Identity();
    // 20 Hz: 11 samples in the first 0.5 s; ask for 20.
    auto log = stillLog(R_ItoC, Vec3(0, 1, 0), 40, 0.01, 8);
    for (std::size_t k = 0; k < log.size(); ++k) {
        log[k].t_ns = static_cast<int64_t>(k) * 50'000'000;
    }
    GravityOptions opt;
    opt.min_samples = 20;
    auto est = estimateGravityDown(log, R_ItoC, opt);
    ASSERT_FALSE(est.ok());
    EXPECT_EQ(est.error().code, ErrorCode::kDegenerate);
    EXPECT_EQ(est.error().message,
              "gravity: 11 accelerometer samples in [0.000, 0.500] s, need at least 20");

    auto none = estimateGravityDown(std::span<const ImuSample>(), R_ItoC);
    ASSERT_FALSE(none.ok());
    EXPECT_EQ(none.error().message, "gravity: no accelerometer samples");
}

TEST(Gravity, InvalidInputs) {
    const auto log = stillLog(Mat3::Identity(), Vec3(0, 1, 0), 50, 0.01, 9);
    Mat3 reflect = Mat3::Identity();
    reflect(2, 2) = -1;
    auto bad_r = estimateGravityDown(log, reflect);
    ASSERT_FALSE(bad_r.ok());
    EXPECT_EQ(bad_r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(bad_r.error().message.find("R_ItoC is not a rotation"), std::string::npos);

    auto unordered = log;
    std::swap(unordered[3].t_ns, unordered[4].t_ns);
    auto bad_t = estimateGravityDown(unordered, Mat3::Identity());
    ASSERT_FALSE(bad_t.ok());
    EXPECT_NE(bad_t.error().message.find("samples out of time order: sample 4"), std::string::npos)
        << bad_t.error().message;

    auto nan = log;
    nan[2].accel_mps2.y() = std::numeric_limits<Scalar>::quiet_NaN();
    auto bad_v = estimateGravityDown(nan, Mat3::Identity());
    ASSERT_FALSE(bad_v.ok());
    EXPECT_EQ(bad_v.error().message, "gravity: sample at 10000000 ns is not finite");

    GravityOptions opt;
    opt.max_spread_mps2 = 0;
    auto bad_o = estimateGravityDown(log, Mat3::Identity(), opt);
    ASSERT_FALSE(bad_o.ok());
    EXPECT_EQ(bad_o.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(bad_o.error().message.find("max_spread_mps2"), std::string::npos);
}

}  // namespace
}  // namespace scaled::core
