// scale-eval's outputs: the JSON summary and the CSV files for the figures.

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <scaled/drivers/base/errno_text.h>

#include "files.h"
#include "json.h"
#include "scale_eval.h"

namespace scaled::tools {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

std::string num(std::optional<double> v, int digits = 6) {
    return jsonNumberOr(v, digits, "null");
}

std::string stats(const ErrorStats& s) {
    return "{\"count\":" + std::to_string(s.count) + ",\"median\":" + num(s.median) +
           ",\"std\":" + num(s.std) + ",\"max\":" + num(s.max) + "}";
}

std::optional<double> relError(std::optional<double> est, std::optional<double> truth) {
    if (!est || !truth) {
        return std::nullopt;
    }
    return std::abs(*est / *truth - 1);
}

std::optional<double> estimateOf(const core::ScaleSummary& s) {
    if (s.state == core::ScaleState::kNoData) {
        return std::nullopt;
    }
    return static_cast<double>(s.map);
}

// The updates the error statistics are taken over: from convergence on, or
// every update when the run did not converge.
std::size_t statsFrom(const EvalResult& r) {
    return r.converged_update.value_or(0);
}

ErrorStats baselineErrors(const EvalResult& r, bool single) {
    std::vector<double> e;
    for (std::size_t i = statsFrom(r); i < r.updates.size(); ++i) {
        const FrameRow& row = r.frame_rows[r.updates[i].row];
        if (auto v =
                relError(single ? row.baseline_single : row.baseline_constant, row.scale_true)) {
            e.push_back(*v);
        }
    }
    return describe(std::move(e));
}

std::optional<double> lastTruth(const EvalResult& r, bool window) {
    for (auto it = r.frame_rows.rbegin(); it != r.frame_rows.rend(); ++it) {
        const auto& v = window ? it->scale_true_window : it->scale_true;
        if (it->epoch != r.frame_rows.back().epoch) {
            break;
        }
        if (v) {
            return v;
        }
    }
    return std::nullopt;
}

std::string field(std::optional<double> v, int digits = 7) {
    return jsonNumberOr(v, digits, "");
}

class CsvFile {
public:
    explicit CsvFile(const std::filesystem::path& path) : path_(path), out_(path) {}
    [[nodiscard]] bool open() const { return out_.is_open(); }
    void line(const std::string& s) { out_ << s << '\n'; }
    Status close() {
        out_.close();
        if (out_.fail()) {
            return makeError(ErrorCode::kIo,
                             path_.string() + ": write failed: " + drivers::base::errnoText(errno));
        }
        return {};
    }

private:
    std::filesystem::path path_;
    std::ofstream out_;
};

std::string curveHeader(const char* first, const char* second, const std::vector<double>& d) {
    std::string s = std::string(first) + "," + second;
    for (const double v : d) {
        s += "," + jsonNumber(v, 6);
    }
    return s;
}

std::string curveRow(const std::vector<float>& c, std::size_t n) {
    std::string s;
    for (std::size_t j = 0; j < n; ++j) {
        s += "," + (j < c.size() ? jsonNumber(static_cast<double>(c[j]), 5) : std::string());
    }
    return s;
}

// An interval as the JSON array [lo, hi].
std::string interval(const core::Interval& i) {
    return "[" + jsonNumber(static_cast<double>(i.lo), 7) + "," +
           jsonNumber(static_cast<double>(i.hi), 7) + "]";
}

// The run's counts: frames, epochs, updates, observations.
void appendCounts(std::string& s, const EvalResult& r, const daemon::PipelineConfig& cfg) {
    s += ",\"frames\":" + std::to_string(r.frames);
    s += ",\"tracked_frames\":" + std::to_string(r.tracked_frames);
    s += ",\"tracking_lost_frames\":" + std::to_string(r.tracking_lost_frames);
    s += ",\"unreadable_frames\":" + std::to_string(r.unreadable_frames);
    s += ",\"epochs\":" + std::to_string(r.epochs);
    s += ",\"relocalisations\":" + std::to_string(r.relocalisations);
    s += ",\"start_restarts\":" + std::to_string(r.start_restarts);
    s += ",\"detect_every_frames\":" + std::to_string(cfg.detection.every_frames);
    s += ",\"detect_phase_frames\":" + std::to_string(cfg.detection.phase_frames);
    s += ",\"updates\":" + std::to_string(r.updates.size());
    s += ",\"observations\":" + std::to_string(r.observations.size());
    s += ",\"ground_truth\":" + std::string(r.has_ground_truth ? "true" : "false");
}

// Convergence, the claimed scale and the final posterior (`last`).
void appendEstimate(std::string& s, const EvalResult& r, const core::ScaleSummary& last) {
    const bool converged = r.converged_update.has_value();
    s += ",\"converged\":" + std::string(converged ? "true" : "false");
    s += ",\"converged_at_frame\":" +
         (converged ? std::to_string(r.updates[*r.converged_update].frame) : "null");
    s += ",\"converged_at_update\":" + (converged ? std::to_string(*r.converged_update) : "null");
    // A scale is claimed only after convergence.
    s += ",\"scale_est\":" + (converged ? jsonNumber(static_cast<double>(last.map), 7) : "null");
    s += ",\"scale_est_ci68\":" + (converged ? interval(last.ci68) : "null");
    s += ",\"scale_est_ci95\":" + (converged ? interval(last.ci95) : "null");
    s += ",\"posterior_final\":{\"state\":" + jsonString(core::toString(last.state)) +
         ",\"map\":" + num(estimateOf(last), 7) +
         ",\"ci95\":" + (last.state == core::ScaleState::kNoData ? "null" : interval(last.ci95)) +
         ",\"rel_width95\":" +
         (last.state == core::ScaleState::kNoData
              ? "null"
              : jsonNumber(static_cast<double>(last.rel_width95), 4)) +
         ",\"observations\":" + std::to_string(last.observations) + "}";
}

// The ground-truth scale at the end and how far it wanders within a map.
void appendTruth(std::string& s, const EvalResult& r, const EvalOptions& options,
                 std::optional<double> truth) {
    s += ",\"scale_true\":" + num(truth, 7);
    s += ",\"scale_true_final\":" + num(truth, 7);
    s += ",\"scale_true_window\":" + num(lastTruth(r, true), 7);
    s += ",\"window_frames\":" + std::to_string(options.window_frames);
    const MapScaleDrift drift = mapScaleDrift(r.frame_rows, r.updates);
    s += ",\"scale_true_window_range\":" + num(drift.window_range, 5);
    s += ",\"scale_true_window_max_dev\":" + num(drift.window_max_dev, 5);
    if (options.depth_unit) {
        const GeometryUnit g = geometryUnit(r.frame_rows, options.window_frames);
        s += ",\"map_unit_depth\":{\"frames\":" + std::to_string(g.frames) +
             ",\"median\":" + num(g.median, 5) + ",\"window_range\":" + num(g.window_range, 5) +
             ",\"motion_over_geometry_range\":" + num(g.motion_over_geometry_range, 5) + "}";
    }
}

// The estimate's relative errors (`last` against `truth` at the end) and the
// distance errors.
void appendErrors(std::string& s, const EvalResult& r, const EvalOptions& options,
                  const core::ScaleSummary& last, std::optional<double> truth) {
    const bool converged = r.converged_update.has_value();
    const ErrorStats e = relativeErrors(r.updates, statsFrom(r), false);
    const ErrorStats ew = relativeErrors(r.updates, statsFrom(r), true);
    s += ",\"rel_error\":" + (converged ? stats(e) : "null");
    s += ",\"rel_error_median\":" + (converged ? num(e.median) : "null");
    s += ",\"rel_error_std\":" + (converged ? num(e.std) : "null");
    s += ",\"rel_error_window\":" + (converged ? stats(ew) : "null");
    s += ",\"rel_error_final\":" +
         (converged ? num(relError(estimateOf(last), truth)) : std::string("null"));
    s += ",\"rel_error_unconverged\":" + (converged ? "null" : stats(e));
    s += ",\"distance_errors\":{\"delta_frames\":" + std::to_string(options.distance_delta_frames) +
         ",\"pairs\":" + std::to_string(r.distance.pairs) +
         ",\"median_abs_m\":" + num(r.distance.median_abs_m) +
         ",\"median_rel\":" + num(r.distance.median_rel) +
         ",\"p90_rel\":" + num(r.distance.p90_rel) + "}";
}

// Distance errors as a JSON object.
std::string distanceJson(const DistanceErrors& d) {
    return "{\"pairs\":" + std::to_string(d.pairs) + ",\"median_rel\":" + num(d.median_rel) +
           ",\"p90_rel\":" + num(d.p90_rel) + ",\"median_abs_m\":" + num(d.median_abs_m) + "}";
}

// The metric trajectory's errors, the depth check and the baselines.
void appendTrajectoryChecks(std::string& s, const EvalResult& r, const EvalOptions& options) {
    const MetricTrajectory& m = r.metric;
    s += ",\"metric_trajectory\":{\"frames\":" + std::to_string(m.frames) +
         ",\"ate_m\":" + num(m.ate_m) + ",\"ate_percent_of_path\":" + num(m.ate_percent_of_path) +
         ",\"distance_error_1s\":" + distanceJson(m.distance_1s) +
         ",\"distance_error_5s\":" + distanceJson(m.distance_5s) + "}";
    s += ",\"depth_check\":{\"features\":" + std::to_string(r.depth.features) +
         ",\"median_rel\":" + num(r.depth.median_rel) +
         ",\"median_abs_m\":" + num(r.depth.median_abs_m) +
         ",\"note\":" + jsonString(r.depth.note) + "}";
    s += ",\"baselines\":{\"constant\":{\"seconds\":" + jsonNumber(options.baseline_seconds) +
         ",\"scale\":" + num(r.baseline_constant_scale, 7) +
         ",\"rel_error\":" + stats(baselineErrors(r, false)) +
         "},\"single_detection\":{\"scale\":" + num(r.baseline_single_scale, 7) +
         ",\"rel_error\":" + stats(baselineErrors(r, true)) + "}}";
}

// Calibration and the served estimate's accuracy, whatever its state.
void appendCalibration(std::string& s, const EvalResult& r, const EvalOptions& options) {
    const Calibration cal = calibration(r.updates, options.settle_seconds);
    s += ",\"model\":" + jsonString(core::toString(options.config.estimator.model));
    s += ",\"truth_geometry\":" + std::string(options.truth_geometry ? "true" : "false");
    s += ",\"ci95_coverage\":" + num(cal.ci95_coverage, 4);
    s += ",\"ci95_coverage_updates\":" + std::to_string(cal.updates);
    s += ",\"wrong_converged_updates\":" + std::to_string(cal.wrong_converged_updates);
    s += ",\"rel_error_after_5s\":" + stats(cal.after_settle);
    s += ",\"rel_error_after_5s_window\":" + stats(cal.after_settle_window);
    s += ",\"observations_per_100_frames\":" +
         jsonNumber(r.frames > 0 ? 100.0 * static_cast<double>(r.observations.size()) /
                                       static_cast<double>(r.frames)
                                 : 0.0,
                    4);
}

// The objects seen and used, and what they allow next to what was reached.
void appendObjects(std::string& s, const EvalResult& r) {
    const UpdateRow* last_up = r.updates.empty() ? nullptr : &r.updates.back();
    int objects_seen = 0;
    for (const ObjectRow& o : r.objects) {
        objects_seen = std::max(objects_seen, o.id);
    }
    s += ",\"objects\":{\"seen\":" + std::to_string(objects_seen) +
         ",\"used_final\":" + std::to_string(last_up ? last_up->objects_used : 0) +
         ",\"views_used_final\":" + std::to_string(last_up ? last_up->views_used : 0) + "}";
    // What the distinct objects and their classes allow, next to what was reached.
    s += ",\"information_limit\":{\"rel_width95_final\":" +
         (last_up && last_up->information_limit > 0 ? jsonNumber(last_up->information_limit, 4)
                                                    : std::string("null")) +
         ",\"achieved_rel_width95_final\":" +
         (last_up && last_up->scale.state != core::ScaleState::kNoData
              ? jsonNumber(static_cast<double>(last_up->scale.rel_width95), 4)
              : std::string("null")) +
         "}";
}

// Timings and where the vertical and the gyro prior came from; closes the object.
void appendTimingsAndSources(std::string& s, const EvalResult& r) {
    s += ",\"ms_per_frame\":" + jsonNumber(r.ms_per_frame, 4);
    s += ",\"tracker_ms_per_frame\":" + jsonNumber(r.tracker_ms_per_frame, 4);
    s += ",\"detector_ms_per_update\":" + jsonNumber(r.detector_ms_per_update, 4);
    s += ",\"estimator_ms_per_update\":" + jsonNumber(r.estimator_ms_per_update, 4);
    s += ",\"gravity_source\":" + jsonString(r.gravity_source);
    s += ",\"gyro_source\":" + jsonString(r.gyro_source);
    s += ",\"gyro_frames\":" + std::to_string(r.gyro_frames) + "}";
}

// Writes one CSV file's header and rows.
using TableWriter = void (*)(CsvFile&, const EvalResult&);

void writeFrames(CsvFile& f, const EvalResult& r) {
    f.line(
        "frame,t_s,tracked,epoch,features_measured,scale_est,ci95_lo,ci95_hi,state,scale_true,"
        "scale_true_window,rel_error,rel_error_window,baseline_constant_rel_error,"
        "baseline_single_rel_error,map_unit_depth");
    for (const auto& fr : r.frame_rows) {
        const auto est = estimateOf(fr.scale);
        const bool has = est.has_value();
        f.line(std::to_string(fr.frame) + "," + jsonNumber(fr.t_s, 9) + "," +
               (fr.tracked ? "1" : "0") + "," + std::to_string(fr.epoch) + "," +
               std::to_string(fr.features_measured) + "," + field(est) + "," +
               (has ? jsonNumber(static_cast<double>(fr.scale.ci95.lo), 7) : "") + "," +
               (has ? jsonNumber(static_cast<double>(fr.scale.ci95.hi), 7) : "") + "," +
               core::toString(fr.scale.state) + "," + field(fr.scale_true) + "," +
               field(fr.scale_true_window) + "," + field(relError(est, fr.scale_true)) + "," +
               field(relError(est, fr.scale_true_window)) + "," +
               field(relError(fr.baseline_constant, fr.scale_true)) + "," +
               field(relError(fr.baseline_single, fr.scale_true)) + "," + field(fr.map_unit_depth));
    }
}

void writeUpdates(CsvFile& f, const EvalResult& r) {
    f.line(
        "update,frame,t_s,epoch,detections,observations,total_observations,scale_est,mean,ci68_lo,"
        "ci68_hi,ci95_lo,ci95_hi,rel_width95,state,converged,scale_true,scale_true_window,"
        "rel_error,rel_error_window");
    for (const auto& u : r.updates) {
        const auto est = estimateOf(u.scale);
        const auto v = [&](core::Scalar x) {
            return est ? jsonNumber(static_cast<double>(x), 7) : std::string();
        };
        const bool conv =
            r.converged_update && static_cast<std::size_t>(u.update) >= *r.converged_update;
        f.line(std::to_string(u.update) + "," + std::to_string(u.frame) + "," +
               jsonNumber(u.t_s, 9) + "," + std::to_string(u.epoch) + "," +
               std::to_string(u.detections) + "," + std::to_string(u.observations) + "," +
               std::to_string(u.scale.observations) + "," + field(est) + "," + v(u.scale.mean) +
               "," + v(u.scale.ci68.lo) + "," + v(u.scale.ci68.hi) + "," + v(u.scale.ci95.lo) +
               "," + v(u.scale.ci95.hi) + "," + v(u.scale.rel_width95) + "," +
               core::toString(u.scale.state) + "," + (conv ? "1" : "0") + "," +
               field(u.scale_true) + "," + field(u.scale_true_window) + "," +
               field(relError(est, u.scale_true)) + "," +
               field(relError(est, u.scale_true_window)));
    }
}

void writeObservations(CsvFile& f, const EvalResult& r) {
    f.line("update,frame,observation,class,score,D,sigma_D,local_estimate,weight,object_id,kappa");
    for (std::size_t k = 0; k < r.observations.size(); ++k) {
        const auto& o = r.observations[k];
        f.line(std::to_string(o.update) + "," + std::to_string(o.frame) + "," + std::to_string(k) +
               "," + o.class_name + "," + jsonNumber(o.score, 4) + "," + jsonNumber(o.D, 7) + "," +
               jsonNumber(o.sigma_D, 5) + "," + jsonNumber(o.local_estimate, 6) + "," +
               jsonNumber(o.weight, 4) + "," +
               (o.object_id > 0 ? std::to_string(o.object_id) : std::string()) + "," +
               (o.object_id > 0 ? jsonNumber(o.kappa, 4) : std::string()));
    }
}

// Every object after every update (model object; empty otherwise).
void writeObjects(CsvFile& f, const EvalResult& r) {
    f.line(
        "update,frame,id,class,state,detections,views_used,local_estimate,height_m,height_lo_m,"
        "height_hi_m,anchor_x,anchor_y,anchor_z,anchor_rel_sigma");
    for (const ObjectRow& o : r.objects) {
        const bool used = o.state == "used";
        const auto opt = [&](double v) { return used && v > 0 ? jsonNumber(v, 6) : std::string(); };
        f.line(std::to_string(o.update) + "," + std::to_string(o.frame) + "," +
               std::to_string(o.id) + "," + o.class_name + "," + o.state + "," +
               std::to_string(o.detections) + "," + std::to_string(o.views_used) + "," +
               opt(o.local_estimate) + "," + opt(o.height_m) + "," + opt(o.height_lo_m) + "," +
               opt(o.height_hi_m) + "," + jsonNumber(static_cast<double>(o.anchor.x()), 6) + "," +
               jsonNumber(static_cast<double>(o.anchor.y()), 6) + "," +
               jsonNumber(static_cast<double>(o.anchor.z()), 6) + "," +
               jsonNumber(o.anchor_rel_sigma, 4));
    }
}

void writePosteriors(CsvFile& f, const EvalResult& r) {
    f.line(curveHeader("update", "frame", r.curve_d));
    for (std::size_t u = 0; u < r.posterior_curves.size() && u < r.updates.size(); ++u) {
        f.line(std::to_string(u) + "," + std::to_string(r.updates[u].frame) +
               curveRow(r.posterior_curves[u], r.curve_d.size()));
    }
}

void writeLikelihoods(CsvFile& f, const EvalResult& r) {
    f.line(curveHeader("observation", "update", r.curve_d));
    for (std::size_t k = 0; k < r.likelihood_curves.size() && k < r.observations.size(); ++k) {
        if (r.likelihood_curves[k].empty()) {
            continue;
        }
        f.line(std::to_string(k) + "," + std::to_string(r.observations[k].update) +
               curveRow(r.likelihood_curves[k], r.curve_d.size()));
    }
}

}  // namespace

