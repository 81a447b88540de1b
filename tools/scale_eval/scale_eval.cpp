#include "scale_eval.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/scale/likelihood.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/slam_snapshot.h>
#include <scaled/daemon/frame_step.h>
#include <scaled/drivers/dataset/depth_image.h>
#include <scaled/drivers/imu/gyro_feed.h>
#include <scaled/drivers/imu/map_gravity.h>
#include <scaled/drivers/vision/mono_tracker.h>

#include "stats.h"

namespace scaled::tools {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Scalar;
using core::Vec3;

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Per-frame trajectory of one epoch (map): SLAM and ground-truth camera
// centres of its tracked frames, with ground truth.
struct Track {
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    std::vector<double> t_s;
};

// Decimated copy of a grid function, for the figures.
std::vector<float> decimate(std::span<const Scalar> values, std::size_t step) {
    std::vector<float> out;
    out.reserve(values.size() / step + 1);
    for (std::size_t j = 0; j < values.size(); j += step) {
        out.push_back(static_cast<float>(values[j]));
    }
    return out;
}

// Each measured feature of a snapshot in front of the camera whose pixel has
// a depth reading: visit(its camera-frame depth in the snapshot's map, the
// depth image's metres there).
template <typename Visit>
void forEachMeasuredDepth(const core::slam::SlamSnapshot& snapshot, const cv::Mat& depth_m,
                          Visit visit) {
    const core::CameraPose& pose = snapshot.pose();
    const auto features = snapshot.features();
    const auto info = snapshot.featureInfo();
    for (std::size_t i = 0; i < features.size(); ++i) {
        if (!info[i].in_view || !info[i].measured) {
            continue;
        }
        const Vec3 p_C = pose.R_CtoW.transpose() * (features[i].p_FinW - pose.p_CinW);
        const int u = static_cast<int>(std::lround(info[i].px.x()));
        const int v = static_cast<int>(std::lround(info[i].px.y()));
        if (p_C.z() <= 0 || u < 0 || v < 0 || u >= depth_m.cols || v >= depth_m.rows) {
            continue;
        }
        const double truth = static_cast<double>(depth_m.at<float>(v, u));
        if (!(truth > 0.1) || !std::isfinite(truth)) {
            continue;
        }
        visit(static_cast<double>(p_C.z()), truth);
    }
}

// Relative errors between the MAP times the camera-frame depth of each
// measured feature of the detection snapshot (in the estimator's map) and the
// depth image at its pixel.
void depthErrors(const core::slam::SlamSnapshot& snapshot, const cv::Mat& depth_m, double scale,
                 std::vector<double>& rel, std::vector<double>& abs_m) {
    forEachMeasuredDepth(snapshot, depth_m, [&](double z_map, double truth) {
        const double est = scale * z_map;
        rel.push_back(std::abs(est / truth - 1));
        abs_m.push_back(std::abs(est - truth));
    });
}

}  // namespace

ErrorStats describe(std::vector<double> values) {
    ErrorStats s;
    s.count = static_cast<int>(values.size());
    if (values.empty()) {
        return s;
    }
    const double mean =
        std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(values.size());
    double var = 0;
    for (const double v : values) {
        var += (v - mean) * (v - mean);
    }
    s.std = std::sqrt(var / static_cast<double>(values.size()));
    s.max = *std::max_element(values.begin(), values.end());
    s.median = median(std::move(values));
    return s;
}

std::optional<std::size_t> convergedAt(std::span<const UpdateRow> updates, double rel_width) {
    std::optional<std::size_t> first;
    for (std::size_t i = updates.size(); i-- > 0;) {
        const auto& s = updates[i].scale;
        const bool narrow = s.state != core::ScaleState::kNoData &&
                            std::isfinite(static_cast<double>(s.rel_width95)) &&
                            static_cast<double>(s.rel_width95) < rel_width;
        if (!narrow) {
            break;
        }
        first = i;
    }
    return first;
}

Calibration calibration(std::span<const UpdateRow> updates, double settle_s) {
    Calibration c;
    int covered = 0;
    std::vector<double> e;
    std::vector<double> ew;
    for (const UpdateRow& u : updates) {
        if (!u.scale_true || u.scale.state == core::ScaleState::kNoData ||
            u.scale.observations == 0) {
            continue;
        }
        const double truth = *u.scale_true;
        const bool inside = static_cast<double>(u.scale.ci95.lo) <= truth &&
                            truth <= static_cast<double>(u.scale.ci95.hi);
        ++c.updates;
        covered += inside ? 1 : 0;
        if (u.scale.state == core::ScaleState::kConverged && !inside) {
            ++c.wrong_converged_updates;
        }
        if (u.t_in_map_s >= settle_s) {
            e.push_back(std::abs(static_cast<double>(u.scale.map) / truth - 1));
            if (u.scale_true_window) {
                ew.push_back(std::abs(static_cast<double>(u.scale.map) / *u.scale_true_window - 1));
            }
        }
    }
    if (c.updates > 0) {
        c.ci95_coverage = static_cast<double>(covered) / c.updates;
    }
    c.after_settle = describe(std::move(e));
    c.after_settle_window = describe(std::move(ew));
    return c;
}

