// The vertical of a replayed sequence's maps (map_gravity.h): the
// accelerometer log first, then the dataset's gravity, then a level camera.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/geometry/gravity.h>
#include <scaled/drivers/imu/map_gravity.h>

#include "temp_dir.h"

namespace scaled::drivers::imu {
namespace {

using core::Scalar;
using core::Vec3;
using test::TempDir;

// A TUM accelerometer.txt of a Kinect held still in a known attitude for 2 s
// (100 Hz, 0.02 m/s^2 noise), then swung for 2 s: what the Kinect's axes read
// when gravity (down) in the colour camera's frame is down_C.
void writeTumLog(const std::filesystem::path& path, const Vec3& down_C) {
    // a = specific force (up) in the accelerometer's axes: R_ItoC^T * (-g down_C).
    const core::Mat3 R_ItoC = tumKinectImuToCamera();
    const Vec3 f_I = R_ItoC.transpose() * (-Scalar(9.80665) * down_C);
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0.0, 0.02);
    std::ofstream f(path);
    f << "# accelerometer data\n# timestamp ax ay az\n";
    for (int k = 0; k < 400; ++k) {
        const double t = 1305031100.0 + 0.01 * k;
        const double swing = k >= 200 ? 3.0 * std::sin(0.3 * k) : 0.0;
        char line[128];
        std::snprintf(line, sizeof line, "%.4f %.5f %.5f %.5f\n", t,
                      static_cast<double>(f_I.x()) + noise(rng) + swing,
                      static_cast<double>(f_I.y()) + noise(rng),
                      static_cast<double>(f_I.z()) + noise(rng) - swing);
        f << line;
    }
}

double angleDeg(const Vec3& a, const Vec3& b) {
    return static_cast<double>(
               std::acos(std::clamp(a.normalized().dot(b.normalized()), Scalar(-1), Scalar(1)))) *
           180.0 / std::numbers::pi;
}

TEST(MapGravity, TheAccelerometerLogGivesTheVerticalWithinTwoDegrees) {
    const TempDir dir("map_gravity_tum");
    // A camera pitched down 25 degrees and rolled 8: down in its frame.
    const Eigen::AngleAxis<Scalar> pitch(Scalar(25 * std::numbers::pi / 180), Vec3::UnitX());
    const Eigen::AngleAxis<Scalar> roll(Scalar(8 * std::numbers::pi / 180), Vec3::UnitZ());
    const Vec3 down_C = (roll * pitch).toRotationMatrix().transpose() * Vec3(0, 1, 0);
    writeTumLog(dir.path() / "accelerometer.txt", down_C);
    auto sel = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(sel) << sel.error().message;
    EXPECT_TRUE(sel->hasImuLog());

    source::Frame frame;
    frame.t_ns = 1305031101'500'000'000LL;  // 1.5 s into the still part
    frame.gravity_down_C = Vec3(0, 1, 0);   // ground truth says otherwise: the IMU wins
    const MapGravity g = sel->atMapStart(frame);
    EXPECT_NE(g.source.find("accelerometer"), std::string::npos) << g.source;
    EXPECT_LT(angleDeg(g.down_C, down_C), 2.0) << g.source;
    EXPECT_LT(angleDeg(g.down_C, down_C), 0.5) << "the noise allows much better";

    // A map that starts while the camera swings: the accelerometer is refused,
    // with its reason, and the dataset's gravity is used.
    frame.t_ns = 1305031103'500'000'000LL;
    const MapGravity moving = sel->atMapStart(frame);
    EXPECT_EQ(moving.down_C, Vec3(0, 1, 0));
    EXPECT_NE(moving.source.find("dataset gravity"), std::string::npos) << moving.source;
    EXPECT_NE(moving.source.find("refused"), std::string::npos) << moving.source;
    frame.gravity_down_C.reset();
    EXPECT_NE(sel->atMapStart(frame).source.find("level camera"), std::string::npos);
}

TEST(MapGravity, WithoutALogTheDatasetOrALevelCamera) {
    const TempDir dir("map_gravity_none");
    auto sel = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(sel) << sel.error().message;
    EXPECT_FALSE(sel->hasImuLog());
    source::Frame frame;
    frame.gravity_down_C = Vec3(0, 0.6, 0.8);
    MapGravity g = sel->atMapStart(frame);
    EXPECT_EQ(g.down_C, Vec3(0, 0.6, 0.8));
    EXPECT_EQ(g.source, "dataset gravity and ground-truth pose");
    frame.gravity_down_C.reset();
    g = sel->atMapStart(frame);
    EXPECT_EQ(g.down_C, Vec3(0, 1, 0));
    EXPECT_EQ(g.source, "assumed level camera (down = +y)");
}

// A live accelerometer (the daemon's [imu]): 100 Hz samples on the
// monotonic clock up to now_ns, still for `still_s` and swinging before.
std::vector<core::ImuSample> liveSamples(const core::Mat3& R_ItoC, const Vec3& down_C,
                                         std::int64_t now_ns, double still_s) {
    const Vec3 f_I = R_ItoC.transpose() * (-Scalar(9.80665) * down_C);
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 0.02);
    std::vector<core::ImuSample> out;
    for (int k = 200; k >= 0; --k) {  // 2 s, oldest first
        core::ImuSample s;
        s.t_ns = now_ns - std::int64_t{k} * 10'000'000;
        const double age_s = k * 0.01;
        const double swing = age_s > still_s ? 3.0 * std::sin(0.3 * k) : 0.0;
        s.accel_mps2 =
            f_I + Vec3(static_cast<Scalar>(noise(rng) + swing), static_cast<Scalar>(noise(rng)),
                       static_cast<Scalar>(noise(rng) - swing));
        out.push_back(s);
    }
    return out;
}

