#include <cmath>
#include <limits>

#include <scaled/core/slam/feature_model.h>
#include <scaled/core/slam/quaternion.h>

namespace scaled::core::slam {

Vec3 directionFromAngles(Scalar theta, Scalar phi, Vec3* dm_dtheta, Vec3* dm_dphi) {
    const Scalar ct = std::cos(theta), st = std::sin(theta);
    const Scalar cp = std::cos(phi), sp = std::sin(phi);
    if (dm_dtheta != nullptr) {
        *dm_dtheta = Vec3(cp * ct, 0, -cp * st);
    }
    if (dm_dphi != nullptr) {
        *dm_dphi = Vec3(-sp * st, -cp, -sp * ct);
    }
    return {cp * st, -sp, cp * ct};
}

std::optional<FeatureProjection> projectFeature(const PinholeRadialCamera& cam, const Vec3& r,
                                                const Vec4& q, FeatureKind kind, const Scalar* y,
                                                bool want_jacobians) {
    FeatureProjection out;
    Vec3 a;
    Vec3 dm_dtheta;
    Vec3 dm_dphi;
    Scalar rho = 1;
    Eigen::Map<const Vec3> x0(y);
    if (kind == FeatureKind::kInverseDepth) {
        rho = y[5];
        const Vec3 m = directionFromAngles(y[3], y[4], &dm_dtheta, &dm_dphi);
        a = rho * (x0 - r) + m;
    } else {
        a = x0 - r;
    }
    Mat34 J_q;
    out.h_C = rotateInverse(q, a, want_jacobians ? &J_q : nullptr);
    Mat23 J_px_hC;
    const auto px = cam.project(out.h_C, want_jacobians ? &J_px_hC : nullptr);
    if (!px) {
        return std::nullopt;
    }
    out.h_px = *px;
    if (!want_jacobians) {
        return out;
    }
    const Mat3 Rt = rotationFromQuat(q).transpose();
    const Mat23 J_a = J_px_hC * Rt;  // d h / d a
    out.H_pose.leftCols<3>() = -rho * J_a;
    out.H_pose.rightCols<4>() = J_px_hC * J_q;
    if (kind == FeatureKind::kInverseDepth) {
        out.H_feature.leftCols<3>() = rho * J_a;
        out.H_feature.col(3) = J_a * dm_dtheta;
        out.H_feature.col(4) = J_a * dm_dphi;
        out.H_feature.col(5) = J_a * (x0 - r);
    } else {
        out.H_feature.leftCols<3>() = J_a;
        out.H_feature.rightCols<3>().setZero();
    }
    return out;
}

std::optional<InverseDepthInit> initInverseDepth(const PinholeRadialCamera& cam, const Vec3& r,
                                                 const Vec4& q, const Vec2& px, Scalar rho0) {
    Mat32 J_ray_px;
    const auto ray_C = cam.unproject(px, &J_ray_px);
    if (!ray_C) {
        return std::nullopt;
    }
    Mat34 J_hW_q;
    const Vec3 h = rotate(q, *ray_C, &J_hW_q);
    const Scalar s2 = h.x() * h.x() + h.z() * h.z();
    const Scalar s = std::sqrt(s2);
    const Scalar r2 = s2 + h.y() * h.y();
    if (s2 <= std::numeric_limits<Scalar>::min() || !std::isfinite(r2)) {
        return std::nullopt;
    }
    InverseDepthInit out;
    out.y.head<3>() = r;
    out.y(3) = std::atan2(h.x(), h.z());
    out.y(4) = std::atan2(-h.y(), s);
    out.y(5) = rho0;

    Eigen::Matrix<Scalar, 2, 3> J_angles_h;
    J_angles_h.row(0) = RowVec3(h.z() / s2, 0, -h.x() / s2);
    J_angles_h.row(1) = RowVec3(h.y() * h.x() / (r2 * s), -s / r2, h.y() * h.z() / (r2 * s));
    out.J_pose.block<3, 3>(0, 0).setIdentity();
    out.J_pose.block<2, 4>(3, 3) = J_angles_h * J_hW_q;
    out.J_px.block<2, 2>(3, 0) = J_angles_h * rotationFromQuat(q) * J_ray_px;
    return out;
}

Vec3 inverseDepthToXyz(const Vec6& y, Mat36* J) {
    Vec3 dm_dtheta;
    Vec3 dm_dphi;
    const Vec3 m = directionFromAngles(y(3), y(4), &dm_dtheta, &dm_dphi);
    const Scalar rho = y(5);
    if (J != nullptr) {
        J->leftCols<3>().setIdentity();
        J->col(3) = dm_dtheta / rho;
        J->col(4) = dm_dphi / rho;
        J->col(5) = -m / (rho * rho);
    }
    return y.head<3>() + m / rho;
}

Scalar linearityIndex(const Vec6& y, Scalar sigma_rho, const Vec3& r) {
    const Scalar rho = y(5);
    if (!(rho > 0)) {
        return std::numeric_limits<Scalar>::infinity();
    }
    const Vec3 m = directionFromAngles(y(3), y(4));
    const Vec3 h = y.head<3>() + m / rho - r;
    const Scalar d1 = h.norm();
    if (!(d1 > 0)) {
        return std::numeric_limits<Scalar>::infinity();
    }
    const Scalar sigma_d = sigma_rho / (rho * rho);
    const Scalar cos_alpha = m.dot(h) / d1;
    return 4 * sigma_d / d1 * std::abs(cos_alpha);
}

}  // namespace scaled::core::slam
