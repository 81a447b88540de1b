#pragma once

// Runs the tracker (EKF MonoSLAM + image front end) over a dataset and
// evaluates the trajectory against ground truth: the library behind slam-run,
// also used by the integration tests.

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/result.h>
#include <scaled/drivers/imu/simulated_gyro.h>
#include <scaled/drivers/source/frame_selection.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::tools {

struct SlamRunOptions {
    drivers::vision::TrackerConfig tracker;
    std::size_t first_frame = 0;
    std::optional<std::size_t> end_frame;       // exclusive
    drivers::source::FrameSelection selection;  // --stride, --blank
    // --gyro-sim: the gyro prior fed from the ground truth (an evaluation of
    // what a gyro would give; drivers/imu/simulated_gyro.h). Without it the
    // dataset's own IMU log feeds the prior when it has a gyroscope.
    std::optional<drivers::imu::SimulatedGyroOptions> gyro_sim;
    int window_frames = 150;  // the sliding-window scale's window (tracked frames)
    // Called after every frame (progress display); may be empty.
    std::function<void(std::size_t done, std::size_t total, const drivers::vision::TrackStats&)>
        progress;
};

struct AttitudeError {
    double max = 0;  // the whole rotation's error, degrees
    double final = 0;
    // The error of the map's vertical in the camera (the one it was given at
    // its start, carried by the filter's rotation), where the dataset gives
    // the true one.
    std::optional<double> tilt_max;
    std::optional<double> tilt_final;
};

struct SlamRunResult {
    std::size_t frames = 0;
    std::size_t tracked_frames = 0;  // frames tracked (healthy, not starting a replacement map)
    int reinitialisations = 0;
    int relocalisations = 0;  // losses the tracker recovered from in the same map
    // of which from a PnP hypothesis verified by a second search around it
    // (tracker.relocalise_verify_px), and the features the tracker added
    // while lost that they removed
    int relocalisations_verified = 0;
    int relocalise_dropped_features = 0;
    int relocalising_frames = 0;    // frames spent looking for the camera in a lost map
    int near_loss_frames = 0;       // near-loss frames (tracker.near_loss_ratio)
    int rotation_check_frames = 0;  // predicted with the small images' rotation
    // Maps the start check began again (TrackerConfig::start_check_s): the
    // same map's frame and unit, new features (not a reinitialisation, not a
    // loss, not a new segment).
    std::size_t start_restarts = 0;
    // tracker.window_ba: its optimisations, their mean points and residual
    // after (px); the trajectory is then the adjusted one (MonoTracker::pose).
    int window_ba_optimisations = 0;
    double window_ba_mean_points = 0;
    double window_ba_mean_rms_px = 0;
    double window_ba_rolling_shutter_s = 0;  // the last optimisation's readout time
    double window_ba_focal_scale = 1;        // its focal length over the camera's
    double window_ba_k1 = 0;                 // its radial distortion
    double mean_features_measured = 0;       // accepted matches per tracked frame
    double mean_features_in_map = 0;
    double ms_per_frame = 0;  // tracker only (image decoding excluded)
    double ms_per_frame_max = 0;
    // Trajectory of the tracked frames of the longest map segment (SLAM frame).
    std::vector<std::int64_t> t_ns;
    std::vector<core::CameraPose> poses;
    std::vector<core::Vec3> gt_positions;  // matching ground truth, when present
    // Ground-truth metrics (when every tracked frame has ground truth).
    bool has_gt = false;
    double path_length_m = 0;
    double ate_rmse_m = 0;
    double scale_to_gt = 0;         // metres per SLAM unit of the Sim(3) alignment
    double scale_drift_thirds = 0;  // first-third scale / last-third scale
    // The Sim(3) scale over every window of window_frames tracked frames and
    // its range max/min: how far the map's scale wanders (issue 19).
    std::optional<core::WindowScales> window_scale;
    // Per camera axis (x right, y down, z forward), the least-squares gain of
    // the tracker's rotation over 30 frames against the ground truth's: 1
    // when it turns as much as the camera did (docs/accuracy.md, issue 18).
    std::optional<Eigen::Vector3d> rotation_gain_30;
    // The filter's rotation since the segment's first frame against the
    // ground truth's: its largest and last error. The vertical the scale
    // estimator measures objects along is carried by this rotation (in the
    // served map too: pose() and the vertical turn together with the window
    // adjustment's world); on a map started in motion it can turn away by
    // tens of degrees (docs/slam.md, "A map started in motion").
    std::optional<AttitudeError> attitude_error_deg;
    // Mean normalised innovation squared of the accepted matches per feature
    // age bin (searches so far: [1, 5), [5, 15), [15, 50), 50+; 2 = consistent)
    // and the matches in each: is a young feature as trustworthy as its S says?
    std::array<double, 4> nis_by_age{};
    std::array<long, 4> nis_by_age_count{};
    std::string gravity_source;   // where the vertical came from
    std::string gyro_source;      // what fed the gyro prior ("none" when nothing did)
    std::size_t gyro_frames = 0;  // frames predicted with the gyro
    core::Vec3 gyro_bias_C = core::Vec3::Zero();  // the tracker's bias estimate at the end
};

core::Result<SlamRunResult> runSlam(drivers::source::FrameSource& source,
                                    const core::PinholeRadialCamera& camera,
                                    const SlamRunOptions& options);

// The sliding-window scale as CSV: `t_s,scale` (the time of each window's
// last frame; an empty scale where the window was degenerate).
core::Status writeWindowScales(const std::filesystem::path& path, const SlamRunResult& r);

// The JSON summary slam-run prints (one object, one line).
std::string toJson(const SlamRunResult& r, const std::string& dataset);

}  // namespace scaled::tools
