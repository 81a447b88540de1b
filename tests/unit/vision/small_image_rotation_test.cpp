// The rotation check's alignment (small_image_rotation.h) on rendered views of
// the synthetic room: a known rotation between two frames is found from the
// identity, a translation given is taken out, none given is partly taken for
// a rotation, and no previous frame or no one scene means no answer.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/vision/small_image_rotation.h>

namespace scaled::drivers::vision {
namespace {

using core::Mat3;
using core::Scalar;
using core::Vec3;
using AngleAxis = Eigen::AngleAxis<Scalar>;

core::PinholeRadialCamera camera525() {
    return core::PinholeRadialCamera::create({525, 525, 320, 240, 0, 0, 640, 480}).value();
}

const synth::Scene& room() {
    static const synth::Scene scene = synth::Scene::create().value();
    return scene;
}

// A level camera 1.45 m up in the room looking along world +x, then turned by
// R_CinP about its own axes and moved by p_CinP (camera frame of the first).
core::CameraPose poseAfter(const Mat3& R_CinP, const Vec3& p_CinP) {
    Mat3 level;
    level << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    core::CameraPose first;
    first.R_CtoW = level * AngleAxis(Scalar(-0.15), Vec3::UnitX()).toRotationMatrix();
    first.p_CinW = Vec3(Scalar(-0.5), Scalar(0.2), Scalar(1.45));
    core::CameraPose second;
    second.R_CtoW = first.R_CtoW * R_CinP;
    second.p_CinW = first.p_CinW + first.R_CtoW * p_CinP;
    return second;
}

cv::Mat render(const core::CameraPose& pose, double* median_depth = nullptr) {
    synth::RenderOptions options;
    options.noise_sigma = 1.0;
    options.noise_seed = 3;
    synth::Renderer renderer(room(), options);
    cv::Mat gray;
    cv::Mat depth;
    renderer.render(camera525(), pose, gray, &depth, 0);
    if (median_depth != nullptr) {
        std::vector<float> z(depth.begin<float>(), depth.end<float>());
        std::nth_element(z.begin(), z.begin() + static_cast<long>(z.size() / 2), z.end());
        *median_depth = z[z.size() / 2];
    }
    return gray;
}

double angleBetween(const Mat3& a, const Mat3& b) {
    return std::abs(static_cast<double>(AngleAxis(a.transpose() * b).angle()));
}

TEST(SmallImageRotation, FindsAPureRotationFromTheIdentity) {
    // 0.02 rad (10.5 px at f 525): a 0.6 rad/s jolt at 30 Hz, about a tilted axis.
    const Mat3 R_true =
        AngleAxis(Scalar(0.02), Vec3(1, 2, Scalar(0.5)).normalized()).toRotationMatrix();
    const cv::Mat a = render(poseAfter(Mat3::Identity(), Vec3::Zero()));
    const cv::Mat b = render(poseAfter(R_true, Vec3::Zero()));
    SmallImageRotation sir;
    sir.create(640, 480);
    EXPECT_FALSE(sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero())) << "no previous frame";
    const auto r = sir.push(b, camera525(), Mat3::Identity(), Vec3::Zero());
    ASSERT_TRUE(r);
    // A small pixel is 8 px, 0.015 rad: a tenth of one.
    EXPECT_LT(angleBetween(r->R_CinP, R_true), 0.0015);
    EXPECT_GT(r->pixels, 500);
    EXPECT_LT(r->rms, 0.5F);
    // Back the other way, and after reset() nothing to align with.
    const auto back = sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero());
    ASSERT_TRUE(back);
    EXPECT_LT(angleBetween(back->R_CinP, R_true.transpose()), 0.0015);
    sir.reset();
    EXPECT_FALSE(sir.push(b, camera525(), Mat3::Identity(), Vec3::Zero()));
}

