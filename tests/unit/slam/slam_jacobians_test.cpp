// Every analytic Jacobian of the EKF MonoSLAM against central differences.

#include <gtest/gtest.h>

#include <scaled/core/slam/feature_model.h>
#include <scaled/core/slam/motion_model.h>
#include <scaled/core/slam/quaternion.h>

#include "numeric_jacobian.h"
#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core::slam {
namespace {

using test::expectJacobianNear;

Vec4 someQuat() {
    return quatFromRotationVector(Vec3(0.2, -0.4, 0.3));
}

TEST(SlamQuaternion, RotationMatchesEigen) {
    const Vec4 q = someQuat();
    // Float: short chains on unit quaternions and O(1) vectors, 1e-6.
    const double tol = test::tolerance(1e-12, 1e-6);
    const Eigen::Quaternion<Scalar> e(q(0), q(1), q(2), q(3));
    EXPECT_LE((rotationFromQuat(q) - e.toRotationMatrix()).cwiseAbs().maxCoeff(), tol);
    const Vec3 a(0.3, -1.2, 2.0);
    EXPECT_LE((rotate(q, a) - e * a).norm(), tol);
    EXPECT_LE((rotateInverse(q, a) - e.conjugate() * a).norm(), tol);
    EXPECT_LE((quatFromRotation(rotationFromQuat(q)) - q).norm(), tol);
    // Multiplication composes rotations.
    const Vec4 p = quatFromRotationVector(Vec3(-0.1, 0.5, 0.05));
    EXPECT_LE((rotationFromQuat(quatMultiply(q, p)) - rotationFromQuat(q) * rotationFromQuat(p))
                  .cwiseAbs()
                  .maxCoeff(),
              tol);
    EXPECT_LE((quatRightMatrix(p) * q - quatMultiply(q, p)).norm(), test::tolerance(1e-14, 1e-6));
}

TEST(SlamQuaternion, RotateJacobians) {
    const Vec3 a(0.3, -1.2, 2.0);
    Mat34 J;
    for (const Vec4& q0 : {someQuat(), Vec4(1, 0, 0, 0), Vec4(0.9, 0.1, -0.3, 0.2)}) {
        rotate(q0, a, &J);
        const auto rotated = [&](const Vec4& q) { return rotate(q, a); };
        expectJacobianNear<3, 4>("dRa/dq", J, rotated, q0);
        rotateInverse(q0, a, &J);
        expectJacobianNear<3, 4>(
            "dR^Ta/dq", J, [&](const Vec4& q) { return rotateInverse(q, a); }, q0);
    }
    Mat4 Jn;
    const Vec4 q0(0.9, 0.1, -0.3, 0.2);
    quatNormalized(q0, &Jn);
    expectJacobianNear<4, 4>(
        "dnormalize/dq", Jn, [](const Vec4& q) { return quatNormalized(q); }, q0);
}

TEST(SlamQuaternion, ExpJacobianIncludingNearZero) {
    Mat43 J;
    for (const Vec3& phi : {Vec3(0.3, -0.2, 0.5), Vec3(1e-3, 2e-3, -1e-3), Vec3(1e-6, 0, 2e-6),
                            Vec3::Zero().eval()}) {
        const Vec4 q = quatFromRotationVector(phi, &J);
        EXPECT_NEAR(q.norm(), 1.0, test::tolerance(1e-9, 1e-6));
        expectJacobianNear<4, 3>(
            "dExp/dphi", J, [](const Vec3& p) { return quatFromRotationVector(p); }, phi, 1e-7,
            1e-7);
    }
}

TEST(SlamMotionModel, JacobianAndNoise) {
    Vec13 x;
    x << 0.1, -0.2, 0.3, 0, 0, 0, 0, 0.02, -0.05, 0.01, 0.3, -0.6, 0.2;
    x.segment<4>(kQuat) = someQuat();
    const Scalar dt = 1.0 / 30;
    MotionNoise noise{2.0, 3.0};
    Mat13 F;
    Mat13 Q;
    const Vec13 out = predictCamera(x, dt, noise, &F, &Q);
    EXPECT_LE((out.segment<3>(kPos) - (x.segment<3>(kPos) + dt * x.segment<3>(kVel))).norm(),
              1e-15);
    EXPECT_NEAR(out.segment<4>(kQuat).norm(), 1.0, test::tolerance(1e-12, 1e-6));
    expectJacobianNear<13, 13>(
        "F", F, [&](const Vec13& s) { return predictCamera(s, dt, noise); }, x);
    // Q is G diag(...) G^T with G the Jacobian with respect to the impulses:
    // check through the numeric Jacobian of the impulse-perturbed model.
    auto withImpulse = [&](const Eigen::Matrix<Scalar, 6, 1>& imp) {
        Vec13 s = x;
        s.segment<3>(kVel) += imp.head<3>();
        s.segment<3>(kAngVel) += imp.tail<3>();
        return predictCamera(s, dt, noise);
    };
    // Float: the step of expectJacobianNear; G is then good to ~1e-4, and Q
    // (largest entry 9 dt^2 = 0.01) to ~1e-6.
    const Mat136 G =
        test::numericJacobian<13, 6>(withImpulse, Eigen::Matrix<Scalar, 6, 1>::Zero().eval(),
                                     static_cast<Scalar>(test::tolerance(1e-6, test::kFloatStep)));
    Eigen::Matrix<Scalar, 6, 1> diag;
    const Scalar va = 4.0 * dt * dt, vw = 9.0 * dt * dt;
    diag << va, va, va, vw, vw, vw;
    const Mat13 Qn = G * diag.asDiagonal() * G.transpose();
    EXPECT_LE((Q - Qn).cwiseAbs().maxCoeff(), test::tolerance(1e-9, 1e-5));
    // Variable frame interval: twice dt moves twice as far.
    const Vec13 out2 = predictCamera(x, 2 * dt, noise);
    // Float: a few ulps of the position (|x| ~ 0.4), which the differences cancel.
    EXPECT_NEAR((out2.head<3>() - x.head<3>()).norm(), 2 * (out.head<3>() - x.head<3>()).norm(),
                test::tolerance(1e-12, 5e-7));
}

// The velocity's noise as a random walk (reference_hz): MonoSLAM's impulse at
// the reference rate, a variance growing with dt, not dt^2, elsewhere; the
// angular impulse keeps MonoSLAM's form.
TEST(SlamMotionModel, RandomWalkVelocityNoiseMatchesMonoSlamAtItsReferenceRate) {
    Vec13 x;
    x << 0.1, -0.2, 0.3, 0, 0, 0, 0, 0.02, -0.05, 0.01, 0.3, -0.6, 0.2;
    x.segment<4>(kQuat) = someQuat();
    const MotionNoise impulse{Scalar(2), Scalar(3)};
    const MotionNoise walk{Scalar(2), Scalar(3), Scalar(30)};
    auto noiseOf = [&](const MotionNoise& n, Scalar dt) {
        Mat13 Q;
        (void)predictCamera(x, dt, n, nullptr, &Q);
        return Q;
    };
    const double tol = test::tolerance(1e-12, 1e-6);
    const Scalar dt30 = Scalar(1) / 30;
    // At 30 Hz the two models are the same.
    EXPECT_LE((noiseOf(walk, dt30) - noiseOf(impulse, dt30)).cwiseAbs().maxCoeff(), tol);
    for (const Scalar dt : {Scalar(0.1), Scalar(0.2), Scalar(1) / 60}) {
        const Mat13 Qw = noiseOf(walk, dt);
        const Mat13 Qi = noiseOf(impulse, dt);
        // Velocity: 4 dt / 30 against 4 dt^2, i.e. (1 / 30) / dt times the impulse's.
        const double ratio = static_cast<double>(dt30 / dt);
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(static_cast<double>(Qw(kVel + i, kVel + i)),
                        4.0 * static_cast<double>(dt) / 30, tol);
            EXPECT_NEAR(static_cast<double>(Qw(kVel + i, kVel + i)),
                        ratio * static_cast<double>(Qi(kVel + i, kVel + i)), tol);
        }
        // The angular block is MonoSLAM's whatever the rate.
        EXPECT_LE(
            (Qw.bottomRightCorner<3, 3>() - Qi.bottomRightCorner<3, 3>()).cwiseAbs().maxCoeff(),
            tol);
    }
    // Every 10 Hz frame, the velocity's variance after a second: the same as
    // thirty 30 Hz frames' (the walk), three times it with the impulse.
    const double walk_per_s_10 = 10 * static_cast<double>(noiseOf(walk, Scalar(0.1))(kVel, kVel));
    const double walk_per_s_30 = 30 * static_cast<double>(noiseOf(walk, dt30)(kVel, kVel));
    const double imp_per_s_10 = 10 * static_cast<double>(noiseOf(impulse, Scalar(0.1))(kVel, kVel));
    EXPECT_NEAR(walk_per_s_10, walk_per_s_30, test::tolerance(1e-12, 1e-6));
    EXPECT_NEAR(imp_per_s_10, 3 * walk_per_s_30, test::tolerance(1e-12, 1e-6));
}