namespace {

// The summary of paired displacement errors (absolute, metres; relative).
DistanceErrors summariseDistances(const std::vector<double>& abs_m,
                                  const std::vector<double>& rel) {
    DistanceErrors d;
    d.pairs = static_cast<int>(rel.size());
    if (!rel.empty()) {
        d.median_abs_m = median(abs_m);
        d.median_rel = median(rel);
        d.p90_rel = quantile(rel, 0.9);
    }
    return d;
}

}  // namespace

MetricTrajectory metricTrajectory(std::span<const FrameRow> rows, double min_distance_m,
                                  const daemon::PipelineConfig& config) {
    MetricTrajectory m;
    // As the daemon's POSE: a scale, and not too loose to put poses in metres.
    const auto served = [&config](const FrameRow& f) {
        return f.has_position && f.scale.state != core::ScaleState::kNoData &&
               !daemon::wideForPoses(config, static_cast<double>(f.scale.map),
                                     static_cast<double>(f.scale.ci95.lo),
                                     static_cast<double>(f.scale.ci95.hi));
    };
    const auto metric = [](const FrameRow& f) -> Vec3 { return f.scale.map * f.p_map; };
    double sq = 0;
    double path = 0;
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    const auto closeEpoch = [&] {
        if (est.size() >= 3) {
            if (auto a = core::alignTrajectories(est, gt, false)) {
                const double e = static_cast<double>(a->ate_rmse);
                sq += e * e * static_cast<double>(est.size());
                path += static_cast<double>(core::pathLength(gt));
                m.frames += static_cast<int>(est.size());
            }
        }
        est.clear();
        gt.clear();
    };
    std::optional<int> epoch;
    for (const FrameRow& f : rows) {
        if (!served(f)) {
            continue;
        }
        if (epoch && *epoch != f.epoch) {
            closeEpoch();
        }
        epoch = f.epoch;
        est.push_back(metric(f));
        gt.push_back(f.p_gt);
    }
    closeEpoch();
    if (m.frames > 0) {
        m.ate_m = std::sqrt(sq / m.frames);
        if (path > 0) {
            m.ate_percent_of_path = 100 * *m.ate_m / path;
        }
    }
    // Displacements between a served frame and the first served frame of the
    // same epoch at least dt later, against the truth's.
    const auto distances = [&](double dt_s) {
        std::vector<double> abs_m;
        std::vector<double> rel;
        std::size_t j = 0;
        for (std::size_t i = 0; i < rows.size(); ++i) {
            if (!served(rows[i])) {
                continue;
            }
            j = std::max(j, i + 1);
            while (j < rows.size() &&
                   (rows[j].epoch == rows[i].epoch && rows[j].t_s - rows[i].t_s < dt_s)) {
                ++j;
            }
            if (j >= rows.size() || rows[j].epoch != rows[i].epoch || !served(rows[j])) {
                continue;
            }
            const double gt_dist = static_cast<double>((rows[j].p_gt - rows[i].p_gt).norm());
            if (gt_dist < min_distance_m) {
                continue;
            }
            const double est_dist = static_cast<double>((metric(rows[j]) - metric(rows[i])).norm());
            abs_m.push_back(std::abs(est_dist - gt_dist));
            rel.push_back(std::abs(est_dist / gt_dist - 1));
        }
        return summariseDistances(abs_m, rel);
    };
    m.distance_1s = distances(1.0);
    m.distance_5s = distances(5.0);
    return m;
}

namespace {

// max / min of positive values within an epoch; close() folds it into the
// largest over the epochs so far and starts the next.
struct EpochRange {
    double lo = 0;
    double hi = 0;
    void add(double v) {
        lo = lo > 0 ? std::min(lo, v) : v;
        hi = std::max(hi, v);
    }
    void close(std::optional<double>& largest) {
        if (lo > 0) {
            largest = std::max(largest.value_or(1.0), hi / lo);
        }
        *this = {};
    }
};

}  // namespace

MapScaleDrift mapScaleDrift(std::span<const FrameRow> frames, std::span<const UpdateRow> updates) {
    MapScaleDrift d;
    std::optional<int> epoch;
    EpochRange range;
    for (const FrameRow& f : frames) {
        if (!f.window_full || !f.scale_true_window || !(*f.scale_true_window > 0)) {
            continue;
        }
        if (epoch && *epoch != f.epoch) {
            range.close(d.window_range);
        }
        epoch = f.epoch;
        range.add(*f.scale_true_window);
    }
    range.close(d.window_range);
    for (const UpdateRow& u : updates) {
        if (u.scale_true && u.scale_true_window && *u.scale_true > 0) {
            const double dev = std::abs(*u.scale_true_window / *u.scale_true - 1);
            d.window_max_dev = std::max(d.window_max_dev.value_or(0.0), dev);
        }
    }
    return d;
}

