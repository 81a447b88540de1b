#pragma once

// Several dot products of one column with J others at once, each summed in
// exactly the order of Eigen's vectorised dot (Eigen/src/Core/Redux.h,
// LinearVectorizedTraversal: two packet accumulators over pairs of packets,
// their sum, one more packet if left, the lanes reduced by halves, then the
// scalar tail). Sharing the loads of x and keeping 2 J independent
// accumulators makes the EKF covariance downdate several times faster than
// one Eigen dot per element, while every element keeps Eigen's rounding (on
// x86-64 without FMA contraction, where the recorded runs were measured:
// tests/unit/slam/column_dots_test.cpp checks equality there, and closeness
// elsewhere).

#include <cstddef>

#include <Eigen/Core>

#include <scaled/core/types.h>

namespace scaled::core::slam::detail {

// Lanes of Eigen's default packet for Scalar (2 doubles or 4 floats with SSE2).
inline constexpr std::size_t kDotLanes =
    static_cast<std::size_t>(Eigen::internal::packet_traits<Scalar>::size);

// Eigen's predux: the lanes summed by halves, (a0 + a2) + (a1 + a3) for 4.
template <std::size_t P>
inline Scalar reduceLanes(const Scalar* a) {
    if constexpr (P == 1) {
        return a[0];
    } else {
        Scalar half[P / 2];
        for (std::size_t l = 0; l < P / 2; ++l) {
            half[l] = a[l] + a[l + P / 2];
        }
        return reduceLanes<P / 2>(half);
    }
}

// out[j] = sum_k x[k] y[j][k] over k < m, for j < J.
template <std::size_t J>
inline void columnDots(const Scalar* x, const Scalar* const (&y)[J], Eigen::Index m,
                       Scalar (&out)[J]) {
    constexpr std::size_t P = kDotLanes;
    constexpr auto p = static_cast<Eigen::Index>(P);
    const Eigen::Index aligned = (m / p) * p;
    const Eigen::Index aligned2 = (m / (2 * p)) * (2 * p);
    if (aligned == 0) {
        for (std::size_t j = 0; j < J; ++j) {
            Scalar r = x[0] * y[j][0];
            for (Eigen::Index k = 1; k < m; ++k) {
                r += x[k] * y[j][k];
            }
            out[j] = r;
        }
        return;
    }
    Scalar acc0[J][P];
    for (std::size_t j = 0; j < J; ++j) {
        for (Eigen::Index l = 0; l < p; ++l) {
            acc0[j][l] = x[l] * y[j][l];
        }
    }
    if (aligned > p) {
        Scalar acc1[J][P];
        for (std::size_t j = 0; j < J; ++j) {
            for (Eigen::Index l = 0; l < p; ++l) {
                acc1[j][l] = x[p + l] * y[j][p + l];
            }
        }
        for (Eigen::Index k = 2 * p; k < aligned2; k += 2 * p) {
            for (std::size_t j = 0; j < J; ++j) {
                for (Eigen::Index l = 0; l < p; ++l) {
                    acc0[j][l] += x[k + l] * y[j][k + l];
                    acc1[j][l] += x[k + p + l] * y[j][k + p + l];
                }
            }
        }
        for (std::size_t j = 0; j < J; ++j) {
            for (Eigen::Index l = 0; l < p; ++l) {
                acc0[j][l] += acc1[j][l];
            }
        }
        if (aligned > aligned2) {
            for (std::size_t j = 0; j < J; ++j) {
                for (Eigen::Index l = 0; l < p; ++l) {
                    acc0[j][l] += x[aligned2 + l] * y[j][aligned2 + l];
                }
            }
        }
    }
    for (std::size_t j = 0; j < J; ++j) {
        Scalar r = reduceLanes<P>(acc0[j]);
        for (Eigen::Index k = aligned; k < m; ++k) {
            r += x[k] * y[j][k];
        }
        out[j] = r;
    }
}

}  // namespace scaled::core::slam::detail
