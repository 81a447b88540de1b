#pragma once

// One inertial measurement, as an accelerometer (and a gyroscope, when the
// device has one) reports it, in the IMU's own frame I. Plain data: the
// drivers (drivers/imu) produce these, core's gravity estimate
// (geometry/gravity.h) consumes them.

#include <cstdint>
#include <optional>

#include <scaled/core/types.h>

namespace scaled::core {

struct ImuSample {
    // Time of the measurement in nanoseconds on the source's clock: a
    // dataset log's own timestamps, or the IIO device's timestamp clock
    // (drivers/imu/iio_device.h says which).
    int64_t t_ns = 0;
    // Specific force in the IMU frame I, m/s^2: at rest it points UP (+9.81
    // m/s^2 against gravity), as every accelerometer measures it.
    Vec3 accel_mps2 = Vec3::Zero();
    // Angular velocity in the IMU frame I, rad/s, when the device has a gyroscope.
    std::optional<Vec3> gyro_radps;
};

}  // namespace scaled::core
