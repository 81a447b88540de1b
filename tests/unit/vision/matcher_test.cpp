#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include <Eigen/LU>
#include <gtest/gtest.h>

#include <scaled/drivers/vision/corner_detector.h>
#include <scaled/drivers/vision/matcher.h>
#include <scaled/drivers/vision/patch.h>

#include "vision_test_images.h"

namespace scaled::drivers::vision {
namespace {

using core::Mat2;
using core::Scalar;
using core::Vec2;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Mat2 diag(double sx2, double sy2) {
    Mat2 S = Mat2::Zero();
    S(0, 0) = static_cast<Scalar>(sx2);
    S(1, 1) = static_cast<Scalar>(sy2);
    return S;
}

Vec2 vec(double x, double y) {
    return {static_cast<Scalar>(x), static_cast<Scalar>(y)};
}

// The image content moved by (tx, ty): a point p of `img` is at p + t in the result.
cv::Mat shifted(const cv::Mat& img, double tx, double ty) {
    const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, tx, 0, 1, ty);
    cv::Mat out;
    cv::warpAffine(img, out, M, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
    return out;
}

double mahalanobis2(const Vec2& d, const Mat2& S) {
    return static_cast<double>(d.dot(S.inverse() * d));
}

// Features are found again to sub-pixel accuracy. As in the tracker, they sit
// at Shi-Tomasi corners (here moved off the pixel grid), where the NCC peak is
// well conditioned in both directions.
TEST(Matcher, FindsSubPixelShift) {
    const cv::Mat img = test::smoothTexture(cv::Size(640, 480), 1.5, 21);
    CornerConfig corner_cfg;
    corner_cfg.max_corners = 12;
    corner_cfg.border_px = 40;
    std::vector<Vec2> corners;
    detectCorners(img, cv::Mat(), corner_cfg, corners);
    ASSERT_EQ(corners.size(), 12U);

    const MatchConfig cfg;
    const Mat2 S = diag(25, 25);
    int n = 0;
    double worst = 0;
    for (const auto& [tx, ty] : {std::pair{2.3, -1.6}, {-0.5, 0.5}, {4.75, 3.25}, {0.0, 0.0}}) {
        const cv::Mat moved = shifted(img, tx, ty);
        for (const Vec2& c : corners) {
            const Vec2 at = c + vec(0.37, -0.21);
            const auto patch = extractPatch(img, at);
            ASSERT_TRUE(patch);
            // Predicted position off by a few pixels, well inside the gate.
            const Vec2 truth = at + vec(tx, ty);
            const Vec2 predicted = truth + vec(1.5, -2.0);
            const auto m = matchInEllipse(moved, *patch, predicted, S, cfg);
            ASSERT_TRUE(m) << at.transpose() << " shift " << tx << " " << ty;
            const double err = static_cast<double>((m->px - truth).norm());
            EXPECT_LT(err, 0.15) << m->px.transpose() << " vs " << truth.transpose();
            EXPECT_GT(m->ncc, 0.95);
            worst = std::max(worst, err);
            ++n;
        }
    }
    EXPECT_EQ(n, 48);
    RecordProperty("worst_error_px", std::to_string(worst));
}

TEST(Matcher, SubPixelRefinementHelps) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 22);
    const cv::Mat moved = shifted(img, 0.4, -0.35);
    const auto patch = extractPatch(img, vec(160, 120));
    ASSERT_TRUE(patch);
    const Vec2 truth = vec(160.4, 119.65);
    MatchConfig cfg;
    cfg.subpixel = false;
    const auto coarse = matchInEllipse(moved, *patch, truth, diag(25, 25), cfg);
    cfg.subpixel = true;
    const auto fine = matchInEllipse(moved, *patch, truth, diag(25, 25), cfg);
    ASSERT_TRUE(coarse && fine);
    EXPECT_EQ(coarse->px, vec(160, 120));
    EXPECT_LT((fine->px - truth).norm(), Scalar(0.15));
    EXPECT_LT((fine->px - truth).norm(), (coarse->px - truth).norm());
}

