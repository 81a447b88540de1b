#pragma once

// Where a new map's vertical comes from when a recorded sequence is replayed
// (slam-run, scale-eval), in this order:
//   1. the sequence's accelerometer log (TUM accelerometer.txt, or EuRoC
//      imu0/data.csv next to the images): the mean specific force over the
//      half second before the frame (core::estimateGravityDown), refused when
//      the camera was moving then;
//   2. the dataset's gravity rotated by the frame's ground-truth pose
//      (Frame::gravity_down_C: a TUM gravity.txt, KITTI's level mount);
//   3. a level camera (down = +y).
// A live system puts its own accelerometer (LiveAccelerometer) before all three.
// The first is what a robot with an IMU has; the second needs ground truth.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/imu/imu_log.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::imu {

// A live accelerometer (the daemon's [imu] device): the samples its thread
// kept, stamped on the clock of now_ns (CLOCK_MONOTONIC).
struct LiveAccelerometer {
    std::span<const core::ImuSample> samples;
    core::Mat3 R_ItoC = core::Mat3::Identity();
    std::string_view label;  // "iio:device0 [mpu6050]", for the source text
    std::int64_t now_ns = 0;
    double window_s = 0.5;  // the average over [now - window_s, now]
};

struct MapGravity {
    core::Vec3 down_C = core::Vec3(0, 1, 0);  // unit, the map's first camera frame
    std::string source;                       // for logs and --json: which of the three, and why
};

class MapGravitySelector {
public:
    // Reads DIR/accelerometer.txt or DIR/imu0/data.csv when one exists; a log
    // that exists but cannot be read is an error (FILE:LINE). No log: fine.
    [[nodiscard]] static core::Result<MapGravitySelector> forDataset(
        const std::filesystem::path& dir);

    // The vertical for a map that starts at this frame.
    [[nodiscard]] MapGravity atMapStart(const source::Frame& frame) const;
    // The live accelerometer first (its last window_s before now_ns), then
    // the order above; a refusal is named with its reason after the source
    // used. Allocates only the source text.
    [[nodiscard]] MapGravity atMapStart(const source::Frame& frame,
                                        const LiveAccelerometer& live) const;

    [[nodiscard]] bool hasImuLog() const { return log_.has_value(); }
    // The sequence's IMU log (also the gyro prior's samples when it has a
    // gyroscope), or nullptr; and where it was read from.
    [[nodiscard]] const ImuLog* imuLog() const { return log_ ? &*log_ : nullptr; }
    [[nodiscard]] const std::filesystem::path& imuLogPath() const { return log_path_; }

private:
    std::optional<ImuLog> log_;
    std::filesystem::path log_path_;
};

}  // namespace scaled::drivers::imu