struct ProjectionCase {
    Scalar k1;
    Scalar k2;
};

class SlamMeasurement : public ::testing::TestWithParam<ProjectionCase> {};

TEST_P(SlamMeasurement, InverseDepthAndXyzJacobians) {
    const auto cam = test::makeCamera(GetParam().k1, GetParam().k2, 520);
    const Vec3 r(0.1, -0.05, 0.2);
    const Vec4 q = quatFromRotationVector(Vec3(0.05, 0.1, -0.03));
    // An inverse-depth feature first seen from elsewhere.
    Vec6 y;
    y << -0.05, 0.02, -0.1, 0.15, -0.08, 0.4;
    auto p = projectFeature(cam, r, q, FeatureKind::kInverseDepth, y.data(), true);
    ASSERT_TRUE(p.has_value());
    // Versus pose (r, q). Set by segments, not `pose << r, q`: with float,
    // GCC 12 flags Eigen's packet path of that comma initialiser
    // (-Warray-bounds, a false positive).
    Eigen::Matrix<Scalar, 7, 1> pose;
    pose.head<3>() = r;
    pose.tail<4>() = q;
    auto hOfPose = [&](const Eigen::Matrix<Scalar, 7, 1>& s) {
        return projectFeature(cam, s.head<3>(), s.tail<4>(), FeatureKind::kInverseDepth, y.data(),
                              false)
            ->h_px;
    };
    expectJacobianNear<2, 7>("ID dh/dpose", p->H_pose, hOfPose, pose, 1e-5);
    auto hOfY = [&](const Vec6& s) {
        return projectFeature(cam, r, q, FeatureKind::kInverseDepth, s.data(), false)->h_px;
    };
    expectJacobianNear<2, 6>("ID dh/dy", p->H_feature, hOfY, y, 1e-5);

    // The same point as XYZ projects to the same pixel.
    const Vec3 xyz = inverseDepthToXyz(y);
    auto px = projectFeature(cam, r, q, FeatureKind::kXyz, xyz.data(), true);
    ASSERT_TRUE(px.has_value());
    EXPECT_LE((px->h_px - p->h_px).norm(), 1e-9);
    auto hOfPoseXyz = [&](const Eigen::Matrix<Scalar, 7, 1>& s) {
        return projectFeature(cam, s.head<3>(), s.tail<4>(), FeatureKind::kXyz, xyz.data(), false)
            ->h_px;
    };
    expectJacobianNear<2, 7>("XYZ dh/dpose", px->H_pose, hOfPoseXyz, pose, 1e-5);
    auto hOfP = [&](const Vec3& s) {
        return projectFeature(cam, r, q, FeatureKind::kXyz, s.data(), false)->h_px;
    };
    const Mat23 Hp = px->H_feature.leftCols<3>();
    expectJacobianNear<2, 3>("XYZ dh/dp", Hp, hOfP, xyz, 1e-5);
}

