#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include <scaled/core/geometry/trajectory_alignment.h>

namespace scaled::core {

Result<Sim3Alignment> alignTrajectories(std::span<const Vec3> est, std::span<const Vec3> gt,
                                        bool with_scale) {
    if (est.size() != gt.size()) {
        return makeError(ErrorCode::kInvalidArgument,
                         "alignment: " + std::to_string(est.size()) + " estimated vs " +
                             std::to_string(gt.size()) + " ground-truth positions");
    }
    const auto n = static_cast<Eigen::Index>(est.size());
    if (n < 3) {
        return makeError(ErrorCode::kDegenerate,
                         "alignment: needs at least 3 positions, got " + std::to_string(n));
    }
    Eigen::Matrix<Scalar, 3, Eigen::Dynamic> A(3, n);
    Eigen::Matrix<Scalar, 3, Eigen::Dynamic> B(3, n);
    for (Eigen::Index i = 0; i < n; ++i) {
        A.col(i) = est[static_cast<size_t>(i)];
        B.col(i) = gt[static_cast<size_t>(i)];
    }
    if (!A.allFinite() || !B.allFinite()) {
        return makeError(ErrorCode::kInvalidArgument, "alignment: non-finite position");
    }
    // Degenerate when the estimate has (almost) no extent.
    const Vec3 mean = A.rowwise().mean();
    const Scalar spread = (A.colwise() - mean).squaredNorm() / Scalar(n);
    if (!(spread > Scalar(1e-12))) {
        return makeError(ErrorCode::kDegenerate, "alignment: estimated positions do not move");
    }
    const Eigen::Matrix<Scalar, 4, 4> T = Eigen::umeyama(A, B, with_scale);
    Sim3Alignment out;
    const Mat3 sR = T.topLeftCorner<3, 3>();
    out.scale = std::cbrt(sR.determinant());
    out.R = sR / out.scale;
    out.t = T.topRightCorner<3, 1>();
    Scalar sq = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
        sq += (B.col(i) - (sR * A.col(i) + out.t)).squaredNorm();
    }
    out.ate_rmse = std::sqrt(sq / Scalar(n));
    out.count = static_cast<int>(n);
    return out;
}

Scalar pathLength(std::span<const Vec3> positions) {
    Scalar len = 0;
    for (size_t i = 1; i < positions.size(); ++i) {
        len += (positions[i] - positions[i - 1]).norm();
    }
    return len;
}

Result<Scalar> scaleDriftBetweenThirds(std::span<const Vec3> est, std::span<const Vec3> gt) {
    if (est.size() != gt.size() || est.size() < 9) {
        return makeError(ErrorCode::kDegenerate,
                         "scale drift: needs at least 9 matched positions, got " +
                             std::to_string(std::min(est.size(), gt.size())));
    }
    const size_t third = est.size() / 3;
    const auto first = alignTrajectories(est.first(third), gt.first(third));
    const auto last = alignTrajectories(est.last(third), gt.last(third));
    if (!first) {
        return first.error();
    }
    if (!last) {
        return last.error();
    }
    return first->scale / last->scale;
}

}  // namespace scaled::core
