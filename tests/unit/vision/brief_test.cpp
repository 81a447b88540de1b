// The relocalisation descriptor (brief.h).

#include <limits>
#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include <scaled/drivers/vision/brief.h>

#include "vision_test_images.h"

namespace scaled::drivers::vision {
namespace {

using core::Scalar;
using core::Vec2;

TEST(Brief, SamePointMatchesOtherPointsDoNot) {
    const cv::Mat img = test::smoothTexture(cv::Size(200, 160), 2.0, 3);
    BriefDescriptor a;
    BriefDescriptor b;
    ASSERT_TRUE(computeBrief(img, Vec2(100, 80), a));
    ASSERT_TRUE(computeBrief(img, Vec2(Scalar(100.3), Scalar(79.8)), b));
    EXPECT_EQ(briefDistance(a, b), 0) << "the pixel is rounded";
    // The same texture shifted by (7, -4): the descriptor follows it.
    cv::Mat shifted;
    const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, 7, 0, 1, -4);
    cv::warpAffine(img, shifted, M, img.size());
    ASSERT_TRUE(computeBrief(shifted, Vec2(107, 76), b));
    EXPECT_EQ(briefDistance(a, b), 0);
    // Brighter and with more contrast: comparisons do not change.
    cv::Mat brighter;
    img.convertTo(brighter, -1, 1.2, 10);
    ASSERT_TRUE(computeBrief(brighter, Vec2(100, 80), b));
    EXPECT_LE(briefDistance(a, b), 8);
    // A different place of the texture is far away in descriptor space.
    ASSERT_TRUE(computeBrief(img, Vec2(60, 50), b));
    EXPECT_GT(briefDistance(a, b), 32);
}

TEST(Brief, NeedsTheWholeWindowAndAnEightBitImage) {
    const cv::Mat img = test::smoothTexture(cv::Size(100, 80), 2.0, 4);
    BriefDescriptor d;
    EXPECT_TRUE(computeBrief(img, Vec2(kBriefRadiusPx, kBriefRadiusPx), d));
    EXPECT_FALSE(computeBrief(img, Vec2(kBriefRadiusPx - 1, 40), d));
    EXPECT_FALSE(computeBrief(img, Vec2(50, 80 - kBriefRadiusPx), d));
    EXPECT_FALSE(computeBrief(img, Vec2(std::numeric_limits<Scalar>::quiet_NaN(), 40), d));
    cv::Mat f;
    img.convertTo(f, CV_32F);
    EXPECT_FALSE(computeBrief(f, Vec2(50, 40), d));
    EXPECT_FALSE(computeBrief(cv::Mat(), Vec2(50, 40), d));
}

}  // namespace
}  // namespace scaled::drivers::vision
