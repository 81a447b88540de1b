// Two views' relative motion (two_view.h): the essential matrix of a new
// map's start check.

#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/drivers/vision/two_view.h>

namespace scaled::drivers::vision {
namespace {

using core::Mat3;
using core::Scalar;
using core::Vec2;
using core::Vec3;

double angleDeg(const Mat3& R) {
    return std::abs(static_cast<double>(Eigen::AngleAxis<Scalar>(R).angle())) * 180.0 /
           std::numbers::pi;
}

// Points 1.5-4 units in front of camera S, seen again from camera K (attitude
// R_KtoS, centre p_KinS), with pixel noise of noise_px (a fixed sequence) and
// the last `outliers` pairs of K moved by 40 px.
struct Scene {
    std::vector<Vec2> x_S;
    std::vector<Vec2> x_K;
    std::vector<double> depth_K;  // true distance from K along the ray
};

Scene makeScene(const Mat3& R_KtoS, const Vec3& p_KinS, int n, double noise_px, int outliers,
                double focal_px) {
    Scene s;
    std::uint64_t state = 12345;
    auto uniform = [&state]() {
        state = state * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(state >> 11) / static_cast<double>(1ULL << 53);
    };
    for (int i = 0; i < n; ++i) {
        const Vec3 p_S(static_cast<Scalar>(uniform() * 2 - 1),
                       static_cast<Scalar>(uniform() * 1.5 - 0.75),
                       static_cast<Scalar>(1.5 + 2.5 * uniform()));
        const Vec3 p_K = R_KtoS.transpose() * (p_S - p_KinS);
        const auto noise = [&]() {
            return static_cast<Scalar>((uniform() * 2 - 1) * noise_px / focal_px);
        };
        s.x_S.emplace_back(p_S.x() / p_S.z() + noise(), p_S.y() / p_S.z() + noise());
        Vec2 k(p_K.x() / p_K.z() + noise(), p_K.y() / p_K.z() + noise());
        if (i >= n - outliers) {
            k.x() += static_cast<Scalar>(40 / focal_px);
        }
        s.x_K.push_back(k);
        s.depth_K.push_back(static_cast<double>(p_K.norm()));  // along the ray
    }
    return s;
}

// One scene: the rotation within rot_deg, the translation's direction within
// 8 degrees (cos 0.99), the 6 moved pairs out, the others' depths within depth_rel.
void checkScene(double noise_px, double rot_deg, double depth_rel) {
    // 5 degrees of turn about a tilted axis and a slide mostly sideways: the
    // motion a filter started without depths can mistake for a larger turn.
    const Mat3 R_KtoS(Eigen::AngleAxis<Scalar>(Scalar(5 * std::numbers::pi / 180),
                                               Vec3(0.3, 1, 0.2).normalized()));
    const Vec3 p_KinS(0.12, 0.01, 0.03);
    const double f = 585;
    const Scene s = makeScene(R_KtoS, p_KinS, 40, noise_px, 6, f);
    std::vector<double> depth(s.x_K.size());
    const auto m = estimateTwoViewMotion(s.x_S, s.x_K, f, 1.0, depth);
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_LT(angleDeg(m->R_KtoS.transpose() * R_KtoS), rot_deg);
    EXPECT_GT(static_cast<double>(m->t_KinS.normalized().dot(p_KinS.normalized())), 0.99);
    EXPECT_GE(m->inliers, 30);
    EXPECT_LE(m->inliers, 34) << "the 6 moved pairs are outliers";
    EXPECT_GT(m->median_parallax_deg, 0.5);
    // Depths in units of |t|: times |t| they are the true ones.
    const double t_norm = static_cast<double>(p_KinS.norm());
    int checked = 0;
    for (std::size_t i = 0; i + 6 < depth.size(); ++i) {
        if (depth[i] > 0) {
            EXPECT_NEAR(depth[i] * t_norm / s.depth_K[i], 1.0, depth_rel) << i;
            ++checked;
        }
    }
    EXPECT_GE(checked, 25);
    for (std::size_t i = depth.size() - 6; i < depth.size(); ++i) {
        EXPECT_EQ(depth[i], 0.0) << "an outlier has no depth";
    }
}

TEST(TwoView, RecoversTheRotationTheDirectionAndTheRelativeDepths) {
    checkScene(0.0, 0.01, 0.01);  // exact pairs: exact up to the refinement's tolerance
    // Half a pixel of noise on both views with 2-3 degrees of parallax: the
    // rotation stays within 0.3 degrees, the depths move together by up to 10%
    // (a turn and a slide still trade a little; measured 6-12% low).
    checkScene(0.5, 0.3, 0.15);
}

TEST(TwoView, RefusesTooFewOrMismatchedPairs) {
    const std::vector<Vec2> seven(7, Vec2(0.1, 0.2));
    EXPECT_FALSE(estimateTwoViewMotion(seven, seven, 585, 1, {}));
    const std::vector<Vec2> ten(10, Vec2(0.1, 0.2));
    EXPECT_FALSE(estimateTwoViewMotion(ten, seven, 585, 1, {}));
    std::vector<double> depth(3);
    EXPECT_FALSE(estimateTwoViewMotion(ten, ten, 585, 1, depth));
    EXPECT_FALSE(estimateTwoViewMotion(ten, ten, 0, 1, {}));
}

}  // namespace
}  // namespace scaled::drivers::vision
