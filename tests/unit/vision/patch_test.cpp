#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include <scaled/drivers/vision/patch.h>

#include "vision_test_images.h"

namespace scaled::drivers::vision {
namespace {

using core::Mat2;
using core::Scalar;
using core::Vec2;

double maxAbsDiff(const cv::Mat& a, const cv::Mat& b) {
    return cv::norm(a, b, cv::NORM_INF);
}

TEST(Patch, IntegerPositionCopiesPixels) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 7);
    const auto p = extractPatch(img, Vec2(60, 50));
    ASSERT_TRUE(p);
    EXPECT_EQ(p->size, 11);
    ASSERT_EQ(p->source.type(), CV_32FC1);
    ASSERT_EQ(p->source.size(), cv::Size(41, 41));
    ASSERT_EQ(p->templ.type(), CV_32FC1);
    ASSERT_EQ(p->templ.size(), cv::Size(11, 11));
    cv::Mat expect_src;
    img(cv::Rect(40, 30, 41, 41)).convertTo(expect_src, CV_32F);
    EXPECT_EQ(maxAbsDiff(p->source, expect_src), 0.0);
    cv::Mat expect_t;
    img(cv::Rect(55, 45, 11, 11)).convertTo(expect_t, CV_32F);
    EXPECT_EQ(maxAbsDiff(p->templ, expect_t), 0.0);
}

TEST(Patch, SubPixelIsBilinear) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 8);
    const Vec2 px(Scalar(70.3), Scalar(55.8));
    const auto p = extractPatch(img, px, 7, 21);
    ASSERT_TRUE(p);
    EXPECT_EQ(p->size, 7);
    cv::Mat expect;
    cv::getRectSubPix(img, cv::Size(21, 21), cv::Point2f(70.3F, 55.8F), expect, CV_32F);
    EXPECT_LT(maxAbsDiff(p->source, expect), 0.02);
    // One value by hand: the source centre is the image at (70.3, 55.8).
    const auto at = [&](int x, int y) { return static_cast<double>(img.at<uchar>(y, x)); };
    const double top = 0.7 * at(70, 55) + 0.3 * at(71, 55);
    const double bottom = 0.7 * at(70, 56) + 0.3 * at(71, 56);
    EXPECT_NEAR(p->source.at<float>(10, 10), 0.2 * top + 0.8 * bottom, 1e-3);
    EXPECT_NEAR(p->templ.at<float>(3, 3), 0.2 * top + 0.8 * bottom, 1e-3);
}

TEST(Patch, TemplateMustLieInTheImageTheSourceMayLeaveIt) {
    // Default sizes: template 11 (half 5), source 41 (half 20).
    const cv::Mat img = test::smoothTexture(cv::Size(100, 80), 2.0, 9);
    EXPECT_TRUE(extractPatch(img, Vec2(20, 20)));
    EXPECT_TRUE(extractPatch(img, Vec2(79, 59)));
    EXPECT_TRUE(extractPatch(img, Vec2(Scalar(78.5), Scalar(58.5))));
    // The template square touches the border: accepted; the source beyond it
    // takes the nearest border pixel.
    EXPECT_TRUE(extractPatch(img, Vec2(5, 5)));
    EXPECT_TRUE(extractPatch(img, Vec2(94, 74)));
    EXPECT_FALSE(extractPatch(img, Vec2(Scalar(4.5), 30)));
    EXPECT_FALSE(extractPatch(img, Vec2(30, Scalar(4.9))));
    EXPECT_FALSE(extractPatch(img, Vec2(Scalar(94.2), 30)));
    EXPECT_FALSE(extractPatch(img, Vec2(30, Scalar(74.5))));
    EXPECT_FALSE(extractPatch(img, Vec2(-500, 1e9)));
    EXPECT_FALSE(extractPatch(img, Vec2(std::numeric_limits<Scalar>::quiet_NaN(), 30)));

    // Inside, the source is the image; outside, the replicated border.
    const auto p = extractPatch(img, Vec2(5, 40));
    ASSERT_TRUE(p);
    for (int j = 0; j < 41; ++j) {
        const int x = std::clamp(5 - 20 + j, 0, img.cols - 1);
        EXPECT_FLOAT_EQ(p->source.at<float>(20, j), static_cast<float>(img.at<uchar>(40, x)))
            << "column " << j;
    }
    for (int i = 0; i < 11; ++i) {
        for (int j = 0; j < 11; ++j) {
            EXPECT_FLOAT_EQ(p->templ.at<float>(i, j), static_cast<float>(img.at<uchar>(35 + i, j)));
        }
    }
}

