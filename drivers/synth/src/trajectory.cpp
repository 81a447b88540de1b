#include <cmath>
#include <cstddef>
#include <numbers>
#include <string>

#include <Eigen/Geometry>

#include <scaled/drivers/synth/rng.h>
#include <scaled/drivers/synth/trajectory.h>

namespace scaled::drivers::synth {

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kMaxSpeedScale = 4.0;
constexpr double kMaxShakeRad = 0.1;
constexpr double kShakeMinHz = 2.0;
constexpr double kShakeMaxHz = 8.0;

// Loop shape.
constexpr double kSemiAxisX = 1.2;
constexpr double kSemiAxisY = 0.9;
constexpr double kBulge = 0.05;       // relative third-harmonic radius modulation
constexpr double kOmega = 0.42;       // rad/s around the loop at speed_scale 1
constexpr double kHeight = 1.45;      // m
constexpr double kHeightAmp = 0.08;   // m
constexpr double kHeightOmega = 0.9;  // rad/s
// Orientation.
constexpr double kYawAmp = 0.35;     // rad, sweep around the outward direction
constexpr double kYawOmega = 0.5;    // rad/s
constexpr double kPitch0 = -0.15;    // rad, looking slightly down
constexpr double kPitchAmp = 0.05;   // rad
constexpr double kPitchOmega = 1.3;  // rad/s
constexpr double kRollAmp = 0.04;    // rad
constexpr double kRollOmega = 1.1;   // rad/s

using Vec3d = Eigen::Vector3d;
using Mat3d = Eigen::Matrix3d;

}  // namespace

core::Result<Trajectory> Trajectory::create(const TrajectoryConfig& config) {
    if (!std::isfinite(config.speed_scale) || !(config.speed_scale > 0.0) ||
        config.speed_scale > kMaxSpeedScale) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth trajectory: speed_scale must be in (0, 4]");
    }
    if (!std::isfinite(config.duration_s) || !(config.duration_s > 0.0)) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth trajectory: duration_s must be positive");
    }
    if (!std::isfinite(config.shake_rms_rad) || config.shake_rms_rad < 0.0 ||
        config.shake_rms_rad > kMaxShakeRad) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth trajectory: shake_rms_rad must be in [0, 0.1]");
    }
    if (!config.centre_W.allFinite()) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth trajectory: centre_W must be finite");
    }
    return Trajectory(config);
}

Trajectory::Trajectory(const TrajectoryConfig& config) : config_(config) {
    SplitMix64 rng(combineSeed(config.seed, 0x7472616aULL));
    theta0_ = rng.uniform(0.0, kTwoPi);
    omega_ = kOmega * rng.uniform(0.95, 1.05);
    bulge_phase_ = rng.uniform(0.0, kTwoPi);
    height_phase_ = rng.uniform(0.0, kTwoPi);
    yaw_phase_ = rng.uniform(0.0, kTwoPi);
    pitch_phase_ = rng.uniform(0.0, kTwoPi);
    roll_phase_ = rng.uniform(0.0, kTwoPi);
    // The shake's own stream: the loop above is the same with or without it.
    SplitMix64 shake_rng(combineSeed(config.seed, 0x7368616bULL));
    for (int a = 0; a < 3; ++a) {
        for (int k = 0; k < kShakeTerms; ++k) {
            shake_omega_[a][k] = kTwoPi * shake_rng.uniform(kShakeMinHz, kShakeMaxHz);
            shake_phase_[a][k] = shake_rng.uniform(0.0, kTwoPi);
        }
    }
}

core::CameraPose Trajectory::poseAt(double t_s) const {
    const double t = t_s * config_.speed_scale;
    const double theta = theta0_ + omega_ * t;
    const double radius = 1.0 + kBulge * std::sin(3.0 * theta + bulge_phase_);
    const Vec3d p(static_cast<double>(config_.centre_W.x()) + kSemiAxisX * radius * std::cos(theta),
                  static_cast<double>(config_.centre_W.y()) + kSemiAxisY * radius * std::sin(theta),
                  kHeight + kHeightAmp * std::sin(kHeightOmega * t + height_phase_));

    const double yaw = theta + kYawAmp * std::sin(kYawOmega * t + yaw_phase_);
    const double pitch = kPitch0 + kPitchAmp * std::sin(kPitchOmega * t + pitch_phase_);
    const double roll = kRollAmp * std::sin(kRollOmega * t + roll_phase_);

    // A level camera looking along world +x: columns are the camera axes in the world.
    Mat3d level;
    level << 0, 0, 1,  //
        -1, 0, 0,      //
        0, -1, 0;
    using AngleAxis = Eigen::AngleAxisd;
    const Mat3d R = AngleAxis(yaw, Vec3d::UnitZ()).toRotationMatrix() * level *
                    AngleAxis(pitch, Vec3d::UnitX()).toRotationMatrix() *
                    AngleAxis(roll, Vec3d::UnitZ()).toRotationMatrix();
    Mat3d R_shaken = R;
    if (config_.shake_rms_rad > 0.0) {
        // Per camera axis three equal sinusoids whose sum has the configured
        // RMS (over a long run; two near frequencies beat, and a short one
        // can be off by tens of percent).
        const double amp = config_.shake_rms_rad * std::sqrt(2.0 / double(kShakeTerms));
        Vec3d angle = Vec3d::Zero();
        for (int a = 0; a < 3; ++a) {
            for (int k = 0; k < kShakeTerms; ++k) {
                angle(a) += amp * std::sin(shake_omega_[a][k] * t_s + shake_phase_[a][k]);
            }
        }
        const double norm = angle.norm();
        if (norm > 0.0) {
            R_shaken = R * AngleAxis(norm, angle / norm).toRotationMatrix();
        }
    }
    core::CameraPose pose;
    pose.R_CtoW = R_shaken.cast<core::Scalar>();
    pose.p_CinW = p.cast<core::Scalar>();
    return pose;
}

