#include <gtest/gtest.h>

#include <scaled/core/camera/pinhole_radial.h>

#include "numeric_jacobian.h"
#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core {
namespace {

// The 7-Scenes intrinsics (f = 585), with optional distortion.
CameraIntrinsics kitchenIntrinsics(Scalar k1 = 0, Scalar k2 = 0) {
    return test::makeIntrinsics(k1, k2, 585);
}

PinholeRadialCamera make(Scalar k1 = 0, Scalar k2 = 0) {
    auto cam = PinholeRadialCamera::create(kitchenIntrinsics(k1, k2));
    EXPECT_TRUE(cam.ok());
    return cam.value();
}

TEST(Camera, RejectsBadIntrinsics) {
    auto k = kitchenIntrinsics();
    k.fx = 0;
    const auto r = PinholeRadialCamera::create(k);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("fx"), std::string::npos);
    k = kitchenIntrinsics();
    k.width_px = 0;
    EXPECT_FALSE(PinholeRadialCamera::create(k).ok());
    k = kitchenIntrinsics();
    k.k1 = std::numeric_limits<Scalar>::quiet_NaN();
    EXPECT_FALSE(PinholeRadialCamera::create(k).ok());
}

TEST(Camera, ProjectsByHand) {
    const auto cam = make();
    // (0.5, -0.25, 2) -> x_u = (0.25, -0.125) -> (320 + 146.25, 240 - 73.125)
    const auto px = cam.project(Vec3(0.5, -0.25, 2));
    ASSERT_TRUE(px);
    EXPECT_NEAR(px->x(), 466.25, 1e-12);
    EXPECT_NEAR(px->y(), 166.875, 1e-12);
    EXPECT_FALSE(cam.project(Vec3(0, 0, -1)));
    EXPECT_FALSE(cam.project(Vec3(1, 0, 0)));
}

TEST(Camera, DistortsByHand) {
    const auto cam = make(-0.2, 0.05);
    // r^2 = 0.25: factor 1 - 0.2*0.25 + 0.05*0.0625 = 0.953125
    const Vec2 xd = cam.distort(Vec2(0.3, 0.4));
    EXPECT_NEAR(xd.x(), 0.3 * 0.953125, test::tolerance(1e-15, 4e-7));  // float: 1e-6 relative
    EXPECT_NEAR(xd.y(), 0.4 * 0.953125, test::tolerance(1e-15, 4e-7));
}

TEST(Camera, UndistortInvertsDistort) {
    for (const auto& [k1, k2] : {std::pair{-0.25, 0.07}, {0.1, 0.01}, {-0.05, 0.0}}) {
        const auto cam = make(k1, k2);
        for (const Vec2& x : {Vec2(0.0, 0.0), Vec2(0.3, -0.2), Vec2(-0.5, 0.35), Vec2(0.6, 0.1)}) {
            const auto back = cam.undistort(cam.distort(x));
            ASSERT_TRUE(back) << k1 << " " << x.transpose();
            // Float: undistort's stopping residual, through a distortion derivative
            // of at least 0.7 on these cases.
            EXPECT_LT((*back - x).norm(),
                      test::tolerance(1e-12, 2 * test::kFloatUndistortResidual));
        }
    }
}

TEST(Camera, UndistortFailsBeyondTheFold) {
    const auto cam = make(-0.4, 0.0);  // monotonic for r < sqrt(1/1.2) = 0.913
    EXPECT_NEAR(cam.maxUndistortedRadius(), std::sqrt(1 / 1.2), test::tolerance(1e-12, 1e-6));
    EXPECT_FALSE(cam.undistort(Vec2(2.0, 0.0)));
    EXPECT_FALSE(cam.project(Vec3(1.0, 0, 1)));  // r = 1 > 0.913
}

TEST(Camera, DistortionJacobianMatchesNumeric) {
    const auto cam = make(-0.21, 0.06);
    const Vec2 x(0.31, -0.17);
    Mat2 J;
    (void)cam.distort(x, &J);
    test::expectJacobianNear(
        "d distort / d x_u", J, [&](const Vec2& v) { return cam.distort(v); }, x);
}

TEST(Camera, UndistortionJacobianMatchesNumeric) {
    const auto cam = make(-0.21, 0.06);
    const Vec2 x(0.28, 0.19);
    Mat2 J;
    ASSERT_TRUE(cam.undistort(x, &J));
    test::expectJacobianNear(
        "d undistort / d x_d", J, [&](const Vec2& v) { return *cam.undistort(v); }, x);
}

TEST(Camera, ProjectionJacobianMatchesNumeric) {
    for (const Scalar k1 : {0.0, -0.2}) {
        const auto cam = make(k1, 0.03);
        const Vec3 p(0.4, -0.3, 1.7);
        Mat23 J;
        ASSERT_TRUE(cam.project(p, &J));
        test::expectJacobianNear(
            "d pixel / d p_C", J, [&](const Vec3& v) { return *cam.project(v); }, p, 1e-5);
    }
}

TEST(Camera, UnprojectionJacobianMatchesNumeric) {
    const auto cam = make(-0.2, 0.03);
    const Vec2 px(500, 100);
    Mat32 J;
    const auto ray = cam.unproject(px, &J);
    ASSERT_TRUE(ray);
    EXPECT_EQ(ray->z(), 1);
    test::expectJacobianNear(
        "d ray / d pixel", J, [&](const Vec2& v) { return *cam.unproject(v); }, px, 1e-6, 1e-3);
    // Round trip.
    const auto px2 = cam.project(*ray * 3.0);
    ASSERT_TRUE(px2);
    // Float: undistort's stopping residual at f = 585 (about 9e-3 px).
    EXPECT_LT((*px2 - px).norm(), test::tolerance(1e-9, test::kFloatUndistortResidual * 585));
}

}  // namespace
}  // namespace scaled::core
