#pragma once

// The gyro motion prior (issue 21): the camera's rotation between two frames
// from a gyroscope's angular rate instead of the constant-velocity guess.
//
// integrateGyro() turns the samples around a frame interval (t0, t1] into one
// mean angular rate in the camera frame,
//   w_C = R_ItoC * Log( prod_k Exp((w_k - bias_I) dtau_k) ) / (t1 - t0),
// the rate taken as linear between samples and constant beyond the first and
// last (at most max_gap_ns), integrated piece by piece at the sample times,
// with a per-axis standard deviation
//   sigma^2 = noise_density^2 / (t1 - t0) + bias_sigma^2
// (white rate noise averaged over the interval, plus what is left of the
// bias; the bias is treated as independent from frame to frame, which is
// pessimistic about its mean and optimistic about its correlation).
// EkfSlam::predict(t_ns, &rate) then puts w_C into the state's angular
// velocity with that variance, uncorrelated with the rest, and propagates
// without the angular-acceleration impulse: the rotation over the interval is
// the gyro's, its uncertainty the gyro's (docs/slam.md "The gyro prior").
//
// Samples must be in time order (ImuSample::t_ns on the frames' clock);
// samples without a gyroscope reading are skipped. Nothing allocates; the
// work is a binary search and one step per sample in the interval.

#include <cstdint>
#include <span>

#include <scaled/core/imu_sample.h>
#include <scaled/core/types.h>

namespace scaled::core::slam {

struct GyroModel {
    Mat3 R_ItoC = Mat3::Identity();          // IMU frame to camera (optical) frame
    Vec3 bias_I_radps = Vec3::Zero();        // subtracted from every sample
    Scalar noise_density = Scalar(2e-4);     // rad/s/sqrt(Hz): a consumer MEMS gyro's
    Scalar bias_sigma_radps = Scalar(0.02);  // about 1 deg/s: an uncalibrated bias
    // The largest gap between two samples used, and between the interval's
    // ends and the nearest sample: a device that went silent gives no rate.
    int64_t max_gap_ns = 50'000'000;
};

// A mean angular rate over one frame interval, for EkfSlam::predict.
struct GyroRate {
    Vec3 w_C_radps = Vec3::Zero();  // camera frame
    Scalar sigma_radps = 0;         // per axis, 1 sigma
    int samples = 0;  // gyro samples used: the last at or before t0, and those after it
};

// The samples one frame's prediction may draw on: in time order, stamped on
// the frames' clock, covering the interval since the previous frame (more is
// fine: a whole log, a device's ring), and the IMU-to-camera rotation.
struct ImuWindow {
    std::span<const ImuSample> samples;
    Mat3 R_ItoC = Mat3::Identity();
};

enum class GyroCoverage : std::uint8_t {
    kOk,
    kBadInterval,  // t1 <= t0, a non-finite sample, or a non-positive model sigma
    kNoSamples,    // no gyro sample within max_gap_ns of the interval
    kGap,          // samples stop short of an end, or two are too far apart
};
const char* toString(GyroCoverage coverage);

struct GyroIntegration {
    GyroCoverage coverage = GyroCoverage::kNoSamples;
    GyroRate rate;  // meaningful when coverage == kOk
};

[[nodiscard]] GyroIntegration integrateGyro(std::span<const ImuSample> samples, int64_t t0_ns,
                                            int64_t t1_ns, const GyroModel& model);

}  // namespace scaled::core::slam