GeometryUnit geometryUnit(std::span<const FrameRow> frames, int window_frames) {
    GeometryUnit g;
    std::vector<double> all;
    std::vector<double> w;
    EpochRange geometry;
    EpochRange motion;
    std::optional<int> epoch;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const FrameRow& f = frames[i];
        if (f.map_unit_depth) {
            all.push_back(*f.map_unit_depth);
        }
        if (epoch && *epoch != f.epoch) {
            geometry.close(g.window_range);
            motion.close(g.motion_over_geometry_range);
        }
        epoch = f.epoch;
        if (!f.window_full || !f.scale_true_window) {
            continue;
        }
        w.clear();
        for (std::size_t k = i + 1; k-- > 0 && i - k < static_cast<std::size_t>(window_frames);) {
            if (frames[k].epoch != f.epoch) {
                break;
            }
            if (frames[k].map_unit_depth) {
                w.push_back(*frames[k].map_unit_depth);
            }
        }
        if (w.size() * 2 < static_cast<std::size_t>(window_frames)) {
            continue;  // fewer than half the window's frames have one
        }
        const double unit = median(w);
        geometry.add(unit);
        motion.add(*f.scale_true_window / unit);
    }
    geometry.close(g.window_range);
    motion.close(g.motion_over_geometry_range);
    g.frames = static_cast<int>(all.size());
    if (!all.empty()) {
        g.median = median(all);
    }
    return g;
}

ErrorStats relativeErrors(std::span<const UpdateRow> updates, std::size_t first, bool window) {
    std::vector<double> e;
    for (std::size_t i = first; i < updates.size(); ++i) {
        const auto& truth = window ? updates[i].scale_true_window : updates[i].scale_true;
        if (truth && updates[i].scale.state != core::ScaleState::kNoData) {
            e.push_back(std::abs(static_cast<double>(updates[i].scale.map) / *truth - 1));
        }
    }
    return describe(std::move(e));
}

std::optional<double> truthScale(std::span<const Vec3> est, std::span<const Vec3> gt,
                                 double min_path_m) {
    if (est.size() < 3 || est.size() != gt.size() ||
        static_cast<double>(core::pathLength(gt)) < min_path_m) {
        return std::nullopt;
    }
    auto a = core::alignTrajectories(est, gt, true);
    if (!a || !(a->scale > 0) || !std::isfinite(static_cast<double>(a->scale))) {
        return std::nullopt;
    }
    return static_cast<double>(a->scale);
}

namespace {

// Distance errors between camera positions delta frames apart, both after
// the converged update and in its epoch, with the estimate current at the
// later one.
DistanceErrors distanceErrorsAfter(const EvalResult& r, std::size_t converged_update,
                                   const EvalOptions& options) {
    const std::int64_t from_frame = r.updates[converged_update].frame;
    const int epoch = r.updates[converged_update].epoch;
    std::vector<double> abs_m;
    std::vector<double> rel;
    const auto delta = static_cast<std::size_t>(options.distance_delta_frames);
    for (std::size_t j = delta; j < r.frame_rows.size(); ++j) {
        const auto& a = r.frame_rows[j - delta];
        const auto& b = r.frame_rows[j];
        if (!a.has_position || !b.has_position || a.frame < from_frame || a.epoch != epoch ||
            b.epoch != epoch || b.scale.state == core::ScaleState::kNoData) {
            continue;
        }
        const double gt_dist = (b.p_gt - a.p_gt).norm();
        if (gt_dist < options.min_distance_m) {
            continue;
        }
        const double est_dist =
            static_cast<double>(b.scale.map) * static_cast<double>((b.p_map - a.p_map).norm());
        abs_m.push_back(std::abs(est_dist - gt_dist));
        rel.push_back(std::abs(est_dist / gt_dist - 1));
    }
    return summariseDistances(abs_m, rel);
}

// One scale-eval run over a dataset: the daemon's frame step (frame_step.h)
// and, on the frames it hands to the detector, the detector and the
// estimator run synchronously; ground truth and the rows of the report
// around them.
class EvalRun {
public:
    EvalRun(drivers::source::FrameSource& source, drivers::detector::ObjectDetector& detector,
            const core::PriorTable& priors, const EvalOptions& options,
            drivers::vision::MonoTracker& tracker, core::ScaleEstimator& estimator,
            const drivers::imu::MapGravitySelector& gravity, drivers::imu::GyroFeed& gyro_feed)
        : source_(source),
          detector_(detector),
          priors_(priors),
          options_(options),
          config_(options.config),
          tracker_(tracker),
          estimator_(estimator),
          gravity_(gravity),
          gyro_feed_(gyro_feed),
          step_(tracker),
          dets_(static_cast<std::size_t>(options.config.detector.max_detections)),
          records_(4096),
          log_l_(estimator.posterior().grid().size()) {}