TEST(SmallImageRotation, TakesOutTheTranslationItIsGiven) {
    // 2 cm sideways, the walls 1.5-3 m away: without the translation the
    // alignment turns the camera instead (about y).
    const Mat3 R_true = AngleAxis(Scalar(0.01), Vec3::UnitX()).toRotationMatrix();
    const Vec3 p_CinP(Scalar(0.02), 0, 0);
    double depth = 0;
    const cv::Mat a = render(poseAfter(Mat3::Identity(), Vec3::Zero()), &depth);
    const cv::Mat b = render(poseAfter(R_true, p_CinP));
    ASSERT_GT(depth, 1.0);
    SmallImageRotation blind;
    blind.create(640, 480);
    (void)blind.push(a, camera525(), Mat3::Identity(), Vec3::Zero());
    const auto r_blind = blind.push(b, camera525(), Mat3::Identity(), Vec3::Zero());
    SmallImageRotation told;
    told.create(640, 480);
    (void)told.push(a, camera525(), Mat3::Identity(), Vec3::Zero());
    // The translation over the scene's median depth.
    const auto r_told = told.push(b, camera525(), Mat3::Identity(), p_CinP / Scalar(depth));
    ASSERT_TRUE(r_blind && r_told);
    const double err_blind = angleBetween(r_blind->R_CinP, R_true);
    const double err_told = angleBetween(r_told->R_CinP, R_true);
    std::printf(
        "2 cm sideways, median depth %.2f m: rotation error %.4f rad without the "
        "translation, %.4f with it\n",
        depth, err_blind, err_told);
    EXPECT_GT(err_blind, 0.004);  // 2 cm at 2-4 m: 0.005-0.01 rad of false turn
    EXPECT_LT(err_told, 0.5 * err_blind);
}

// Two views of different walls (a quarter turn apart, started from the
// identity) show no one scene under any small rotation: no answer rather than
// whatever the last step reached. A blank frame after a textured one neither.
TEST(SmallImageRotation, ImagesThatDoNotShowOneSceneGiveNoAnswer) {
    const Mat3 quarter = AngleAxis(Scalar(1.5708), Vec3::UnitY()).toRotationMatrix();
    const cv::Mat a = render(poseAfter(Mat3::Identity(), Vec3::Zero()));
    const cv::Mat b = render(poseAfter(quarter, Vec3::Zero()));
    SmallImageRotation sir;
    sir.create(640, 480);
    (void)sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero());
    EXPECT_FALSE(sir.push(b, camera525(), Mat3::Identity(), Vec3::Zero()));
    const cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(0));
    EXPECT_FALSE(sir.push(blank, camera525(), Mat3::Identity(), Vec3::Zero()));
    // And no alignment when it is not asked for (a frame the gyro predicts).
    (void)sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero());
    EXPECT_FALSE(sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero(), false));
    EXPECT_TRUE(sir.push(a, camera525(), Mat3::Identity(), Vec3::Zero()));
}

TEST(SmallImageRotation, ImagesOfAnotherSizeAreTakenToo) {
    const cv::Mat a = render(poseAfter(Mat3::Identity(), Vec3::Zero()));
    cv::Mat small_a;
    cv::Mat small_b;
    a(cv::Rect(0, 0, 320, 240)).copyTo(small_a);
    a(cv::Rect(0, 0, 320, 240)).copyTo(small_b);
    SmallImageRotation sir;
    sir.create(640, 480);
    const auto cam =
        core::PinholeRadialCamera::create({262.5, 262.5, 160, 120, 0, 0, 320, 240}).value();
    EXPECT_FALSE(sir.push(small_a, cam, Mat3::Identity(), Vec3::Zero()));
    const auto r = sir.push(small_b, cam, Mat3::Identity(), Vec3::Zero());
    ASSERT_TRUE(r);
    EXPECT_LT(angleBetween(r->R_CinP, Mat3::Identity()), 1e-4) << "the same image: no rotation";
}

}  // namespace
}  // namespace scaled::drivers::vision
