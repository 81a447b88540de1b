// What feeds the gyro prior on a replayed sequence (gyro_feed.h): the
// sequence's own gyroscope log when its axes are known, a gyro simulated from
// the ground truth when asked for (simulated_gyro.h), else nothing.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/core/slam/gyro_prior.h>
#include <scaled/drivers/imu/gyro_feed.h>
#include <scaled/drivers/imu/map_gravity.h>
#include <scaled/drivers/imu/simulated_gyro.h>

#include "temp_dir.h"

namespace scaled::drivers::imu {
namespace {

using core::Mat3;
using core::Scalar;
using core::Vec3;
using test::TempDir;

Mat3 rotationAbout(const Vec3& axis, double angle) {
    return Eigen::AngleAxis<Scalar>(Scalar(angle), axis.normalized()).toRotationMatrix();
}

// An EuRoC imu0/data.csv turning at 0.3 rad/s about the IMU's z for 1 s at
// 200 Hz, and (with_yaml) the cam0/imu0 sensor.yaml that make R_ItoC known:
// the camera is the IMU turned by 90 degrees about x.
void writeEuroc(const std::filesystem::path& seq, bool with_yaml) {
    std::filesystem::create_directories(seq / "imu0");
    std::ofstream csv(seq / "imu0" / "data.csv");
    csv << "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
           "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
    for (std::int64_t t = 0; t <= 1'000'000'000; t += 5'000'000) {
        csv << t << ",0,0,0.3,0,0,9.81\n";
    }
    if (with_yaml) {
        std::filesystem::create_directories(seq / "cam0");
        // T_BS of the camera: R_CtoB = Rx(90 deg); the IMU is the body.
        std::ofstream(seq / "cam0" / "sensor.yaml")
            << "sensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n"
               "  data: [1.0, 0.0, 0.0, 0.0,\n         0.0, 0.0, -1.0, 0.0,\n"
               "         0.0, 1.0, 0.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\n";
    }
}

TEST(GyroFeed, ASequenceGyroWithKnownAxesFeedsThePrior) {
    const TempDir dir("gyro_feed");
    writeEuroc(dir.path(), true);
    auto gravity = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(gravity.ok()) << gravity.error().message;
    auto feed = GyroFeed::create(*gravity, std::nullopt);
    ASSERT_TRUE(feed.ok()) << feed.error().message;
    EXPECT_TRUE(feed->active());
    EXPECT_NE(feed->source().find("imu0/data.csv"), std::string::npos) << feed->source();
    source::Frame frame;
    frame.t_ns = 500'000'000;
    const core::slam::ImuWindow* w = feed->forFrame(frame);
    ASSERT_NE(w, nullptr);
    const auto g = core::slam::integrateGyro(
        w->samples, 400'000'000, 500'000'000,
        {w->R_ItoC, Vec3::Zero(), Scalar(2e-4), Scalar(0.02), 50'000'000});
    ASSERT_EQ(g.coverage, core::slam::GyroCoverage::kOk);
    // R_ItoC = R_CtoB^T = Rx(90)^T takes the IMU's z to the camera's +y.
    EXPECT_NEAR(g.rate.w_C_radps.x(), 0, 1e-9);
    EXPECT_NEAR(g.rate.w_C_radps.y(), 0.3, 1e-9);
    EXPECT_NEAR(g.rate.w_C_radps.z(), 0, 1e-9);
}

TEST(GyroFeed, AGyroAboutUnknownAxesIsNotUsed) {
    const TempDir dir("gyro_feed");
    writeEuroc(dir.path(), false);
    auto gravity = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(gravity.ok()) << gravity.error().message;
    auto feed = GyroFeed::create(*gravity, std::nullopt);
    ASSERT_TRUE(feed.ok()) << feed.error().message;
    EXPECT_FALSE(feed->active());
    EXPECT_EQ(feed->source().rfind("none (", 0), 0U) << feed->source();
    EXPECT_NE(feed->source().find("no camera-IMU rotation"), std::string::npos) << feed->source();
    source::Frame frame;
    frame.t_ns = 500'000'000;
    EXPECT_EQ(feed->forFrame(frame), nullptr);
}

TEST(GyroFeed, NothingWithoutALog) {
    const TempDir dir("gyro_feed");
    auto gravity = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(gravity.ok());
    auto feed = GyroFeed::create(*gravity, std::nullopt);
    ASSERT_TRUE(feed.ok());
    EXPECT_FALSE(feed->active());
    EXPECT_EQ(feed->source(), "none");
}

// The simulated gyro: the ground truth's rotation between two frames, with
// its drawn bias (no white noise here), integrates back to that rotation.
TEST(GyroFeed, TheSimulatedGyroIntegratesToTheGroundTruthsRotation) {
    SimulatedGyroOptions o;
    o.noise_density = 0;
    o.bias_sigma_radps = 0.02;
    o.seed = 3;
    const TempDir dir("gyro_feed");
    auto gravity = MapGravitySelector::forDataset(dir.path());
    ASSERT_TRUE(gravity.ok());
    auto feed = GyroFeed::create(*gravity, o);
    ASSERT_TRUE(feed.ok()) << feed.error().message;
    EXPECT_TRUE(feed->active());
    EXPECT_EQ(feed->source().rfind("simulated gyro from ground truth (200 Hz, 0 rad/s", 0), 0U)
        << feed->source();
    auto sim = SimulatedGyro::create(o);  // the same draw: the feed's bias
    ASSERT_TRUE(sim.ok());
    const Vec3 bias = sim->bias();
    EXPECT_GT(bias.norm(), 0);

    source::Frame a;
    a.t_ns = 1'000'000'000;
    a.T_CtoW_gt = core::CameraPose{};
    a.T_CtoW_gt->R_CtoW = rotationAbout(Vec3(0.2, 1, 0.1), 0.3);
    EXPECT_EQ(feed->forFrame(a), nullptr);  // the first frame has no interval
    source::Frame b = a;
    b.t_ns = 1'100'000'000;
    const Mat3 R_rel = rotationAbout(Vec3(1, -0.5, 0.3), 0.12);
    b.T_CtoW_gt->R_CtoW = a.T_CtoW_gt->R_CtoW * R_rel;
    const core::slam::ImuWindow* w = feed->forFrame(b);
    ASSERT_NE(w, nullptr);
    ASSERT_EQ(w->samples.front().t_ns, a.t_ns);
    ASSERT_EQ(w->samples.back().t_ns, b.t_ns);
    EXPECT_EQ(w->samples.size(), 21U);  // 100 ms at 200 Hz, both ends
    core::slam::GyroModel model;
    model.bias_I_radps = bias;
    const auto g = core::slam::integrateGyro(w->samples, a.t_ns, b.t_ns, model);
    ASSERT_EQ(g.coverage, core::slam::GyroCoverage::kOk);
    const Eigen::AngleAxis<Scalar> truth(R_rel);
    EXPECT_LT((g.rate.w_C_radps * Scalar(0.1) - truth.axis() * truth.angle()).norm(), 1e-9);

    // A frame without ground truth breaks the chain: no window, and none for
    // the frame after it either.
    source::Frame c;
    c.t_ns = 1'200'000'000;
    EXPECT_EQ(feed->forFrame(c), nullptr);
    source::Frame d = b;
    d.t_ns = 1'300'000'000;
    EXPECT_EQ(feed->forFrame(d), nullptr);
}

TEST(GyroFeed, TheSimulatedGyroRefusesBadOptionsAndLongGaps) {
    SimulatedGyroOptions o;
    o.rate_hz = 5;
    auto bad = SimulatedGyro::create(o);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("rate_hz = 5"), std::string::npos) << bad.error().message;
    o = {};
    o.noise_density = 2;
    EXPECT_FALSE(SimulatedGyro::create(o).ok());
    o = {};
    auto sim = SimulatedGyro::create(o);
    ASSERT_TRUE(sim.ok());
    EXPECT_TRUE(sim->between(0, Mat3::Identity(), 11'000'000'000, Mat3::Identity()).empty());
    EXPECT_TRUE(sim->between(5, Mat3::Identity(), 5, Mat3::Identity()).empty());
}

}  // namespace
}  // namespace scaled::drivers::imu
