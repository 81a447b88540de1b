#pragma once

// A simulated gyroscope for evaluation (slam-run, scale-eval --gyro-sim):
// what the gyro motion prior would do on a recorded sequence that has no IMU
// but has ground truth (redkitchen, KITTI). Not a device and not a log: the
// samples between two frames are the ground truth's mean body rate over the
// interval, Log(R_CtoW(t0)^T R_CtoW(t1)) / (t1 - t0), in the camera frame
// (R_ItoC = identity), at rate_hz, plus white noise of noise_density
// (rad/s/sqrt(Hz)) and a constant bias drawn once per axis from
// N(0, bias_sigma_radps) with `seed`. The rotation inside an interval is
// therefore the true one only in its mean: what a camera at this frame rate
// with ground truth at the frames can show.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::drivers::imu {

struct SimulatedGyroOptions {
    double rate_hz = 200;
    double noise_density = 2e-4;  // rad/s/sqrt(Hz)
    double bias_sigma_radps = 0.01;
    std::uint64_t seed = 1;
};

class SimulatedGyro {
public:
    // rate_hz in [10, 10000], noise_density in [0, 1], bias_sigma_radps in
    // [0, 10]; the message names the value.
    [[nodiscard]] static core::Result<SimulatedGyro> create(const SimulatedGyroOptions& options);

    // Samples covering [t0_ns, t1_ns] (both ends included) for a camera that
    // turned from R0_CtoW to R1_CtoW; empty when t1_ns <= t0_ns or the
    // interval is longer than 10 s (no tracker bridges such a gap). The span
    // stays valid until the next call.
    std::span<const core::ImuSample> between(std::int64_t t0_ns, const core::Mat3& R0_CtoW,
                                             std::int64_t t1_ns, const core::Mat3& R1_CtoW);

    [[nodiscard]] const core::Vec3& bias() const { return bias_; }
    // "simulated gyro from ground truth (200 Hz, 2e-4 rad/s/sqrt(Hz), bias
    // (0.004, -0.011, 0.002) rad/s)", for reports.
    [[nodiscard]] std::string describe() const;

private:
    SimulatedGyro(const SimulatedGyroOptions& options, const core::Vec3& bias);
    SimulatedGyroOptions options_;
    core::Vec3 bias_;
    std::uint64_t state_;  // splitmix64 state for the white noise
    std::vector<core::ImuSample> samples_;
};

}  // namespace scaled::drivers::imu
