#pragma once

// Replay of a dataset's IMU log: samples (core::ImuSample, IMU frame) and the
// rotation R_ItoC that takes the log's axes into the camera's optical frame
// (x right, y down, z forward), ready for core::estimateGravityDown().
//
//   TUM RGB-D   accelerometer.txt: `timestamp ax ay az` per line, timestamps
//               in seconds, '#' comments; the Kinect's accelerometer, no gyro.
//               R_ItoC = tumKinectImuToCamera() (below).
//   EuRoC MAV   imu0/data.csv: `#timestamp [ns],w_RS_S_x [rad s^-1],
//               w_RS_S_y,w_RS_S_z,a_RS_S_x [m s^-2],a_RS_S_y,a_RS_S_z`,
//               comma separated, integer nanoseconds. R_ItoC from the
//               sensors' T_BS (cam0/sensor.yaml, imu0/sensor.yaml) when they
//               are next to imu0/, else the identity (and a note says so).
//
// Timestamps must strictly increase and values be finite (at most 1e4 m/s^2
// and 1e3 rad/s). Errors read `FILE:LINE: what (the offending text)`, e.g.
//   `seq/accelerometer.txt:7: expected 4 fields `timestamp ax ay az`, got 3 (1.5 0.1 9.8)`.

#include <filesystem>
#include <string>
#include <vector>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::drivers::imu {

struct ImuLog {
    std::vector<core::ImuSample> samples;  // in time order, IMU frame I
    // Rotation from the log's IMU frame into the camera's optical frame.
    core::Mat3 R_ItoC = core::Mat3::Identity();
    // Where R_ItoC came from, e.g. "TUM Kinect default (docs/imu.md)" or
    // "cam0/sensor.yaml T_BS"; for logs and messages.
    std::string R_ItoC_source;
    // False when R_ItoC is a default taken for want of the rotation (an EuRoC
    // log without cam0/sensor.yaml): fine for nothing that turns with it (the
    // gyro prior refuses such a log).
    bool R_ItoC_known = true;
    std::vector<std::string> notes;  // what a user should know (defaults taken)
};

// The TUM RGB-D Kinect accelerometer in the colour camera's optical frame:
// a rotation of 180 degrees about z, diag(-1, -1, 1). Measured on a TUM fr1
// sequence against its ground truth: gravity (down) in the colour camera's
// optical frame is (ax, ay, -az) / |a|. With the accelerometer reading the
// specific force (up at rest, core/imu_sample.h), down_inI = -a / |a| and
// R_ItoC * down_inI = (ax, ay, -az) / |a| exactly.
[[nodiscard]] core::Mat3 tumKinectImuToCamera();

// A TUM accelerometer.txt, R_ItoC = tumKinectImuToCamera().
[[nodiscard]] core::Result<ImuLog> readTumAccelerometer(const std::filesystem::path& path);

// An EuRoC imu0/data.csv (accelerometer and gyroscope). R_ItoC = R_CtoB^T *
// R_ItoB from `DIR/../cam0/sensor.yaml` and `DIR/../imu0/sensor.yaml` (DIR the
// csv's directory) when cam0/sensor.yaml exists (a missing imu0/sensor.yaml
// is the identity, as EuRoC's is); their errors name the yaml file.
[[nodiscard]] core::Result<ImuLog> readEurocImu(const std::filesystem::path& path);

// The rotation of `T_BS` (sensor to body) in an EuRoC sensor.yaml: 16 numbers
// in `data: [...]`, row-major 4x4; fails unless it is a rotation to 1e-3.
[[nodiscard]] core::Result<core::Mat3> readEurocSensorRotation(
    const std::filesystem::path& sensor_yaml);

}  // namespace scaled::drivers::imu
