#include <random>

#include <Eigen/Cholesky>
#include <gtest/gtest.h>

#include <scaled/core/scale/vertical_extent.h>

#include "numeric_jacobian.h"
#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core {
namespace {

using test::boxOf;
using test::lookAlongY;
using test::makeCamera;

const Vec3 kUp(0, 0, 1);

// Hand-computed case: camera at the origin looking along +y, f = 500,
// feature at (0, 2, 0), i.e. 2 m straight ahead on the optical axis. The box
// spans rows 115..315: the top ray leaves at x_u.y = -0.25, the bottom at +0.15,
// so p_t = (0, 2, 0.5), p_d = (0, 2, -0.3) and D = 0.8.
struct HandCase {
    PinholeRadialCamera cam = makeCamera();
    CameraPose pose = lookAlongY(Vec3::Zero());
    MapFeature feature{Vec3(0, 2, 0), Vec3(0.01 * 0.01, 0.02 * 0.02, 0.03 * 0.03).asDiagonal()};
    BoundingBox box{300, 115, 340, 315};
};

TEST(VerticalExtent, HandComputedGeometry) {
    const HandCase c;
    ExtentConfig cfg;
    const ExtentResult r = measureVerticalExtent(c.cam, c.pose, kUp, c.feature, c.box, cfg);
    ASSERT_EQ(r.status, ExtentStatus::kOk) << toString(r.status);
    const VerticalExtent& e = r.extent;
    EXPECT_NEAR(e.pi_i_px.x(), 320, 1e-12);
    EXPECT_NEAR(e.pi_i_px.y(), 240, 1e-12);
    EXPECT_NEAR(e.pi_t_px.y(), 115, 1e-9);
    EXPECT_NEAR(e.pi_d_px.y(), 315, 1e-9);
    EXPECT_EQ(e.top_edge, BoxEdge::kTop);
    EXPECT_EQ(e.bottom_edge, BoxEdge::kBottom);
    EXPECT_LT((e.p_t_W - Vec3(0, 2, 0.5)).norm(), 1e-12);
    EXPECT_LT((e.p_d_W - Vec3(0, 2, -0.3)).norm(), 1e-12);
    EXPECT_NEAR(e.D, 0.8, test::tolerance(1e-12, 1e-6));
    // J = (0, 0, 1): sigma_D^2 = 2 * 0.03^2.
    EXPECT_NEAR(e.sigma_D_paper, std::sqrt(2.0) * 0.03, test::tolerance(1e-12, 1e-7));
    // D = 0.4 * depth: dD/dp = (0, 0.4, 0) -> sigma = 0.4 * 0.02.
    // Float: central differences with the capped steps (0.1 px, 2e-4 of the
    // distance) keep about 1e-3 of the derivative (rounding ~ eps / step).
    EXPECT_NEAR(e.sigma_D_feature, 0.008, test::tolerance(1e-7, 1e-5));
    // dD/dy_min = -depth / f = -0.004, dD/dy_max = +0.004; sigma_px = 2.
    EXPECT_NEAR(e.sigma_D_box, 2 * std::sqrt(2.0) * 0.004, test::tolerance(1e-7, 1e-5));
}

TEST(VerticalExtent, ExactForAnyPoseAndDistortion) {
    // The box of a vertical segment (plus horizontal margin) must give back the
    // segment's length exactly, for any feature on it, any camera attitude and
    // with or without lens distortion.
    std::mt19937 rng(7);
    std::uniform_real_distribution<Scalar> u(-1, 1);
    int checked = 0;
    for (const Scalar k1 : {0.0, -0.15}) {
        const auto cam = makeCamera(k1, k1 == 0 ? 0 : 0.02);
        for (int trial = 0; trial < 200; ++trial) {
            const CameraPose pose = lookAlongY(Vec3(u(rng) * 0.3, 0, u(rng) * 0.2), u(rng) * 0.3,
                                               u(rng) * 0.3, u(rng) * 0.15);
            const Vec3 base(u(rng) * 0.3, 2 + u(rng) * 0.5, -0.4 + u(rng) * 0.1);
            const Scalar h = 0.5 + 0.3 * u(rng);
            const Vec3 top = base + h * kUp;
            const BoundingBox box = boxOf(cam, pose, {base, top}, 40);
            MapFeature f;
            f.p_FinW = base + (0.5 + 0.4 * u(rng)) * h * kUp;
            ExtentConfig cfg;
            cfg.propagate_variance = false;
            const ExtentResult r = measureVerticalExtent(cam, pose, kUp, f, box, cfg);
            if (r.status == ExtentStatus::kTruncatedBox) {
                continue;  // the random pose put the segment at the image border
            }
            ASSERT_EQ(r.status, ExtentStatus::kOk)
                << "trial " << trial << " k1 " << k1 << ": " << toString(r.status);
            // Float: 1e-6 relative to the 2-2.5 m the geometry works at.
            EXPECT_NEAR(r.extent.D, h, test::tolerance(1e-9, 2e-6))
                << "trial " << trial << " k1 " << k1;
            EXPECT_LT((r.extent.p_t_W - top).norm(), test::tolerance(1e-9, 2e-6));
            ++checked;
        }
    }
    EXPECT_GT(checked, 300);
}

TEST(VerticalExtent, RollCompensationRecoversAWideFace) {
    // A 0.5 m wide, 0.3 m tall face parallel to the image plane, camera rolled by
    // 5 degrees: the axis-aligned box is too tall by about 0.5 sin(5 deg).
    const auto cam = makeCamera();
    const Scalar roll = 5 * M_PI / 180;
    const CameraPose pose = lookAlongY(Vec3(0, 0, 0.15), 0, 0, roll);
    const Vec3 c(0, 1.5, 0);
    const BoundingBox box = boxOf(cam, pose,
                                  {c + Vec3(-0.25, 0, 0), c + Vec3(0.25, 0, 0),
                                   c + Vec3(-0.25, 0, 0.3), c + Vec3(0.25, 0, 0.3)});
    MapFeature f;
    f.p_FinW = c + Vec3(0.1, 0, 0.12);
    ExtentConfig plain;
    plain.propagate_variance = false;
    const auto r_plain = measureVerticalExtent(cam, pose, kUp, f, box, plain);
    ASSERT_EQ(r_plain.status, ExtentStatus::kOk) << toString(r_plain.status);
    EXPECT_GT(r_plain.extent.D, 0.3 + 0.5 * std::sin(roll) * 0.9);

    ExtentConfig comp = plain;
    comp.compensate_roll = true;
    const auto r_comp = measureVerticalExtent(cam, pose, kUp, f, box, comp);
    ASSERT_EQ(r_comp.status, ExtentStatus::kOk) << toString(r_comp.status);
    EXPECT_NEAR(r_comp.extent.D, 0.3, test::tolerance(1e-9, 2e-6));
}

TEST(VerticalExtent, SigmaMatchesMonteCarlo) {
    // sigma_D_feature (first-order propagation) against the spread of D over
    // feature positions drawn from N(p, P).
    const auto cam = makeCamera(-0.1, 0.01);
    const CameraPose pose = lookAlongY(Vec3(0.1, 0, 0.05), 0.1, -0.05, 0.03);
    const Vec3 base(0, 2, -0.3);
    const BoundingBox box = boxOf(cam, pose, {base, base + 0.6 * kUp}, 40);
    MapFeature f;
    f.p_FinW = base + 0.3 * kUp;
    const Mat3 A = (Mat3() << 0.02, 0.005, 0.0, 0.003, 0.04, 0.004, 0.0, 0.002, 0.015).finished();
    f.P_FinW = A * A.transpose();
    ExtentConfig cfg;
    const auto r = measureVerticalExtent(cam, pose, kUp, f, box, cfg);
    ASSERT_EQ(r.status, ExtentStatus::kOk);

    const Eigen::LLT<Mat3> llt(f.P_FinW);
    const Mat3 L = llt.matrixL();
    std::mt19937 rng(42);
    std::normal_distribution<Scalar> n01(0, 1);
    constexpr int kSamples = 20000;
    Scalar sum = 0;
    Scalar sum2 = 0;
    int n = 0;
    VerticalExtent e;
    for (int i = 0; i < kSamples; ++i) {
        const Vec3 p = f.p_FinW + L * Vec3(n01(rng), n01(rng), n01(rng));
        if (computeVerticalExtent(cam, pose, kUp, p, box, cfg, &e) == ExtentStatus::kOk) {
            sum += e.D;
            sum2 += e.D * e.D;
            ++n;
        }
    }
    ASSERT_GT(n, kSamples * 0.99);
    const Scalar mean = sum / static_cast<Scalar>(n);
    const Scalar sd = std::sqrt(sum2 / static_cast<Scalar>(n) - mean * mean);
    EXPECT_NEAR(r.extent.sigma_D_feature, sd, 0.05 * sd);

    // The paper's sigma_D^2 = 2 J P J^T is the variance of |p_t - p_d| when p_t
    // and p_d are displaced independently by N(0, P).
    Scalar s2 = 0;
    Scalar s1 = 0;
    for (int i = 0; i < kSamples; ++i) {
        const Vec3 pt = r.extent.p_t_W + L * Vec3(n01(rng), n01(rng), n01(rng));
        const Vec3 pd = r.extent.p_d_W + L * Vec3(n01(rng), n01(rng), n01(rng));
        const Scalar D = (pt - pd).norm();
        s1 += D;
        s2 += D * D;
    }
    const Scalar m2 = s1 / kSamples;
    const Scalar sd2 = std::sqrt(s2 / kSamples - m2 * m2);
    EXPECT_NEAR(r.extent.sigma_D_paper, sd2, 0.05 * sd2);
}

TEST(VerticalExtent, PaperJacobianMatchesNumeric) {
    // J = (p_t - p_d)^T / D is dD/dp_t of D = |p_t - p_d|.
    const Vec3 pt(0.3, 1.9, 0.7);
    const Vec3 pd(0.25, 2.0, -0.2);
    const Scalar D = (pt - pd).norm();
    const RowVec3 J = (pt - pd).transpose() / D;
    // Float: the step and tolerance of expectJacobianNear (numeric_jacobian.h).
    const double h = test::tolerance(1e-6, test::kFloatStep);
    for (int i = 0; i < 3; ++i) {
        Vec3 a = pt;
        Vec3 b = pt;
        a(i) += h;
        b(i) -= h;
        EXPECT_NEAR(J(i), ((a - pd).norm() - (b - pd).norm()) / (2 * h),
                    test::tolerance(1e-8, test::kFloatTolerance));
    }
}

TEST(VerticalExtent, DegenerateInputsGiveNoObservation) {
    const HandCase c;
    ExtentConfig cfg;
    const auto status = [&](const CameraPose& pose, const Vec3& p, const BoundingBox& b) {
        MapFeature f = c.feature;
        f.p_FinW = p;
        return measureVerticalExtent(c.cam, pose, kUp, f, b, cfg).status;
    };
    // Behind the camera.
    EXPECT_EQ(status(c.pose, Vec3(0, -2, 0), c.box), ExtentStatus::kBehindCamera);
    // Outside the box.
    EXPECT_EQ(status(c.pose, Vec3(1, 2, 0), c.box), ExtentStatus::kOutsideBox);
    // Box touching the top image border: truncated object.
    EXPECT_EQ(status(c.pose, c.feature.p_FinW, BoundingBox{300, 0, 340, 315}),
              ExtentStatus::kTruncatedBox);
    EXPECT_EQ(status(c.pose, c.feature.p_FinW, BoundingBox{300, 115, 340, 479}),
              ExtentStatus::kTruncatedBox);
    // A box truncated at the left border does not matter when the line exits top and bottom.
    EXPECT_EQ(status(c.pose, c.feature.p_FinW, BoundingBox{0, 115, 340, 315}), ExtentStatus::kOk);
    // Too small in the image.
    EXPECT_EQ(status(c.pose, c.feature.p_FinW, BoundingBox{300, 239, 340, 241}),
              ExtentStatus::kTooSmall);
    // Camera looking straight down: the vertical vanishing point (the nadir) lies
    // at the principal point, inside a box around the image centre.
    const CameraPose down = lookAlongY(Vec3::Zero(), 0, -M_PI / 2);
    EXPECT_EQ(status(down, Vec3(0.1, 0.05, -2), BoundingBox{250, 170, 390, 310}),
              ExtentStatus::kVanishingPointInBox);
    // Feature right on the principal ray of a camera looking straight down: its
    // vertical line images to a point.
    EXPECT_EQ(status(down, Vec3(0, 0, -2), BoundingBox{250, 170, 390, 310}),
              ExtentStatus::kDegenerateDirection);
    // Rolled camera, feature near the side of a wide box: the line leaves through the side.
    const CameraPose rolled = lookAlongY(Vec3::Zero(), 0, 0, 0.5);
    const auto pi = test::projectW(c.cam, rolled, Vec3(0, 2, 0));
    const BoundingBox narrow{pi->x() - 3, pi->y() - 100, pi->x() + 40, pi->y() + 100};
    EXPECT_EQ(status(rolled, Vec3(0, 2, 0), narrow), ExtentStatus::kSideExit);
    for (int s = 0; s < static_cast<int>(ExtentStatus::kCount); ++s) {
        EXPECT_STRNE(toString(static_cast<ExtentStatus>(s)), "unknown");
    }
}

}  // namespace
}  // namespace scaled::core
