#pragma once

// Constant-velocity motion model of the camera (Davison's MonoSLAM):
//   r' = r + (v + V) dt,  q' = q (x) Exp((w + W) dt),  v' = v + V,  w' = w + W
// with impulses V = a dt, W = alpha dt from zero-mean white accelerations of
// standard deviation sigma_a (SLAM units/s^2) and sigma_alpha (rad/s^2).
// The angular velocity w is expressed in the camera frame.
//
// With reference_hz > 0 the linear impulse is a random walk instead:
// Var(V) = sigma_a^2 dt / reference_hz per axis, which is MonoSLAM's
// sigma_a^2 dt^2 at dt = 1 / reference_hz and grows with dt, not dt^2, at
// other frame intervals (the velocity's variance after a second is the same
// whatever the frame rate). The angular impulse keeps MonoSLAM's form
// (docs/slam.md, "The velocity's noise as a random walk").

#include <scaled/core/slam/slam_types.h>

namespace scaled::core::slam {

struct MotionNoise {
    Scalar sigma_a = 1;      // linear acceleration, SLAM units / s^2
    Scalar sigma_alpha = 1;  // angular acceleration, rad / s^2
    // Frame rate at which sigma_a gives MonoSLAM's impulse; 0: MonoSLAM's
    // sigma_a^2 dt^2 at every frame interval.
    Scalar reference_hz = 0;
};

// x: the 13-D camera state. F = dx'/dx, Q = G diag(V, W) G^T: the process
// noise added over dt (both optional).
Vec13 predictCamera(const Vec13& x, Scalar dt_s, const MotionNoise& noise, Mat13* F = nullptr,
                    Mat13* Q = nullptr);

}  // namespace scaled::core::slam