    [[nodiscard]] core::Status run(std::size_t end, EvalResult& r);

private:
    [[nodiscard]] core::Status evaluateFrame(const drivers::source::Frame& frame, EvalResult& r);
    void recordTruth(const drivers::source::Frame& frame, FrameRow& row, EvalResult& r);
    void recordDepthUnit(const drivers::source::Frame& frame, FrameRow& row);
    [[nodiscard]] core::Status detectAndUpdate(const drivers::source::Frame& frame,
                                               const FrameRow& row, EvalResult& r);
    [[nodiscard]] core::FrameSnapshot snapshotOf(const drivers::source::Frame& frame);
    [[nodiscard]] std::optional<double> medianTrueDepthM(const drivers::source::Frame& frame);
    void appendObjects(const UpdateRow& up, EvalResult& r) const;
    void appendObservations(const UpdateRow& up, const core::UpdateStats& u, EvalResult& r);
    void appendDepthErrors(const drivers::source::Frame& frame, const UpdateRow& up, EvalResult& r);
    void endMap(EvalResult& r);
    void summarise(EvalResult& r);

    drivers::source::FrameSource& source_;
    drivers::detector::ObjectDetector& detector_;
    const core::PriorTable& priors_;
    const EvalOptions& options_;
    const daemon::PipelineConfig& config_;
    drivers::vision::MonoTracker& tracker_;
    core::ScaleEstimator& estimator_;
    const drivers::imu::MapGravitySelector& gravity_;
    drivers::imu::GyroFeed& gyro_feed_;
    daemon::FrameStep step_;

    core::slam::SlamSnapshot snapshot_;
    std::vector<core::MapFeature> truth_features_;  // --truth-geometry's map
    core::slam::SlamSnapshot depth_snapshot_;       // --depth-unit's, every tracked frame
    std::vector<double> depth_ratios_;
    std::vector<core::Detection> dets_;
    std::vector<core::ObservationRecord> records_;
    std::vector<Scalar> log_l_;
    drivers::detector::DetectionResult boxes_;
    std::size_t detections_ = 0;  // dets_ used by the last update
    std::size_t curve_step_ = 1;

    // Per epoch: the trajectory, its frame rows, and the baselines.
    Track track_;
    // This frame's truth scale of the tracker's trajectory so far (recordTruth;
    // none without truth), which --truth-geometry's rows replace by 1.
    std::optional<double> map_scale_true_;
    std::optional<double> epoch_baseline_constant_;
    std::optional<double> epoch_baseline_single_;
    double epoch_t0_s_ = 0;

    // Depth errors per update, filtered to the converged updates at the end.
    std::vector<std::pair<std::size_t, double>> depth_rel_;
    std::vector<std::pair<std::size_t, double>> depth_abs_;

