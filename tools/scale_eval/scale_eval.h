#pragma once

// scale-eval's library: runs the tracker, the detector and the scale estimator
// over a recorded sequence, synchronously and deterministically (the detector
// runs on every Nth tracked frame and its boxes update the estimator against
// the filter of that same frame), and measures the scale estimate against the
// ground truth. The metrics (convergence rule, error statistics, distance
// errors) are separate functions so that tests can check them on series with
// known answers.

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/imu/simulated_gyro.h>
#include <scaled/drivers/source/frame_selection.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::tools {

struct EvalOptions {
    daemon::PipelineConfig config;
    std::size_t first_frame = 0;
    std::optional<std::size_t> end_frame;       // exclusive
    drivers::source::FrameSelection selection;  // --stride, --blank
    // --gyro-sim: the gyro prior fed by a gyro simulated from the ground truth
    // (drivers/imu/gyro_feed.h); else the dataset's IMU log when it has a gyro.
    std::optional<drivers::imu::SimulatedGyroOptions> gyro_sim;
    // Ground-truth scale over a sliding window of this many tracked frames.
    int window_frames = 150;
    // The constant-scale baseline is fitted on this much ground truth at the
    // start of the map (the paper's marker-initialised d).
    double baseline_seconds = 1.0;
    // The ground-truth scale is reported once the ground-truth camera path of
    // the frames it is fitted on is at least this long (shorter paths give a
    // Umeyama scale dominated by noise).
    double min_truth_path_m = 0.10;
    // Distance errors between camera positions k and k + distance_delta_frames
    // whose ground-truth distance is at least min_distance_m.
    int distance_delta_frames = 30;
    double min_distance_m = 0.05;
    // Give the estimator the ground-truth camera poses and gravity (metric:
    // the true scale is then 1) instead of the tracker's: what the evidence
    // can do when the map is right. Frames without ground truth give no update.
    bool truth_geometry = false;
    // --depth-unit: on every tracked frame with a depth image, the map's
    // metres per unit by that image (FrameRow::map_unit_depth).
    bool depth_unit = false;
    // The served estimate's accuracy is taken over the updates at least this
    // long after their map started.
    double settle_seconds = 5.0;
    // Keep every update's posterior and every observation's likelihood,
    // decimated to at most curve_bins grid points (for figures).
    bool keep_curves = false;
    int curve_bins = 256;
    // Called after every frame; may be empty.
    std::function<void(std::size_t done, std::size_t total, const core::ScaleSummary& summary)>
        progress;
};

struct FrameRow {
    std::int64_t frame = 0;
    double t_s = 0;
    bool tracked = false;
    int epoch = 0;
    int features_measured = 0;
    core::ScaleSummary scale;                 // the estimate after this frame
    std::optional<double> scale_true;         // cumulative Sim(3) scale of this epoch so far
    std::optional<double> scale_true_window;  // the same over the last window_frames
    bool window_full = false;                 // the epoch has window_frames tracked frames
    // The camera's position in the map (SLAM units) and the ground truth's
    // (metres), when the frame was tracked and has ground truth.
    bool has_position = false;
    core::Vec3 p_map = core::Vec3::Zero();
    core::Vec3 p_gt = core::Vec3::Zero();
    std::optional<double> baseline_constant;  // this epoch's constant-scale baseline
    std::optional<double> baseline_single;    // this epoch's single-early-detection scale
    // --depth-unit: the median over the features measured in this frame of
    // their depth in the depth image over their depth in the map (the one
    // scale_true is for): metres per unit of the map's geometry, against
    // scale_true's of its motion.
    std::optional<double> map_unit_depth;
};

struct UpdateRow {
    int update = 0;
    std::size_t row = 0;  // index of the frame's FrameRow
    std::int64_t frame = 0;
    double t_s = 0;
    double t_in_map_s = 0;  // since this epoch's map started
    int epoch = 0;
    int detections = 0;
    int observations = 0;
    int objects_used = 0;          // model object: objects in the posterior
    int views_used = 0;            // and their views
    double information_limit = 0;  // 95% relative width the evidence allows at best (0: unknown)
    core::ScaleSummary scale;
    std::optional<double> scale_true;
    std::optional<double> scale_true_window;
};

struct ObservationRow {
    int update = 0;
    std::int64_t frame = 0;
    std::string class_name;
    double score = 0;
    double D = 0;
    double sigma_D = 0;  // the likelihood's sigma in SLAM units (the variance model in use)
    double local_estimate = 0;
    double weight = 1;
    int object_id = 0;  // model object
    double kappa = 0;
};

// One object's state after an update (model object), for objects.csv.
struct ObjectRow {
    int update = 0;
    std::int64_t frame = 0;
    int id = 0;
    std::string class_name;
    std::string state;
    int detections = 0;
    int views_used = 0;
    double local_estimate = 0;  // 0: none
    double height_m = 0;
    double height_lo_m = 0;
    double height_hi_m = 0;
    core::Vec3 anchor = core::Vec3::Zero();
    double anchor_rel_sigma = 0;
};

// How an estimate compares with the truth over a run.
struct ErrorStats {
    int count = 0;
    std::optional<double> median;
    std::optional<double> std;
    std::optional<double> max;
};

struct DistanceErrors {
    int pairs = 0;
    std::optional<double> median_abs_m;
    std::optional<double> median_rel;
    std::optional<double> p90_rel;
};

