#include <cmath>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/synth/scene.h>

#include "synth_test_util.h"

namespace scaled::drivers::synth {
namespace {

using test::defaultScene;
using test::emptyScene;
using test::lookAt;
using test::makeCamera;

TEST(SynthScene, RejectsBadConfig) {
    SceneConfig c;
    c.texel_m = 0;
    EXPECT_FALSE(Scene::create(c).ok());
    c = SceneConfig{};
    c.room.max_m.x() = c.room.min_m.x();
    EXPECT_FALSE(Scene::create(c).ok());
    c = SceneConfig{};
    c.furniture.push_back(Aabb{Vec3(2, 2, 0), Vec3(4, 3, 1)});  // pokes through a wall
    const auto r = Scene::create(c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("furniture"), std::string::npos);
    for (const Scalar richness : {Scalar(0), Scalar(-0.1), Scalar(1.5), Scalar(NAN)}) {
        c = SceneConfig{};
        c.texture_richness = richness;
        const auto bad = Scene::create(c);
        ASSERT_FALSE(bad.ok()) << richness;
        EXPECT_NE(bad.error().message.find("texture_richness"), std::string::npos);
    }
}

// A poorer texture: mostly plain, far fewer corners and less contrast, but
// still some marks to track.
TEST(SynthScene, TextureRichnessThinsTheMarks) {
    SceneConfig c;
    c.furniture.clear();
    c.texel_m = Scalar(0.01);
    const Scene rich = Scene::create(c).value();
    c.texture_richness = Scalar(0.1);
    const Scene poor = Scene::create(c).value();
    const auto corners = [](const cv::Mat& t) {
        std::vector<cv::Point2f> pts;
        cv::goodFeaturesToTrack(t, pts, 5000, 0.05, 5);
        return pts.size();
    };
    const cv::Mat& wall_rich = rich.texture(0);
    const cv::Mat& wall_poor = poor.texture(0);
    cv::Scalar mean;
    cv::Scalar sd_rich;
    cv::Scalar sd_poor;
    cv::meanStdDev(wall_rich, mean, sd_rich);
    cv::meanStdDev(wall_poor, mean, sd_poor);
    EXPECT_LT(sd_poor[0], 0.5 * sd_rich[0]);
    EXPECT_LT(corners(wall_poor), corners(wall_rich) / 3);
    EXPECT_GT(corners(wall_poor), 20U);
}

TEST(SynthScene, HasOneTexturedSurfacePerFace) {
    const Scene& s = defaultScene();
    ASSERT_EQ(s.surfaceCount(), 6 + 6 * static_cast<int>(s.furniture().size()));
    EXPECT_GE(s.furniture().size(), 3U);
    for (int i = 0; i < s.surfaceCount(); ++i) {
        const cv::Mat& t = s.texture(i);
        ASSERT_EQ(t.type(), CV_8UC1) << i;
        cv::Scalar mean;
        cv::Scalar stddev;
        cv::meanStdDev(t, mean, stddev);
        EXPECT_GT(stddev[0], 35.0) << "surface " << i;
        EXPECT_GT(mean[0], 60.0) << "surface " << i;
        EXPECT_LT(mean[0], 195.0) << "surface " << i;
    }
    // The floor (6 m x 5 m) at 5 mm per texel.
    EXPECT_NEAR(s.texture(4).cols, 1200, 4);
    EXPECT_NEAR(s.texture(4).rows, 1000, 4);
    EXPECT_TRUE(s.texture(-1).empty());
    EXPECT_TRUE(s.texture(s.surfaceCount()).empty());
}

TEST(SynthScene, TexturesAreDeterministicInTheSeed) {
    SceneConfig c;
    c.furniture.clear();
    c.texel_m = Scalar(0.01);
    const Scene a = Scene::create(c).value();
    const Scene b = Scene::create(c).value();
    c.seed = 2;
    const Scene other = Scene::create(c).value();
    for (int i = 0; i < a.surfaceCount(); ++i) {
        EXPECT_EQ(cv::norm(a.texture(i), b.texture(i), cv::NORM_INF), 0.0) << i;
        EXPECT_GT(cv::norm(a.texture(i), other.texture(i), cv::NORM_L1) /
                      static_cast<double>(a.texture(i).total()),
                  20.0)
            << i;
    }
    // Different faces have different textures (no repetition across walls).
    const cv::Mat w0 = a.texture(0)(cv::Rect(0, 0, 200, 200));
    const cv::Mat w1 = a.texture(1)(cv::Rect(0, 0, 200, 200));
    EXPECT_GT(cv::norm(w0, w1, cv::NORM_L1) / 40000.0, 20.0);
}

TEST(SynthScene, CastRayHitsTheNearestSurface) {
    const Scene& s = defaultScene();
    const Vec3 o(0, 0, Scalar(1.5));
    auto hit = s.castRay(o, Vec3(1, 0, 0));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 1);  // x = max wall
    EXPECT_NEAR(hit->t, 3.0, 1e-12);
    EXPECT_NEAR(hit->p_W.x(), 3.0, 1e-12);
    hit = s.castRay(o, Vec3(0, 0, -2));  // direction need not be unit
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 4);  // floor
    EXPECT_NEAR(hit->t, 0.75, 1e-12);
    hit = s.castRay(o, Vec3(0, -1, 0));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 2);
    EXPECT_NEAR(hit->p_W.y(), -2.5, 1e-12);
    // Towards the crate (box 2: y from 1.85, up to z = 1): its y-min face.
    hit = s.castRay(Vec3(0, 0, Scalar(0.5)), Vec3(0, 1, 0));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 6 + 6 * 2 + 2);
    EXPECT_NEAR(hit->t, 1.85, 1e-12);
    // Over the crate, the wall behind it.
    hit = s.castRay(Vec3(0, 0, Scalar(1.5)), Vec3(0, 1, 0));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 3);
    // The table's top, from above.
    hit = s.castRay(Vec3(Scalar(2.4), Scalar(-2), Scalar(1.5)), Vec3(0, 0, -1));
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->surface, 6 + 5);
    EXPECT_NEAR(hit->p_W.z(), 0.75, 1e-12);
    EXPECT_FALSE(s.castRay(o, Vec3::Zero()));
    const float v = s.intensityAt(*hit);
    EXPECT_GE(v, 0.0f);
    EXPECT_LE(v, 255.0f);
}

