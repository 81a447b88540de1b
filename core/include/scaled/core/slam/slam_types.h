#pragma once

// Fixed-size types of the EKF MonoSLAM (Civera, Davison, Montiel).
//
// Camera state (13): r (position of the camera in the world), q (orientation,
// camera-to-world, stored as w, x, y, z), v (linear velocity, world frame),
// w (angular velocity, camera frame). Features follow: inverse depth (6:
// x0, y0, z0, theta, phi, rho) or Euclidean (3: x, y, z). The world frame is
// the first camera frame; lengths are in SLAM units (unknown scale).

#include <Eigen/Core>

#include <scaled/core/types.h>

namespace scaled::core::slam {

using Vec4 = Eigen::Matrix<Scalar, 4, 1>;
using Vec6 = Eigen::Matrix<Scalar, 6, 1>;
using Vec13 = Eigen::Matrix<Scalar, 13, 1>;
using Mat4 = Eigen::Matrix<Scalar, 4, 4>;
using Mat6 = Eigen::Matrix<Scalar, 6, 6>;
using Mat13 = Eigen::Matrix<Scalar, 13, 13>;
using Mat34 = Eigen::Matrix<Scalar, 3, 4>;
using Mat43 = Eigen::Matrix<Scalar, 4, 3>;
using Mat36 = Eigen::Matrix<Scalar, 3, 6>;
using Mat26 = Eigen::Matrix<Scalar, 2, 6>;
using Mat27 = Eigen::Matrix<Scalar, 2, 7>;
using Mat67 = Eigen::Matrix<Scalar, 6, 7>;
using Mat62 = Eigen::Matrix<Scalar, 6, 2>;
using Mat136 = Eigen::Matrix<Scalar, 13, 6>;
using MatX = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
using VecX = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

// Offsets into the camera part of the state.
inline constexpr int kPos = 0;
inline constexpr int kQuat = 3;
inline constexpr int kVel = 7;
inline constexpr int kAngVel = 10;
inline constexpr int kCameraDim = 13;
inline constexpr int kPoseDim = 7;  // r and q: the part measurements depend on

enum class FeatureKind : unsigned char { kInverseDepth, kXyz };

inline constexpr int dimOf(FeatureKind kind) {
    return kind == FeatureKind::kInverseDepth ? 6 : 3;
}

}  // namespace scaled::core::slam
