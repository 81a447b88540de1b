#pragma once

// Scalar type and fixed-size Eigen aliases used throughout core.
// SCALED_CORE_SCALAR selects double (default) or float at build time.

#include <Eigen/Core>

namespace scaled::core {

#ifdef SCALED_CORE_SCALAR
using Scalar = SCALED_CORE_SCALAR;
#else
using Scalar = double;
#endif

using Vec2 = Eigen::Matrix<Scalar, 2, 1>;
using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
using Mat2 = Eigen::Matrix<Scalar, 2, 2>;
using Mat3 = Eigen::Matrix<Scalar, 3, 3>;
using Mat23 = Eigen::Matrix<Scalar, 2, 3>;
using Mat32 = Eigen::Matrix<Scalar, 3, 2>;
using RowVec3 = Eigen::Matrix<Scalar, 1, 3>;

}  // namespace scaled::core
