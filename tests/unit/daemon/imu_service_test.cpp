// The daemon's live IMU (imu_service.h) on a directory tree laid out like
// /sys/bus/iio/devices/iio:deviceN (sysfs mode reads plain attribute files,
// so a tree of real files is the driver's real input); the kernel's own
// device is tested in the VM (tests/vm, vm.imu_iio, vm.daemon).

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/geometry/gravity.h>
#include <scaled/core/slam/gyro_prior.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/imu_service.h>
#include <scaled/daemon/pipeline.h>
#include <scaled/daemon/report.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>

#include "fake_iio.h"
#include "hub_wait.h"
#include "temp_dir.h"

namespace scaled::daemon {
namespace {

namespace fs = std::filesystem;
using test::putFile;
using test::TempDir;

// An accelerometer at rest, its z axis up: it reads +1 g on z.
class ImuServiceTest : public ::testing::Test {
protected:
    void SetUp() override {
        options_.sysfs_root = tmp_.path() / "sys";
        options_.dev_root = tmp_.path() / "dev";
        // 16393 * 0.000598 = 9.803 m/s^2
        test::writeFakeAccelerometer(dev0(), "lsm6dsl", {0, 0, 16393}, "0.000598");
        config_.device = "lsm6dsl";
        config_.rate_hz = 200;
    }

    [[nodiscard]] fs::path dev0() const { return options_.sysfs_root / "iio:device0"; }

    // Polls the service's status until `done` holds or 10 s pass.
    template <typename Pred>
    bool waitFor(const ImuService& s, Pred done) {
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (std::chrono::steady_clock::now() < deadline) {
            if (done(s.status())) {
                return true;
            }
            std::this_thread::yield();
        }
        return done(s.status());
    }

