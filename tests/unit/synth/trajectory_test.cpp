#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/trajectory.h>

#include "synth_test_util.h"

namespace scaled::drivers::synth {
namespace {

using test::defaultScene;
using test::makeCamera;

// Rotation angle between two rotation matrices, radians.
double angleBetween(const core::Mat3& a, const core::Mat3& b) {
    const Eigen::AngleAxisd aa((a.transpose() * b).cast<double>());
    return std::abs(aa.angle());
}

TEST(SynthTrajectory, RejectsBadConfig) {
    TrajectoryConfig c;
    c.speed_scale = 0;
    EXPECT_FALSE(Trajectory::create(c).ok());
    c.speed_scale = 10;
    EXPECT_FALSE(Trajectory::create(c).ok());
    c = TrajectoryConfig{};
    c.duration_s = -1;
    EXPECT_FALSE(Trajectory::create(c).ok());
    c = TrajectoryConfig{};
    c.duration_s = std::nan("");
    EXPECT_FALSE(Trajectory::create(c).ok());
    c = TrajectoryConfig{};
    c.shake_rms_rad = -0.001;
    EXPECT_FALSE(Trajectory::create(c).ok());
    c.shake_rms_rad = 0.2;
    EXPECT_FALSE(Trajectory::create(c).ok());
    c.shake_rms_rad = std::nan("");
    EXPECT_FALSE(Trajectory::create(c).ok());
}

// The shake turns the camera about its own axes by the configured RMS, at
// 2-8 Hz, and leaves the path and the unshaken attitude alone.
TEST(SynthTrajectory, ShakeTurnsTheCameraByItsRmsAtHandFrequencies) {
    TrajectoryConfig c;
    const auto calm = Trajectory::create(c).value();
    c.shake_rms_rad = 0.004;
    const auto shaken = Trajectory::create(c).value();
    Eigen::Vector3d sum_sq = Eigen::Vector3d::Zero();
    double max_step = 0;  // largest change of the shake between 1 ms samples
    Eigen::Vector3d previous = Eigen::Vector3d::Zero();
    constexpr int kSamples = 60000;  // 60 s at 1 kHz
    for (int i = 0; i < kSamples; ++i) {
        const double t = i * 1e-3;
        const auto a = calm.poseAt(t);
        const auto b = shaken.poseAt(t);
        ASSERT_EQ(a.p_CinW, b.p_CinW);
        const Eigen::AngleAxisd aa((a.R_CtoW.transpose() * b.R_CtoW).cast<double>());
        const Eigen::Vector3d angle = aa.axis() * aa.angle();  // in the camera frame
        sum_sq += angle.cwiseProduct(angle);
        if (i > 0) {
            max_step = std::max(max_step, (angle - previous).norm());
        }
        previous = angle;
    }
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(std::sqrt(sum_sq(a) / kSamples), 0.004, 0.0008) << "axis " << a;
    }
    // At most 8 Hz: three terms of amplitude 0.004 sqrt(2/3) per axis change
    // by at most 3 * 2 pi 8 * 0.0033 rad/s = 0.49 rad/s, 0.5 mrad per ms on
    // one axis (0.86 mrad on three).
    EXPECT_LT(max_step, 0.00086);
    EXPECT_GT(max_step, 0.0001);
    // The shake draws from its own stream: with it off, the seed's loop is
    // the one it always was.
    c.shake_rms_rad = 0;
    EXPECT_EQ(Trajectory::create(c).value().poseAt(2.5).R_CtoW, calm.poseAt(2.5).R_CtoW);
}

TEST(SynthTrajectory, GravityPointsDown) {
    EXPECT_EQ(gravityDirectionW(), Vec3(0, 0, -1));
}

TEST(SynthTrajectory, SequenceTimestampsAndPathLength) {
    const auto traj = Trajectory::create().value();
    EXPECT_EQ(traj.frameCount(), 1800);
    EXPECT_EQ(traj.frameCount(10), 600);
    const auto seq = traj.makeSequence(91, 30);
    ASSERT_EQ(seq.size(), 91U);
    EXPECT_EQ(seq[0].t_ns, 0);
    EXPECT_EQ(seq[1].t_ns, 33333333);
    EXPECT_EQ(seq[90].t_ns, 3000000000);
    for (std::size_t i = 0; i < seq.size(); ++i) {
        const auto p = traj.poseAt(static_cast<double>(seq[i].t_ns) * 1e-9);
        EXPECT_EQ(p.p_CinW, seq[i].pose_CtoW.p_CinW);
    }
    // Path length against a fine numerical integration of the same curve.
    double fine = 0;
    for (int i = 1; i <= 3000; ++i) {
        fine += static_cast<double>(
            (traj.poseAt(i * 1e-3).p_CinW - traj.poseAt((i - 1) * 1e-3).p_CinW).norm());
    }
    EXPECT_NEAR(pathLength(seq), fine, 1e-3 * fine);
    EXPECT_EQ(pathLength({}), 0);
    EXPECT_TRUE(traj.makeSequence(0).empty());
    EXPECT_TRUE(traj.makeSequence(10, 0).empty());
}

TEST(SynthTrajectory, SeedSelectsTheTrajectory) {
    TrajectoryConfig c;
    const auto a = Trajectory::create(c).value();
    const auto b = Trajectory::create(c).value();
    c.seed = 2;
    const auto other = Trajectory::create(c).value();
    EXPECT_EQ(a.poseAt(1.5).p_CinW, b.poseAt(1.5).p_CinW);
    EXPECT_EQ(a.poseAt(1.5).R_CtoW, b.poseAt(1.5).R_CtoW);
    EXPECT_GT((a.poseAt(1.5).p_CinW - other.poseAt(1.5).p_CinW).norm(), 0.05);
}

TEST(SynthTrajectory, SpeedScaleScalesTime) {
    TrajectoryConfig c;
    c.speed_scale = 2;
    const auto fast = Trajectory::create(c).value();
    const auto slow = Trajectory::create().value();
    EXPECT_NEAR((fast.poseAt(1.0).p_CinW - slow.poseAt(2.0).p_CinW).norm(), 0.0, 1e-12);
}

TEST(SynthTrajectory, IsSmoothHandheldAndInsideTheRoom) {
    const Scene& scene = defaultScene();
    for (const std::uint64_t seed : {1U, 2U, 3U}) {
        TrajectoryConfig c;
        c.seed = seed;
        const auto traj = Trajectory::create(c).value();
        const double fps = 30;
        const auto seq = traj.makeSequence(traj.frameCount(fps), fps);
        ASSERT_EQ(seq.size(), 1800U);
        const double dt = 1.0 / fps;
        double speed_sum = 0;
        Vec3 v_prev = Vec3::Zero();
        for (std::size_t i = 0; i < seq.size(); ++i) {
            const auto& pose = seq[i].pose_CtoW;
            // A rotation.
            EXPECT_NEAR((pose.R_CtoW.transpose() * pose.R_CtoW - core::Mat3::Identity()).norm(),
                        0.0, 1e-12);
            EXPECT_NEAR(pose.R_CtoW.determinant(), 1.0, 1e-12);
            // Inside the room and away from the furniture by half a metre.
            EXPECT_TRUE(scene.isFree(pose.p_CinW, Scalar(0.5)))
                << "seed " << seed << " frame " << i << " at " << pose.p_CinW.transpose();
            // Nearly level: the optical axis within 20 degrees of horizontal, small roll
            // (the camera x axis stays nearly horizontal).
            EXPECT_LT(std::abs(pose.R_CtoW(2, 2)), std::sin(20.0 * std::numbers::pi / 180.0));
            EXPECT_LT(std::abs(pose.R_CtoW(2, 0)), std::sin(5.0 * std::numbers::pi / 180.0));
            if (i == 0) {
                continue;
            }
            const auto& prev = seq[i - 1].pose_CtoW;
            const Vec3 v = (pose.p_CinW - prev.p_CinW) / dt;
            const double speed = static_cast<double>(v.norm());
            speed_sum += speed;
            EXPECT_GT(speed, 0.25) << "frame " << i;
            EXPECT_LT(speed, 0.7) << "frame " << i;
            EXPECT_LT(angleBetween(prev.R_CtoW, pose.R_CtoW) / dt, 1.2) << "frame " << i;
            if (i >= 2) {
                EXPECT_LT(static_cast<double>((v - v_prev).norm()) / dt, 1.0)
                    << "acceleration, frame " << i;
            }
            v_prev = v;
        }
        const double mean_speed = speed_sum / static_cast<double>(seq.size() - 1);
        EXPECT_GT(mean_speed, 0.35);
        EXPECT_LT(mean_speed, 0.55);
        // The loop closes: it goes around the room at least once in a minute.
        EXPECT_GT(pathLength(seq), 20.0);
    }
}

TEST(SynthTrajectory, EveryFrameSeesTexturedSurfacesAtUsableDepth) {
    const auto cam = makeCamera(320, 240, Scalar(262.5));
    const auto traj = Trajectory::create().value();
    const auto seq = traj.makeSequence(traj.frameCount(30), 30);
    // Every frame: the centre and the corners of the image see a surface 0.5-6 m away.
    for (std::size_t i = 0; i < seq.size(); ++i) {
        for (const Vec2& px :
             {Vec2(160, 120), Vec2(0, 0), Vec2(319, 0), Vec2(0, 239), Vec2(319, 239)}) {
            const auto d = defaultScene().depthAt(cam, seq[i].pose_CtoW, px);
            ASSERT_TRUE(d) << "frame " << i;
            EXPECT_GT(*d, 0.5) << "frame " << i;
            EXPECT_LT(*d, 6.0) << "frame " << i;
        }
    }
    // Every half second, whole images: depths in range, walls at a few metres, texture.
    RenderOptions fast;
    fast.antialias = false;
    Renderer renderer(defaultScene(), fast);
    cv::Mat img;
    cv::Mat depth;
    for (std::size_t i = 0; i < seq.size(); i += 15) {
        renderer.render(cam, seq[i].pose_CtoW, img, &depth);
        const cv::Mat in_range = (depth >= 0.5) & (depth <= 6.0);
        const double frac = cv::countNonZero(in_range) / static_cast<double>(depth.total());
        EXPECT_GT(frac, 0.99) << "frame " << i;
        // Median depth: looking at walls, not into a corner or down at the floor.
        std::vector<float> d(depth.begin<float>(), depth.end<float>());
        std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
        const float median = d[d.size() / 2];
        EXPECT_GT(median, 1.0f) << "frame " << i;
        EXPECT_LT(median, 4.0f) << "frame " << i;
        std::vector<cv::Point2f> corners;
        cv::goodFeaturesToTrack(img, corners, 500, 0.01, 6);
        EXPECT_GT(corners.size(), 150U) << "frame " << i;
    }
}

// A recording in a tilted world frame is turned upright and centred in the
// room: its down becomes the room's, its mean position the room's axis at the
// given height, its relative motion and times are kept.
TEST(SynthTrajectory, ARecordedTrajectoryIsPlacedUprightInTheRoom) {
    const Eigen::Quaterniond tilt(Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 0).normalized()));
    const Vec3 down_W = (tilt * Eigen::Vector3d(0, 0, -1)).cast<Scalar>();
    std::vector<RecordedPose> poses;
    for (int i = 0; i < 50; ++i) {
        RecordedPose p;
        p.t_ns = 5'000'000'000LL + i * 33'333'333LL;
        // A camera whose y axis (image down) points along the recording's down.
        const Eigen::Matrix3d R_level =
            Eigen::AngleAxisd(0.02 * i, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
            (Eigen::Matrix3d() << 1, 0, 0, 0, 0, 1, 0, -1, 0).finished();
        p.pose_CtoW.R_CtoW = (tilt.toRotationMatrix() * R_level).cast<Scalar>();
        p.pose_CtoW.p_CinW =
            (tilt * Eigen::Vector3d(0.01 * i, 0.005 * i, 0.002 * i) + Eigen::Vector3d(7, -3, 2))
                .cast<Scalar>();
        poses.push_back(p);
    }
    const SceneConfig room;
    const auto placed =
        placeRecordedTrajectory(poses, down_W, room.room, room.furniture, Vec3::Zero(), 1.45, 0.3);
    ASSERT_TRUE(placed.ok()) << placed.error().message;
    ASSERT_EQ(placed->size(), poses.size());
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < poses.size(); ++i) {
        const Frame& f = (*placed)[i];
        EXPECT_EQ(f.t_ns, poses[i].t_ns - poses.front().t_ns);
        // Image down is the room's down.
        const Vec3 y_W = f.pose_CtoW.R_CtoW * Vec3::UnitY();
        EXPECT_NEAR(y_W.z(), -1, 1e-5) << i;
        mean += f.pose_CtoW.p_CinW.cast<double>();
        if (i > 0) {
            const Frame& g = (*placed)[i - 1];
            const double moved = (f.pose_CtoW.p_CinW - g.pose_CtoW.p_CinW).norm();
            const double recorded =
                (poses[i].pose_CtoW.p_CinW - poses[i - 1].pose_CtoW.p_CinW).norm();
            EXPECT_NEAR(moved, recorded, 1e-5) << i;
            EXPECT_NEAR(angleBetween(g.pose_CtoW.R_CtoW, f.pose_CtoW.R_CtoW),
                        angleBetween(poses[i - 1].pose_CtoW.R_CtoW, poses[i].pose_CtoW.R_CtoW),
                        1e-5)
                << i;
        }
    }
    mean /= static_cast<double>(poses.size());
    EXPECT_NEAR(mean.x(), 0, 1e-5);
    EXPECT_NEAR(mean.y(), 0, 1e-5);
    EXPECT_NEAR(mean.z(), 1.45, 1e-5);
}

