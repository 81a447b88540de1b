// Dataset IMU logs (drivers/imu/imu_log.h): TUM accelerometer.txt and EuRoC
// imu0/data.csv, good files and every malformed case named by file:line; the
// TUM Kinect mapping gives down_inC = (ax, ay, -az) / |a| through the gravity
// estimate.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include <gtest/gtest.h>

#include <scaled/core/geometry/gravity.h>
#include <scaled/drivers/imu/imu_log.h>

#include "temp_dir.h"

namespace scaled::drivers::imu {
namespace {

using core::ErrorCode;
using core::Mat3;
using core::Scalar;
using core::Vec3;
using test::TempDir;

void writeFile(const std::filesystem::path& path, std::string_view content) {
    std::filesystem::create_directories(path.parent_path());
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << content;
    ASSERT_TRUE(out.good()) << "cannot write " << path;
}

// --- TUM accelerometer.txt -------------------------------------------------------

// The head of a TUM fr1 accelerometer.txt: the Kinect level, tilted a little.
constexpr std::string_view kTum =
    "# accelerometer data\n"
    "# file: 'rgbd_dataset_freiburg1_xyz.bag'\n"
    "# timestamp ax ay az\n"
    "1305031098.737361 -0.053590 9.587386 -1.723740\n"
    "1305031098.747420 -0.064680 9.597554 -1.733908\n"
    "1305031098.757478 -0.043418 9.577218 -1.713572\n";

TEST(TumAccelerometer, ReadsSamplesAndTheKinectMapping) {
    const TempDir dir("imu_tum");
    const auto file = dir.path() / "accelerometer.txt";
    writeFile(file, kTum);
    auto log = readTumAccelerometer(file);
    ASSERT_TRUE(log.ok()) << log.error().message;
    ASSERT_EQ(log->samples.size(), 3U);
    EXPECT_EQ(log->samples[0].t_ns, 1305031098737361000);
    EXPECT_EQ(log->samples[2].t_ns, 1305031098757478000);
    EXPECT_EQ(log->samples[1].accel_mps2, Vec3(-0.064680, 9.597554, -1.733908));
    EXPECT_FALSE(log->samples[0].gyro_radps.has_value());
    Mat3 expected = Mat3::Identity();
    expected(0, 0) = -1;
    expected(1, 1) = -1;
    EXPECT_EQ(log->R_ItoC, expected);
    EXPECT_EQ(tumKinectImuToCamera(), expected);
    EXPECT_NE(log->R_ItoC_source.find("TUM Kinect"), std::string::npos);
}

// The fact measured on TUM fr1 against ground truth: down in the colour
// camera's optical frame is (ax, ay, -az) / |a|. The reader's default mapping
// and the gravity estimate give exactly that.
TEST(TumAccelerometer, DefaultMappingGivesAxAyMinusAz) {
    const TempDir dir("imu_tum");
    const auto file = dir.path() / "accelerometer.txt";
    std::string text = "# timestamp ax ay az\n";
    for (int k = 0; k < 20; ++k) {
        text += "1305031098." + std::to_string(100000 + k * 10000) + " 1.25 9.5 -2.0\n";
    }
    writeFile(file, text);
    auto log = readTumAccelerometer(file);
    ASSERT_TRUE(log.ok()) << log.error().message;
    auto g = core::estimateGravityDown(log->samples, log->R_ItoC);
    ASSERT_TRUE(g.ok()) << g.error().message;
    const Vec3 a(1.25, 9.5, -2.0);
    const Vec3 expected = Vec3(a.x(), a.y(), -a.z()) / a.norm();
    EXPECT_LT((g->down_inC - expected).norm(), 1e-6) << g->down_inC.transpose();
}

struct BadCase {
    const char* name;
    std::string_view text;
    int line;
    std::string_view what;
};

TEST(TumAccelerometer, MalformedLinesNameFileAndLine) {
    const BadCase cases[] = {
        {"fields", "# c\n1.0 0 9.8 0\n1.1 0 9.8\n", 3,
         "expected 4 fields `timestamp ax ay az`, got 3"},
        {"number", "1.0 0 9.8 0\n1.1 0 nine 0\n", 2, "ay is not a number: 'nine'"},
        {"order", "1.0 0 9.8 0\n\n1.0 0 9.8 0\n", 3,
         "timestamp does not increase (previous at line 1)"},
        {"time", "x1.0 0 9.8 0\n", 1, "timestamp is not a number"},
        {"finite", "1.0 0 9.8 nan\n", 1, "az is not finite: 'nan'"},
        {"huge", "1.0 0 9.8 2e4\n", 1, "az is implausibly large"},
    };
    const TempDir dir("imu_tum");
    for (const BadCase& c : cases) {
        SCOPED_TRACE(c.name);
        const auto file = dir.path() / (std::string(c.name) + ".txt");
        writeFile(file, c.text);
        auto log = readTumAccelerometer(file);
        ASSERT_FALSE(log.ok());
        EXPECT_EQ(log.error().code, ErrorCode::kParse);
        const std::string prefix = file.string() + ":" + std::to_string(c.line) + ": ";
        EXPECT_EQ(log.error().message.rfind(prefix, 0), 0U) << log.error().message;
        EXPECT_NE(log.error().message.find(c.what), std::string::npos) << log.error().message;
    }
    auto missing = readTumAccelerometer(dir.path() / "none.txt");
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
    EXPECT_NE(missing.error().message.find("none.txt"), std::string::npos);
}

// --- EuRoC imu0/data.csv --------------------------------------------------------

constexpr std::string_view kEurocCsv =
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
    "1403636579758555392,-0.099134701513277898,0.14730578886832138,0.02722713633111154,"
    "8.1476917083333333,-0.37592158333333331,-2.4026292499999999\n"
    "1403636579763555584, -0.099134701513277898, 0.14032447186034408, 0.029321531433504733,"
    " 8.033280791666666, -0.40861041666666664, -2.4026292499999999\r\n";

// EuRoC MH_01's cam0/sensor.yaml (T_BS: camera to body) and imu0/sensor.yaml.
constexpr std::string_view kCamYaml =
    "# General sensor definitions.\n"
    "sensor_type: camera\n"
    "comment: VI-Sensor cam0 (MT9M034)\n"
    "\n"
    "# Sensor extrinsics wrt. the body-frame.\n"
    "T_BS:\n"
    "  cols: 4\n"
    "  rows: 4\n"
    "  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,\n"
    "         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,\n"
    "        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,\n"
    "         0.0, 0.0, 0.0, 1.0]\n"
    "\n"
    "rate_hz: 20\n";
constexpr std::string_view kImuYaml =
    "sensor_type: imu\n"
    "T_BS:\n"
    "  cols: 4\n"
    "  rows: 4\n"
    "  data: [1.0, 0.0, 0.0, 0.0,\n"
    "         0.0, 1.0, 0.0, 0.0,\n"
    "         0.0, 0.0, 1.0, 0.0,\n"
    "         0.0, 0.0, 0.0, 1.0]\n";

TEST(EurocImu, ReadsSamplesWithGyro) {
    const TempDir dir("imu_euroc");
    const auto file = dir.path() / "mav0" / "imu0" / "data.csv";
    writeFile(file, kEurocCsv);
    auto log = readEurocImu(file);
    ASSERT_TRUE(log.ok()) << log.error().message;
    ASSERT_EQ(log->samples.size(), 2U);
    EXPECT_EQ(log->samples[0].t_ns, 1403636579758555392);
    EXPECT_EQ(log->samples[1].t_ns, 1403636579763555584);
    EXPECT_EQ(log->samples[0].accel_mps2,
              Vec3(8.1476917083333333, -0.37592158333333331, -2.4026292499999999));
    ASSERT_TRUE(log->samples[1].gyro_radps.has_value());
    EXPECT_EQ(*log->samples[1].gyro_radps,
              Vec3(-0.099134701513277898, 0.14032447186034408, 0.029321531433504733));
    // No cam0/sensor.yaml: the identity, and a note.
    EXPECT_EQ(log->R_ItoC, Mat3::Identity());
    ASSERT_EQ(log->notes.size(), 1U);
    EXPECT_NE(log->notes[0].find("R_ItoC is the identity"), std::string::npos);
}

TEST(EurocImu, CameraRotationFromSensorYaml) {
    const TempDir dir("imu_euroc");
    const auto file = dir.path() / "mav0" / "imu0" / "data.csv";
    writeFile(file, kEurocCsv);
    writeFile(dir.path() / "mav0" / "imu0" / "sensor.yaml", kImuYaml);
    writeFile(dir.path() / "mav0" / "cam0" / "sensor.yaml", kCamYaml);
    auto log = readEurocImu(file);
    ASSERT_TRUE(log.ok()) << log.error().message;
    Mat3 R_CtoB;
    R_CtoB << 0.0148655429818, -0.999880929698, 0.00414029679422, 0.999557249008, 0.0149672133247,
        0.025715529948, -0.0257744366974, 0.00375618835797, 0.999660727178;
    EXPECT_LT((log->R_ItoC - R_CtoB.transpose()).norm(), 1e-12);
    EXPECT_TRUE(log->notes.empty());
    EXPECT_NE(log->R_ItoC_source.find("cam0/sensor.yaml"), std::string::npos);
    // On MH_01's start the MAV stands level and its IMU reads about +9.8
    // m/s^2 along x_I (x_B points up); the camera looks ahead, level, so down
    // (-x_I) is about +y_C in the optical frame.
    const Vec3 down_inC = log->R_ItoC * Vec3(-1, 0, 0);
    EXPECT_GT(down_inC.y(), 0.99) << down_inC.transpose();
}

TEST(EurocImu, MalformedLinesNameFileAndLine) {
    const std::string head = "#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n";
    const BadCase cases[] = {
        {"fields", "1000,0,0,0,0,0,9.8\n2000,0,0,0,0,9.8\n", 3,
         "expected 7 comma-separated fields"},
        {"time", "1000.5,0,0,0,0,0,9.8\n", 2,
         "timestamp is not a non-negative integer [ns]: '1000.5'"},
        {"negative", "-5,0,0,0,0,0,9.8\n", 2, "timestamp is not a non-negative integer"},
        {"order", "2000,0,0,0,0,0,9.8\n1000,0,0,0,0,0,9.8\n", 3,
         "timestamp does not increase (previous at line 2)"},
        {"number", "1000,0,0,0,0,x,9.8\n", 2, "a_RS_S_y is not a number: 'x'"},
        {"empty", "1000,0,,0,0,0,9.8\n", 2, "w_RS_S_y is not a number: ''"},
        {"gyro", "1000,0,0,5000,0,0,9.8\n", 2, "w_RS_S_z is implausibly large"},
    };
    const TempDir dir("imu_euroc");
    for (const BadCase& c : cases) {
        SCOPED_TRACE(c.name);
        const auto file = dir.path() / (std::string(c.name) + ".csv");
        writeFile(file, head + std::string(c.text));
        auto log = readEurocImu(file);
        ASSERT_FALSE(log.ok());
        EXPECT_EQ(log.error().code, ErrorCode::kParse);
        const std::string prefix = file.string() + ":" + std::to_string(c.line) + ": ";
        EXPECT_EQ(log.error().message.rfind(prefix, 0), 0U) << log.error().message;
        EXPECT_NE(log.error().message.find(c.what), std::string::npos) << log.error().message;
    }
    const auto empty = dir.path() / "header_only.csv";
    writeFile(empty, head);
    auto none = readEurocImu(empty);
    ASSERT_FALSE(none.ok());
    EXPECT_EQ(none.error().message, empty.string() + ": no samples");
}

TEST(EurocImu, BadSensorYamlIsNamed) {
    const TempDir dir("imu_euroc");
    const auto file = dir.path() / "mav0" / "imu0" / "data.csv";
    writeFile(file, kEurocCsv);
    const auto yaml = dir.path() / "mav0" / "cam0" / "sensor.yaml";
    writeFile(yaml, "T_BS:\n  cols: 4\n  rows: 4\n  data: [1, 0, 0, 0, 0, 1, 0, 0]\n");
    auto short_data = readEurocImu(file);
    ASSERT_FALSE(short_data.ok());
    EXPECT_EQ(short_data.error().message.rfind(
                  yaml.string() + ":4: T_BS data: expected 16 numbers, got 8", 0),
              0U)
        << short_data.error().message;

    writeFile(yaml, "T_BS:\n  data: [2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]\n");
    auto scaled_r = readEurocImu(file);
    ASSERT_FALSE(scaled_r.ok());
    EXPECT_NE(scaled_r.error().message.find(yaml.string() + ":2: T_BS is not a rotation"),
              std::string::npos)
        << scaled_r.error().message;

    writeFile(yaml, "sensor_type: camera\n");
    auto no_key = readEurocImu(file);
    ASSERT_FALSE(no_key.ok());
    EXPECT_EQ(no_key.error().message, yaml.string() + ": no T_BS");
}

}  // namespace
}  // namespace scaled::drivers::imu