    TempDir tmp_{"imu_service"};
    drivers::imu::IioOptions options_;
    ImuConfig config_;
};

TEST_F(ImuServiceTest, PollsTheAccelerometerIntoTheRingOldestFirst) {
    auto s = ImuService::open(config_, options_);
    ASSERT_TRUE(s) << s.error().message;
    const ImuStatus before = (*s)->status();
    EXPECT_TRUE(before.configured);
    EXPECT_EQ(before.device, "iio:device0 [lsm6dsl]");
    EXPECT_EQ(before.mode, "sysfs 200 Hz");
    EXPECT_EQ(before.samples, 0U);
    // 200 Hz over max(2 window_s, 2 s), plus a margin.
    EXPECT_EQ((*s)->capacity(), 416U);

    (*s)->start();
    ASSERT_TRUE(waitFor(**s, [](const ImuStatus& st) { return st.samples >= 20; }));
    (*s)->stop();
    std::vector<core::ImuSample> got;
    got.reserve((*s)->capacity());
    (*s)->copyRecent(got);
    ASSERT_GE(got.size(), 20U);
    EXPECT_EQ(got.size(), (*s)->status().samples);
    for (std::size_t i = 0; i < got.size(); ++i) {
        EXPECT_NEAR(got[i].accel_mps2.z(), 16393 * 0.000598, 1e-4);
        EXPECT_EQ(got[i].accel_mps2.x(), 0);
        if (i > 0) {
            EXPECT_GT(got[i].t_ns, got[i - 1].t_ns) << i;
        }
    }
    // Stamped on the monotonic clock, as the daemon's frames.
    std::string clock;
    std::ifstream(dev0() / "current_timestamp_clock") >> clock;
    EXPECT_EQ(clock, "monotonic");
    EXPECT_LE(got.back().t_ns, (*s)->nowNs());
    EXPECT_LE(got.back().t_ns, monotonicNowNs());
    EXPECT_GT(got.back().t_ns, monotonicNowNs() - 10'000'000'000);
    // Those samples give the vertical: IMU z up is camera -y with the
    // identity mount, so down is +z of the IMU.
    core::GravityOptions opt;
    opt.at_t_ns = got.back().t_ns;
    opt.window_ns = got.back().t_ns - got.front().t_ns;
    const auto g = core::estimateGravityDown(got, (*s)->rotationImuToCamera(), opt);
    ASSERT_TRUE(g) << g.error().message;
    EXPECT_NEAR(g->down_inC.z(), -1, 1e-6);
}

TEST_F(ImuServiceTest, AFailingReadIsCountedNamedAndClearedWhenItReadsAgain) {
    auto s = ImuService::open(config_, options_);
    ASSERT_TRUE(s) << s.error().message;
    fs::remove(dev0() / "in_accel_z_raw");  // the device went away, in part
    (*s)->start();
    ASSERT_TRUE(waitFor(**s, [](const ImuStatus& st) { return st.errors >= 3; }));
    const ImuStatus bad = (*s)->status();
    EXPECT_EQ(bad.samples, 0U);
    EXPECT_NE(bad.error.find("in_accel_z_raw"), std::string::npos) << bad.error;
    putFile(dev0() / "in_accel_z_raw", "16393\n");
    ASSERT_TRUE(waitFor(**s, [](const ImuStatus& st) { return st.samples >= 3; }));
    (*s)->stop();
    EXPECT_EQ((*s)->status().error, "");
}

TEST_F(ImuServiceTest, OpenNamesWhatIsMissing) {
    config_.device = "bmi270";
    auto missing = ImuService::open(config_, options_);
    ASSERT_FALSE(missing);
    EXPECT_NE(missing.error().message.find("bmi270"), std::string::npos) << missing.error().message;

    const fs::path d1 = options_.sysfs_root / "iio:device1";
    putFile(d1 / "name", "adc\n");
    putFile(d1 / "in_voltage0_raw", "7\n");
    config_.device = "adc";
    auto no_accel = ImuService::open(config_, options_);
    ASSERT_FALSE(no_accel);
    EXPECT_NE(
        no_accel.error().message.find("no accelerometer (needs accel_x, accel_y and accel_z)"),
        std::string::npos)
        << no_accel.error().message;
}

// With a gyroscope (in_anglvel_*): the samples carry the rate, copySince
// gives a frame interval's samples with the one before it, and they
// integrate to the rate in the camera frame (the gyro prior's input).
TEST_F(ImuServiceTest, AGyroscopesSamplesServeTheGyroPrior) {
    // 0.5 rad/s about the IMU's z (1000 LSB at 0.0005 rad/s per LSB).
    putFile(dev0() / "in_anglvel_x_raw", "0\n");
    putFile(dev0() / "in_anglvel_y_raw", "0\n");
    putFile(dev0() / "in_anglvel_z_raw", "1000\n");
    putFile(dev0() / "in_anglvel_scale", "0.0005\n");
    config_.rotation_imu_to_camera = {0, -1, 0, 0, 0, -1, 1, 0, 0};
    auto s = ImuService::open(config_, options_);
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_TRUE((*s)->hasGyro());
    (*s)->start();
    ASSERT_TRUE(waitFor(**s, [](const ImuStatus& st) { return st.samples >= 30; }));
    (*s)->stop();
    std::vector<core::ImuSample> all;
    all.reserve((*s)->capacity());
    (*s)->copyRecent(all);
    ASSERT_GE(all.size(), 30U);
    ASSERT_TRUE(all.front().gyro_radps.has_value());
    EXPECT_NEAR(all.front().gyro_radps->z(), 0.5, 1e-9);

    std::vector<core::ImuSample> since;
    since.reserve((*s)->capacity());
    const std::int64_t t0 = all[10].t_ns + 1;
    (*s)->copySince(t0, since);
    ASSERT_EQ(since.size(), all.size() - 10);
    EXPECT_EQ(since.front().t_ns, all[10].t_ns);  // the sample before t0 bounds it
    EXPECT_EQ(since.back().t_ns, all.back().t_ns);
    // Nothing before the ring: everything; after the last sample: the last.
    (*s)->copySince(0, since);
    EXPECT_EQ(since.size(), all.size());
    (*s)->copySince(all.back().t_ns + 1, since);
    ASSERT_EQ(since.size(), 1U);

    core::slam::GyroModel model;
    model.R_ItoC = (*s)->rotationImuToCamera();
    model.max_gap_ns = 1'000'000'000;  // a loaded test machine polls unevenly
    (*s)->copySince(t0, since);
    const auto g = core::slam::integrateGyro(since, t0, all.back().t_ns, model);
    ASSERT_EQ(g.coverage, core::slam::GyroCoverage::kOk) << core::slam::toString(g.coverage);
    // IMU z (up) is the camera's -y: a yaw to the left.
    EXPECT_NEAR(g.rate.w_C_radps.x(), 0, 1e-9);
    EXPECT_NEAR(g.rate.w_C_radps.y(), -0.5, 1e-9);
    EXPECT_NEAR(g.rate.w_C_radps.z(), 0, 1e-9);
}

// The daemon's pipeline starts its map with the live accelerometer's
// vertical and says so in STATUS: an IMU in a drone's body axes (x forward,
// y left, z up) on a camera pitched down 30 degrees.
TEST_F(ImuServiceTest, ThePipelineStartsItsMapWithTheAccelerometersVertical) {
    // f_I = -g R_ItoC^T down_C with down_C = (0, cos 30, sin 30):
    // (-4.903, 0, 8.493) m/s^2 at 0.000598 per LSB.
    putFile(dev0() / "in_accel_x_raw", "-8199\n");
    putFile(dev0() / "in_accel_z_raw", "14202\n");
    config_.rotation_imu_to_camera = {0, -1, 0, 0, 0, -1, 1, 0, 0};
    auto imu = ImuService::open(config_, options_);
    ASSERT_TRUE(imu) << imu.error().message;
    (*imu)->start();
    // Half a second of samples before the first frame (window_s 0.5).
    ASSERT_TRUE(waitFor(**imu, [](const ImuStatus& st) { return st.samples >= 100; }));

    DaemonConfig c = defaultDaemonConfig();
    c.source.kind = SourceKind::kSim;
    c.source.pacing = drivers::source::PacingMode::kAsFastAsPossible;
    c.source.at_end = AtEnd::kExit;
    c.log.frame_every = 0;
    c.imu = config_;
    PipelineParts p;
    drivers::sim::SimConfig sc;
    sc.duration_s = 1.0;
    auto src = drivers::sim::openSimSource(sc);
    ASSERT_TRUE(src) << src.error().message;
    p.source = std::move(*src);
    auto det = drivers::sim::createSimDetector(sc);
    ASSERT_TRUE(det) << det.error().message;
    p.detector = std::move(*det);
    auto priors = drivers::priors::loadPriorsFile(SCALED_SOURCE_DIR "/config/priors.toml");
    ASSERT_TRUE(priors) << priors.error().message;
    p.priors = std::move(*priors);
    p.source_name = "sim";
    p.lossless = true;
    p.imu = imu->get();
    ReportHub hub(static_cast<std::size_t>(c.pipeline.estimator.posterior.grid.bins));
    auto pipeline = Pipeline::create(c, std::move(p), hub, nullptr);
    ASSERT_TRUE(pipeline) << pipeline.error().message;
    ASSERT_TRUE((*pipeline)->start());
    const auto finished = [&] { return (*pipeline)->finished(); };
    ASSERT_TRUE(test::waitUntil(hub, finished, std::chrono::seconds(120)));
    (*pipeline)->stop();
    (*imu)->stop();

    const PipelineStatus st = hub.status();
    EXPECT_EQ(st.gravity_source.rfind("accelerometer (iio:device0 [lsm6dsl], ", 0), 0U)
        << st.gravity_source;
    ASSERT_TRUE(st.gravity_down_C.has_value());
    EXPECT_NEAR((*st.gravity_down_C)[0], 0, 1e-3);
    EXPECT_NEAR((*st.gravity_down_C)[1], std::cos(M_PI / 6), 1e-3);
    EXPECT_NEAR((*st.gravity_down_C)[2], 0.5, 1e-3);
    EXPECT_TRUE(st.imu.configured);
    EXPECT_EQ(st.imu.device, "iio:device0 [lsm6dsl]");
    EXPECT_GE(st.imu.samples, 100U);
    EXPECT_EQ(st.imu.errors, 0U);
}

}  // namespace
}  // namespace scaled::daemon
