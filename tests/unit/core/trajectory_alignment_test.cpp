#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>

namespace scaled::core {
namespace {

// A helix in metres, and a map that follows it at `scale_a` metres per unit
// for its first `switch_at` steps and `scale_b` after: the drift a monocular
// map shows, its positions continuous across the change.
struct Drifting {
    std::vector<Vec3> gt;
    std::vector<Vec3> est;
};

Drifting drifting(int n, int switch_at, double scale_a, double scale_b) {
    Drifting d;
    Vec3 e = Vec3::Zero();
    for (int k = 0; k < n; ++k) {
        const double t = 0.05 * k;
        const Vec3 g(static_cast<Scalar>(std::cos(t)), static_cast<Scalar>(std::sin(t)),
                     static_cast<Scalar>(0.1 * t));
        if (k > 0) {
            const double s = k <= switch_at ? scale_a : scale_b;
            e += (g - d.gt.back()) / static_cast<Scalar>(s);
        }
        d.gt.push_back(g);
        d.est.push_back(e);
    }
    return d;
}

TEST(SlidingWindowScales, FollowsAMapWhoseScaleChanges) {
    const Drifting d = drifting(300, 150, 2.0, 2.5);
    const auto w = slidingWindowScales(d.est, d.gt, 50);
    ASSERT_TRUE(w) << w.error().message;
    ASSERT_EQ(w->scale.size(), 251u);
    EXPECT_EQ(w->valid, 251);
    // Windows on either side of the change see that side's scale exactly.
    EXPECT_NEAR(w->scale.front(), 2.0, 1e-4);
    EXPECT_NEAR(w->scale[100], 2.0, 1e-4);  // positions 100..149
    EXPECT_NEAR(w->scale[150], 2.5, 1e-4);  // positions 150..199
    EXPECT_NEAR(w->scale.back(), 2.5, 1e-4);
    EXPECT_NEAR(w->min, 2.0, 1e-4);
    EXPECT_NEAR(w->max, 2.5, 1e-4);
    EXPECT_NEAR(w->range, 1.25, 1e-4);
}

TEST(SlidingWindowScales, SeesDriftThatTheThirdsMiss) {
    // Up by 30% in the middle third, back to the start's scale at the end.
    Drifting d = drifting(300, 100, 2.0, 2.6);
    const Drifting back = drifting(300, 200, 2.6, 2.0);
    for (size_t k = 101; k < 300; ++k) {
        const Vec3 step = k <= 200 ? d.est[k] - d.est[k - 1] : back.est[k] - back.est[k - 1];
        d.est[k] = d.est[k - 1] + step;
    }
    const auto thirds = scaleDriftBetweenThirds(d.est, d.gt);
    ASSERT_TRUE(thirds);
    EXPECT_NEAR(*thirds, 1.0, 1e-4);
    const auto w = slidingWindowScales(d.est, d.gt, 60);
    ASSERT_TRUE(w);
    EXPECT_NEAR(w->range, 1.3, 1e-4);
}

TEST(SlidingWindowScales, NamesWhatItCannotDo) {
    const Drifting d = drifting(40, 20, 1.0, 1.0);
    const auto small = slidingWindowScales(d.est, d.gt, 2);
    ASSERT_FALSE(small);
    EXPECT_NE(small.error().message.find("at least 3"), std::string::npos);
    const auto short_run = slidingWindowScales(d.est, d.gt, 41);
    ASSERT_FALSE(short_run);
    EXPECT_NE(short_run.error().message.find("got 40"), std::string::npos);
    const std::vector<Vec3> still(40, Vec3(1, 2, 3));
    const auto static_map = slidingWindowScales(still, d.gt, 10);
    ASSERT_FALSE(static_map);
    EXPECT_NE(static_map.error().message.find("does not move"), std::string::npos);
}

TEST(SlidingWindowScales, AStillStretchLeavesItsWindowsOut) {
    Drifting d = drifting(100, 100, 1.5, 1.5);
    for (size_t k = 40; k < 60; ++k) {  // the map stands still while the camera moves
        d.est[k] = d.est[39];
    }
    for (size_t k = 60; k < 100; ++k) {
        d.est[k] = d.est[k - 1] + (d.gt[k] - d.gt[k - 1]) / Scalar(1.5);
    }
    const auto w = slidingWindowScales(d.est, d.gt, 10);
    ASSERT_TRUE(w);
    EXPECT_TRUE(std::isnan(w->scale[42]));  // positions 42..51: not one moves
    // Positions 39..59 are one point: the 12 windows that start at 39..50.
    EXPECT_EQ(w->valid, static_cast<int>(w->scale.size()) - 12);
    EXPECT_NEAR(w->min, 1.5, 1e-3);
}

}  // namespace
}  // namespace scaled::core
