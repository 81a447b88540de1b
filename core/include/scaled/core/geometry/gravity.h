#pragma once

// Gravity from an accelerometer: the unit "down" direction in the camera
// frame C from a short window of accelerometer samples taken while the
// camera is (nearly) still.
//
// At rest an accelerometer measures the specific force f = a - g: with a = 0
// it reads +|g| pointing UP. So the mean of the window, f_mean (frame I),
// gives down_inI = -f_mean / |f_mean| and down_inC = R_ItoC * down_inI, where
// R_ItoC rotates IMU-frame vectors into the camera frame (x right, y down,
// z forward for an optical frame).
//
// The window is near-static when
//   - it holds at least min_samples samples,
//   - |f_mean| is within magnitude_tolerance_mps2 of gravity_mps2,
//   - the spread (RMS of |f_k - f_mean|) is at most max_spread_mps2,
//   - and, when the samples carry a gyroscope, the mean angular rate is at
//     most max_rate_radps.
// Otherwise the estimate is refused (ErrorCode::kDegenerate) and the message
// says every reason with its numbers, e.g.
//   "gravity: not static in [0.000, 0.500] s (50 samples): accelerometer
//    spread 1.237 m/s^2 rms > 0.250 (moving or vibrating)".
//
// For a TUM RGB-D accelerometer.txt use drivers/imu's tumKinectImuToCamera()
// (docs/imu.md): with it down_inC = (ax, ay, -az) / |a|, measured on TUM fr1
// against its ground truth.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::core {

struct GravityOptions {
    // The window averaged: with at_t_ns, the samples in [at_t_ns - window_ns,
    // at_t_ns] ("the last half second before this frame"); without it, the
    // samples in [t0, t0 + window_ns], t0 the first sample's time ("the
    // first half second of the log").
    int64_t window_ns = 500'000'000;
    std::optional<int64_t> at_t_ns;
    std::size_t min_samples = 10;
    // Standard gravity; a near-static accelerometer reads about this much.
    Scalar gravity_mps2 = Scalar(9.80665);
    // Allowed |f_mean| - gravity_mps2: an uncalibrated MEMS accelerometer is
    // off by a few percent.
    Scalar magnitude_tolerance_mps2 = Scalar(0.8);
    // Allowed RMS of |f_k - f_mean|: the noise of a still MEMS accelerometer
    // is a few hundredths of m/s^2; a hand-held camera that moves is far above.
    Scalar max_spread_mps2 = Scalar(0.25);
    // Allowed mean |gyro| when the samples carry one (about 6 deg/s).
    Scalar max_rate_radps = Scalar(0.1);
};

struct GravityEstimate {
    Vec3 down_inC = Vec3::Zero();           // unit gravity direction (down), camera frame
    Vec3 down_inI = Vec3::Zero();           // the same in the IMU frame
    Vec3 mean_accel_mps2 = Vec3::Zero();    // f_mean, IMU frame (points up)
    Scalar magnitude_mps2 = 0;              // |f_mean|
    Scalar spread_mps2 = 0;                 // RMS of |f_k - f_mean|
    std::optional<Scalar> mean_rate_radps;  // mean |gyro|, when the samples carry one
    // 1-sigma angular uncertainty of down from the noise in the window:
    // spread / (|f_mean| sqrt(n)). A bias of the accelerometer (or an error in
    // R_ItoC) adds to it and is not in it.
    Scalar sigma_rad = 0;
    std::size_t samples = 0;  // n, samples in the window
    int64_t t_first_ns = 0;   // first and last sample used
    int64_t t_last_ns = 0;
};

// How far a matrix is from a proper rotation, computed in double: the
// largest |R^T R - I| entry and det R. estimateGravityDown accepts R_ItoC
// when isRotation() holds; the daemon checks imu.rotation_imu_to_camera with
// the same test when its configuration is read.
struct RotationDefect {
    double orthogonality = 0;  // max |R^T R - I|
    double determinant = 1;
};
inline constexpr double kRotationTolerance = 1e-3;
[[nodiscard]] RotationDefect rotationDefect(const Mat3& R);
// orthogonality <= kRotationTolerance and determinant > 0 (false for NaN).
[[nodiscard]] bool isRotation(const RotationDefect& d);

// The gravity direction from `samples` (in time order, t_ns non-decreasing)
// over the window of `options`. Errors: kInvalidArgument for options out of
// range, R_ItoC not a rotation (max |R^T R - I| > 1e-3 or det <= 0),
// samples out of time order or not finite; kDegenerate when the window holds
// too few samples or is not near-static (the message gives the reasons).
[[nodiscard]] Result<GravityEstimate> estimateGravityDown(std::span<const ImuSample> samples,
                                                          const Mat3& R_ItoC,
                                                          const GravityOptions& options = {});

// The angle between two directions, radians (0 when either is zero).
[[nodiscard]] Scalar angleBetween(const Vec3& a, const Vec3& b);

}  // namespace scaled::core
