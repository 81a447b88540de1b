#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/trajectory.h>

#include "synth_test_util.h"

namespace scaled::drivers::synth {
namespace {

using test::defaultScene;
using test::emptyScene;
using test::lookAt;
using test::makeCamera;

// A view of the cabinet corner and the far walls from the trajectory's height.
core::CameraPose someView() {
    return lookAt(Vec3(Scalar(0.3), Scalar(-0.2), Scalar(1.45)), Scalar(2.4), Scalar(-0.15),
                  Scalar(0.03));
}

// Normalised cross-correlation of two patches (CV_32F).
double ncc(const cv::Mat& a, const cv::Mat& b) {
    cv::Mat r;
    cv::matchTemplate(a, b, r, cv::TM_CCOEFF_NORMED);
    return static_cast<double>(r.at<float>(0, 0));
}

// The size x size patch centred on px (bilinear) of a CV_32F image.
cv::Mat patchAt(const cv::Mat& image, const Vec2& px, int size = 11) {
    cv::Mat patch;
    cv::getRectSubPix(image, cv::Size(size, size),
                      cv::Point2f(static_cast<float>(px.x()), static_cast<float>(px.y())), patch);
    return patch;
}

TEST(SynthRender, ProducesTheCameraSizeAndIsDeterministic) {
    const auto cam = makeCamera();
    Renderer r1(defaultScene());
    Renderer r2(defaultScene());
    cv::Mat a;
    cv::Mat b;
    r1.render(cam, someView(), a);
    r2.render(cam, someView(), b);
    ASSERT_EQ(a.type(), CV_8UC1);
    ASSERT_EQ(a.cols, 640);
    ASSERT_EQ(a.rows, 480);
    EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
    r1.render(cam, someView(), b);  // cached rays
    EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
    // Another pose gives another image.
    r1.render(cam, lookAt(Vec3(0, 0, Scalar(1.5)), 0), b);
    EXPECT_GT(cv::norm(a, b, cv::NORM_L1) / static_cast<double>(a.total()), 10.0);
}

TEST(SynthRender, HasTextureWithManyCorners) {
    const auto cam = makeCamera();
    Renderer r(defaultScene());
    for (const auto& pose :
         {someView(), lookAt(Vec3(1, Scalar(0.3), Scalar(1.5)), 0),
          lookAt(Vec3(-1, -Scalar(0.5), Scalar(1.4)), -Scalar(1.8), -Scalar(0.2))}) {
        cv::Mat img;
        r.render(cam, pose, img);
        cv::Scalar mean;
        cv::Scalar stddev;
        cv::meanStdDev(img, mean, stddev);
        EXPECT_GT(stddev[0], 30.0);
        std::vector<cv::Point2f> corners;
        cv::goodFeaturesToTrack(img, corners, 2000, 0.01, 8);
        EXPECT_GT(corners.size(), 300U);
        // No big flat areas: most 11x11 windows have texture.
        cv::Mat mu;
        cv::Mat mu2;
        cv::Mat f;
        img.convertTo(f, CV_32F);
        cv::blur(f, mu, cv::Size(11, 11));
        cv::blur(f.mul(f), mu2, cv::Size(11, 11));
        cv::Mat local_var = mu2 - mu.mul(mu);
        const double textured =
            cv::countNonZero(local_var > 25.0) / static_cast<double>(img.total());
        EXPECT_GT(textured, 0.9);
    }
}

TEST(SynthRender, PatchesOfAWallPointMatchAcrossASmallMotion) {
    // Project a grid of points on the x = 3 wall into two poses; the 11x11
    // patches around the two projections must agree, and searching the second
    // image around the projection must find the best match on it: the
    // rendering is geometrically exact and the texture is distinctive.
    for (const Scalar k1 : {Scalar(0), Scalar(-0.2)}) {
        const auto cam = makeCamera(640, 480, 525, k1, k1 == 0 ? Scalar(0) : Scalar(0.04));
        Renderer r(emptyScene());
        const auto pose_a = lookAt(Vec3(Scalar(0.8), Scalar(0.2), Scalar(1.5)), Scalar(0.1));
        auto pose_b = lookAt(Vec3(Scalar(0.85), Scalar(0.25), Scalar(1.47)), Scalar(0.14),
                             Scalar(0.03), Scalar(0.02));
        cv::Mat a;
        cv::Mat b;
        r.render(cam, pose_a, a);
        r.render(cam, pose_b, b);
        a.convertTo(a, CV_32F);
        b.convertTo(b, CV_32F);
        int checked = 0;
        int best_at_projection = 0;
        constexpr int kSearch = 6;
        for (int iy = 0; iy <= 8; ++iy) {
            for (int iz = 0; iz <= 4; ++iz) {
                const Vec3 p_W(3, Scalar(-0.6) + Scalar(0.2) * Scalar(iy),
                               1 + Scalar(0.25) * Scalar(iz));
                const auto pa = cam.project(pose_a.R_CtoW.transpose() * (p_W - pose_a.p_CinW));
                const auto pb = cam.project(pose_b.R_CtoW.transpose() * (p_W - pose_b.p_CinW));
                ASSERT_TRUE(pa && pb);
                const auto inside = [](const Vec2& px) {
                    const Scalar m = 6 + kSearch;
                    return px.x() > m && px.y() > m && px.x() < 639 - m && px.y() < 479 - m;
                };
                if (!inside(*pa) || !inside(*pb)) {
                    continue;
                }
                ++checked;
                const cv::Mat patch_a = patchAt(a, *pa);
                EXPECT_GT(ncc(patch_a, patchAt(b, *pb)), 0.9)
                    << "k1 " << k1 << " point " << p_W.transpose();
                double best = -2;
                Vec2 best_offset = Vec2::Zero();
                for (int dy = -kSearch; dy <= kSearch; ++dy) {
                    for (int dx = -kSearch; dx <= kSearch; ++dx) {
                        const double c = ncc(patch_a, patchAt(b, *pb + Vec2(dx, dy)));
                        if (c > best) {
                            best = c;
                            best_offset = Vec2(dx, dy);
                        }
                    }
                }
                best_at_projection += best_offset.norm() <= 1 ? 1 : 0;
            }
        }
        EXPECT_GT(checked, 30);
        EXPECT_GE(best_at_projection, checked * 95 / 100) << "k1 " << k1;
    }
}

TEST(SynthRender, DepthOutputMatchesDepthAt) {
    const auto cam = makeCamera(320, 240, 262);
    Renderer r(defaultScene());
    cv::Mat img;
    cv::Mat depth;
    r.render(cam, someView(), img, &depth);
    ASSERT_EQ(depth.type(), CV_32FC1);
    ASSERT_EQ(depth.size(), img.size());
    for (int row = 5; row < 240; row += 37) {
        for (int col = 3; col < 320; col += 41) {
            const auto d = defaultScene().depthAt(cam, someView(), Vec2(col, row));
            ASSERT_TRUE(d);
            EXPECT_NEAR(depth.at<float>(row, col), *d, 1e-5 * static_cast<double>(*d));
        }
    }
}

TEST(SynthRender, NoiseHasTheRequestedSigmaAndSeed) {
    const auto cam = makeCamera(320, 240, 262);
    Renderer clean(emptyScene());
    RenderOptions o;
    o.noise_sigma = 3.0;
    o.noise_seed = 7;
    Renderer noisy(emptyScene(), o);
    // A mid-grey-ish view so clipping at 0 and 255 stays rare.
    const auto pose = lookAt(Vec3(0, 0, Scalar(1.5)), Scalar(0.5));
    cv::Mat c;
    cv::Mat n1;
    cv::Mat n1b;
    cv::Mat n2;
    clean.render(cam, pose, c);
    noisy.render(cam, pose, n1, nullptr, 1);
    noisy.render(cam, pose, n1b, nullptr, 1);
    noisy.render(cam, pose, n2, nullptr, 2);
    EXPECT_EQ(cv::norm(n1, n1b, cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(n1, n2, cv::NORM_L1), 0.0);
    cv::Mat diff;
    cv::subtract(n1, c, diff, cv::noArray(), CV_32F);
    cv::Scalar mean;
    cv::Scalar stddev;
    cv::meanStdDev(diff, mean, stddev);
    EXPECT_NEAR(mean[0], 0.0, 0.1);
    EXPECT_NEAR(stddev[0], 3.0, 0.25);
}

TEST(SynthRender, AntialiasingOnlySmoothes) {
    const auto cam = makeCamera(320, 240, 262);
    Renderer aa(defaultScene());
    RenderOptions o;
    o.antialias = false;
    Renderer plain(defaultScene(), o);
    cv::Mat a;
    cv::Mat p;
    aa.render(cam, someView(), a);
    plain.render(cam, someView(), p);
    // Same picture, but supersampling removes some high-frequency energy.
    EXPECT_LT(cv::norm(a, p, cv::NORM_L1) / static_cast<double>(a.total()), 12.0);
    cv::Mat la;
    cv::Mat lp;
    cv::Laplacian(a, la, CV_32F);
    cv::Laplacian(p, lp, CV_32F);
    EXPECT_LT(cv::norm(la), cv::norm(lp));
}

// A rolling shutter: every row is seen from its own pose. Rows given one pose
// are the plain render's, and the first and last rows of an image whose rows
// move are those of the views from the first and the last pose.
TEST(SynthRender, RowsAreSeenFromTheirOwnPoses) {
    const auto cam = makeCamera(160, 120, Scalar(131));
    RenderOptions opts;
    opts.noise_sigma = 0.0;
    Renderer renderer(defaultScene(), opts);
    const core::CameraPose a = someView();
    core::CameraPose b = a;
    b.p_CinW += a.R_CtoW * Vec3(Scalar(0.05), 0, 0);  // 5 cm to the right
    cv::Mat plain_a;
    cv::Mat plain_b;
    renderer.render(cam, a, plain_a);
    renderer.render(cam, b, plain_b);
    ASSERT_GT(cv::norm(plain_a, plain_b, cv::NORM_L1), 0.0);

    std::vector<core::CameraPose> rows(120, a);
    cv::Mat still;
    ASSERT_TRUE(renderer.renderRows(cam, rows, still));
    EXPECT_EQ(cv::norm(still, plain_a, cv::NORM_INF), 0.0);

    for (std::size_t r = 0; r < rows.size(); ++r) {
        const Scalar u = Scalar(r) / Scalar(rows.size() - 1);
        rows[r].p_CinW = a.p_CinW * (1 - u) + b.p_CinW * u;
    }
    cv::Mat sheared;
    ASSERT_TRUE(renderer.renderRows(cam, rows, sheared));
    EXPECT_EQ(cv::norm(sheared.row(0), plain_a.row(0), cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(sheared.row(119), plain_b.row(119), cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(sheared.row(119), plain_a.row(119), cv::NORM_L1), 0.0);

    rows.pop_back();
    EXPECT_FALSE(renderer.renderRows(cam, rows, sheared));
}

TEST(SynthRender, TimePerFrame) {
    // Reports the time per 640x480 frame (no bound: debug and sanitizer builds are slow).
    const auto cam = makeCamera();
    Renderer r(defaultScene());
    const auto traj = Trajectory::create().value();
    cv::Mat img;
    r.render(cam, traj.poseAt(0), img);  // rays
    constexpr int kFrames = 10;
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    for (int i = 0; i < kFrames; ++i) {
        r.render(cam, traj.poseAt(0.1 * i), img);
    }
    const double cpu_ms =
        1e3 * static_cast<double>(std::clock() - c0) / static_cast<double>(CLOCKS_PER_SEC);
    const std::chrono::duration<double, std::milli> dt = std::chrono::steady_clock::now() - t0;
    std::printf("[ synth    ] render 640x480, 2x2 supersampling: %.2f ms/frame (%.2f ms CPU)\n",
                dt.count() / kFrames, cpu_ms / kFrames);
    EXPECT_EQ(img.cols, 640);
}

}  // namespace
}  // namespace scaled::drivers::synth