TEST(Matcher, SearchesOnlyInsideEllipse) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 1.5, 23);
    const auto patch = extractPatch(img, vec(150, 110));
    ASSERT_TRUE(patch);
    MatchConfig cfg;
    cfg.subpixel = false;
    // A tilted ellipse that still holds the true position.
    Mat2 S;
    S << 30, 12, 12, 10;
    const Vec2 center = vec(153, 111);
    const auto m = matchInEllipse(img, *patch, center, S, cfg);
    ASSERT_TRUE(m);
    EXPECT_EQ(m->px, vec(150, 110));
    EXPECT_LE(mahalanobis2(m->px - center, S), cfg.chi2_gate);
    // Every pixel of the ellipse is evaluated: about its area pi * gate * sqrt(det S).
    const double area =
        std::numbers::pi * cfg.chi2_gate * std::sqrt(static_cast<double>(S.determinant()));
    EXPECT_NEAR(m->evaluated, area, 0.1 * area);

    // Same ellipse moved so the true position is outside it: no match.
    const Vec2 away = vec(150 - 6, 110 + 16);
    ASSERT_GT(mahalanobis2(vec(150, 110) - away, S), cfg.chi2_gate);
    EXPECT_FALSE(matchInEllipse(img, *patch, away, S, cfg));
    // Accepting anything shows the search did run there, and stayed inside the gate.
    cfg.min_ncc = -1;
    const auto any = matchInEllipse(img, *patch, away, S, cfg);
    ASSERT_TRUE(any);
    EXPECT_LE(mahalanobis2(any->px - away, S), cfg.chi2_gate);
    EXPECT_LT(any->ncc, 0.8);
}

TEST(Matcher, RejectsTooUncertainEllipse) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 24);
    const auto patch = extractPatch(img, vec(160, 120));
    ASSERT_TRUE(patch);
    MatchConfig cfg;
    const Mat2 S = diag(400, 400);  // ~11600 pixels in the gate
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(160, 120), S, cfg));
    cfg.max_search_pixels = 20000;
    const auto m = matchInEllipse(img, *patch, vec(160, 120), S, cfg);
    ASSERT_TRUE(m);
    EXPECT_LT((m->px - vec(160, 120)).norm(), Scalar(0.15));
    // A needle-thin ellipse longer than the budget is rejected too.
    cfg.max_search_pixels = 100;
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(160, 120), diag(1e-4, 1e4), cfg));
}

TEST(Matcher, ClipsSearchToImage) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 25);
    const auto patch = extractPatch(img, vec(22, 230 - 12));
    ASSERT_TRUE(patch);
    // Ellipse hanging over the bottom-left corner; the feature is near it.
    const auto m = matchInEllipse(img, *patch, vec(10, 232), diag(100, 100), MatchConfig{});
    ASSERT_TRUE(m);
    EXPECT_LT((m->px - vec(22, 218)).norm(), Scalar(0.15));
    // Ellipse entirely outside the image.
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(-100, 50), diag(25, 25), MatchConfig{}));
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(1e12, 50), diag(25, 25), MatchConfig{}));
}

TEST(Matcher, RejectsFlatTemplate) {
    cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 26);
    img(cv::Rect(100, 80, 60, 60)).setTo(cv::Scalar(90));
    Patch flat;
    flat.size = 11;
    flat.source = cv::Mat(41, 41, CV_32FC1, cv::Scalar(90));
    flat.templ = cv::Mat(11, 11, CV_32FC1, cv::Scalar(90));
    EXPECT_FALSE(matchInEllipse(img, flat, vec(130, 110), diag(25, 25), MatchConfig{}));
    // Barely textured (one grey level of noise): still too flat.
    cv::RNG rng(3);
    rng.fill(flat.templ, cv::RNG::UNIFORM, 89.5, 90.5);
    EXPECT_FALSE(matchInEllipse(img, flat, vec(130, 110), diag(25, 25), MatchConfig{}));
    // A textured template on a flat image region scores nothing useful.
    const auto textured = extractPatch(img, vec(60, 60));
    ASSERT_TRUE(textured);
    EXPECT_FALSE(matchInEllipse(img, *textured, vec(130, 110), diag(25, 25), MatchConfig{}));
}

TEST(Matcher, RejectsBadInputs) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 27);
    const auto patch = extractPatch(img, vec(160, 120));
    ASSERT_TRUE(patch);
    const MatchConfig cfg;
    const Mat2 S = diag(25, 25);
    ASSERT_TRUE(matchInEllipse(img, *patch, vec(161, 121), S, cfg));

    cv::Mat f;
    img.convertTo(f, CV_32F);
    EXPECT_FALSE(matchInEllipse(f, *patch, vec(161, 121), S, cfg));
    cv::Mat color;
    cv::cvtColor(img, color, cv::COLOR_GRAY2BGR);
    EXPECT_FALSE(matchInEllipse(color, *patch, vec(161, 121), S, cfg));
    EXPECT_FALSE(matchInEllipse(cv::Mat(), *patch, vec(161, 121), S, cfg));

    EXPECT_FALSE(matchInEllipse(img, *patch, vec(161, 121), diag(25, -1), cfg));
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(161, 121), diag(0, 25), cfg));
    Mat2 singular;
    singular << 25, 25, 25, 25;
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(161, 121), singular, cfg));
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(161, 121), diag(kNaN, 25), cfg));
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(kNaN, 121), S, cfg));

    EXPECT_FALSE(matchInEllipse(img, Patch{}, vec(161, 121), S, cfg));
    Patch wrong = *patch;
    wrong.size = 9;  // does not agree with the template
    EXPECT_FALSE(matchInEllipse(img, wrong, vec(161, 121), S, cfg));
    wrong = *patch;
    wrong.templ.convertTo(wrong.templ, CV_64F);
    EXPECT_FALSE(matchInEllipse(img, wrong, vec(161, 121), S, cfg));

    MatchConfig bad = cfg;
    bad.chi2_gate = -1;
    EXPECT_FALSE(matchInEllipse(img, *patch, vec(161, 121), S, bad));
    // Images smaller than the template.
    EXPECT_FALSE(matchInEllipse(img(cv::Rect(0, 0, 9, 40)), *patch, vec(4, 20), S, cfg));
}

