#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/vision/corner_detector.h>

#include "vision_test_images.h"

namespace scaled::drivers::vision {
namespace {

using core::Scalar;
using core::Vec2;

// A 640x480 image with 3 x 4 bright rectangles on a dark background; rectangle k
// has contrast 20 + 15 k, so its corners get stronger with k.
struct RectScene {
    cv::Mat image;
    std::vector<std::array<int, 4>> rects;  // x0, y0, x1, y1 (inclusive), weakest first
};

RectScene rectScene() {
    RectScene s;
    s.image = cv::Mat(480, 640, CV_8UC1, cv::Scalar(30));
    int k = 0;
    for (int gy = 0; gy < 3; ++gy) {
        for (int gx = 0; gx < 4; ++gx, ++k) {
            const int x0 = 60 + 150 * gx;
            const int y0 = 60 + 140 * gy;
            const std::array<int, 4> r{x0, y0, x0 + 59, y0 + 49};
            s.image(cv::Rect(r[0], r[1], 60, 50)).setTo(cv::Scalar(50 + 15 * k));
            s.rects.push_back(r);
        }
    }
    return s;
}

// Distance from px to the nearest corner of rectangle r (corners between pixels).
double distanceToRectCorner(const Vec2& px, const std::array<int, 4>& r) {
    double best = 1e9;
    for (const double x : {r[0] - 0.5, r[2] + 0.5}) {
        for (const double y : {r[1] - 0.5, r[3] + 0.5}) {
            best = std::min(
                best, std::hypot(static_cast<double>(px.x()) - x, static_cast<double>(px.y()) - y));
        }
    }
    return best;
}

// Index of the rectangle whose corner px is (within 2 px), or -1.
int rectOf(const RectScene& s, const Vec2& px) {
    for (std::size_t i = 0; i < s.rects.size(); ++i) {
        if (distanceToRectCorner(px, s.rects[i]) < 2.0) {
            return static_cast<int>(i);
        }
    }
    return -1;
}

TEST(CornerDetector, FindsEveryRectangleCorner) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    cfg.max_corners = 100;
    std::vector<Vec2> corners;
    detectCorners(s.image, cv::Mat(), cfg, corners);
    ASSERT_EQ(corners.size(), 48U);
    std::vector<int> per_rect(s.rects.size(), 0);
    for (const Vec2& c : corners) {
        const int k = rectOf(s, c);
        ASSERT_GE(k, 0) << c.transpose();
        ++per_rect[static_cast<std::size_t>(k)];
    }
    for (const int n : per_rect) {
        EXPECT_EQ(n, 4);
    }
}

TEST(CornerDetector, HarrisFindsTheSameCorners) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    cfg.max_corners = 100;
    cfg.use_harris = true;
    cfg.quality_level = 1e-5;  // Harris grows with contrast^4: admit the faint rectangles
    std::vector<Vec2> corners;
    detectCorners(s.image, cv::Mat(), cfg, corners);
    ASSERT_EQ(corners.size(), 48U);
    for (const Vec2& c : corners) {
        EXPECT_GE(rectOf(s, c), 0) << c.transpose();
    }
    EXPECT_EQ(rectOf(s, corners.front()), 11);
}

TEST(CornerDetector, StrongestFirst) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    cfg.max_corners = 100;
    std::vector<Vec2> corners;
    detectCorners(s.image, cv::Mat(), cfg, corners);
    ASSERT_EQ(corners.size(), 48U);
    // Corners come in groups of four from the strongest rectangle down.
    for (std::size_t i = 0; i < corners.size(); ++i) {
        EXPECT_EQ(rectOf(s, corners[i]), 11 - static_cast<int>(i / 4)) << i;
    }
    // And the Shi-Tomasi response itself does not increase along the list.
    cv::Mat eig;
    cv::cornerMinEigenVal(s.image, eig, cfg.block_size, 3);
    for (std::size_t i = 1; i < corners.size(); ++i) {
        const auto at = [&](const Vec2& p) {
            return eig.at<float>(static_cast<int>(p.y()), static_cast<int>(p.x()));
        };
        EXPECT_LE(at(corners[i]), at(corners[i - 1]) * 1.0001F) << i;
    }
}

TEST(CornerDetector, HonoursMaxCorners) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    cfg.max_corners = 100;
    std::vector<Vec2> all;
    detectCorners(s.image, cv::Mat(), cfg, all);
    cfg.max_corners = 6;
    std::vector<Vec2> few;
    detectCorners(s.image, cv::Mat(), cfg, few);
    ASSERT_EQ(few.size(), 6U);
    for (std::size_t i = 0; i < few.size(); ++i) {
        EXPECT_EQ(few[i], all[i]) << i;
    }
    cfg.max_corners = 0;
    detectCorners(s.image, cv::Mat(), cfg, few);
    EXPECT_TRUE(few.empty());
}

