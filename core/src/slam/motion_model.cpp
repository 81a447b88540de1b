#include <scaled/core/slam/motion_model.h>
#include <scaled/core/slam/quaternion.h>

namespace scaled::core::slam {

Vec13 predictCamera(const Vec13& x, Scalar dt_s, const MotionNoise& noise, Mat13* F, Mat13* Q) {
    const Vec4 q = x.segment<4>(kQuat);
    const Vec3 v = x.segment<3>(kVel);
    const Vec3 w = x.segment<3>(kAngVel);

    Mat43 J_dq_phi;
    const Vec4 dq = quatFromRotationVector(w * dt_s, &J_dq_phi);

    Vec13 out = x;
    out.segment<3>(kPos) += v * dt_s;
    out.segment<4>(kQuat) = quatMultiply(q, dq);

    // d q' / d w (also d q' / d W): L(q) * dExp/dphi * dt.
    const Mat43 J_q_w = quatLeftMatrix(q) * J_dq_phi * dt_s;
    if (F != nullptr) {
        F->setIdentity();
        F->block<3, 3>(kPos, kVel) = Mat3::Identity() * dt_s;
        F->block<4, 4>(kQuat, kQuat) = quatRightMatrix(dq);
        F->block<4, 3>(kQuat, kAngVel) = J_q_w;
    }
    if (Q != nullptr) {
        // G = d x' / d (V, W).
        Mat136 G = Mat136::Zero();
        G.block<3, 3>(kPos, 0) = Mat3::Identity() * dt_s;
        G.block<4, 3>(kQuat, 3) = J_q_w;
        G.block<3, 3>(kVel, 0) = Mat3::Identity();
        G.block<3, 3>(kAngVel, 3) = Mat3::Identity();
        const Scalar var_v = noise.reference_hz > 0
                                 ? noise.sigma_a * noise.sigma_a * dt_s / noise.reference_hz
                                 : noise.sigma_a * noise.sigma_a * dt_s * dt_s;
        const Scalar var_w = noise.sigma_alpha * noise.sigma_alpha * dt_s * dt_s;
        Eigen::Matrix<Scalar, 6, 1> diag;
        diag << var_v, var_v, var_v, var_w, var_w, var_w;
        *Q = G * diag.asDiagonal() * G.transpose();
    }
    return out;
}

}  // namespace scaled::core::slam
