#pragma once

// What feeds the frame step's gyro prior (core/slam/gyro_prior.h) when a
// recorded sequence is replayed (slam-run, scale-eval, the daemon's replay):
//   1. a simulated gyro from the ground truth, when asked for (evaluation
//      only: simulated_gyro.h);
//   2. the sequence's own IMU log when it carries a gyroscope (EuRoC
//      imu0/data.csv; TUM's accelerometer.txt has none), on the frames' clock;
//   3. nothing: the constant-velocity model.

#include <optional>
#include <string>

#include <scaled/core/result.h>
#include <scaled/core/slam/gyro_prior.h>
#include <scaled/drivers/imu/map_gravity.h>
#include <scaled/drivers/imu/simulated_gyro.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::imu {

class GyroFeed {
public:
    GyroFeed() = default;
    // dataset: the sequence's selector (its IMU log), which must outlive the feed.
    [[nodiscard]] static core::Result<GyroFeed> create(
        const MapGravitySelector& dataset, const std::optional<SimulatedGyroOptions>& simulated);

    // The samples for this frame's prediction, or nullptr (then constant
    // velocity). Frames come in replay order; the simulated gyro needs this
    // frame's and the previous frame's ground truth.
    const core::slam::ImuWindow* forFrame(const source::Frame& frame);

    // Something feeds the prior (a log with a gyroscope and a known R_ItoC,
    // or the simulated gyro).
    [[nodiscard]] bool active() const { return simulated_.has_value() || log_window_.has_value(); }
    // "none" (with the reason when a log has a gyro that cannot be used), the
    // log's path and where its R_ItoC came from, or the simulated gyro's
    // description.
    [[nodiscard]] const std::string& source() const { return source_; }

private:
    std::optional<SimulatedGyro> simulated_;
    std::optional<core::slam::ImuWindow> log_window_;
    core::slam::ImuWindow window_;
    bool have_prev_ = false;
    std::int64_t prev_t_ns_ = 0;
    core::Mat3 prev_R_ = core::Mat3::Identity();
    std::string source_ = "none";
};

}  // namespace scaled::drivers::imu