TEST(CornerDetector, RespectsMask) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    cfg.max_corners = 100;
    cv::Mat mask(s.image.size(), CV_8UC1, cv::Scalar(255));
    mask.colRange(0, 320).setTo(cv::Scalar(0));
    std::vector<Vec2> corners;
    detectCorners(s.image, mask, cfg, corners);
    // Rectangles 2, 3 (x from 360), 6, 7, 10, 11: 6 rectangles, 24 corners.
    ASSERT_EQ(corners.size(), 24U);
    for (const Vec2& c : corners) {
        EXPECT_GE(c.x(), Scalar(320));
    }

    // A free mask around known corners hides exactly those.
    std::vector<Vec2> all;
    detectCorners(s.image, cv::Mat(), cfg, all);
    const std::vector<Vec2> occupied(all.begin(), all.begin() + 8);
    makeFreeMask(s.image.size(), occupied, 10, mask);
    detectCorners(s.image, mask, cfg, corners);
    ASSERT_EQ(corners.size(), 40U);
    for (const Vec2& c : corners) {
        for (const Vec2& o : occupied) {
            EXPECT_GT((c - o).norm(), Scalar(10));
        }
    }
}

// With no border, detectCorners is meant to pick what cv::goodFeaturesToTrack
// picks (minimum-eigenvalue response, 3x3 local maxima, quality threshold,
// minimum distance), in the same order. OpenCV's box filter sums with running
// sums and ours sums each window directly, so responses differ in their last
// bits; on images without exact ties that changes no pick.
TEST(CornerDetector, PicksWhatGoodFeaturesToTrackPicks) {
    struct Case {
        cv::Mat image;
        int block_size;
        int max_corners;
        double min_distance;
        bool masked;
    };
    const cv::Mat fine = test::smoothTexture(cv::Size(640, 480), 1.5, 7);
    const cv::Mat coarse = test::smoothTexture(cv::Size(320, 240), 4.0, 11);
    const cv::Mat odd = test::smoothTexture(cv::Size(97, 61), 1.0, 13);
    const std::vector<Case> cases{
        {fine, 3, 200, 10, false},  {fine, 3, 50, 25, true},   {fine, 5, 300, 5, false},
        {coarse, 3, 100, 8, false}, {coarse, 4, 100, 8, true}, {coarse, 7, 40, 12, false},
        {odd, 3, 1000, 1, false},   {odd, 2, 1000, 2, true},
    };
    int compared = 0;
    for (std::size_t n = 0; n < cases.size(); ++n) {
        const Case& c = cases[n];
        cv::Mat mask;
        if (c.masked) {
            // Holes like the tracker's free mask, and one blocked quadrant.
            const std::vector<Vec2> occupied{Vec2(30, 20), Vec2(50, 40), Vec2(200, 150)};
            makeFreeMask(c.image.size(), occupied, 12, mask);
            mask(cv::Rect(0, 0, c.image.cols / 2, c.image.rows / 2)).setTo(cv::Scalar(0));
        }
        CornerConfig cfg;
        cfg.max_corners = c.max_corners;
        cfg.min_distance_px = static_cast<int>(c.min_distance);
        cfg.block_size = c.block_size;
        cfg.border_px = 0;
        std::vector<Vec2> ours;
        detectCorners(c.image, mask, cfg, ours);
        std::vector<cv::Point2f> theirs;
        cv::goodFeaturesToTrack(c.image, theirs, c.max_corners, cfg.quality_level, c.min_distance,
                                mask.empty() ? cv::noArray() : mask, c.block_size, 3, false);
        ASSERT_EQ(ours.size(), theirs.size()) << "case " << n;
        ASSERT_GT(ours.size(), 10U) << "case " << n;
        for (std::size_t i = 0; i < ours.size(); ++i) {
            EXPECT_EQ(ours[i].x(), Scalar(theirs[i].x)) << "case " << n << " corner " << i;
            EXPECT_EQ(ours[i].y(), Scalar(theirs[i].y)) << "case " << n << " corner " << i;
        }
        compared += static_cast<int>(ours.size());
    }
    EXPECT_GT(compared, 500);
}

