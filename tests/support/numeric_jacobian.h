#pragma once

// Numeric-vs-analytic Jacobian check (in the spirit of Basalt's test_utils.h):
// central differences of f around x, compared entry-wise with J_analytic.

#include <functional>

#include <Eigen/Core>
#include <gtest/gtest.h>

namespace scaled::test {

template <int Out, int In, typename Scalar = double>
Eigen::Matrix<Scalar, Out, In> numericJacobian(
    const std::function<Eigen::Matrix<Scalar, Out, 1>(const Eigen::Matrix<Scalar, In, 1>&)>& f,
    const Eigen::Matrix<Scalar, In, 1>& x, Scalar h = Scalar(1e-6)) {
    Eigen::Matrix<Scalar, Out, In> J;
    for (int i = 0; i < In; ++i) {
        Eigen::Matrix<Scalar, In, 1> xp = x;
        Eigen::Matrix<Scalar, In, 1> xm = x;
        xp(i) += h;
        xm(i) -= h;
        J.col(i) = (f(xp) - f(xm)) / (2 * h);
    }
    return J;
}

template <int Out, int In, typename Scalar = double>
void expectJacobianNear(
    const char* what, const Eigen::Matrix<Scalar, Out, In>& analytic,
    const std::function<Eigen::Matrix<Scalar, Out, 1>(const Eigen::Matrix<Scalar, In, 1>&)>& f,
    const Eigen::Matrix<Scalar, In, 1>& x, Scalar tol = Scalar(1e-6), Scalar h = Scalar(1e-6)) {
    const auto numeric = numericJacobian<Out, In, Scalar>(f, x, h);
    const Scalar scale = std::max(Scalar(1), numeric.cwiseAbs().maxCoeff());
    EXPECT_TRUE(numeric.isApprox(analytic, tol) ||
                (numeric - analytic).cwiseAbs().maxCoeff() <= tol * scale)
        << what << "\nanalytic:\n" << analytic << "\nnumeric:\n" << numeric;
}

}  // namespace scaled::test
