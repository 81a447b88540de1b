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

// Relative errors between the MAP times the camera-frame depth of each
// measured feature and the depth image at its pixel.
void depthErrors(const core::slam::EkfSlam& slam, const std::vector<core::slam::MapPoint>& points,
                 const cv::Mat& depth_m, double scale, std::vector<double>& rel,
                 std::vector<double>& abs_m) {
    const core::CameraPose pose = slam.pose();
    for (const auto& m : points) {
        if (!m.in_view || !m.measured) {
            continue;
        }
        const Vec3 p_C = pose.R_CtoW.transpose() * (m.p_FinW - pose.p_CinW);
        const int u = static_cast<int>(std::lround(m.px.x()));
        const int v = static_cast<int>(std::lround(m.px.y()));
        if (p_C.z() <= 0 || u < 0 || v < 0 || u >= depth_m.cols || v >= depth_m.rows) {
            continue;
        }
        const double truth = static_cast<double>(depth_m.at<float>(v, u));
        if (!(truth > 0.1) || !std::isfinite(truth)) {
            continue;
        }
        const double est = scale * static_cast<double>(p_C.z());
        rel.push_back(std::abs(est / truth - 1));
        abs_m.push_back(std::abs(est - truth));
    }
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

MetricTrajectory metricTrajectory(std::span<const FrameRow> rows, double min_distance_m) {
    MetricTrajectory m;
    const auto served = [](const FrameRow& f) {
        return f.has_position && f.scale.state != core::ScaleState::kNoData && f.scale.map > 0;
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

MapScaleDrift mapScaleDrift(std::span<const FrameRow> frames, std::span<const UpdateRow> updates) {
    MapScaleDrift d;
    std::optional<int> epoch;
    double lo = 0;
    double hi = 0;
    const auto close = [&] {
        if (epoch && lo > 0) {
            d.window_range = std::max(d.window_range.value_or(1.0), hi / lo);
        }
    };
    for (const FrameRow& f : frames) {
        if (!f.window_full || !f.scale_true_window || !(*f.scale_true_window > 0)) {
            continue;
        }
        if (!epoch || *epoch != f.epoch) {
            close();
            epoch = f.epoch;
            lo = hi = *f.scale_true_window;
        }
        lo = std::min(lo, *f.scale_true_window);
        hi = std::max(hi, *f.scale_true_window);
    }
    close();
    for (const UpdateRow& u : updates) {
        if (u.scale_true && u.scale_true_window && *u.scale_true > 0) {
            const double dev = std::abs(*u.scale_true_window / *u.scale_true - 1);
            d.window_max_dev = std::max(d.window_max_dev.value_or(0.0), dev);
        }
    }
    return d;
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

    EvalResult r;
    r.dataset = info.name;
    const auto& grid = estimator->posterior().grid();
    const std::size_t step =
        std::max<std::size_t>(1, (grid.size() + static_cast<std::size_t>(options.curve_bins) - 1) /
                                     static_cast<std::size_t>(options.curve_bins));
    if (options.keep_curves) {
        for (std::size_t j = 0; j < grid.size(); j += step) {
            r.curve_d.push_back(static_cast<double>(grid.d(j)));
        }
    }

    std::vector<core::slam::MapPoint> points;
    std::vector<core::MapFeature> features;
    std::vector<core::Detection> dets(static_cast<std::size_t>(config.detector.max_detections));
    std::vector<core::ObservationRecord> records(4096);
    std::vector<Scalar> log_l(grid.size());
    drivers::detector::DetectionResult boxes;

    // Per epoch: the trajectory, its frame rows, and the baselines.
    Track track;
    std::optional<double> epoch_baseline_constant;
    std::optional<double> epoch_baseline_single;
    double epoch_t0_s = 0;
    int frames_in_map = 0;
    const auto gravity = drivers::imu::MapGravitySelector::forDataset(info.dir);
    if (!gravity) {
        return gravity.error();
    }
    bool need_gravity = true;
    auto gyro_feed = drivers::imu::GyroFeed::create(*gravity, options.gyro_sim);
    if (!gyro_feed) {
        return gyro_feed.error();
    }
    r.gyro_source = gyro_feed->source();

    // Depth errors per update, filtered to the converged updates at the end.
    std::vector<std::pair<std::size_t, double>> depth_rel;
    std::vector<std::pair<std::size_t, double>> depth_abs;

    double tracker_ms = 0;
    double detector_ms = 0;
    double estimator_ms = 0;

    drivers::source::Frame frame;
    const std::size_t stride = std::max<std::size_t>(options.selection.stride, 1);
    std::optional<std::string> first_read_error;
    for (std::size_t i = options.first_frame; i < end; i += stride) {
        auto got = drivers::source::readSelected(source, options.selection, i, frame);
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
        ++r.frames;
        if (need_gravity) {
            const drivers::imu::MapGravity g = gravity->atMapStart(frame);
            r.gravity_source = g.source;
            tracker->setGravityDownC(g.down_C);
            need_gravity = false;
        }
        auto t0 = Clock::now();
        const drivers::vision::TrackStats stats =
            tracker->processFrame(frame.t_ns, frame.gray, gyro_feed->forFrame(frame));
        tracker_ms += msSince(t0);
        if (stats.gyro == core::slam::GyroCoverage::kOk) {
            ++r.gyro_frames;
        }

        FrameRow row;
        row.frame = frame.id;
        row.t_s = static_cast<double>(frame.t_ns) * 1e-9;
        row.epoch = r.epochs - 1;
        row.features_measured = stats.inliers + stats.rescued;
        const bool ok = stats.health == core::slam::SlamHealth::kOk;
        row.tracked = ok && (!stats.new_map || r.frames == 1);
        if (ok && stats.new_map) {
            frames_in_map = 0;
            epoch_t0_s = row.t_s;
        }
        if (ok) {
            ++frames_in_map;
        }
        if (row.tracked) {
            ++r.tracked_frames;
        } else {
            ++r.tracking_lost_frames;
        }
        const core::slam::EkfSlam& slam = tracker->filter();

        // Ground truth over this epoch's tracked frames.
        if (ok && frame.T_CtoW_gt) {
            r.has_ground_truth = true;
            track.est.push_back(slam.pose().p_CinW);
            track.gt.push_back(frame.T_CtoW_gt->p_CinW);
            row.has_position = true;
            row.p_map = slam.pose().p_CinW;
            row.p_gt = frame.T_CtoW_gt->p_CinW;
            track.t_s.push_back(row.t_s);
            row.scale_true = truthScale(track.est, track.gt, options.min_truth_path_m);
            if (options.truth_geometry) {
                row.scale_true = 1.0;  // the estimator sees metric poses
            }
            const std::size_t w = std::min<std::size_t>(
                track.est.size(), static_cast<std::size_t>(options.window_frames));
            const std::size_t from = track.est.size() - w;
            row.window_full = w == static_cast<std::size_t>(options.window_frames);
            row.scale_true_window =
                options.truth_geometry
                    ? std::optional<double>(1.0)
                    : truthScale(std::span(track.est).subspan(from),
                                 std::span(track.gt).subspan(from), options.min_truth_path_m);
            if (!epoch_baseline_constant && row.t_s - epoch_t0_s >= options.baseline_seconds) {
                epoch_baseline_constant = truthScale(track.est, track.gt, 0);
                if (!r.baseline_constant_scale) {
                    r.baseline_constant_scale = epoch_baseline_constant;
                }
            }
        }

        // Synchronous detection on every Nth frame of the map.
        if (ok && frames_in_map > 1 && (frames_in_map - 1) % config.detection.every_frames == 0) {
            t0 = Clock::now();
            auto det = detector.detect(frame.color, frame.id, frame.t_ns, boxes);
            detector_ms += msSince(t0);
            if (!det) {
                return makeError(det.error().code,
                                 "frame " + std::to_string(frame.id) + ": " + det.error().message);
            }
            const std::size_t n = drivers::detector::toEstimatorDetections(boxes, dets);
            slam.mapPoints(points);
            features.clear();
            for (const auto& m : points) {
                features.push_back({m.p_FinW, m.P_FinW});
            }
            core::FrameSnapshot snapshot{slam.pose(), slam.upW(), features, frame.id};
            if (options.truth_geometry) {
                // Metric, true geometry: no map features (the object model
                // needs none), the true camera and gravity.
                snapshot.features = {};
                if (frame.T_CtoW_gt && frame.gravity_down_C) {
                    snapshot.pose = *frame.T_CtoW_gt;
                    snapshot.up_W = -(frame.T_CtoW_gt->R_CtoW * *frame.gravity_down_C).normalized();
                } else {
                    // No truth for this frame: no update from it.
                    snapshot.pose = slam.pose();
                }
            }
            t0 = Clock::now();
            const bool usable =
                !options.truth_geometry || (frame.T_CtoW_gt && frame.gravity_down_C);
            const core::UpdateStats u =
                usable ? estimator->update(snapshot, std::span(dets.data(), n), records)
                       : core::UpdateStats{};
            estimator_ms += msSince(t0);

            UpdateRow up;
            up.update = static_cast<int>(r.updates.size());
            up.row = r.frame_rows.size();
            up.frame = frame.id;
            up.t_s = row.t_s;
            up.t_in_map_s = row.t_s - epoch_t0_s;
            up.epoch = row.epoch;
            up.detections = static_cast<int>(n);
            up.observations = u.observations;
            up.objects_used = u.objects_used;
            up.views_used = u.views_used;
            up.information_limit = static_cast<double>(estimator->informationLimitRelWidth95());
            up.scale = estimator->summary();
            up.scale_true = row.scale_true;
            up.scale_true_window = row.scale_true_window;
            if (const core::ObjectEvidence* objs = estimator->objects()) {
                for (int k = 0; k < objs->activeCount(); ++k) {
                    const core::ObjectSummary os = objs->summary(k, up.scale);
                    ObjectRow orow;
                    orow.update = up.update;
                    orow.frame = frame.id;
                    orow.id = os.id;
                    orow.class_name = estimator->priors()
                                          .priors()[static_cast<std::size_t>(os.class_index)]
                                          .className();
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
            if (!epoch_baseline_single && u.observations > 0) {
                epoch_baseline_single = static_cast<double>(up.scale.map);
                if (!r.baseline_single_scale) {
                    r.baseline_single_scale = epoch_baseline_single;
                }
            }
            const bool paper =
                config.estimator.likelihood.variance_model == core::VarianceModel::kPaper;
            for (int k = 0; k < u.records_written; ++k) {
                const auto& rec = records[static_cast<std::size_t>(k)];
                const auto& d = dets[static_cast<std::size_t>(rec.detection_index)];
                ObservationRow o;
                o.update = up.update;
                o.frame = frame.id;
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
                if (options.keep_curves) {
                    const core::HeightPrior* prior = priors.find(d.class_name);
                    core::VerticalExtent ext;
                    ext.D = rec.D;
                    ext.sigma_D_paper = rec.sigma_D_paper;
                    ext.sigma_D_feature = rec.sigma_D_feature;
                    ext.sigma_D_box = rec.sigma_D_box;
                    if (prior != nullptr &&
                        core::evaluateLogLikelihood(ext, *prior, grid, config.estimator.likelihood,
                                                    log_l)) {
                        const Scalar top = *std::max_element(log_l.begin(), log_l.end());
                        for (auto& v : log_l) {
                            v -= top;
                        }
                        r.likelihood_curves.push_back(decimate(log_l, step));
                    } else {
                        r.likelihood_curves.emplace_back();
                    }
                }
            }
            if (options.keep_curves) {
                r.posterior_curves.push_back(decimate(estimator->posterior().logDensity(), step));
            }
            if (frame.depth_path && info.depth_scale_m > 0 &&
                up.scale.state != core::ScaleState::kNoData) {
                if (auto depth = drivers::dataset::loadDepthMetres(frame, info)) {
                    std::vector<double> rel;
                    std::vector<double> abs_m;
                    depthErrors(slam, points, *depth, static_cast<double>(up.scale.map), rel,
                                abs_m);
                    for (std::size_t k = 0; k < rel.size(); ++k) {
                        depth_rel.emplace_back(r.updates.size(), rel[k]);
                        depth_abs.emplace_back(r.updates.size(), abs_m[k]);
                    }
                }
            }
            r.updates.push_back(up);
        }
        row.scale = estimator->summary();
        row.baseline_constant = epoch_baseline_constant;
        row.baseline_single = epoch_baseline_single;
        r.frame_rows.push_back(row);

        if (stats.relocalised) {
            ++r.relocalisations;  // back in the same map: same epoch, same evidence
        }
        if (!ok && stats.health != core::slam::SlamHealth::kRelocalising) {
            // Lost or diverged: the next frame starts a new map with a new,
            // unrelated scale. The evidence about the old one is void.
            tracker->reset();
            estimator->reset();
            need_gravity = true;
            ++r.epochs;
            track = Track{};
            epoch_baseline_constant.reset();
            epoch_baseline_single.reset();
            frames_in_map = 0;
        }
        if (options.progress) {
            options.progress(i + 1 - options.first_frame, end - options.first_frame,
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
    r.ms_per_frame = (tracker_ms + detector_ms + estimator_ms) / static_cast<double>(r.frames);
    r.tracker_ms_per_frame = tracker_ms / static_cast<double>(r.frames);
    if (!r.updates.empty()) {
        r.detector_ms_per_update = detector_ms / static_cast<double>(r.updates.size());
        r.estimator_ms_per_update = estimator_ms / static_cast<double>(r.updates.size());
    }
    r.converged_update =
        convergedAt(r.updates, static_cast<double>(config.estimator.posterior.converged_rel_width));
    if (!options.truth_geometry) {
        r.metric = metricTrajectory(r.frame_rows, options.min_distance_m);
    }

    if (r.converged_update) {
        const std::int64_t from_frame = r.updates[*r.converged_update].frame;
        const int epoch = r.updates[*r.converged_update].epoch;
        // Distance errors between camera positions delta frames apart, both
        // after convergence, with the estimate current at the later one.
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
        r.distance = summariseDistances(abs_m, rel);
        std::vector<double> drel;
        std::vector<double> dabs;
        for (std::size_t k = 0; k < depth_rel.size(); ++k) {
            if (depth_rel[k].first >= *r.converged_update) {
                drel.push_back(depth_rel[k].second);
                dabs.push_back(depth_abs[k].second);
            }
        }
        r.depth.features = static_cast<int>(drel.size());
        if (!drel.empty()) {
            r.depth.median_rel = median(drel);
            r.depth.median_abs_m = median(dabs);
        }
    }
    if (info.depth_scale_m <= 0) {
        r.depth.note = "the dataset has no depth images";
    } else if (!r.converged_update) {
        r.depth.note = "not converged: no scale to check against depth";
    } else {
        r.depth.note =
            "measured features in view at the converged updates; the depth image is read at the "
            "feature's colour pixel (exact only where depth is registered to colour)";
    }
    return r;
}

}  // namespace scaled::tools
