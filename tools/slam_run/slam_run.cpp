#include "slam_run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <optional>

#include <Eigen/Geometry>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/daemon/frame_step.h>
#include <scaled/drivers/imu/gyro_feed.h>
#include <scaled/drivers/imu/map_gravity.h>

#include "json.h"

namespace scaled::tools {

namespace {

using core::Scalar;
using core::Vec3;

struct Segment {
    std::vector<std::int64_t> t_ns;
    std::vector<core::CameraPose> poses;
    std::vector<std::optional<Vec3>> gt;
    std::vector<core::Mat3> gt_R;             // ground-truth attitude (where gt has a value)
    std::vector<std::optional<Vec3>> down_C;  // the true vertical, when the dataset has one
    // The filter's attitude (its world is the map's first camera; pose()'s
    // turns with the window adjustment's at its first optimisation).
    std::vector<core::Mat3> filter_R;
    // The map's vertical (what the estimator measures along), in its world.
    Vec3 up_W = Vec3::Zero();
};

// Rotation vector (axis times angle) of R.
Vec3 rotationVector(const core::Mat3& R) {
    const Eigen::AngleAxis<double> aa(R.cast<double>());
    return (aa.axis() * aa.angle()).cast<core::Scalar>();
}

// Per camera axis, the least-squares gain b of the tracker's rotation over
// `gap` frames against the ground truth's (rotation vectors in the first
// camera's frame): 1 when the tracker turns as much as the camera did.
std::optional<Vec3> rotationGain(const std::vector<core::CameraPose>& poses,
                                 const std::vector<core::Mat3>& gt_R, std::size_t gap) {
    if (poses.size() != gt_R.size() || poses.size() <= gap) {
        return std::nullopt;
    }
    Eigen::Vector3d sxy = Eigen::Vector3d::Zero();
    Eigen::Vector3d sxx = Eigen::Vector3d::Zero();
    for (std::size_t k = 0; k + gap < poses.size(); ++k) {
        const Vec3 est = rotationVector(poses[k].R_CtoW.transpose() * poses[k + gap].R_CtoW);
        const Vec3 gt = rotationVector(gt_R[k].transpose() * gt_R[k + gap]);
        sxy += (est.cast<double>().array() * gt.cast<double>().array()).matrix();
        sxx += gt.cast<double>().cwiseAbs2();
    }
    if (!(sxx.minCoeff() > 0)) {
        return std::nullopt;
    }
    return sxy.cwiseQuotient(sxx).cast<core::Scalar>();
}

double angleDeg(const Vec3& a, const Vec3& b) {
    const double c = std::clamp(static_cast<double>(a.normalized().dot(b.normalized())), -1.0, 1.0);
    return std::acos(c) * 180.0 / std::numbers::pi;
}

// The filter's rotation since the segment's first frame against the ground
// truth's, per frame (degrees), and the error of the map's vertical in the
// camera (where the dataset gives the true one): the vertical the map was
// given at its start carried by the filter's rotation.
std::optional<AttitudeError> attitudeError(const Segment& seg) {
    const auto& est_R = seg.filter_R;
    const auto& gt_R = seg.gt_R;
    if (est_R.size() != gt_R.size() || est_R.empty()) {
        return std::nullopt;
    }
    AttitudeError e;
    for (std::size_t k = 0; k < est_R.size(); ++k) {
        const core::Mat3 est = est_R.front().transpose() * est_R[k];
        const core::Mat3 gt = gt_R.front().transpose() * gt_R[k];
        const double deg = static_cast<double>(rotationVector(gt.transpose() * est).norm()) *
                           180.0 / std::numbers::pi;
        e.max = std::max(e.max, deg);
        e.final = deg;
        if (seg.down_C[k]) {
            const double tilt = angleDeg(*seg.down_C[k], est_R[k].transpose() * -seg.up_W);
            e.tilt_max = std::max(e.tilt_max.value_or(0), tilt);
            e.tilt_final = tilt;
        }
    }
    return e;
}

// Sums over the frames, averaged into the result at the end.
struct FrameSums {
    double track_ms = 0;          // the tracker's time, every frame
    double measured = 0;          // accepted matches, tracked frames
    double in_map = 0;            // features in the map, tracked frames
    double window_ba_points = 0;  // tracker.window_ba's optimisations
    double window_ba_rms_px = 0;
};

// The end of the run (exclusive): the options' end within the dataset; an
// error when the range is empty.
core::Result<std::size_t> endFrame(const drivers::source::SequenceInfo& info,
                                   const SlamRunOptions& options) {
    const std::size_t end =
        std::min(options.end_frame.value_or(info.frame_count), info.frame_count);
    if (options.first_frame >= end) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "frames: range starts at " + std::to_string(options.first_frame) +
                                   " but the dataset has " + std::to_string(info.frame_count) +
                                   " frames");
    }
    return end;
}

