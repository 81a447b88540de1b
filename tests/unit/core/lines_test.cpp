#include <gtest/gtest.h>

#include <scaled/core/geometry/lines.h>

namespace scaled::core {
namespace {

TEST(Lines, ClosestPointsOfSkewLinesByHand) {
    // a: the z axis; b: the line x = 1 along y. Closest points (0,0,0) and (1,0,0).
    const auto st = closestPointParams(Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(1, 5, 0), Vec3(0, 2, 0));
    ASSERT_TRUE(st);
    EXPECT_NEAR(st->s, 0, 1e-15);
    EXPECT_NEAR(st->t, -2.5, 1e-15);
}

TEST(Lines, IntersectingLinesMeet) {
    const Vec3 a0(1, 2, 3), ua(0, 0, 1), b0(0, 0, 0), ub(1, 2, 7);
    const auto st = closestPointParams(a0, ua, b0, ub);
    ASSERT_TRUE(st);
    EXPECT_LT(((a0 + st->s * ua) - (b0 + st->t * ub)).norm(), 1e-12);
    EXPECT_NEAR(st->s, 4, 1e-12);
    EXPECT_NEAR(st->t, 1, 1e-12);
}

TEST(Lines, ParallelLinesHaveNoAnswer) {
    EXPECT_FALSE(closestPointParams(Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3(0, 0, -3)));
}

}  // namespace
}  // namespace scaled::core
