#pragma once

// Tolerances of tests that run in both scalar builds of core
// (SCALED_CORE_SCALAR=double or float, docs/numerics.md). A check states both
// bounds where it compares with values computed in double or by hand; the
// float one is what float32 arithmetic can hold (about 1e-7 relative per
// operation, more through long chains such as the EKF).

#include <type_traits>

#include <gtest/gtest.h>

#include <scaled/core/types.h>

namespace scaled::test {

inline constexpr bool kFloatBuild = std::is_same_v<core::Scalar, float>;

// for_double in a double build, for_float in a float build.
constexpr double tolerance(double for_double, double for_float) {
    return kFloatBuild ? for_float : for_double;
}

// PinholeRadialCamera::undistort (core/src/camera/pinhole_radial.cpp) ends its
// Newton iteration once |distort(x_u) - x_d| <= 64 eps (1 + |x_d|). In float
// that residual can be up to 1.5e-5 (normalised, |x_d| <= 1), about 1e-2 px at
// f ~ 600 (double: 3e-14). Round trips through undistort are no closer.
inline constexpr double kFloatUndistortResidual = 64 * 1.1920929e-7 * 2;

}  // namespace scaled::test

// EXPECT_DOUBLE_EQ in a double build, EXPECT_FLOAT_EQ in a float build: equal
// to within 4 ulps of the build's scalar.
#define SCALED_EXPECT_SCALAR_EQ(a, b)                                         \
    do {                                                                      \
        if constexpr (::scaled::test::kFloatBuild) {                          \
            EXPECT_FLOAT_EQ(static_cast<float>(a), static_cast<float>(b));    \
        } else {                                                              \
            EXPECT_DOUBLE_EQ(static_cast<double>(a), static_cast<double>(b)); \
        }                                                                     \
    } while (false)
