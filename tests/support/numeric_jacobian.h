#pragma once

// Numeric-vs-analytic Jacobian check (in the spirit of Basalt's test_utils.h):
// central differences of f around x, compared entry-wise with the analytic J.

#include <algorithm>

#include <Eigen/Core>
#include <gtest/gtest.h>

namespace scaled::test {

// f maps Eigen::Matrix<S, In, 1> to Eigen::Matrix<S, Out, 1>.
template <int Out, int In, typename S, typename F>
Eigen::Matrix<S, Out, In> numericJacobian(F&& f, const Eigen::Matrix<S, In, 1>& x, S h) {
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

template <int Out, int In, typename S, typename F>
void expectJacobianNear(const char* what, const Eigen::Matrix<S, Out, In>& analytic, F&& f,
                        const Eigen::Matrix<S, In, 1>& x, S tol = S(1e-6), S h = S(1e-6)) {
    const Eigen::Matrix<S, Out, In> numeric = numericJacobian<Out, In>(f, x, h);
    const S scale = std::max(S(1), numeric.cwiseAbs().maxCoeff());
    EXPECT_LE((numeric - analytic).cwiseAbs().maxCoeff(), tol * scale) << what << "\nanalytic:\n"
                                                                       << analytic << "\nnumeric:\n"
                                                                       << numeric;
}

}  // namespace scaled::test