TEST_P(SlamMeasurement, InitialisationInvertsProjectionWithJacobians) {
    const auto cam = test::makeCamera(GetParam().k1, GetParam().k2, 520);
    const Vec3 r(0.1, -0.05, 0.2);
    const Vec4 q = quatFromRotationVector(Vec3(0.05, 0.1, -0.03));
    const Vec2 px(401.3, 122.7);
    const auto init = initInverseDepth(cam, r, q, px, 0.5);
    ASSERT_TRUE(init.has_value());
    // Seen from the same camera it projects back to the pixel, at any rho.
    for (const Scalar rho : {0.0, 0.5, 3.0}) {
        Vec6 y = init->y;
        y(5) = rho;
        const auto back = projectFeature(cam, r, q, FeatureKind::kInverseDepth, y.data(), false);
        ASSERT_TRUE(back.has_value());
        // Float: undistort's stopping residual at f = 520 (about 8e-3 px).
        EXPECT_LE((back->h_px - px).norm(),
                  test::tolerance(1e-8, test::kFloatUndistortResidual * 520));
    }
    // By segments, as above.
    Eigen::Matrix<Scalar, 7, 1> pose;
    pose.head<3>() = r;
    pose.tail<4>() = q;
    auto yOfPose = [&](const Eigen::Matrix<Scalar, 7, 1>& s) {
        return initInverseDepth(cam, s.head<3>(), s.tail<4>(), px, 0.5)->y;
    };
    expectJacobianNear<6, 7>("dy/dpose", init->J_pose, yOfPose, pose, 1e-5);
    auto yOfPx = [&](const Vec2& u) { return initInverseDepth(cam, r, q, u, 0.5)->y; };
    expectJacobianNear<6, 2>("dy/dpx", init->J_px, yOfPx, px, 1e-6, 1e-4);
}

INSTANTIATE_TEST_SUITE_P(Distortion, SlamMeasurement,
                         ::testing::Values(ProjectionCase{0, 0}, ProjectionCase{-0.2, 0.05},
                                           ProjectionCase{0.1, 0.01}));

TEST(SlamFeature, XyzConversionJacobianAndLinearity) {
    Vec6 y;
    y << 0.1, -0.2, 0.05, 0.3, -0.1, 0.5;
    Mat36 J;
    inverseDepthToXyz(y, &J);
    const auto xyz = [](const Vec6& s) { return inverseDepthToXyz(s); };
    expectJacobianNear<3, 6>("dp/dy", J, xyz, y);
    // A point seen along its first ray with a large depth uncertainty is far
    // from linear; the same point with a small uncertainty seen from the side
    // is linear.
    EXPECT_GT(linearityIndex(y, 0.5, y.head<3>()), 1.0);
    const Vec3 p = inverseDepthToXyz(y);
    const Vec3 side = y.head<3>() + (p - y.head<3>()).cross(Vec3::UnitY()).normalized();
    EXPECT_LT(linearityIndex(y, 0.01, side), 0.1);
    y(5) = -0.1;
    EXPECT_TRUE(std::isinf(linearityIndex(y, 0.1, Vec3::Zero())));
}

}  // namespace
}  // namespace scaled::core::slam
