#include <cmath>
#include <cstddef>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include <scaled/core/slam/column_dots.h>

namespace scaled::core::slam {
namespace {

using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;

// Where the recorded runs were measured (x86-64, SSE2 packets, no FMA
// contraction), the EKF downdate must round exactly as one Eigen dot per
// element did: columnDots is then bit-identical. Elsewhere (aarch64 contracts
// a * b + c into FMA, in Eigen's packets and here differently) it must agree
// within the rounding bound of a dot product.
#if defined(__x86_64__) && !defined(__FMA__)
constexpr bool kExact = true;
#else
constexpr bool kExact = false;
#endif

template <std::size_t J>
void checkAgainstEigen(const Matrix& storage, Eigen::Index m) {
    // Columns of a block with the storage's outer stride, as Wt_.topLeftCorner.
    const auto W = storage.topLeftCorner(m, storage.cols());
    for (Eigen::Index i = 0; i + static_cast<Eigen::Index>(J) <= W.cols(); ++i) {
        const Scalar* cols[J];
        for (std::size_t j = 0; j < J; ++j) {
            cols[j] = W.col(i + static_cast<Eigen::Index>(j)).data();
        }
        const Eigen::Index x_col = W.cols() - 1 - i;
        Scalar dots[J];
        detail::columnDots<J>(W.col(x_col).data(), cols, m, dots);
        for (std::size_t j = 0; j < J; ++j) {
            const auto y = W.col(i + static_cast<Eigen::Index>(j));
            const Scalar eigen = W.col(x_col).dot(y);
            if (kExact) {
                ASSERT_EQ(dots[j], eigen) << "m " << m << " column " << i << " + " << j;
            } else {
                const Scalar bound = Scalar(2) * static_cast<Scalar>(m) *
                                     std::numeric_limits<Scalar>::epsilon() *
                                     W.col(x_col).cwiseAbs().dot(y.cwiseAbs());
                ASSERT_LE(std::abs(dots[j] - eigen), bound)
                    << "m " << m << " column " << i << " + " << j;
            }
        }
    }
}

TEST(ColumnDots, SumLikeEigensDotForEveryLength) {
    std::mt19937_64 rng(7);
    std::normal_distribution<double> normal(0.0, 1.0);
    // Rows beyond m as in the EKF's preallocated buffers; values of mixed
    // magnitude so that the order of the sums shows in the last bits.
    Matrix storage(80, 9);
    for (Eigen::Index c = 0; c < storage.cols(); ++c) {
        for (Eigen::Index r = 0; r < storage.rows(); ++r) {
            storage(r, c) = static_cast<Scalar>(normal(rng) * std::exp(3.0 * normal(rng)));
        }
    }
    for (Eigen::Index m = 1; m <= 80; ++m) {
        checkAgainstEigen<4>(storage, m);
        checkAgainstEigen<1>(storage, m);
    }
}

}  // namespace
}  // namespace scaled::core::slam