    double tracker_ms_ = 0;
    double detector_ms_ = 0;
    double estimator_ms_ = 0;
};

core::Status EvalRun::run(std::size_t end, EvalResult& r) {
    if (auto reserved = snapshot_.reserve(config_.tracker.slam.max_features); !reserved) {
        return reserved.error();
    }
    if (options_.depth_unit) {
        if (auto reserved = depth_snapshot_.reserve(config_.tracker.slam.max_features); !reserved) {
            return reserved.error();
        }
    }
    const auto& grid = estimator_.posterior().grid();
    curve_step_ =
        std::max<std::size_t>(1, (grid.size() + static_cast<std::size_t>(options_.curve_bins) - 1) /
                                     static_cast<std::size_t>(options_.curve_bins));
    if (options_.keep_curves) {
        for (std::size_t j = 0; j < grid.size(); j += curve_step_) {
            r.curve_d.push_back(static_cast<double>(grid.d(j)));
        }
    }
    r.gyro_source = gyro_feed_.source();

    drivers::source::Frame frame;
    const std::size_t stride = std::max<std::size_t>(options_.selection.stride, 1);
    std::optional<std::string> first_read_error;
    for (std::size_t i = options_.first_frame; i < end; i += stride) {
        auto got = drivers::source::readSelected(source_, options_.selection, i, frame);
        if (!got) {
            // A frame that cannot be read is skipped (the reader moved past it);
            // the tracker sees a longer frame gap.
            ++r.unreadable_frames;
            if (!first_read_error) {
                first_read_error = got.error().message;
            }
            continue;
        }
        if (!*got) {
            break;
        }
        if (auto s = evaluateFrame(frame, r); !s) {
            return s;
        }
        if (options_.progress) {
            options_.progress(i + 1 - options_.first_frame, end - options_.first_frame,
                              r.frame_rows.back().scale);
        }
    }
    if (r.frames == 0) {
        std::string why = "no frame could be read";
        if (first_read_error) {
            why += " (" + std::to_string(r.unreadable_frames) +
                   " unreadable; the first: " + *first_read_error + ")";
        } else {
            why += " (no frame in the selected range)";
        }
        return makeError(ErrorCode::kInvalidArgument, why);
    }
    summarise(r);
    return {};
}

core::Status EvalRun::evaluateFrame(const drivers::source::Frame& frame, EvalResult& r) {
    ++r.frames;
    const daemon::FrameStepResult step =
        step_.track(frame, gyro_feed_.forFrame(frame),
                    [&](const drivers::source::Frame& f) { return gravity_.atMapStart(f); });
    if (step.gravity != nullptr) {
        r.gravity_source = step.gravity->source;
    }
    tracker_ms_ += step.track_ms;
    const drivers::vision::TrackStats& stats = step.stats;
    if (stats.gyro == core::slam::GyroCoverage::kOk) {
        ++r.gyro_frames;
    }
    // The start check began a young map again (tracker.start_check_s) in
    // the same frame and unit: the epoch goes on, as the daemon's does.
    r.start_restarts += stats.start_redone ? 1 : 0;

    FrameRow row;
    row.frame = frame.id;
    row.t_s = static_cast<double>(frame.t_ns) * 1e-9;
    row.epoch = r.epochs - 1;
    row.features_measured = stats.inliers + stats.rescued;
    row.tracked = step.ok && (!stats.new_map || r.frames == 1);
    if (step.map_started) {
        epoch_t0_s_ = row.t_s;
    }
    if (row.tracked) {
        ++r.tracked_frames;
    } else {
        ++r.tracking_lost_frames;
    }
    map_scale_true_.reset();
    if (step.ok && frame.T_CtoW_gt) {
        recordTruth(frame, row, r);
    }
    if (options_.depth_unit && row.tracked) {
        recordDepthUnit(frame, row);
    }
    // Synchronous detection on the frames the daemon would hand over.
    if (step_.detectionDue(step, config_.detection, frame.t_ns)) {
        if (auto s = detectAndUpdate(frame, row, r); !s) {
            return s;
        }
    }
    row.scale = estimator_.summary();
    row.baseline_constant = epoch_baseline_constant_;
    row.baseline_single = epoch_baseline_single_;
    r.frame_rows.push_back(row);

    if (stats.relocalised) {
        ++r.relocalisations;  // back in the same map: same epoch, same evidence
    }
    if (step.map_lost) {
        endMap(r);
    }
    return {};
}

void EvalRun::recordDepthUnit(const drivers::source::Frame& frame, FrameRow& row) {
    const auto& info = source_.info();
    if (!frame.depth_path || info.depth_scale_m <= 0) {
        return;
    }
    const auto depth = drivers::dataset::loadDepthMetres(frame, info);
    if (!depth) {
        return;
    }
    // The filter carried into the map scale_true is for, as the detection
    // snapshot is (snapshotOf).
    (void)depth_snapshot_.capture(tracker_.filter(), frame.id, 0,
                                  step_.estimatorFromFilter(config_.estimator_map));
    depth_ratios_.clear();
    forEachMeasuredDepth(depth_snapshot_, *depth, [&](double z_map, double z_true) {
        depth_ratios_.push_back(z_true / z_map);
    });
    if (!depth_ratios_.empty()) {
        row.map_unit_depth = median(depth_ratios_);
    }
}

// Ground truth over this epoch's tracked frames.
void EvalRun::recordTruth(const drivers::source::Frame& frame, FrameRow& row, EvalResult& r) {
    r.has_ground_truth = true;
    // The trajectory in the map the scale is estimated in (estimator.map):
    // scale_true is metres per its unit, the metric trajectory d times it.
    const core::slam::Sim3 T = step_.estimatorFromFilter(config_.estimator_map);
    row.p_map = T.apply(tracker_.filter().pose().p_CinW);
    track_.est.push_back(row.p_map);
    track_.gt.push_back(frame.T_CtoW_gt->p_CinW);
    row.has_position = true;
    row.p_gt = frame.T_CtoW_gt->p_CinW;
    track_.t_s.push_back(row.t_s);
    map_scale_true_ = truthScale(track_.est, track_.gt, options_.min_truth_path_m);
    // With --truth-geometry the estimator sees metric poses.
    row.scale_true = options_.truth_geometry ? std::optional<double>(1.0) : map_scale_true_;
    const std::size_t w =
        std::min<std::size_t>(track_.est.size(), static_cast<std::size_t>(options_.window_frames));
    const std::size_t from = track_.est.size() - w;
    row.window_full = w == static_cast<std::size_t>(options_.window_frames);
    row.scale_true_window =
        options_.truth_geometry
            ? std::optional<double>(1.0)
            : truthScale(std::span(track_.est).subspan(from), std::span(track_.gt).subspan(from),
                         options_.min_truth_path_m);
    if (!epoch_baseline_constant_ && row.t_s - epoch_t0_s_ >= options_.baseline_seconds) {
        epoch_baseline_constant_ = truthScale(track_.est, track_.gt, 0);
        if (!r.baseline_constant_scale) {
            r.baseline_constant_scale = epoch_baseline_constant_;
        }
    }
}

// The median of the valid readings of the frame's depth image, metres; none
// without one.
std::optional<double> EvalRun::medianTrueDepthM(const drivers::source::Frame& frame) {
    const auto& info = source_.info();
    if (!frame.depth_path || info.depth_scale_m <= 0) {
        return std::nullopt;
    }
    auto depth = drivers::dataset::loadDepthMetres(frame, info);
    if (!depth) {
        return std::nullopt;
    }
    std::vector<float> z;
    for (int v = 0; v < depth->rows; ++v) {
        const float* row = depth->ptr<float>(v);
        for (int u = 0; u < depth->cols; ++u) {
            if (row[u] > 0) {
                z.push_back(row[u]);
            }
        }
    }
    if (z.empty()) {
        return std::nullopt;
    }
    auto mid = z.begin() + static_cast<std::ptrdiff_t>(z.size() / 2);
    std::nth_element(z.begin(), mid, z.end());
    return static_cast<double>(*mid);
}

// The map as the detection thread sees it; with --truth-geometry, metric,
// true geometry: the true camera and gravity, and for the object model a
// depth hint (below) in place of the map (the paper model gets no features:
// it would measure the hint as one).
core::FrameSnapshot EvalRun::snapshotOf(const drivers::source::Frame& frame) {
    const core::slam::EkfSlam& slam = tracker_.filter();
    // As the daemon hands it to its detection thread (Pipeline::handToDetector).
    (void)snapshot_.capture(slam, frame.id, 0, step_.estimatorFromFilter(config_.estimator_map));
    core::FrameSnapshot snapshot = snapshot_.view();
    if (options_.truth_geometry) {
        // Without truth for this frame there is no update from it. The
        // object model takes only a depth hint from the map (its association
        // searches the depths around it): with a depth image, one point on
        // the optical axis at its median depth; without (KITTI), the
        // tracker's points where it sees them from the camera, in metres by
        // the scale of its trajectory so far. (None at all would be a hint of
        // 1 m, which puts KITTI's cars outside every search.)
        truth_features_.clear();
        const bool hint = config_.estimator.model == core::EstimatorModel::kObject;
        if (frame.T_CtoW_gt && frame.gravity_down_C) {
            const core::CameraPose& gt = *frame.T_CtoW_gt;
            const std::optional<double> z = hint ? medianTrueDepthM(frame) : std::nullopt;
            if (z) {
                core::MapFeature f;
                f.p_FinW = gt.p_CinW + gt.R_CtoW * Vec3(0, 0, static_cast<Scalar>(*z));
                truth_features_.push_back(f);
            } else if (hint && map_scale_true_) {
                // The map carried onto the true camera: its pose to the true
                // one, its unit to metres.
                const core::CameraPose& est = snapshot.pose;
                core::slam::Sim3 to_true;
                to_true.scale = static_cast<Scalar>(*map_scale_true_);
                to_true.R = gt.R_CtoW * est.R_CtoW.transpose();
                to_true.t = gt.p_CinW - to_true.scale * (to_true.R * est.p_CinW);
                for (const core::MapFeature& f : snapshot.features) {
                    truth_features_.push_back(
                        {to_true.apply(f.p_FinW), to_true.applyToCovariance(f.P_FinW)});
                }
            }
            snapshot.pose = gt;
            snapshot.up_W = -(gt.R_CtoW * *frame.gravity_down_C).normalized();
        }
        snapshot.features = truth_features_;
    }
    return snapshot;
}

core::Status EvalRun::detectAndUpdate(const drivers::source::Frame& frame, const FrameRow& row,
                                      EvalResult& r) {
    auto t0 = Clock::now();
    auto det = detector_.detect(frame.color, frame.id, frame.t_ns, boxes_);
    detector_ms_ += msSince(t0);
    if (!det) {
        return makeError(det.error().code,
                         "frame " + std::to_string(frame.id) + ": " + det.error().message);
    }
    detections_ = drivers::detector::toEstimatorDetections(boxes_, dets_);
    const core::FrameSnapshot snapshot = snapshotOf(frame);
    t0 = Clock::now();
    const bool usable = !options_.truth_geometry || (frame.T_CtoW_gt && frame.gravity_down_C);
    const core::UpdateStats u =
        usable ? estimator_.update(snapshot, std::span(dets_.data(), detections_), records_)
               : core::UpdateStats{};
    estimator_ms_ += msSince(t0);

    UpdateRow up;
    up.update = static_cast<int>(r.updates.size());
    up.row = r.frame_rows.size();
    up.frame = frame.id;
    up.t_s = row.t_s;
    up.t_in_map_s = row.t_s - epoch_t0_s_;
    up.epoch = row.epoch;
    up.detections = static_cast<int>(detections_);
    up.observations = u.observations;
    up.objects_used = u.objects_used;
    up.views_used = u.views_used;
    up.information_limit = static_cast<double>(estimator_.informationLimitRelWidth95());
    up.scale = estimator_.summary();
    up.scale_true = row.scale_true;
    up.scale_true_window = row.scale_true_window;
    appendObjects(up, r);
    if (!epoch_baseline_single_ && u.observations > 0) {
        epoch_baseline_single_ = static_cast<double>(up.scale.map);
        if (!r.baseline_single_scale) {
            r.baseline_single_scale = epoch_baseline_single_;
        }
    }
    appendObservations(up, u, r);
    if (options_.keep_curves) {
        r.posterior_curves.push_back(decimate(estimator_.posterior().logDensity(), curve_step_));
    }
    appendDepthErrors(frame, up, r);
    r.updates.push_back(up);
    return {};
}

void EvalRun::appendObjects(const UpdateRow& up, EvalResult& r) const {
    const core::ObjectEvidence* objs = estimator_.objects();
    if (objs == nullptr) {
        return;
    }
    for (int k = 0; k < objs->activeCount(); ++k) {
        const core::ObjectSummary os = objs->summary(k, up.scale);
        ObjectRow orow;
        orow.update = up.update;
        orow.frame = up.frame;
        orow.id = os.id;
        orow.class_name =
            estimator_.priors().priors()[static_cast<std::size_t>(os.class_index)].className();
        orow.state = core::toString(os.state);
        orow.detections = os.detections;
        orow.views_used = os.views_used;
        orow.local_estimate = static_cast<double>(os.local_estimate);
        orow.height_m = static_cast<double>(os.height_m);
        orow.height_lo_m = static_cast<double>(os.height_ci95_m.lo);
        orow.height_hi_m = static_cast<double>(os.height_ci95_m.hi);
        orow.anchor = os.p_AinW;
        orow.anchor_rel_sigma = static_cast<double>(os.anchor_rel_sigma);
        r.objects.push_back(std::move(orow));
    }
}

void EvalRun::appendObservations(const UpdateRow& up, const core::UpdateStats& u, EvalResult& r) {
    const bool paper = config_.estimator.likelihood.variance_model == core::VarianceModel::kPaper;
    const auto& grid = estimator_.posterior().grid();
    for (int k = 0; k < u.records_written; ++k) {
        const auto& rec = records_[static_cast<std::size_t>(k)];
        const auto& d = dets_[static_cast<std::size_t>(rec.detection_index)];
        ObservationRow o;
        o.update = up.update;
        o.frame = up.frame;
        o.class_name = std::string(d.class_name);
        o.score = static_cast<double>(d.score);
        o.D = static_cast<double>(rec.D);
        o.sigma_D = paper ? static_cast<double>(rec.sigma_D_paper)
                          : std::hypot(static_cast<double>(rec.sigma_D_feature),
                                       static_cast<double>(rec.sigma_D_box));
        o.local_estimate = static_cast<double>(rec.local_estimate);
        o.weight = static_cast<double>(rec.weight);
        o.object_id = rec.object_id;
        o.kappa = static_cast<double>(rec.kappa);
        r.observations.push_back(std::move(o));
        if (!options_.keep_curves) {
            continue;
        }
        const core::HeightPrior* prior = priors_.find(d.class_name);
        core::VerticalExtent ext;
        ext.D = rec.D;
        ext.sigma_D_paper = rec.sigma_D_paper;
        ext.sigma_D_feature = rec.sigma_D_feature;
        ext.sigma_D_box = rec.sigma_D_box;
        if (prior != nullptr &&
            core::evaluateLogLikelihood(ext, *prior, grid, config_.estimator.likelihood, log_l_)) {
            const Scalar top = *std::max_element(log_l_.begin(), log_l_.end());
            for (auto& v : log_l_) {
                v -= top;
            }
            r.likelihood_curves.push_back(decimate(log_l_, curve_step_));
        } else {
            r.likelihood_curves.emplace_back();
        }
    }
}

void EvalRun::appendDepthErrors(const drivers::source::Frame& frame, const UpdateRow& up,
                                EvalResult& r) {
    const auto& info = source_.info();
    if (!frame.depth_path || info.depth_scale_m <= 0 ||
        up.scale.state == core::ScaleState::kNoData) {
        return;
    }
    if (auto depth = drivers::dataset::loadDepthMetres(frame, info)) {
        std::vector<double> rel;
        std::vector<double> abs_m;
        // The snapshot the estimator measured (this frame's, in its map: the
        // unit the scale is for).
        depthErrors(snapshot_, *depth, static_cast<double>(up.scale.map), rel, abs_m);
        for (std::size_t k = 0; k < rel.size(); ++k) {
            depth_rel_.emplace_back(r.updates.size(), rel[k]);
            depth_abs_.emplace_back(r.updates.size(), abs_m[k]);
        }
    }
}

// Lost or diverged (the frame step reset the tracker): the next frame starts
// a new map with a new, unrelated scale. The evidence about the old one is void.
void EvalRun::endMap(EvalResult& r) {
    estimator_.reset();
    ++r.epochs;
    track_ = Track{};
    epoch_baseline_constant_.reset();
    epoch_baseline_single_.reset();
}

void EvalRun::summarise(EvalResult& r) {
    r.ms_per_frame = (tracker_ms_ + detector_ms_ + estimator_ms_) / static_cast<double>(r.frames);
    r.tracker_ms_per_frame = tracker_ms_ / static_cast<double>(r.frames);
    if (!r.updates.empty()) {
        r.detector_ms_per_update = detector_ms_ / static_cast<double>(r.updates.size());
        r.estimator_ms_per_update = estimator_ms_ / static_cast<double>(r.updates.size());
    }
    r.converged_update = convergedAt(
        r.updates, static_cast<double>(config_.estimator.posterior.converged_rel_width));
    if (!options_.truth_geometry) {
        r.metric = metricTrajectory(r.frame_rows, options_.min_distance_m, config_);
    }
    if (r.converged_update) {
        r.distance = distanceErrorsAfter(r, *r.converged_update, options_);
        std::vector<double> drel;
        std::vector<double> dabs;
        for (std::size_t k = 0; k < depth_rel_.size(); ++k) {
            if (depth_rel_[k].first >= *r.converged_update) {
                drel.push_back(depth_rel_[k].second);
                dabs.push_back(depth_abs_[k].second);
            }
        }
        r.depth.features = static_cast<int>(drel.size());
        if (!drel.empty()) {
            r.depth.median_rel = median(drel);
            r.depth.median_abs_m = median(dabs);
        }
    }
    if (source_.info().depth_scale_m <= 0) {
        r.depth.note = "the dataset has no depth images";
    } else if (!r.converged_update) {
        r.depth.note = "not converged: no scale to check against depth";
    } else {
        r.depth.note =
            "measured features in view at the converged updates; the depth image is read at the "
            "feature's colour pixel (exact only where depth is registered to colour)";
    }
}

}  // namespace

