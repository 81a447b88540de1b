#include <cmath>

#include <Eigen/Geometry>

#include <scaled/core/slam/quaternion.h>

namespace scaled::core::slam {

Mat3 skew(const Vec3& a) {
    Mat3 S;
    S << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    return S;
}

Vec4 quatMultiply(const Vec4& q, const Vec4& p) {
    return quatLeftMatrix(q) * p;
}

Mat4 quatLeftMatrix(const Vec4& q) {
    const Scalar w = q(0), x = q(1), y = q(2), z = q(3);
    Mat4 L;
    L << w, -x, -y, -z,  //
        x, w, -z, y,     //
        y, z, w, -x,     //
        z, -y, x, w;
    return L;
}

Mat4 quatRightMatrix(const Vec4& p) {
    const Scalar w = p(0), x = p(1), y = p(2), z = p(3);
    Mat4 R;
    R << w, -x, -y, -z,  //
        x, w, z, -y,     //
        y, -z, w, x,     //
        z, y, -x, w;
    return R;
}

Vec4 quatFromRotationVector(const Vec3& phi, Mat43* J_q_phi) {
    const Scalar theta = phi.norm();
    Vec4 q;
    if (theta < Scalar(1e-4)) {
        // Series to second order: q = (1 - theta^2/8, phi/2 (1 - theta^2/24)).
        q(0) = 1 - theta * theta / 8;
        q.tail<3>() = phi * (Scalar(0.5) - theta * theta / 48);
        if (J_q_phi != nullptr) {
            J_q_phi->row(0) = -phi.transpose() / 4;
            J_q_phi->bottomRows<3>() =
                Mat3::Identity() * (Scalar(0.5) - theta * theta / 48) - phi * phi.transpose() / 24;
        }
        return q;
    }
    const Scalar half = theta / 2;
    const Scalar s = std::sin(half);
    const Scalar c = std::cos(half);
    const Vec3 axis = phi / theta;
    q(0) = c;
    q.tail<3>() = s * axis;
    if (J_q_phi != nullptr) {
        // d cos(theta/2) = -sin(theta/2)/2 * axis^T
        // d (s phi/theta) = s/theta I + phi * d(s/theta), d(s/theta)/dphi =
        //   (c/2 / theta - s / theta^2) axis^T
        J_q_phi->row(0) = -s / 2 * axis.transpose();
        J_q_phi->bottomRows<3>() = Mat3::Identity() * (s / theta) +
                                   phi * axis.transpose() * (c / (2 * theta) - s / (theta * theta));
    }
    return q;
}

Mat3 rotationFromQuat(const Vec4& q) {
    const Scalar w = q(0);
    const Vec3 v = q.tail<3>();
    return (w * w - v.squaredNorm()) * Mat3::Identity() + 2 * v * v.transpose() + 2 * w * skew(v);
}

Vec3 rotate(const Vec4& q, const Vec3& a, Mat34* J_q) {
    const Scalar w = q(0);
    const Vec3 v = q.tail<3>();
    const Scalar va = v.dot(a);
    const Vec3 vxa = v.cross(a);
    if (J_q != nullptr) {
        J_q->col(0) = 2 * w * a + 2 * vxa;
        J_q->rightCols<3>() = -2 * a * v.transpose() + 2 * va * Mat3::Identity() +
                              2 * v * a.transpose() - 2 * w * skew(a);
    }
    return (w * w - v.squaredNorm()) * a + 2 * va * v + 2 * w * vxa;
}

Vec3 rotateInverse(const Vec4& q, const Vec3& a, Mat34* J_q) {
    const Scalar w = q(0);
    const Vec3 v = q.tail<3>();
    const Scalar va = v.dot(a);
    const Vec3 vxa = v.cross(a);
    if (J_q != nullptr) {
        J_q->col(0) = 2 * w * a - 2 * vxa;
        J_q->rightCols<3>() = -2 * a * v.transpose() + 2 * va * Mat3::Identity() +
                              2 * v * a.transpose() + 2 * w * skew(a);
    }
    return (w * w - v.squaredNorm()) * a + 2 * va * v - 2 * w * vxa;
}

Vec4 quatNormalized(const Vec4& q, Mat4* J) {
    const Scalar n = q.norm();
    Vec4 u = q / n;
    if (J != nullptr) {
        *J = (Mat4::Identity() - u * u.transpose()) / n;
    }
    return u;
}

Vec4 quatFromRotation(const Mat3& R) {
    Eigen::Quaternion<Scalar> e(R);
    e.normalize();
    Vec4 q(e.w(), e.x(), e.y(), e.z());
    if (q(0) < 0) {
        q = -q;
    }
    return q;
}

Vec3 rotationError(const Mat3& R_est, const Mat3& R_true) {
    const Eigen::AngleAxis<Scalar> aa(R_est.transpose() * R_true);
    return aa.axis() * aa.angle();
}

}  // namespace scaled::core::slam