TEST(MapGravity, ALiveAccelerometerComesFirst) {
    // An IMU mounted with its x forward, y left, z up (a drone's FLU body
    // axes) on a camera pitched down 30 degrees.
    core::Mat3 R_ItoC;
    R_ItoC << 0, -1, 0, 0, 0, -1, 1, 0, 0;
    const Eigen::AngleAxis<Scalar> pitch(Scalar(30 * std::numbers::pi / 180), Vec3::UnitX());
    const Vec3 down_C = pitch.toRotationMatrix() * Vec3(0, 1, 0);
    const std::int64_t now_ns = 5'000'000'000;
    const auto samples = liveSamples(R_ItoC, down_C, now_ns, 1.0);

    MapGravitySelector sel;  // no log
    source::Frame frame;
    frame.gravity_down_C = Vec3(0, 1, 0);  // a dataset's: the accelerometer wins
    LiveAccelerometer live;
    live.samples = samples;
    live.R_ItoC = R_ItoC;
    live.label = "iio:device0 [mpu6050]";
    live.now_ns = now_ns;
    live.window_s = 0.5;
    const MapGravity g = sel.atMapStart(frame, live);
    EXPECT_LT(angleDeg(g.down_C, down_C), 0.5) << g.down_C.transpose();
    EXPECT_EQ(g.source.rfind("accelerometer (iio:device0 [mpu6050], 51 samples, spread ", 0), 0u)
        << g.source;
}

TEST(MapGravity, ALiveAccelerometerThatMovedOrIsSilentIsRefusedWithItsReason) {
    const core::Mat3 R_ItoC = core::Mat3::Identity();
    const std::int64_t now_ns = 5'000'000'000;
    MapGravitySelector sel;
    source::Frame frame;
    frame.gravity_down_C = Vec3(0, 0.6, 0.8);
    LiveAccelerometer live;
    live.R_ItoC = R_ItoC;
    live.label = "iio:device0 [mpu6050]";
    live.now_ns = now_ns;
    // Swinging over the whole window.
    const auto moving = liveSamples(R_ItoC, Vec3(0, 1, 0), now_ns, 0.0);
    live.samples = moving;
    MapGravity g = sel.atMapStart(frame, live);
    EXPECT_EQ(g.down_C, Vec3(0, 0.6, 0.8));
    EXPECT_EQ(g.source.rfind("dataset gravity and ground-truth pose; the accelerometer "
                             "(iio:device0 [mpu6050]) was refused: ",
                             0),
              0u)
        << g.source;
    EXPECT_NE(g.source.find("spread"), std::string::npos) << g.source;
    // Samples that stopped 3 s ago (a device gone): too few in the window.
    live.now_ns = now_ns + 3'000'000'000;
    const auto silent = liveSamples(R_ItoC, Vec3(0, 1, 0), now_ns, 2.0);
    live.samples = silent;
    frame.gravity_down_C.reset();
    g = sel.atMapStart(frame, live);
    EXPECT_EQ(g.down_C, Vec3(0, 1, 0));
    EXPECT_EQ(g.source.rfind("assumed level camera (down = +y); the accelerometer", 0), 0u)
        << g.source;
}

TEST(MapGravity, ABrokenLogIsAnErrorNamingFileAndLine) {
    const TempDir dir("map_gravity_bad");
    std::ofstream(dir.path() / "accelerometer.txt") << "1.0 0 0 9.8\n2.0 0 9.8\n";
    auto sel = MapGravitySelector::forDataset(dir.path());
    ASSERT_FALSE(sel);
    EXPECT_NE(sel.error().message.find("accelerometer.txt:2"), std::string::npos)
        << sel.error().message;
}

}  // namespace
}  // namespace scaled::drivers::imu