std::vector<Frame> Trajectory::makeSequence(int n_frames, double fps) const {
    std::vector<Frame> frames;
    if (n_frames <= 0 || !std::isfinite(fps) || !(fps > 0.0)) {
        return frames;
    }
    frames.reserve(static_cast<std::size_t>(n_frames));
    for (int i = 0; i < n_frames; ++i) {
        Frame f;
        f.t_ns = std::llround(static_cast<double>(i) * 1e9 / fps);
        f.pose_CtoW = poseAt(static_cast<double>(f.t_ns) * 1e-9);
        frames.push_back(f);
    }
    return frames;
}

int Trajectory::frameCount(double fps) const {
    if (!std::isfinite(fps) || !(fps > 0.0)) {
        return 0;
    }
    return static_cast<int>(std::lround(config_.duration_s * fps));
}

core::Result<std::vector<Frame>> placeRecordedTrajectory(const std::vector<RecordedPose>& poses,
                                                         const core::Vec3& down_W, const Aabb& room,
                                                         const std::vector<Aabb>& obstacles,
                                                         const core::Vec3& centre_W,
                                                         double height_m, double margin_m) {
    using core::ErrorCode;
    using core::makeError;
    if (poses.empty()) {
        return makeError(ErrorCode::kInvalidArgument, "recorded trajectory: no poses");
    }
    const Vec3d& down = down_W.cast<double>();  // a reference for double, a temporary for float
    if (!down.allFinite() || down.norm() < 1e-6 || !std::isfinite(height_m) ||
        !std::isfinite(margin_m) || margin_m < 0) {
        return makeError(ErrorCode::kInvalidArgument,
                         "recorded trajectory: the down direction, height and margin must be "
                         "finite (down non-zero, margin >= 0)");
    }
    // The smallest rotation taking the recording's down to the room's.
    const Mat3d R_RfromW =
        Eigen::Quaterniond::FromTwoVectors(down.normalized(), Vec3d(0, 0, -1)).toRotationMatrix();
    Vec3d mean = Vec3d::Zero();
    for (std::size_t i = 0; i < poses.size(); ++i) {
        const Vec3d p = poses[i].pose_CtoW.p_CinW.cast<double>();
        const Mat3d R = poses[i].pose_CtoW.R_CtoW.cast<double>();
        if (!p.allFinite() || !R.allFinite() ||
            (R.transpose() * R - Mat3d::Identity()).norm() > 1e-3) {
            return makeError(ErrorCode::kInvalidArgument, "recorded trajectory: pose " +
                                                              std::to_string(i) +
                                                              " is not finite or not a rotation");
        }
        mean += R_RfromW * p;
    }
    mean /= static_cast<double>(poses.size());
    const Vec3d shift = Vec3d(centre_W.x(), centre_W.y(), height_m) - mean;
    const auto margin = static_cast<core::Scalar>(margin_m);
    std::vector<Frame> frames;
    frames.reserve(poses.size());
    for (std::size_t i = 0; i < poses.size(); ++i) {
        Frame f;
        f.t_ns = poses[i].t_ns - poses.front().t_ns;
        const Vec3d p = R_RfromW * poses[i].pose_CtoW.p_CinW.cast<double>() + shift;
        f.pose_CtoW.p_CinW = p.cast<core::Scalar>();
        const Mat3d R = R_RfromW * poses[i].pose_CtoW.R_CtoW.cast<double>();
        f.pose_CtoW.R_CtoW =
            Eigen::Quaterniond(R).normalized().toRotationMatrix().cast<core::Scalar>();
        const auto where = [&](const std::string& what) {
            const core::Vec3& p_W = f.pose_CtoW.p_CinW;
            return makeError(
                ErrorCode::kInvalidArgument,
                "recorded trajectory: the camera of pose " + std::to_string(i) +
                    (poses[i].line > 0 ? " (line " + std::to_string(poses[i].line) + ")" : "") +
                    " lands at (" + std::to_string(static_cast<double>(p_W.x())) + ", " +
                    std::to_string(static_cast<double>(p_W.y())) + ", " +
                    std::to_string(static_cast<double>(p_W.z())) + ") m, " + what);
        };
        if (!room.contains(f.pose_CtoW.p_CinW, margin)) {
            return where("within " + std::to_string(margin_m) +
                         " m of the room's walls, floor or ceiling");
        }
        for (std::size_t k = 0; k < obstacles.size(); ++k) {
            const Aabb grown{obstacles[k].min_m - core::Vec3::Constant(margin),
                             obstacles[k].max_m + core::Vec3::Constant(margin)};
            if (grown.contains(f.pose_CtoW.p_CinW)) {
                return where("within " + std::to_string(margin_m) + " m of box " +
                             std::to_string(k));
            }
        }
        frames.push_back(f);
    }
    return frames;
}

core::Vec3 gravityDirectionW() {
    return {core::Scalar(0), core::Scalar(0), core::Scalar(-1)};
}

core::Scalar pathLength(const std::vector<Frame>& sequence) {
    core::Scalar length = 0;
    for (std::size_t i = 1; i < sequence.size(); ++i) {
        length += (sequence[i].pose_CtoW.p_CinW - sequence[i - 1].pose_CtoW.p_CinW).norm();
    }
    return length;
}

}  // namespace scaled::drivers::synth