TEST(Matcher, TinyImageAndImageView) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 28);
    const auto patch = extractPatch(img, vec(160, 120));
    ASSERT_TRUE(patch);
    // A non-continuous view exactly the template's size: one candidate.
    const cv::Mat view = img(cv::Rect(155, 115, 11, 11));
    const auto m = matchInEllipse(view, *patch, vec(5, 5), diag(4, 4), MatchConfig{});
    ASSERT_TRUE(m);
    EXPECT_EQ(m->evaluated, 1);
    EXPECT_EQ(m->px, vec(5, 5));
    EXPECT_NEAR(m->ncc, 1.0, 1e-5);
}

TEST(Matcher, ClassAndFreeFunctionAgree) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 2.5, 29);
    const cv::Mat moved = shifted(img, 1.3, 0.8);
    Matcher matcher;
    for (const auto& [x, y] : {std::pair{100.5, 80.25}, {200.0, 150.0}, {250.75, 60.5}}) {
        const auto patch = extractPatch(img, vec(x, y));
        ASSERT_TRUE(patch);
        const Vec2 c = vec(x + 2, y);
        const auto a = matcher.match(moved, *patch, c, diag(16, 9), MatchConfig{});
        const auto b = matchInEllipse(moved, *patch, c, diag(16, 9), MatchConfig{});
        ASSERT_TRUE(a && b);
        EXPECT_EQ(a->px, b->px);
        EXPECT_EQ(a->ncc, b->ncc);
        EXPECT_EQ(a->evaluated, b->evaluated);
    }
}

// Viewpoint change by scale: the source was cut where the feature looked twice as
// large (or small) as now; warping the template with A restores the match.
TEST(Matcher, WarpedTemplateMatchesScaledImage) {
    const cv::Mat img = test::smoothTexture(cv::Size(320, 240), 1.5, 30);
    cv::Mat big;
    cv::resize(img, big, cv::Size(), 2.0, 2.0, cv::INTER_LINEAR);
    // Point p of img is at 2p + 0.5 in big.
    const Vec2 p = vec(150.25, 110.25);
    const Vec2 q = vec(301.0, 221.0);
    MatchConfig cfg;
    cfg.min_ncc = -1;  // report scores, judge them below

    // Source cut from the big image, searched for in the small one: A = 2.
    auto from_big = extractPatch(big, q);
    ASSERT_TRUE(from_big);
    const auto unwarped = matchInEllipse(img, *from_big, p, diag(9, 9), cfg);
    warpTemplate(*from_big, Mat2::Identity() * Scalar(2));
    const auto warped = matchInEllipse(img, *from_big, p, diag(9, 9), cfg);
    ASSERT_TRUE(unwarped && warped);
    EXPECT_GT(warped->ncc, 0.97);
    EXPECT_LT(unwarped->ncc, 0.9);
    EXPECT_LT((warped->px - p).norm(), Scalar(0.2));

    // Source cut from the small image, searched for in the big one: A = 0.5.
    auto from_small = extractPatch(img, p);
    ASSERT_TRUE(from_small);
    const auto unwarped2 = matchInEllipse(big, *from_small, q, diag(9, 9), cfg);
    warpTemplate(*from_small, Mat2::Identity() * Scalar(0.5));
    const auto warped2 = matchInEllipse(big, *from_small, q, diag(9, 9), cfg);
    ASSERT_TRUE(unwarped2 && warped2);
    EXPECT_GT(warped2->ncc, 0.97);
    EXPECT_LT(unwarped2->ncc, 0.9);
    EXPECT_LT((warped2->px - q).norm(), Scalar(0.2));
}

}  // namespace
}  // namespace scaled::drivers::vision
