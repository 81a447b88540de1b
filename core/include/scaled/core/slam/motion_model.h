#pragma once

// Constant-velocity motion model of the camera (Davison's MonoSLAM):
//   r' = r + (v + V) dt,  q' = q (x) Exp((w + W) dt),  v' = v + V,  w' = w + W
// with impulses V = a dt, W = alpha dt from zero-mean white accelerations of
// standard deviation sigma_a (SLAM units/s^2) and sigma_alpha (rad/s^2).
// The angular velocity w is expressed in the camera frame.

#include <scaled/core/slam/slam_types.h>

namespace scaled::core::slam {

struct MotionNoise {
    Scalar sigma_a = 1;      // linear acceleration, SLAM units / s^2
    Scalar sigma_alpha = 1;  // angular acceleration, rad / s^2
};

// x: the 13-D camera state. F = dx'/dx, Q = G diag(V, W) G^T: the process
// noise added over dt (both optional).
Vec13 predictCamera(const Vec13& x, Scalar dt_s, const MotionNoise& noise, Mat13* F = nullptr,
                    Mat13* Q = nullptr);

}  // namespace scaled::core::slam