// Counts one frame's step into the result and the sums; a tracked frame's
// pose (and ground truth) goes to the current segment, a lost map starts
// a new one.
void countFrame(const daemon::FrameStepResult& r, const drivers::source::Frame& frame,
                const drivers::vision::MonoTracker& tracker, FrameSums& sums,
                std::vector<Segment>& segments, SlamRunResult& result) {
    if (r.gravity != nullptr) {
        result.gravity_source = r.gravity->source;
    }
    const drivers::vision::TrackStats& stats = r.stats;
    if (stats.gyro == core::slam::GyroCoverage::kOk) {
        ++result.gyro_frames;
    }
    sums.track_ms += r.track_ms;
    result.ms_per_frame_max = std::max(result.ms_per_frame_max, r.track_ms);
    ++result.frames;
    result.near_loss_frames += stats.near_loss ? 1 : 0;
    result.rotation_check_frames += stats.rotation_check ? 1 : 0;
    result.start_restarts += stats.start_redone ? 1 : 0;
    if (r.ok) {
        // A frame that starts a replacement map was not tracked.
        if (!stats.new_map || result.frames == 1) {
            ++result.tracked_frames;
        }
        sums.measured += stats.inliers + stats.rescued;
        for (std::size_t b = 0; b < result.nis_by_age.size(); ++b) {
            result.nis_by_age[b] += static_cast<double>(stats.nis_sum[b]);
            result.nis_by_age_count[b] += stats.nis_count[b];
        }
        sums.in_map += stats.features;
        Segment& seg = segments.back();
        seg.t_ns.push_back(frame.t_ns);
        seg.poses.push_back(tracker.pose());
        seg.gt.push_back(frame.T_CtoW_gt ? std::optional<Vec3>(frame.T_CtoW_gt->p_CinW)
                                         : std::nullopt);
        if (frame.T_CtoW_gt) {
            seg.gt_R.push_back(frame.T_CtoW_gt->R_CtoW);
        }
        seg.down_C.push_back(frame.gravity_down_C);
        seg.filter_R.push_back(tracker.filter().pose().R_CtoW);
        seg.up_W = tracker.filter().upW();
        if (stats.relocalised) {
            ++result.relocalisations;
            result.relocalisations_verified += stats.relocalise_verified ? 1 : 0;
            result.relocalise_dropped_features += stats.relocalise_dropped;
        }
        if (stats.window_ba.optimised) {
            ++result.window_ba_optimisations;
            sums.window_ba_points += stats.window_ba.points;
            sums.window_ba_rms_px += static_cast<double>(stats.window_ba.rms_after_px);
            result.window_ba_rolling_shutter_s =
                static_cast<double>(stats.window_ba.rolling_shutter_s);
            result.window_ba_focal_scale = static_cast<double>(stats.window_ba.focal_scale);
            result.window_ba_k1 = static_cast<double>(stats.window_ba.k1);
        }
    } else if (r.map_lost) {
        // Lost or diverged: the next frame starts a new map (new scale).
        ++result.reinitialisations;
        segments.emplace_back();
    } else {
        // Lost, the map kept: the tracker looks for the camera in it.
        ++result.relocalising_frames;
    }
}

// The per-frame means from the counts and sums.
void averageCounts(const FrameSums& sums, SlamRunResult& result) {
    for (std::size_t b = 0; b < result.nis_by_age.size(); ++b) {
        result.nis_by_age[b] = result.nis_by_age_count[b] > 0
                                   ? result.nis_by_age[b] / double(result.nis_by_age_count[b])
                                   : 0;
    }
    result.ms_per_frame = result.frames > 0 ? sums.track_ms / double(result.frames) : 0;
    result.mean_features_measured =
        result.tracked_frames > 0 ? sums.measured / double(result.tracked_frames) : 0;
    result.mean_features_in_map =
        result.tracked_frames > 0 ? sums.in_map / double(result.tracked_frames) : 0;
    const double optimisations = result.window_ba_optimisations;
    result.window_ba_mean_points = optimisations > 0 ? sums.window_ba_points / optimisations : 0;
    result.window_ba_mean_rms_px = optimisations > 0 ? sums.window_ba_rms_px / optimisations : 0;
}