TEST(CornerDetector, RespectsBorder) {
    // Checkerboard corners at 7, 27, 47, ... reach close to every border.
    const cv::Mat img = test::checkerboard(cv::Size(207, 167), 20, 7);
    CornerConfig cfg;
    cfg.max_corners = 1000;
    cfg.min_distance_px = 5;
    cfg.border_px = 0;
    std::vector<Vec2> corners;
    detectCorners(img, cv::Mat(), cfg, corners);
    const auto near_border = [&](const Vec2& c, Scalar b) {
        return c.x() < b || c.y() < b || c.x() > Scalar(img.cols - 1) - b ||
               c.y() > Scalar(img.rows - 1) - b;
    };
    const auto n_near = std::count_if(corners.begin(), corners.end(),
                                      [&](const Vec2& c) { return near_border(c, Scalar(12)); });
    EXPECT_GT(n_near, 0);  // without a border, corners do come that close

    cfg.border_px = 12;
    detectCorners(img, cv::Mat(), cfg, corners);
    EXPECT_GT(corners.size(), 20U);
    for (const Vec2& c : corners) {
        EXPECT_FALSE(near_border(c, Scalar(12))) << c.transpose();
    }
}

TEST(CornerDetector, RejectsBadInputs) {
    const RectScene s = rectScene();
    CornerConfig cfg;
    std::vector<Vec2> corners{Vec2(1, 2)};
    cv::Mat color;
    cv::cvtColor(s.image, color, cv::COLOR_GRAY2BGR);
    detectCorners(color, cv::Mat(), cfg, corners);
    EXPECT_TRUE(corners.empty());

    corners.emplace_back(1, 2);
    detectCorners(s.image, cv::Mat(10, 10, CV_8UC1, cv::Scalar(255)), cfg, corners);
    EXPECT_TRUE(corners.empty());
    detectCorners(s.image, cv::Mat(s.image.size(), CV_32FC1, cv::Scalar(1)), cfg, corners);
    EXPECT_TRUE(corners.empty());
    detectCorners(cv::Mat(), cv::Mat(), cfg, corners);
    EXPECT_TRUE(corners.empty());
    // Border larger than the image, odd settings: no crash, no corners / sane corners.
    cfg.border_px = 400;
    detectCorners(s.image, cv::Mat(), cfg, corners);
    EXPECT_TRUE(corners.empty());
    cfg.border_px = std::numeric_limits<int>::max();
    detectCorners(s.image, cv::Mat(), cfg, corners);
    EXPECT_TRUE(corners.empty());
    cfg.border_px = 0;  // a 3x3 image has one interior pixel; no crash
    detectCorners(s.image(cv::Rect(0, 0, 3, 3)), cv::Mat(), cfg, corners);
    EXPECT_LE(corners.size(), 1U);
    cfg = CornerConfig{};
    cfg.quality_level = -1;
    cfg.min_distance_px = -3;
    cfg.block_size = 0;
    detectCorners(s.image, cv::Mat(), cfg, corners);
    EXPECT_GT(corners.size(), 0U);
    EXPECT_LE(corners.size(), static_cast<std::size_t>(cfg.max_corners));
}

TEST(FreeMask, ZeroesAroundPoints) {
    const std::vector<Vec2> pts{Vec2(100, 50), Vec2(Scalar(300.4), Scalar(200.6)), Vec2(-1000, 5),
                                Vec2(std::numeric_limits<Scalar>::quiet_NaN(), 3), Vec2(2, 2)};
    cv::Mat mask;
    makeFreeMask(cv::Size(320, 240), pts, 10, mask);
    ASSERT_EQ(mask.type(), CV_8UC1);
    ASSERT_EQ(mask.size(), cv::Size(320, 240));
    EXPECT_EQ(mask.at<uchar>(50, 100), 0);
    EXPECT_EQ(mask.at<uchar>(50, 109), 0);
    EXPECT_EQ(mask.at<uchar>(57, 107), 0);  // inside the disc (distance 9.9)
    EXPECT_EQ(mask.at<uchar>(50, 112), 255);
    EXPECT_EQ(mask.at<uchar>(59, 109), 255);  // inside the square, outside the disc
    EXPECT_EQ(mask.at<uchar>(201, 300), 0);
    EXPECT_EQ(mask.at<uchar>(201, 312), 255);
    EXPECT_EQ(mask.at<uchar>(0, 0), 0);  // disc clipped at the corner
    EXPECT_EQ(mask.at<uchar>(120, 200), 255);
    // Zeroed pixels: the two full discs and the clipped one, nothing else.
    const int zeros = 320 * 240 - cv::countNonZero(mask);
    EXPECT_GT(zeros, 2 * 300);
    EXPECT_LT(zeros, 2 * 330 + 200);

    makeFreeMask(cv::Size(64, 48), {}, 10, mask);
    EXPECT_EQ(cv::countNonZero(mask), 64 * 48);
    makeFreeMask(cv::Size(0, 48), pts, 10, mask);
    EXPECT_TRUE(mask.empty());
}

}  // namespace
}  // namespace scaled::drivers::vision
