#pragma once

// Quaternion algebra with the Jacobians the filter needs. Quaternions are
// Vec4 (w, x, y, z). Rotations use the homogeneous quadratic form
//   R(q) a = (w^2 - |v|^2) a + 2 (v.a) v + 2 w (v x a),
// exact for unit q and differentiable everywhere, which is what the EKF
// linearises (the filter re-normalises q after every update).

#include <scaled/core/slam/slam_types.h>

namespace scaled::core::slam {

// [a]x: skew(a) b = a x b.
Mat3 skew(const Vec3& a);

// q (x) p.
Vec4 quatMultiply(const Vec4& q, const Vec4& p);
// Matrices with q (x) p = leftMatrix(q) p = rightMatrix(p) q.
Mat4 quatLeftMatrix(const Vec4& q);
Mat4 quatRightMatrix(const Vec4& p);

// exp of a rotation vector: the unit quaternion of angle |phi| about phi.
// J (4x3) is d q / d phi; finite (series) near zero.
Vec4 quatFromRotationVector(const Vec3& phi, Mat43* J_q_phi = nullptr);

// R(q), quadratic form above.
Mat3 rotationFromQuat(const Vec4& q);
// R(q) a and R(q)^T a with their 3x4 Jacobians with respect to q.
Vec3 rotate(const Vec4& q, const Vec3& a, Mat34* J_q = nullptr);
Vec3 rotateInverse(const Vec4& q, const Vec3& a, Mat34* J_q = nullptr);

// q / |q| and its 4x4 Jacobian.
Vec4 quatNormalized(const Vec4& q, Mat4* J = nullptr);

// Rotation matrix <-> unit quaternion (w, x, y, z).
Vec4 quatFromRotation(const Mat3& R);

// Small-angle error: the rotation vector of R_est^T R_true's inverse, i.e.
// delta with R_true = R_est Exp(delta). Used for NEES and tests.
Vec3 rotationError(const Mat3& R_est, const Mat3& R_true);

}  // namespace scaled::core::slam