// The trajectory of the longest segment and, when every frame of it has
// ground truth, its metrics against the ground truth.
void evaluateLongestSegment(const std::vector<Segment>& segments, int window_frames,
                            SlamRunResult& result) {
    const auto longest = std::max_element(
        segments.begin(), segments.end(),
        [](const Segment& a, const Segment& b) { return a.poses.size() < b.poses.size(); });
    result.t_ns = longest->t_ns;
    result.poses = longest->poses;
    const bool all_gt =
        !longest->gt.empty() && std::all_of(longest->gt.begin(), longest->gt.end(),
                                            [](const auto& g) { return g.has_value(); });
    if (!all_gt) {
        return;
    }
    std::vector<Vec3> est;
    for (std::size_t k = 0; k < longest->gt.size(); ++k) {
        result.gt_positions.push_back(*longest->gt[k]);
        est.push_back(longest->poses[k].p_CinW);
    }
    const auto a = core::alignTrajectories(est, result.gt_positions);
    if (!a) {
        return;
    }
    result.has_gt = true;
    result.ate_rmse_m = static_cast<double>(a->ate_rmse);
    result.scale_to_gt = static_cast<double>(a->scale);
    result.path_length_m = static_cast<double>(core::pathLength(result.gt_positions));
    const auto drift = core::scaleDriftBetweenThirds(est, result.gt_positions);
    result.scale_drift_thirds = drift ? static_cast<double>(*drift) : 0;
    if (auto w = core::slidingWindowScales(est, result.gt_positions, window_frames)) {
        result.window_scale = std::move(*w);
    }
    if (const auto g = rotationGain(longest->poses, longest->gt_R, 30)) {
        result.rotation_gain_30 = g->cast<double>();
    }
    result.attitude_error_deg = attitudeError(*longest);
}

}  // namespace

core::Result<SlamRunResult> runSlam(drivers::source::FrameSource& source,
                                    const core::PinholeRadialCamera& camera,
                                    const SlamRunOptions& options) {
    auto tracker = drivers::vision::MonoTracker::create(camera, options.tracker);
    if (!tracker) {
        return tracker.error();
    }
    const auto& info = source.info();
    const auto end_frame = endFrame(info, options);
    if (!end_frame) {
        return end_frame.error();
    }
    const std::size_t end = *end_frame;
    if (auto s = source.seek(options.first_frame); !s) {
        return s.error();
    }
    const auto gravity = drivers::imu::MapGravitySelector::forDataset(info.dir);
    if (!gravity) {
        return gravity.error();
    }
    SlamRunResult result;
    auto gyro_feed = drivers::imu::GyroFeed::create(*gravity, options.gyro_sim);
    if (!gyro_feed) {
        return gyro_feed.error();
    }
    result.gyro_source = gyro_feed->source();
    std::vector<Segment> segments(1);
    drivers::source::Frame frame;
    FrameSums sums;
    daemon::FrameStep step(*tracker);
    const std::size_t stride = std::max<std::size_t>(options.selection.stride, 1);
    for (std::size_t i = options.first_frame; i < end; i += stride) {
        auto got = drivers::source::readSelected(source, options.selection, i, frame);
        if (!got) {
            return got.error();
        }
        if (!*got) {
            break;
        }
        const daemon::FrameStepResult r =
            step.track(frame, gyro_feed->forFrame(frame),
                       [&](const drivers::source::Frame& f) { return gravity->atMapStart(f); });
        countFrame(r, frame, *tracker, sums, segments, result);
        if (options.progress) {
            options.progress(i + 1 - options.first_frame, end - options.first_frame, r.stats);
        }
    }
    averageCounts(sums, result);
    result.gyro_bias_C = tracker->gyroBiasC();
    evaluateLongestSegment(segments, options.window_frames, result);
    return result;
}

core::Status writeWindowScales(const std::filesystem::path& path, const SlamRunResult& r) {
    if (!r.window_scale) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               path.string() + ": the run has no window scale");
    }
    std::ofstream f(path);
    if (!f) {
        return core::makeError(core::ErrorCode::kIo, path.string() + ": cannot create");
    }
    f << "t_s,scale\n";
    const core::WindowScales& w = *r.window_scale;
    for (std::size_t k = 0; k < w.scale.size(); ++k) {
        const std::size_t last = k + static_cast<std::size_t>(w.window) - 1;
        f << jsonNumber(static_cast<double>(r.t_ns[last]) * 1e-9) << ",";
        if (std::isfinite(static_cast<double>(w.scale[k]))) {
            f << jsonNumber(static_cast<double>(w.scale[k]));
        }
        f << "\n";
    }
    f.flush();
    if (!f) {
        return core::makeError(core::ErrorCode::kIo, path.string() + ": write failed");
    }
    return {};
}