// What a user of the served pose gets (issue 20): the trajectory scaled by
// the estimate served at each frame (no scale fitted to the ground truth),
// aligned to the ground truth by a rotation and translation per epoch only.
// A frame counts when the daemon's POSE would be in metres: a scale not too
// loose for it (daemon::wideForPoses, estimator.pose_max_rel_width95).
struct MetricTrajectory {
    int frames = 0;  // tracked, with ground truth and a served estimate
    std::optional<double> ate_m;
    std::optional<double> ate_percent_of_path;
    DistanceErrors distance_1s;  // |served displacement| vs the truth's, frames 1 s apart
    DistanceErrors distance_5s;
};
MetricTrajectory metricTrajectory(std::span<const FrameRow> rows, double min_distance_m,
                                  const daemon::PipelineConfig& config);

struct DepthCheck {
    int features = 0;
    std::optional<double> median_rel;
    std::optional<double> median_abs_m;
    std::string note;
};

struct EvalResult {
    std::string dataset;
    std::size_t frames = 0;
    std::size_t tracked_frames = 0;
    std::size_t tracking_lost_frames = 0;
    int epochs = 1;
    int relocalisations = 0;  // losses the tracker recovered from in the same map (epoch)
    int start_restarts = 0;   // young maps the start check began again (same epoch)
    std::size_t unreadable_frames = 0;
    bool has_ground_truth = false;
    std::string gravity_source;
    std::string gyro_source;      // what fed the gyro prior ("none" when nothing did)
    std::size_t gyro_frames = 0;  // frames predicted with the gyro

    std::vector<FrameRow> frame_rows;
    std::vector<UpdateRow> updates;
    std::vector<ObservationRow> observations;
    std::vector<ObjectRow> objects;

    // Curves for the figures (keep_curves): grid values of d, one normalised
    // log posterior per update, one normalised log likelihood per observation.
    std::vector<double> curve_d;
    std::vector<std::vector<float>> posterior_curves;
    std::vector<std::vector<float>> likelihood_curves;

    std::optional<std::size_t> converged_update;  // index into updates
    std::optional<double> baseline_constant_scale;
    std::optional<double> baseline_single_scale;
    DistanceErrors distance;
    MetricTrajectory metric;
    DepthCheck depth;

    double ms_per_frame = 0;  // tracker + detector + estimator, image decoding excluded
    double tracker_ms_per_frame = 0;
    double detector_ms_per_update = 0;
    double estimator_ms_per_update = 0;
};

core::Result<EvalResult> evaluate(drivers::source::FrameSource& source,
                                  drivers::detector::ObjectDetector& detector,
                                  const core::PriorTable& priors, const EvalOptions& options);

// ---- metrics -------------------------------------------------------------

// The convergence rule: the first update after which every later update of the
// run (itself included) has a 95% interval narrower than rel_width of its MAP.
// nullopt when the last update is not that narrow (or there are none).
std::optional<std::size_t> convergedAt(std::span<const UpdateRow> updates, double rel_width);

// The calibration and served-accuracy figures of a run (docs/accuracy.md).
struct Calibration {
    int updates = 0;                      // with ground truth and at least one observation
    std::optional<double> ci95_coverage;  // share of them whose 95% interval holds the truth
    int wrong_converged_updates = 0;      // converged, and the 95% interval excludes the truth
    ErrorStats after_settle;         // |MAP/truth - 1| over the updates settle_s after map start
    ErrorStats after_settle_window;  // the same against the sliding-window truth
};
Calibration calibration(std::span<const UpdateRow> updates, double settle_s);

// How far the map's own scale wanders (issue 19), from the frames' truths.
struct MapScaleDrift {
    // max/min of scale_true_window over the frames whose window is full, the
    // largest of that over the epochs (a new map has a new scale).
    std::optional<double> window_range;
    // max over the updates of |scale_true_window / scale_true - 1|: the map's
    // recent scale against its average so far.
    std::optional<double> window_max_dev;
};
MapScaleDrift mapScaleDrift(std::span<const FrameRow> frames, std::span<const UpdateRow> updates);

// --depth-unit: the map's geometry against its motion. Over each frame whose
// truth window is full, the median of map_unit_depth over the same window of
// frames (its epoch's) is the geometry's metres per unit there, and
// scale_true_window the motion's.
struct GeometryUnit {
    int frames = 0;  // frames with a map_unit_depth
    std::optional<double> median;
    // max/min over the frames of the geometry's window unit, and of the
    // motion's over the geometry's (the largest over the epochs).
    std::optional<double> window_range;
    std::optional<double> motion_over_geometry_range;
};
GeometryUnit geometryUnit(std::span<const FrameRow> frames, int window_frames);

// |estimate / truth - 1| of every update from `first` on that has a truth.
ErrorStats relativeErrors(std::span<const UpdateRow> updates, std::size_t first, bool window);

// Median and standard deviation (population) of a sample; empty: nullopt.
ErrorStats describe(std::vector<double> values);

// The scale of the Sim(3) alignment of est to gt, when the ground-truth path
// is at least min_path_m long (and the alignment is defined).
std::optional<double> truthScale(std::span<const core::Vec3> est, std::span<const core::Vec3> gt,
                                 double min_path_m);

// JSON summary (one object, one line) and the CSV files scale_eval_plot.py
// reads (frames, updates, observations, posterior, likelihoods, summary.json).
std::string toJson(const EvalResult& r, const EvalOptions& options);
core::Status writeOutputs(const EvalResult& r, const EvalOptions& options,
                          const std::string& out_dir);

}  // namespace scaled::tools