// A recording that does not fit the room, or is not a trajectory, is refused
// with the pose named.
TEST(SynthTrajectory, ARecordingThatDoesNotFitIsRefused) {
    const SceneConfig room;
    std::vector<RecordedPose> poses(3);
    poses[1].t_ns = 33'333'333;
    poses[2].t_ns = 66'666'667;
    poses[2].pose_CtoW.p_CinW = Vec3(Scalar(8.4), 0, 0);  // 5.6 m either side of the centre
    const auto wide =
        placeRecordedTrajectory(poses, Vec3(0, 0, -1), room.room, {}, Vec3::Zero(), 1.45, 0.3);
    ASSERT_FALSE(wide.ok());
    EXPECT_NE(wide.error().message.find("pose 0"), std::string::npos) << wide.error().message;
    // Pose 2 lands in the table (x 1.9-2.9, y -2.4 to -1.5, up to 0.75 m), the
    // others at (-1.2, 1, 0.5), in the open.
    poses[2].pose_CtoW.p_CinW = Vec3(Scalar(3.6), Scalar(-3), 0);
    const auto table = placeRecordedTrajectory(poses, Vec3(0, 0, -1), room.room, room.furniture,
                                               Vec3::Zero(), 0.5, 0.1);
    ASSERT_FALSE(table.ok());
    EXPECT_NE(table.error().message.find("pose 2"), std::string::npos) << table.error().message;
    EXPECT_TRUE(
        placeRecordedTrajectory(poses, Vec3(0, 0, -1), room.room, {}, Vec3::Zero(), 0.5, 0.1).ok());
    EXPECT_FALSE(
        placeRecordedTrajectory({}, Vec3(0, 0, -1), room.room, {}, Vec3::Zero(), 1.45, 0).ok());
    EXPECT_FALSE(
        placeRecordedTrajectory(poses, Vec3::Zero(), room.room, {}, Vec3::Zero(), 1.45, 0).ok());
    poses[1].pose_CtoW.p_CinW.x() = std::numeric_limits<Scalar>::quiet_NaN();
    const auto nan =
        placeRecordedTrajectory(poses, Vec3(0, 0, -1), room.room, {}, Vec3::Zero(), 1.45, 0);
    ASSERT_FALSE(nan.ok());
    EXPECT_NE(nan.error().message.find("pose 1"), std::string::npos) << nan.error().message;
}

}  // namespace
}  // namespace scaled::drivers::synth
