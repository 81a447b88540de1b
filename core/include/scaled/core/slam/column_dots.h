#pragma once

// Several dot products of one column with J others at once, each summed in
// exactly the order of Eigen's vectorised dot (Eigen/src/Core/Redux.h,
// LinearVectorizedTraversal: two packet accumulators over pairs of packets,
// their sum, one more packet if left, Eigen's predux of the lanes, then the
// scalar tail), with Eigen's own packet primitives. Sharing the loads of x and
// keeping 2 J independent accumulators makes the EKF covariance downdate a
// little faster than one Eigen dot per element (6-7% of a frame at 100
// features, docs/benchmarks.md), while every element keeps Eigen's rounding:
// tests/unit/slam/column_dots_test.cpp checks equality on x86-64 (where the
// recorded runs were measured) and closeness elsewhere.

#include <cstddef>

#include <Eigen/Core>

#include <scaled/core/types.h>

namespace scaled::core::slam::detail {

// Eigen's default packet for Scalar (2 doubles or 4 floats with SSE2; Scalar
// itself without vectorisation) and the primitives its dot is made of.
using DotPacket = Eigen::internal::packet_traits<Scalar>::type;
inline constexpr auto kDotLanes =
    static_cast<Eigen::Index>(Eigen::internal::packet_traits<Scalar>::size);

// out[j] = sum_k x[k] y[j][k] over k < m, for j < J.
template <std::size_t J>
inline void columnDots(const Scalar* x, const Scalar* const (&y)[J], Eigen::Index m,
                       Scalar (&out)[J]) {
    using Eigen::internal::padd;
    using Eigen::internal::ploadu;
    using Eigen::internal::pmul;
    constexpr Eigen::Index p = kDotLanes;
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
    DotPacket acc0[J];
    const DotPacket x0 = ploadu<DotPacket>(x);
    for (std::size_t j = 0; j < J; ++j) {
        acc0[j] = pmul(x0, ploadu<DotPacket>(y[j]));
    }
    if (aligned > p) {
        DotPacket acc1[J];
        const DotPacket x1 = ploadu<DotPacket>(x + p);
        for (std::size_t j = 0; j < J; ++j) {
            acc1[j] = pmul(x1, ploadu<DotPacket>(y[j] + p));
        }
        for (Eigen::Index k = 2 * p; k < aligned2; k += 2 * p) {
            const DotPacket xa = ploadu<DotPacket>(x + k);
            const DotPacket xb = ploadu<DotPacket>(x + k + p);
            for (std::size_t j = 0; j < J; ++j) {
                acc0[j] = padd(acc0[j], pmul(xa, ploadu<DotPacket>(y[j] + k)));
                acc1[j] = padd(acc1[j], pmul(xb, ploadu<DotPacket>(y[j] + k + p)));
            }
        }
        for (std::size_t j = 0; j < J; ++j) {
            acc0[j] = padd(acc0[j], acc1[j]);
        }
        if (aligned > aligned2) {
            const DotPacket xa = ploadu<DotPacket>(x + aligned2);
            for (std::size_t j = 0; j < J; ++j) {
                acc0[j] = padd(acc0[j], pmul(xa, ploadu<DotPacket>(y[j] + aligned2)));
            }
        }
    }
    for (std::size_t j = 0; j < J; ++j) {
        Scalar r = Eigen::internal::predux(acc0[j]);
        for (Eigen::Index k = aligned; k < m; ++k) {
            r += x[k] * y[j][k];
        }
        out[j] = r;
    }
}

}  // namespace scaled::core::slam::detail