Result<EvalResult> evaluate(drivers::source::FrameSource& source,
                            drivers::detector::ObjectDetector& detector,
                            const core::PriorTable& priors, const EvalOptions& options) {
    const auto& info = source.info();
    if (!info.has_intrinsics) {
        return makeError(ErrorCode::kInvalidArgument,
                         info.dir.string() + ": the dataset gives no camera intrinsics");
    }
    auto camera = core::PinholeRadialCamera::create(info.intrinsics);
    if (!camera) {
        return camera.error();
    }
    const daemon::PipelineConfig& config = options.config;
    auto tracker = drivers::vision::MonoTracker::create(*camera, config.tracker);
    if (!tracker) {
        return tracker.error();
    }
    auto estimator = core::ScaleEstimator::create(config.estimator, priors, *camera);
    if (!estimator) {
        return estimator.error();
    }
    const std::size_t end =
        std::min(options.end_frame.value_or(info.frame_count), info.frame_count);
    if (options.first_frame >= end) {
        return makeError(ErrorCode::kInvalidArgument,
                         "frames " + std::to_string(options.first_frame) + ":" +
                             std::to_string(end) + " select nothing: the dataset has " +
                             std::to_string(info.frame_count) + " frames");
    }
    if (auto s = source.seek(options.first_frame); !s) {
        return s.error();
    }
    const auto gravity = drivers::imu::MapGravitySelector::forDataset(info.dir);
    if (!gravity) {
        return gravity.error();
    }
    auto gyro_feed = drivers::imu::GyroFeed::create(*gravity, options.gyro_sim);
    if (!gyro_feed) {
        return gyro_feed.error();
    }
    EvalResult r;
    r.dataset = info.name;
    EvalRun run(source, detector, priors, options, *tracker, *estimator, *gravity, *gyro_feed);
    if (auto s = run.run(end, r); !s) {
        return s.error();
    }
    return r;
}

}  // namespace scaled::tools