TEST(Patch, RejectsBadInputs) {
    const cv::Mat img = test::smoothTexture(cv::Size(100, 80), 2.0, 10);
    EXPECT_FALSE(extractPatch(img, Vec2(50, 40), 10, 41));  // even template
    EXPECT_FALSE(extractPatch(img, Vec2(50, 40), 11, 40));  // even source
    EXPECT_FALSE(extractPatch(img, Vec2(50, 40), 13, 11));  // template larger than source
    EXPECT_FALSE(extractPatch(img, Vec2(50, 40), -1, 41));
    cv::Mat f;
    img.convertTo(f, CV_32F);
    EXPECT_FALSE(extractPatch(f, Vec2(50, 40)));
    cv::Mat color;
    cv::cvtColor(img, color, cv::COLOR_GRAY2BGR);
    EXPECT_FALSE(extractPatch(color, Vec2(50, 40)));
    EXPECT_FALSE(extractPatch(cv::Mat(), Vec2(50, 40)));
}

TEST(WarpTemplate, IdentityReproducesTemplate) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 11);
    auto p = extractPatch(img, Vec2(Scalar(80.37), Scalar(61.62)));
    ASSERT_TRUE(p);
    const cv::Mat direct = p->templ.clone();
    p->templ = cv::Mat();
    warpTemplate(*p, Mat2::Identity());
    ASSERT_EQ(p->templ.size(), direct.size());
    EXPECT_LT(maxAbsDiff(p->templ, direct), 1e-4);
}

TEST(WarpTemplate, RotationByQuarterTurnPermutesPixels) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 12);
    auto p = extractPatch(img, Vec2(80, 60));
    ASSERT_TRUE(p);
    Mat2 A;
    A << 0, -1, 1, 0;  // template offset (dx, dy) shows source offset (-dy, dx)
    warpTemplate(*p, A);
    for (int i = 0; i < 11; ++i) {
        for (int j = 0; j < 11; ++j) {
            const int dx = j - 5;
            const int dy = i - 5;
            const double expect = img.at<uchar>(60 + dx, 80 - dy);
            EXPECT_NEAR(p->templ.at<float>(i, j), expect, 1e-4) << i << " " << j;
        }
    }
}

TEST(WarpTemplate, ScaleSamplesSourceFartherOut) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 13);
    auto p = extractPatch(img, Vec2(80, 60));
    ASSERT_TRUE(p);
    warpTemplate(*p, Mat2::Identity() * Scalar(2));
    for (int i = 0; i < 11; ++i) {
        for (int j = 0; j < 11; ++j) {
            const double expect = img.at<uchar>(60 + 2 * (i - 5), 80 + 2 * (j - 5));
            EXPECT_NEAR(p->templ.at<float>(i, j), expect, 1e-4);
        }
    }
    // Beyond the source the nearest border value is used; no crash, finite values.
    warpTemplate(*p, Mat2::Identity() * Scalar(10));
    EXPECT_NEAR(p->templ.at<float>(0, 0), img.at<uchar>(40, 60), 1e-4);
    EXPECT_TRUE(cv::checkRange(p->templ));
}

TEST(WarpTemplate, InvalidInputIsNoOp) {
    const cv::Mat img = test::smoothTexture(cv::Size(160, 120), 2.0, 14);
    auto p = extractPatch(img, Vec2(80, 60));
    ASSERT_TRUE(p);
    const cv::Mat before = p->templ.clone();
    Mat2 bad = Mat2::Identity();
    bad(0, 1) = std::numeric_limits<Scalar>::quiet_NaN();
    warpTemplate(*p, bad);
    EXPECT_EQ(maxAbsDiff(p->templ, before), 0.0);
    Patch empty;
    warpTemplate(empty, Mat2::Identity());
    EXPECT_TRUE(empty.templ.empty());
    p->size = 43;  // larger than the source
    warpTemplate(*p, Mat2::Identity());
    EXPECT_EQ(maxAbsDiff(p->templ, before), 0.0);
}

}  // namespace
}  // namespace scaled::drivers::vision
