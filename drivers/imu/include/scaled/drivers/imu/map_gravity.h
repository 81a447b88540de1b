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
// The first is what a robot with an IMU has; the second needs ground truth.

#include <filesystem>
#include <optional>
#include <string>

#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/frame_source.h>
#include <scaled/drivers/imu/imu_log.h>

namespace scaled::drivers::imu {

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
    [[nodiscard]] MapGravity atMapStart(const Frame& frame) const;

    [[nodiscard]] bool hasImuLog() const { return log_.has_value(); }

private:
    std::optional<ImuLog> log_;
    std::filesystem::path log_path_;
};

}  // namespace scaled::drivers::imu