std::string toJson(const EvalResult& r, const EvalOptions& options) {
    const core::ScaleSummary last =
        r.frame_rows.empty() ? core::ScaleSummary{} : r.frame_rows.back().scale;
    const std::optional<double> truth = lastTruth(r, false);
    std::string s = "{\"dataset\":" + jsonString(r.dataset);
    appendCounts(s, r, options.config);
    appendEstimate(s, r, last);
    appendTruth(s, r, options, truth);
    appendErrors(s, r, options, last, truth);
    appendTrajectoryChecks(s, r, options);
    appendCalibration(s, r, options);
    appendObjects(s, r);
    appendTimingsAndSources(s, r);
    return s;
}

Status writeOutputs(const EvalResult& r, const EvalOptions& options, const std::string& out_dir) {
    if (auto ok = createOutputDir(out_dir); !ok) {
        return ok;
    }
    const std::filesystem::path dir(out_dir);
    // A deque keeps the files where they are as more are opened (open() hands
    // out pointers).
    std::deque<CsvFile> files;
    auto open = [&](const char* name) -> Result<CsvFile*> {
        files.emplace_back(dir / name);
        if (!files.back().open()) {
            return makeError(ErrorCode::kIo, (dir / name).string() + ": cannot create: " +
                                                 drivers::base::errnoText(errno));
        }
        return &files.back();
    };
    // Each file is opened and written before the next is opened.
    const std::array<std::pair<const char*, TableWriter>, 6> tables = {{
        {"frames.csv", writeFrames},
        {"updates.csv", writeUpdates},
        {"observations.csv", writeObservations},
        {"objects.csv", writeObjects},
        {"posterior.csv", writePosteriors},
        {"likelihoods.csv", writeLikelihoods},
    }};
    for (const auto& [name, write] : tables) {
        auto file = open(name);
        if (!file) {
            return file.error();
        }
        write(**file, r);
    }

    auto summary = open("summary.json");
    if (!summary) {
        return summary.error();
    }
    (*summary)->line(toJson(r, options));

    auto config = open("config.toml");
    if (!config) {
        return config.error();
    }
    (*config)->line("# The configuration of this run (every key; see config/scaled.toml).\n\n" +
                    daemon::toToml(options.config));

    for (auto& f : files) {
        if (auto ok = f.close(); !ok) {
            return ok.error();
        }
    }
    return {};
}

}  // namespace scaled::tools
