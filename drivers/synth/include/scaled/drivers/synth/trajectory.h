#pragma once

// A smooth, known, handheld-like camera trajectory through the default room.
//
// The camera walks a closed loop around the room centre (an ellipse of
// semi-axes 1.2 m x 0.9 m with a gentle third-harmonic bulge, at 1.35-1.55 m
// height) at about 0.37-0.56 m/s, looking outwards at the walls (mostly 1.5-3 m)
// with a slow yaw sweep of +-20 degrees, about 9 degrees of downward pitch and
// small pitch and roll wobble. Every component is a sum of sinusoids, so the
// pose is infinitely differentiable in time. World frame: z up (gravity along
// -z), metres; camera frame: x right, y down, z forward.

#include <cstdint>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/types.h>
#include <scaled/drivers/synth/scene.h>

namespace scaled::drivers::synth {

inline constexpr double kDefaultFps = 30.0;

struct TrajectoryConfig {
    std::uint64_t seed = 1;                    // phases of the loop and the wobble
    double speed_scale = 1.0;                  // time scaling of the whole motion, in (0, 4]
    double duration_s = 60.0;                  // length of the sequence frameCount() describes
    core::Vec3 centre_W = core::Vec3::Zero();  // loop centre (z ignored), the room's by default
    // Hand shake: a rotation about each camera axis of this RMS (radians),
    // the sum of three sinusoids of 2-8 Hz (real time, not scaled by
    // speed_scale) with phases and frequencies from the seed. 0: none, and the
    // trajectory is the one without the option. In [0, 0.1].
    double shake_rms_rad = 0.0;
};

struct Frame {
    std::int64_t t_ns = 0;
    core::CameraPose pose_CtoW;
};

class Trajectory {
public:
    // Validates the configuration (finite, speed_scale in (0, 4], duration_s > 0).
    static core::Result<Trajectory> create(const TrajectoryConfig& config = {});

    [[nodiscard]] const TrajectoryConfig& config() const { return config_; }

    // Ground-truth camera-to-world pose at time t_s (seconds; any real t).
    [[nodiscard]] core::CameraPose poseAt(double t_s) const;

    // n_frames frames at fps, timestamps i / fps from 0 (rounded to ns). Empty
    // when n_frames <= 0 or fps is not positive and finite.
    [[nodiscard]] std::vector<Frame> makeSequence(int n_frames, double fps = kDefaultFps) const;

    // Frames in the configured duration at fps: round(duration_s * fps).
    [[nodiscard]] int frameCount(double fps = kDefaultFps) const;

private:
    explicit Trajectory(const TrajectoryConfig& config);

    TrajectoryConfig config_;
    // Random phases and rates drawn from the seed.
    double theta0_ = 0;
    double omega_ = 0;
    double bulge_phase_ = 0;
    double height_phase_ = 0;
    double yaw_phase_ = 0;
    double pitch_phase_ = 0;
    double roll_phase_ = 0;
    // Shake: per camera axis, three (frequency rad/s, phase) pairs.
    static constexpr int kShakeTerms = 3;
    double shake_omega_[3][kShakeTerms] = {};
    double shake_phase_[3][kShakeTerms] = {};
};

// A recorded trajectory (a dataset's ground truth: camera-to-world poses in a
// world frame whose "down" is down_W) put into the room: turned by the
// smallest rotation that takes down_W to (0, 0, -1), shifted so that the
// mean camera position lies on the room's vertical axis through centre_W at
// height_m, timestamps made relative to the first. The same motion, so a
// tracker can meet it with exact ground truth and an exact camera. Fails
// (kInvalidArgument, naming the frame) on an empty list, a non-finite pose or
// down_W, or a camera that comes within margin_m of the room's walls, floor
// or ceiling, or inside a box of `obstacles` grown by margin_m (naming the
// pose, its line when known, where it lands and what it meets).
struct RecordedPose {
    std::int64_t t_ns = 0;
    core::CameraPose pose_CtoW;
    int line = 0;  // where it was read, for messages (0: not from a file)
};
core::Result<std::vector<Frame>> placeRecordedTrajectory(const std::vector<RecordedPose>& poses,
                                                         const core::Vec3& down_W, const Aabb& room,
                                                         const std::vector<Aabb>& obstacles,
                                                         const core::Vec3& centre_W,
                                                         double height_m, double margin_m);

// Unit gravity ("down") direction in the world frame: (0, 0, -1).
core::Vec3 gravityDirectionW();

// Sum of the distances between consecutive camera centres, metres.
core::Scalar pathLength(const std::vector<Frame>& sequence);

}  // namespace scaled::drivers::synth
