#include <algorithm>
#include <cmath>
#include <limits>
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
    // The alignment is an evaluation metric, computed in double whatever core's
    // Scalar is: a float build's trajectories are then judged by the same
    // yardstick as a double build's (docs/numerics.md).
    Eigen::Matrix3Xd A(3, n);
    Eigen::Matrix3Xd B(3, n);
    for (Eigen::Index i = 0; i < n; ++i) {
        A.col(i) = est[static_cast<size_t>(i)].cast<double>();
        B.col(i) = gt[static_cast<size_t>(i)].cast<double>();
    }
    if (!A.allFinite() || !B.allFinite()) {
        return makeError(ErrorCode::kInvalidArgument, "alignment: non-finite position");
    }
    // Degenerate when the estimate has (almost) no extent.
    const Eigen::Vector3d mean = A.rowwise().mean();
    const double spread = (A.colwise() - mean).squaredNorm() / static_cast<double>(n);
    if (!(spread > 1e-12)) {
        return makeError(ErrorCode::kDegenerate, "alignment: estimated positions do not move");
    }
    const Eigen::Matrix4d T = Eigen::umeyama(A, B, with_scale);
    const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
    const double scale = std::cbrt(sR.determinant());
    const Eigen::Vector3d t = T.topRightCorner<3, 1>();
    double sq = 0;
    for (Eigen::Index i = 0; i < n; ++i) {
        sq += (B.col(i) - (sR * A.col(i) + t)).squaredNorm();
    }
    Sim3Alignment out;
    out.scale = static_cast<Scalar>(scale);
    out.R = (sR / scale).cast<Scalar>();
    out.t = t.cast<Scalar>();
    out.ate_rmse = static_cast<Scalar>(std::sqrt(sq / static_cast<double>(n)));
    out.count = static_cast<int>(n);
    return out;
}

Scalar pathLength(std::span<const Vec3> positions) {
    double len = 0;  // summed in double: thousands of short segments
    for (size_t i = 1; i < positions.size(); ++i) {
        len += (positions[i] - positions[i - 1]).cast<double>().norm();
    }
    return static_cast<Scalar>(len);
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

Result<WindowScales> slidingWindowScales(std::span<const Vec3> est, std::span<const Vec3> gt,
                                         int window) {
    if (window < 3) {
        return makeError(
            ErrorCode::kInvalidArgument,
            "window scale: window of " + std::to_string(window) + " positions, needs at least 3");
    }
    const auto w = static_cast<size_t>(window);
    if (est.size() != gt.size() || est.size() < w) {
        return makeError(ErrorCode::kDegenerate,
                         "window scale: needs " + std::to_string(window) +
                             " matched positions, got " +
                             std::to_string(std::min(est.size(), gt.size())));
    }
    WindowScales out;
    out.window = window;
    out.scale.assign(est.size() - w + 1, std::numeric_limits<Scalar>::quiet_NaN());
    for (size_t k = 0; k < out.scale.size(); ++k) {
        const auto a = alignTrajectories(est.subspan(k, w), gt.subspan(k, w));
        if (!a || !(a->scale > 0)) {
            continue;
        }
        out.scale[k] = a->scale;
        out.min = out.valid == 0 ? a->scale : std::min(out.min, a->scale);
        out.max = out.valid == 0 ? a->scale : std::max(out.max, a->scale);
        ++out.valid;
    }
    if (out.valid == 0) {
        return makeError(ErrorCode::kDegenerate,
                         "window scale: the estimate does not move in any window of " +
                             std::to_string(window) + " positions");
    }
    out.range = out.max / out.min;
    return out;
}

}  // namespace scaled::core