std::string toJson(const SlamRunResult& r, const std::string& dataset) {
    const auto num = [](double v) { return jsonNumber(v); };
    std::string s = "{\"dataset\":" + jsonString(dataset);
    s += ",\"frames\":" + std::to_string(r.frames);
    s += ",\"tracked_frames\":" + std::to_string(r.tracked_frames);
    s += ",\"reinitialisations\":" + std::to_string(r.reinitialisations);
    s += ",\"relocalisations\":" + std::to_string(r.relocalisations);
    s += ",\"relocalisations_verified\":" + std::to_string(r.relocalisations_verified);
    s += ",\"relocalise_dropped_features\":" + std::to_string(r.relocalise_dropped_features);
    s += ",\"relocalising_frames\":" + std::to_string(r.relocalising_frames);
    s += ",\"near_loss_frames\":" + std::to_string(r.near_loss_frames);
    s += ",\"rotation_check_frames\":" + std::to_string(r.rotation_check_frames);
    s += ",\"start_restarts\":" + std::to_string(r.start_restarts);
    if (r.window_ba_optimisations > 0) {
        s += ",\"window_ba\":{\"optimisations\":" + std::to_string(r.window_ba_optimisations) +
             ",\"mean_points\":" + num(r.window_ba_mean_points) +
             ",\"mean_rms_after_px\":" + num(r.window_ba_mean_rms_px) +
             ",\"rolling_shutter_s\":" + num(r.window_ba_rolling_shutter_s) +
             ",\"focal_scale\":" + num(r.window_ba_focal_scale) + ",\"k1\":" + num(r.window_ba_k1) +
             "}";
    }
    s += ",\"mean_features_measured\":" + num(r.mean_features_measured);
    s += ",\"mean_features_in_map\":" + num(r.mean_features_in_map);
    s += ",\"ms_per_frame\":" + num(r.ms_per_frame);
    s += ",\"ms_per_frame_max\":" + num(r.ms_per_frame_max);
    s += ",\"trajectory_frames\":" + std::to_string(r.poses.size());
    s += ",\"nis_by_feature_age\":{\"searches\":[\"1-4\",\"5-14\",\"15-49\",\"50+\"],\"mean\":[";
    for (std::size_t b = 0; b < r.nis_by_age.size(); ++b) {
        s += (b > 0 ? "," : "") + num(r.nis_by_age[b]);
    }
    s += "],\"matches\":[";
    for (std::size_t b = 0; b < r.nis_by_age.size(); ++b) {
        s += (b > 0 ? "," : "") + std::to_string(r.nis_by_age_count[b]);
    }
    s += "]}";
    if (r.has_gt) {
        s += ",\"path_length_m\":" + num(r.path_length_m);
        s += ",\"ate_rmse_m\":" + num(r.ate_rmse_m);
        s += ",\"ate_percent_of_path\":" +
             num(r.path_length_m > 0 ? 100 * r.ate_rmse_m / r.path_length_m : 0);
        s += ",\"scale_to_gt\":" + num(r.scale_to_gt);
        s += ",\"scale_drift_thirds\":" + num(r.scale_drift_thirds);
        if (r.window_scale) {
            const core::WindowScales& w = *r.window_scale;
            s += ",\"window_scale\":{\"frames\":" + std::to_string(w.window) +
                 ",\"windows\":" + std::to_string(w.valid) + ",\"min\":" + num(w.min) +
                 ",\"max\":" + num(w.max) + ",\"range\":" + num(w.range) + "}";
        }
        if (r.rotation_gain_30) {
            const Eigen::Vector3d& g = *r.rotation_gain_30;
            s += ",\"rotation_gain_30_frames\":[" + num(g.x()) + "," + num(g.y()) + "," +
                 num(g.z()) + "]";
        }
        if (r.attitude_error_deg) {
            const AttitudeError& e = *r.attitude_error_deg;
            s += ",\"attitude_error_deg\":{\"max\":" + num(e.max) + ",\"final\":" + num(e.final);
            if (e.tilt_max && e.tilt_final) {
                s += ",\"tilt_max\":" + num(*e.tilt_max) + ",\"tilt_final\":" + num(*e.tilt_final);
            }
            s += "}";
        }
    }
    s += ",\"gravity_source\":" + jsonString(r.gravity_source);
    s += ",\"gyro_source\":" + jsonString(r.gyro_source);
    s += ",\"gyro_frames\":" + std::to_string(r.gyro_frames);
    s += ",\"gyro_bias_C_radps\":[" + jsonNumber(double(r.gyro_bias_C.x()), 5) + "," +
         jsonNumber(double(r.gyro_bias_C.y()), 5) + "," + jsonNumber(double(r.gyro_bias_C.z()), 5) +
         "]}";
    return s;
}

}  // namespace scaled::tools