TEST(SynthScene, IsFreeKeepsAMargin) {
    const Scene& s = defaultScene();
    EXPECT_TRUE(s.isFree(Vec3(0, 0, Scalar(1.5)), Scalar(0.5)));
    EXPECT_FALSE(s.isFree(Vec3(Scalar(2.8), 0, Scalar(1.5)), Scalar(0.5)));
    EXPECT_TRUE(s.isFree(Vec3(Scalar(2.8), 0, Scalar(1.5)), 0));
    EXPECT_FALSE(s.isFree(Vec3(0, 0, Scalar(3.5)), 0));
    EXPECT_FALSE(s.isFree(Vec3(Scalar(2.4), -2, Scalar(0.5)), 0));            // in the table
    EXPECT_FALSE(s.isFree(Vec3(Scalar(2.4), -2, Scalar(0.9)), Scalar(0.2)));  // just above it
    EXPECT_TRUE(s.isFree(Vec3(Scalar(2.4), -2, Scalar(0.9)), Scalar(0.1)));
}

TEST(SynthScene, DepthAtMatchesTheWallDistance) {
    const Scene& s = emptyScene();
    const auto cam = makeCamera();
    // Facing the x = 3 wall from x = 1: depth 2 m at every pixel.
    const auto pose = lookAt(Vec3(1, Scalar(0.3), Scalar(1.5)), 0);
    for (const Vec2& px : {Vec2(320, 240), Vec2(0, 0), Vec2(639, 479), Vec2(100, 400)}) {
        const auto d = s.depthAt(cam, pose, px);
        ASSERT_TRUE(d) << px.transpose();
        EXPECT_NEAR(*d, 2.0, 1e-9) << px.transpose();
        const auto p = s.pointAt(cam, pose, px);
        ASSERT_TRUE(p);
        EXPECT_NEAR(p->x(), 3.0, 1e-9);
        // The point projects back onto the pixel.
        const auto back = cam.project(pose.R_CtoW.transpose() * (*p - pose.p_CinW));
        ASSERT_TRUE(back);
        EXPECT_NEAR((*back - px).norm(), 0.0, 1e-6);
    }
    // Turned 30 degrees: the optical axis meets the wall 2 / cos 30 away, at depth 2 / cos 30.
    const Scalar yaw = std::numbers::pi_v<Scalar> / 6;
    const auto turned = lookAt(Vec3(1, 0, Scalar(1.5)), yaw);
    const auto d = s.depthAt(cam, turned, Vec2(320, 240));
    ASSERT_TRUE(d);
    EXPECT_NEAR(*d, 2 / std::cos(yaw), 1e-9);
    // Looking down 30 degrees from 1.5 m at the floor, along the axis: 1.5 / sin 30.
    const auto down = lookAt(Vec3(0, 0, Scalar(1.5)), 0, -std::numbers::pi_v<Scalar> / 6);
    const auto df = s.depthAt(cam, down, Vec2(320, 240));
    ASSERT_TRUE(df);
    EXPECT_NEAR(*df, 3.0, 1e-9);
}

TEST(SynthScene, DepthAtHonoursDistortion) {
    const Scene& s = emptyScene();
    const auto cam = makeCamera(640, 480, 525, Scalar(-0.2), Scalar(0.05));
    const auto pose = lookAt(Vec3(Scalar(0.5), 0, Scalar(1.5)), Scalar(0.2), Scalar(0.1));
    for (const Vec2& px : {Vec2(10, 20), Vec2(600, 450), Vec2(320, 240)}) {
        const auto p = s.pointAt(cam, pose, px);
        ASSERT_TRUE(p);
        const Vec3 p_C = pose.R_CtoW.transpose() * (*p - pose.p_CinW);
        const auto back = cam.project(p_C);
        ASSERT_TRUE(back);
        EXPECT_NEAR((*back - px).norm(), 0.0, 1e-6) << px.transpose();
        const auto d = s.depthAt(cam, pose, px);
        ASSERT_TRUE(d);
        EXPECT_NEAR(*d, p_C.z(), 1e-9);
    }
}

}  // namespace
}  // namespace scaled::drivers::synth
