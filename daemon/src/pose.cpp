#include <cmath>

#include <Eigen/Geometry>

#include <scaled/daemon/pose.h>

namespace scaled::daemon {
namespace {

// Below this, a horizontal direction is too short to define an axis.
constexpr double kMinHorizontal = 1e-6;

void storeRowMajor(const Eigen::Matrix3d& m, std::array<double, 9>& out) {
    for (Eigen::Index r = 0; r < 3; ++r) {
        for (Eigen::Index c = 0; c < 3; ++c) {
            out[static_cast<std::size_t>(r) * 3 + static_cast<std::size_t>(c)] = m(r, c);
        }
    }
}

}  // namespace

Eigen::Matrix3d gravityAlignedFromMap(const Eigen::Vector3d& up_W) {
    Eigen::Vector3d z = up_W;
    const double n = z.norm();
    if (!(n > 0) || !std::isfinite(n)) {
        z = Eigen::Vector3d(0, -1, 0);
    } else {
        z /= n;
    }
    // The first camera's optical axis (z_W), else its image-up axis (-y_W).
    Eigen::Vector3d x = Eigen::Vector3d::UnitZ() - z.z() * z;
    if (x.norm() < kMinHorizontal) {
        x = -Eigen::Vector3d::UnitY() - (-z.y()) * z;
    }
    x.normalize();
    const Eigen::Vector3d y = z.cross(x);
    Eigen::Matrix3d R;
    R.row(0) = x.transpose();
    R.row(1) = y.transpose();
    R.row(2) = z.transpose();
    return R;
}

PoseReport makePoseReport(const core::CameraPose& pose_W, const core::Vec3& velocity_W,
                          const Eigen::Matrix<core::Scalar, 6, 6>& covariance,
                          const core::Vec3& up_W, std::uint64_t epoch, std::int64_t frame_id,
                          std::int64_t t_ns) {
    const Eigen::Matrix3d R_WtoG = gravityAlignedFromMap(up_W.cast<double>());
    const Eigen::Matrix3d R_CtoG = R_WtoG * pose_W.R_CtoW.cast<double>();
    const auto& P = covariance.cast<double>();  // a reference when Scalar is double
    PoseReport r;
    r.epoch = epoch;
    r.frame_id = frame_id;
    r.t_ns = t_ns;
    const Eigen::Vector3d p = R_WtoG * pose_W.p_CinW.cast<double>();
    const Eigen::Vector3d v = R_WtoG * velocity_W.cast<double>();
    for (int i = 0; i < 3; ++i) {
        r.position_map[static_cast<std::size_t>(i)] = p(i);
        r.velocity_map[static_cast<std::size_t>(i)] = v(i);
    }
    Eigen::Quaterniond q(R_CtoG);
    q.normalize();
    if (q.w() < 0) {
        q.coeffs() = -q.coeffs();
    }
    r.orientation_wxyz = {q.w(), q.x(), q.y(), q.z()};
    // Position: rotated into G. Attitude: the filter's error is on the right
    // (in the camera frame), R_true = R Exp(delta) = Exp(R delta) R, so the
    // error in G is R_CtoG delta.
    const Eigen::Matrix3d Pp = R_WtoG * P.topLeftCorner<3, 3>() * R_WtoG.transpose();
    const Eigen::Matrix3d Pa = R_CtoG * P.bottomRightCorner<3, 3>() * R_CtoG.transpose();
    storeRowMajor(0.5 * (Pp + Pp.transpose()), r.position_cov_map);
    storeRowMajor(0.5 * (Pa + Pa.transpose()), r.attitude_cov_rad2);
    return r;
}

MetricPose metricPose(const PoseReport& pose, const ScaleReport& scale) {
    MetricPose m;
    if (pose.frame_id < 0 || !scale.has_scale || scale.wide_for_poses ||
        scale.epoch != pose.epoch || !(scale.scale > 0) || !std::isfinite(scale.scale)) {
        return m;
    }
    m.has_scale = true;
    m.scale = scale.scale;
    const double sigma = 0.5 * (scale.ci68_hi - scale.ci68_lo);
    m.scale_sigma = std::isfinite(sigma) && sigma > 0 ? sigma : 0;
    const double d = m.scale;
    const double d2 = d * d;
    const double s2 = m.scale_sigma * m.scale_sigma;
    for (std::size_t i = 0; i < 3; ++i) {
        m.position_m[i] = d * pose.position_map[i];
        m.velocity_mps[i] = d * pose.velocity_map[i];
        for (std::size_t j = 0; j < 3; ++j) {
            m.position_cov_m2[3 * i + j] = d2 * pose.position_cov_map[3 * i + j] +
                                           s2 * pose.position_map[i] * pose.position_map[j];
        }
    }
    return m;
}

// --- PoseRateLimiter ------------------------------------------------------------

PoseRateLimiter::PoseRateLimiter(double rate_hz)
    : period_ns_(rate_hz > 0 && std::isfinite(rate_hz)
                     ? static_cast<std::int64_t>(std::llround(1e9 / rate_hz))
                     : 0) {}

bool PoseRateLimiter::admit(std::uint64_t epoch, std::int64_t t_ns) {
    const bool restart = !started_ || epoch != epoch_ || t_ns < last_t_ns_;
    last_t_ns_ = t_ns;
    if (restart) {
        started_ = true;
        epoch_ = epoch;
        origin_ns_ = t_ns;
        last_slot_ = 0;
        return true;
    }
    if (period_ns_ <= 0) {
        return true;
    }
    // t_ns >= origin here: the division rounds down.
    const std::int64_t slot = (t_ns - origin_ns_ + period_ns_ / 2) / period_ns_;
    if (slot <= last_slot_) {
        return false;
    }
    last_slot_ = slot;
    return true;
}

}  // namespace scaled::daemon
