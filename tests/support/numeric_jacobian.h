#pragma once

// Numeric-vs-analytic Jacobian check (in the spirit of Basalt's test_utils.h):
// central differences of f around x, compared entry-wise with the analytic J.
//
// In a float build (SCALED_CORE_SCALAR=float) the step is at least
// kFloatStep and the tolerance at least kFloatTolerance: central differences
// in float are best near h ~ cbrt(eps) ~ 5e-3 (truncation ~ h^2, rounding ~
// eps / h), which leaves about 1e-4 of the largest entry; 2e-3 keeps a margin
// and still catches a wrong term (those are off by O(1)).

#include <algorithm>
#include <type_traits>

#include <Eigen/Core>
#include <gtest/gtest.h>

namespace scaled::test {

// f maps Eigen::Matrix<S, In, 1> to Eigen::Matrix<S, Out, 1>.
template <int Out, int In, typename S, typename F>
Eigen::Matrix<S, Out, In> numericJacobian(F&& f, const Eigen::Matrix<S, In, 1>& x,
                                          std::type_identity_t<S> h) {
    Eigen::Matrix<S, Out, In> J;
    for (int i = 0; i < In; ++i) {
        Eigen::Matrix<S, In, 1> xp = x;
        Eigen::Matrix<S, In, 1> xm = x;
        xp(i) += h;
        xm(i) -= h;
        J.col(i) = (f(xp) - f(xm)) / (2 * h);
    }
    return J;
}

inline constexpr double kFloatStep = 2e-3;
inline constexpr double kFloatTolerance = 2e-3;

template <int Out, int In, typename S, typename F>
void expectJacobianNear(const char* what, const Eigen::Matrix<S, Out, In>& analytic, F&& f,
                        const Eigen::Matrix<S, In, 1>& x, double tol = 1e-6, double h = 1e-6) {
    if constexpr (std::is_same_v<S, float>) {
        tol = std::max(tol, kFloatTolerance);
        h = std::max(h, kFloatStep);
    }
    const Eigen::Matrix<S, Out, In> numeric = numericJacobian<Out, In>(f, x, static_cast<S>(h));
    const double scale = std::max(1.0, static_cast<double>(numeric.cwiseAbs().maxCoeff()));
    EXPECT_LE(static_cast<double>((numeric - analytic).cwiseAbs().maxCoeff()), tol * scale)
        << what << "\nanalytic:\n"
        << analytic << "\nnumeric:\n"
        << numeric;
}

}  // namespace scaled::test
