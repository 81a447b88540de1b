// field-log: the lines of a field log into scale-eval's CSV shapes and a summary.

#include "field_log_report.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <utility>

#include <Eigen/Geometry>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "files.h"
#include "json.h"

namespace scaled::tools {

using core::ErrorCode;
using core::makeError;
using core::Status;
using nlohmann::json;

namespace {

constexpr std::size_t kMaxProblems = 20;

const char* const kFramesHeader =
    "frame,t_s,tracked,epoch,features_measured,scale_est,ci95_lo,ci95_hi,state,scale_true,"
    "scale_true_window,rel_error,rel_error_window,baseline_constant_rel_error,"
    "baseline_single_rel_error,features_in_map,tracking_ms,frames_dropped,run";
const char* const kUpdatesHeader =
    "update,frame,t_s,epoch,detections,observations,total_observations,scale_est,mean,ci68_lo,"
    "ci68_hi,ci95_lo,ci95_hi,rel_width95,state,converged,scale_true,scale_true_window,"
    "rel_error,rel_error_window,run";
const char* const kObservationsHeader =
    "update,frame,observation,class,score,D,sigma_D,local_estimate,weight";
const char* const kObjectsHeader =
    "update,frame,t_s,epoch,id,class,state,detections,views,views_used,first_frame,last_frame,"
    "local_estimate,height_m,height_ci95_lo_m,height_ci95_hi_m,anchor_x,anchor_y,anchor_z,"
    "anchor_rel_sigma,run";
const char* const kPosesHeader =
    "t_s,frame,epoch,x_m,y_m,z_m,sigma_x_m,sigma_y_m,sigma_z_m,scale,state,x_map,y_map,z_map,run";
const char* const kWindowsHeader =
    "frame,t_s,epoch,keyframes,free_keyframes,points,observations,rms_before_px,rms_px,scale,"
    "rolling_shutter_s,focal_scale,k1,run";
const char* const kMainTrajectory = "trajectory_metric.tum";

std::optional<double> number(const json& j, const char* key) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_number()) {
        return std::nullopt;
    }
    return it->get<double>();
}

std::optional<std::int64_t> integer(const json& j, const char* key) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_number_integer()) {
        return std::nullopt;
    }
    return it->get<std::int64_t>();
}

std::string text(const json& j, const char* key) {
    const auto it = j.find(key);
    return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

// [lo, hi] from a two-number array.
bool interval(const json& j, const char* key, double& lo, double& hi) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_array() || it->size() != 2 || !(*it)[0].is_number() ||
        !(*it)[1].is_number()) {
        return false;
    }
    lo = (*it)[0].get<double>();
    hi = (*it)[1].get<double>();
    return true;
}

// An array member of N numbers: absent (missing or null), ok, or malformed.
enum class Member : std::uint8_t { kAbsent, kOk, kMalformed };

// A JSON value that is null (absent), an array of N numbers, or something else.
template <std::size_t N>
Member numbersOf(const json& v, std::array<double, N>& out) {
    if (v.is_null()) {
        return Member::kAbsent;
    }
    if (!v.is_array() || v.size() != N) {
        return Member::kMalformed;
    }
    for (std::size_t k = 0; k < N; ++k) {
        if (!v[k].is_number()) {
            return Member::kMalformed;
        }
        out.at(k) = v[k].get<double>();
    }
    return Member::kOk;
}

template <std::size_t N>
Member numbers(const json& j, const char* key, std::array<double, N>& out) {
    const auto it = j.find(key);
    return it == j.end() ? Member::kAbsent : numbersOf(*it, out);
}

// A 3x3 matrix member (rows), row-major into `out`.
Member matrix3(const json& j, const char* key, std::array<double, 9>& out) {
    const auto it = j.find(key);
    if (it == j.end() || it->is_null()) {
        return Member::kAbsent;
    }
    if (!it->is_array() || it->size() != 3) {
        return Member::kMalformed;
    }
    for (std::size_t r = 0; r < 3; ++r) {
        std::array<double, 3> row{};
        if (numbersOf((*it)[r], row) != Member::kOk) {
            return Member::kMalformed;
        }
        for (std::size_t c = 0; c < 3; ++c) {
            out.at(3 * r + c) = row.at(c);
        }
    }
    return Member::kOk;
}

std::string field(std::optional<double> v, int digits = 7) {
    return jsonNumberOr(v, digits, "");
}

std::string intField(std::optional<std::int64_t> v) {
    return v ? std::to_string(*v) : std::string();
}

// A CSV text field (quoted when it holds a comma, quote or line break).
std::string csvText(const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) {
        return s;
    }
    std::string q = "\"";
    for (const char c : s) {
        q += c;
        if (c == '"') {
            q += '"';
        }
    }
    return q + "\"";
}

std::string tSeconds(std::optional<std::int64_t> t_ns) {
    return t_ns ? jsonNumber(static_cast<double>(*t_ns) * 1e-9, 12) : std::string();
}

// What the log says about the scale of the current (run, epoch).
struct Current {
    std::int64_t epoch = -1;
    std::optional<double> scale;
    std::optional<double> ci95_lo;
    std::optional<double> ci95_hi;
    std::string state = "initialising";
};

class Analyser {
public:
    explicit Analyser(FieldLogAnalysis& a) : a_(a) {}

    void line(const json& j, const std::string& where) {
        const auto cls_it = j.find("class");
        if (cls_it == j.end() || !cls_it->is_string()) {
            ++a_.unknown_lines;
            problem(where + ": no \"class\" (skipped)");
            return;
        }
        const std::string cls = cls_it->get<std::string>();
        ++a_.classes[cls];
        if (cls == "START") {
            endRun();  // before this line's mono_ns counts: it starts the next run
        }
        if (const auto mono = integer(j, "mono_ns")) {
            if (!run_first_mono_) {
                run_first_mono_ = *mono;
            }
            run_last_mono_ = *mono;
            a_.first_mono_ns = a_.first_mono_ns ? std::min(*a_.first_mono_ns, *mono) : *mono;
            a_.last_mono_ns = a_.last_mono_ns ? std::max(*a_.last_mono_ns, *mono) : *mono;
        }
        if (cls == "START") {
            ++a_.runs;
            ++run_;
            current_ = Current{};
            a_.release = text(j, "release");
            a_.source = text(j, "source");
        } else if (cls == "STOP") {
            ++a_.stops;
            a_.last_stop_reason = text(j, "reason");
        } else if (cls == "ERROR") {
            ++a_.errors;
            a_.last_error = text(j, "where") + ": " + text(j, "message");
        } else if (cls == "STATE") {
            ++a_.state_changes;
            epoch(integer(j, "epoch"));
            if (auto to = text(j, "to"); !to.empty()) {
                current_.state = std::move(to);
            }
        } else if (cls == "FRAME") {
            frame(j, where);
        } else if (cls == "DETECTION") {
            ++a_.detection_runs;
            const auto it = j.find("boxes");
            if (it != j.end() && it->is_array()) {
                a_.boxes += it->size();
            }
        } else if (cls == "SCALE") {
            scale(j, where);
        } else if (cls == "OBJECT") {
            object(j, where);
        } else if (cls == "POSE") {
            pose(j, where);
        } else if (cls == "WINDOW") {
            window(j, where);
        }
    }

    void finish() {
        endRun();
        a_.epochs = epochs_.size();
        auto& ts = a_.trajectories;
        const bool several_runs = std::any_of(
            ts.begin(), ts.end(), [&](const auto& t) { return t.run != ts.front().run; });
        for (auto& t : ts) {
            t.file = "trajectory_metric_" +
                     (several_runs ? "run" + std::to_string(t.run) + "_" : std::string()) +
                     "epoch" + std::to_string(t.epoch) + ".tum";
        }
        for (std::size_t i = 0; i < ts.size(); ++i) {
            if (!a_.main_trajectory || ts[i].poses.size() >= ts[*a_.main_trajectory].poses.size()) {
                a_.main_trajectory = i;
            }
        }
    }

    [[nodiscard]] double spanSeconds() const { return span_ns_ * 1e-9; }

private:
    void problem(const std::string& s) {
        if (a_.problems.size() < kMaxProblems) {
            a_.problems.push_back(s);
        }
    }

    void endRun() {
        if (run_first_mono_ && run_last_mono_) {
            span_ns_ += static_cast<double>(*run_last_mono_ - *run_first_mono_);
        }
        run_first_mono_.reset();
        run_last_mono_.reset();
    }

    void epoch(std::optional<std::int64_t> e) {
        if (!e) {
            return;
        }
        epochs_.insert({run_, *e});
        if (*e != current_.epoch) {
            const std::string state = current_.state;
            current_ = Current{};
            current_.epoch = *e;
            current_.state = state;
        }
    }

    void frame(const json& j, const std::string& where) {
        const auto frame_id = integer(j, "frame_id");
        const auto ep = integer(j, "epoch");
        if (!frame_id || !ep) {
            ++a_.bad_fields;
            problem(where + ": FRAME without frame_id or epoch (skipped)");
            return;
        }
        epoch(ep);
        const std::string health = text(j, "health");
        a_.frame_rows.push_back(std::to_string(*frame_id) + "," + tSeconds(integer(j, "t_ns")) +
                                "," + (health == "ok" ? "1" : "0") + "," + std::to_string(*ep) +
                                "," + intField(integer(j, "tracked")) + "," +
                                field(current_.scale) + "," + field(current_.ci95_lo) + "," +
                                field(current_.ci95_hi) + "," + csvText(current_.state) +
                                ",,,,,,," + intField(integer(j, "features")) + "," +
                                field(number(j, "ms"), 5) + "," + intField(integer(j, "dropped")) +
                                "," + std::to_string(run_));
    }

    void scale(const json& j, const std::string& where) {
        const auto frame_id = integer(j, "frame_id");
        const auto ep = integer(j, "epoch");
        if (!frame_id || !ep) {
            ++a_.bad_fields;
            problem(where + ": SCALE without frame_id or epoch (skipped)");
            return;
        }
        epoch(ep);
        const std::string state = text(j, "state");
        if (!state.empty()) {
            current_.state = state;
        }
        const auto map = number(j, "scale");
        double lo68 = 0;
        double hi68 = 0;
        double lo95 = 0;
        double hi95 = 0;
        const bool has68 = interval(j, "ci68", lo68, hi68);
        const bool has95 = interval(j, "ci95", lo95, hi95);
        current_.scale = map;
        current_.ci95_lo = has95 ? std::optional<double>(lo95) : std::nullopt;
        current_.ci95_hi = has95 ? std::optional<double>(hi95) : std::nullopt;
        const auto opt = [](bool has, double v) {
            return has ? std::optional<double>(v) : std::nullopt;
        };
        const std::optional<double> width =
            map && has95 && *map > 0 ? std::optional<double>((hi95 - lo95) / *map) : std::nullopt;
        const std::size_t update = a_.update_rows.size();
        const std::string t_s = tSeconds(integer(j, "t_ns"));
        a_.update_rows.push_back(
            std::to_string(update) + "," + std::to_string(*frame_id) + "," + t_s + "," +
            std::to_string(*ep) + "," + intField(integer(j, "detections")) + "," +
            intField(integer(j, "new_observations")) + "," + intField(integer(j, "observations")) +
            "," + field(map) + "," + field(number(j, "mean")) + "," + field(opt(has68, lo68)) +
            "," + field(opt(has68, hi68)) + "," + field(opt(has95, lo95)) + "," +
            field(opt(has95, hi95)) + "," + field(width, 5) + "," + csvText(state) + "," +
            (state == "converged" ? "1" : "0") + ",,,,," + std::to_string(run_));
        const auto obs = j.find("obs");
        if (obs != j.end() && obs->is_array()) {
            for (const json& o : *obs) {
                if (!o.is_object()) {
                    ++a_.bad_fields;
                    continue;
                }
                const std::size_t k = a_.observation_rows.size();
                a_.observation_rows.push_back(
                    std::to_string(update) + "," + std::to_string(*frame_id) + "," +
                    std::to_string(k) + "," + csvText(text(o, "class")) + ",," +
                    field(number(o, "D")) + "," + field(number(o, "sigma_D"), 5) + "," +
                    field(number(o, "local"), 6) + "," + field(number(o, "weight"), 4));
            }
        }
        last_update_ = LastUpdate{update, *frame_id, *ep, run_};
        FieldLogAnalysis::LastScale last;
        last.frame_id = *frame_id;
        last.epoch = static_cast<std::uint64_t>(std::max<std::int64_t>(*ep, 0));
        last.state = state;
        last.scale = map;
        last.ci95_lo = current_.ci95_lo;
        last.ci95_hi = current_.ci95_hi;
        last.observations = static_cast<int>(integer(j, "observations").value_or(0));
        a_.last_scale = last;
    }

    // OBJECT: one row of objects.csv. Its update is the SCALE line of the same
    // run, epoch and frame just before it (empty when that line is missing).
    void object(const json& j, const std::string& where) {
        const auto frame_id = integer(j, "frame_id");
        const auto ep = integer(j, "epoch");
        const auto id = integer(j, "id");
        if (!frame_id || !ep || !id) {
            ++a_.bad_fields;
            problem(where + ": OBJECT without frame_id, epoch or id (skipped)");
            return;
        }
        epoch(ep);
        std::string update;
        if (last_update_ && last_update_->run == run_ && last_update_->epoch == *ep &&
            last_update_->frame_id == *frame_id) {
            update = std::to_string(last_update_->index);
        }
        double lo = 0;
        double hi = 0;
        const bool has95 = interval(j, "height_ci95_m", lo, hi);
        const auto opt = [](bool has, double v) {
            return has ? std::optional<double>(v) : std::nullopt;
        };
        std::array<std::optional<double>, 3> anchor{};
        const auto it = j.find("anchor");
        if (it != j.end() && it->is_array() && it->size() == 3) {
            for (std::size_t k = 0; k < 3; ++k) {
                if ((*it)[k].is_number()) {
                    anchor.at(k) = (*it)[k].get<double>();
                }
            }
        }
        a_.object_rows.push_back(
            update + "," + std::to_string(*frame_id) + "," + tSeconds(integer(j, "t_ns")) + "," +
            std::to_string(*ep) + "," + std::to_string(*id) + "," +
            csvText(text(j, "object_class")) + "," + csvText(text(j, "state")) + "," +
            intField(integer(j, "detections")) + "," + intField(integer(j, "views")) + "," +
            intField(integer(j, "views_used")) + "," + intField(integer(j, "first_frame")) + "," +
            intField(integer(j, "last_frame")) + "," + field(number(j, "local_estimate")) + "," +
            field(number(j, "height_m")) + "," + field(opt(has95, lo)) + "," +
            field(opt(has95, hi)) + "," + field(anchor[0]) + "," + field(anchor[1]) + "," +
            field(anchor[2]) + "," + field(number(j, "anchor_rel_sigma"), 5) + "," +
            std::to_string(run_));
    }

    // WINDOW: one row of windows.csv (a window optimisation and the camera it
    // used). A line without frame_id or epoch is skipped and named.
    void window(const json& j, const std::string& where) {
        const auto frame_id = integer(j, "frame_id");
        const auto ep = integer(j, "epoch");
        if (!frame_id || !ep) {
            ++a_.bad_fields;
            problem(where + ": WINDOW without frame_id or epoch (skipped)");
            return;
        }
        epoch(ep);
        a_.window_rows.push_back(
            std::to_string(*frame_id) + "," + tSeconds(integer(j, "t_ns")) + "," +
            std::to_string(*ep) + "," + intField(integer(j, "keyframes")) + "," +
            intField(integer(j, "free_keyframes")) + "," + intField(integer(j, "points")) + "," +
            intField(integer(j, "observations")) + "," + field(number(j, "rms_before_px"), 9) +
            "," + field(number(j, "rms_px"), 9) + "," + field(number(j, "scale"), 9) + "," +
            field(number(j, "rolling_shutter_s"), 9) + "," + field(number(j, "focal_scale"), 9) +
            "," + field(number(j, "k1"), 9) + "," + std::to_string(run_));
    }

    // POSE: one row of poses.csv and, with a metric position, a pose of its
    // (run, epoch)'s trajectory. A line without the members every POSE has
    // (frame_id, epoch, t_ns, orientation, position_map) or with a member
    // of the wrong shape is skipped and named.
    void pose(const json& j, const std::string& where) {
        const auto frame_id = integer(j, "frame_id");
        const auto ep = integer(j, "epoch");
        const auto t_ns = integer(j, "t_ns");
        std::array<double, 4> q{};
        std::array<double, 3> map{};
        std::array<double, 3> pos{};
        std::array<double, 9> cov{};
        std::string bad;
        Member position = Member::kAbsent;
        Member covariance = Member::kAbsent;
        if (!frame_id || !ep || !t_ns) {
            bad = "without frame_id, epoch or t_ns";
        } else if (numbers(j, "orientation", q) != Member::kOk) {
            bad = "orientation is not [w,x,y,z]";
        } else if (numbers(j, "position_map", map) != Member::kOk) {
            bad = "position_map is not [x,y,z]";
        } else if (position = numbers(j, "position", pos); position == Member::kMalformed) {
            bad = "position is neither null nor [x,y,z]";
        } else if (covariance = matrix3(j, "position_cov", cov); covariance == Member::kMalformed) {
            bad = "position_cov is neither null nor a 3x3 matrix";
        }
        const double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        if (bad.empty() && !(std::abs(qn - 1) <= 1e-3)) {
            bad = "orientation is not a unit quaternion (norm " + jsonNumber(qn, 6) + ")";
        }
        if (!bad.empty()) {
            ++a_.bad_fields;
            problem(where + ": POSE " + bad + " (skipped)");
            return;
        }
        epoch(ep);
        const bool metric = position == Member::kOk;
        const auto opt = [](bool has, double v) {
            return has && std::isfinite(v) ? std::optional<double>(v) : std::nullopt;
        };
        const bool sig = metric && covariance == Member::kOk;
        std::string row =
            tSeconds(t_ns) + "," + std::to_string(*frame_id) + "," + std::to_string(*ep);
        for (std::size_t k = 0; k < 3; ++k) {
            row += "," + field(opt(metric, pos.at(k)));
        }
        for (std::size_t k = 0; k < 3; ++k) {
            const double var = cov.at(4 * k);
            row += "," + field(opt(sig && var >= 0, std::sqrt(std::max(var, 0.0))), 5);
        }
        row += "," + field(number(j, "scale"), 9) + "," + csvText(text(j, "state"));
        for (std::size_t k = 0; k < 3; ++k) {
            row += "," + field(map.at(k));
        }
        row += "," + std::to_string(run_);
        a_.pose_rows.push_back(std::move(row));
        if (!metric) {
            return;
        }
        ++a_.metric_poses;
        const auto key = std::make_pair(run_, *ep);
        auto found = trajectory_index_.find(key);
        if (found == trajectory_index_.end()) {
            FieldLogAnalysis::Trajectory t;
            t.run = run_;
            t.epoch = *ep;
            a_.trajectories.push_back(std::move(t));
            found = trajectory_index_.emplace(key, a_.trajectories.size() - 1).first;
        }
        auto& t = a_.trajectories[found->second];
        if (!t.t_ns.empty() && *t_ns < t.t_ns.back() + 1000) {
            problem(where + ": POSE t_ns " + std::to_string(*t_ns) +
                    " is not after the previous pose of run " + std::to_string(run_) + " epoch " +
                    std::to_string(*ep) + " (left out of its trajectory)");
            return;
        }
        core::CameraPose cp;
        cp.R_CtoW = Eigen::Quaterniond(q[0], q[1], q[2], q[3])
                        .normalized()
                        .toRotationMatrix()
                        .cast<core::Scalar>();
        cp.p_CinW = Eigen::Vector3d(pos[0], pos[1], pos[2]).cast<core::Scalar>();
        t.t_ns.push_back(*t_ns);
        t.poses.push_back(cp);
    }

    struct LastUpdate {
        std::size_t index = 0;  // row of updates.csv
        std::int64_t frame_id = -1;
        std::int64_t epoch = -1;
        std::size_t run = 0;
    };

    FieldLogAnalysis& a_;
    Current current_;
    std::optional<LastUpdate> last_update_;
    std::size_t run_ = 0;
    std::set<std::pair<std::size_t, std::int64_t>> epochs_;
    std::map<std::pair<std::size_t, std::int64_t>, std::size_t> trajectory_index_;
    std::optional<std::int64_t> run_first_mono_;
    std::optional<std::int64_t> run_last_mono_;
    double span_ns_ = 0;
};

std::string num(std::optional<double> v, int digits = 7) {
    return jsonNumberOr(v, digits, "null");
}

}  // namespace

FieldLogAnalysis analyseFieldLog(const drivers::fieldlog::FieldLogContents& contents,
                                 const std::string& log) {
    FieldLogAnalysis a;
    a.log = log;
    a.files = contents.files.size();
    a.lines = contents.lines.size();
    a.corrupt_lines = contents.corrupt_lines;
    a.partial_lines = contents.partial_lines;
    a.problems = contents.problems;
    Analyser an(a);
    for (const auto& l : contents.lines) {
        const json j = json::parse(l.text, nullptr, false);
        const std::string where =
            contents.files.at(l.file).string() + ":" + std::to_string(l.line_no);
        if (j.is_discarded() || !j.is_object()) {
            ++a.corrupt_lines;  // the reader already checks; kept for safety
            continue;
        }
        an.line(j, where);
    }
    an.finish();
    a.time_span_s = an.spanSeconds();
    return a;
}

std::string toJson(const FieldLogAnalysis& a) {
    std::string s = "{\"dataset\":" + jsonString(a.log);
    s += ",\"files\":" + std::to_string(a.files);
    s += ",\"lines\":" + std::to_string(a.lines);
    s += ",\"corrupt_lines\":" + std::to_string(a.corrupt_lines);
    s += ",\"partial_lines\":" + std::to_string(a.partial_lines);
    s += ",\"unknown_lines\":" + std::to_string(a.unknown_lines);
    s += ",\"bad_fields\":" + std::to_string(a.bad_fields);
    s += ",\"classes\":{";
    bool first = true;
    for (const auto& [cls, n] : a.classes) {
        s += (first ? "" : ",") + jsonString(cls) + ":" + std::to_string(n);
        first = false;
    }
    s += "}";
    s += ",\"runs\":" + std::to_string(a.runs);
    s += ",\"release\":" + jsonString(a.release);
    s += ",\"source\":" + jsonString(a.source);
    s += ",\"stops\":" + std::to_string(a.stops);
    s += ",\"last_stop_reason\":" + jsonString(a.last_stop_reason);
    s += ",\"errors\":" + std::to_string(a.errors);
    s += ",\"last_error\":" + jsonString(a.last_error);
    s += ",\"state_changes\":" + std::to_string(a.state_changes);
    s += ",\"epochs\":" + std::to_string(a.epochs);
    s += ",\"frames_logged\":" + std::to_string(a.frame_rows.size());
    s += ",\"detection_runs\":" + std::to_string(a.detection_runs);
    s += ",\"boxes\":" + std::to_string(a.boxes);
    s += ",\"updates\":" + std::to_string(a.update_rows.size());
    s += ",\"observations_logged\":" + std::to_string(a.observation_rows.size());
    s += ",\"objects_logged\":" + std::to_string(a.object_rows.size());
    s += ",\"poses_logged\":" + std::to_string(a.pose_rows.size());
    s += ",\"windows_logged\":" + std::to_string(a.window_rows.size());
    s += ",\"metric_poses_logged\":" + std::to_string(a.metric_poses);
    s += ",\"trajectories\":[";
    for (std::size_t i = 0; i < a.trajectories.size(); ++i) {
        const auto& t = a.trajectories[i];
        double path_m = 0;
        for (std::size_t k = 1; k < t.poses.size(); ++k) {
            path_m += static_cast<double>((t.poses[k].p_CinW - t.poses[k - 1].p_CinW).norm());
        }
        s += (i == 0 ? "{\"file\":" : ",{\"file\":") + jsonString(t.file) +
             ",\"run\":" + std::to_string(t.run) + ",\"epoch\":" + std::to_string(t.epoch) +
             ",\"poses\":" + std::to_string(t.poses.size()) +
             ",\"path_m\":" + jsonNumber(path_m, 6) + "}";
    }
    s += "]";
    s += ",\"trajectory_metric\":" + (a.main_trajectory
                                          ? jsonString(a.trajectories[*a.main_trajectory].file)
                                          : std::string("null"));
    s += ",\"first_mono_ns\":" + (a.first_mono_ns ? std::to_string(*a.first_mono_ns) : "null");
    s += ",\"last_mono_ns\":" + (a.last_mono_ns ? std::to_string(*a.last_mono_ns) : "null");
    s += ",\"time_span_s\":" + jsonNumber(a.time_span_s, 6);
    if (a.last_scale) {
        const auto& l = *a.last_scale;
        s += ",\"last_scale\":{\"frame_id\":" + std::to_string(l.frame_id) +
             ",\"epoch\":" + std::to_string(l.epoch) + ",\"state\":" + jsonString(l.state) +
             ",\"scale\":" + num(l.scale) + ",\"ci95\":" +
             (l.ci95_lo && l.ci95_hi
                  ? "[" + jsonNumber(*l.ci95_lo, 7) + "," + jsonNumber(*l.ci95_hi, 7) + "]"
                  : std::string("null")) +
             ",\"observations\":" + std::to_string(l.observations) + "}";
    } else {
        s += ",\"last_scale\":null";
    }
    // What the plot script reads; a field log has no ground truth.
    s += ",\"scale_true_final\":null,\"converged_at_frame\":null";
    s += ",\"problems\":[";
    for (std::size_t i = 0; i < a.problems.size(); ++i) {
        s += (i == 0 ? "" : ",") + jsonString(a.problems[i]);
    }
    s += "]}";
    return s;
}

std::string toText(const FieldLogAnalysis& a) {
    std::string s =
        a.log + ": " + std::to_string(a.files) + " file(s), " + std::to_string(a.lines) + " lines";
    if (a.corrupt_lines + a.partial_lines + a.unknown_lines > 0) {
        s += " (skipped: " + std::to_string(a.corrupt_lines) + " corrupt, " +
             std::to_string(a.partial_lines) + " partial, " + std::to_string(a.unknown_lines) +
             " without class)";
    }
    s += "\n" + std::to_string(a.runs) + " run(s), " + std::to_string(a.epochs) + " epoch(s), " +
         std::to_string(a.frame_rows.size()) + " frame lines, " + std::to_string(a.detection_runs) +
         " detector runs, " + std::to_string(a.update_rows.size()) + " scale updates, " +
         (a.object_rows.empty() ? std::string()
                                : std::to_string(a.object_rows.size()) + " object lines, ") +
         (a.pose_rows.empty() ? std::string()
                              : std::to_string(a.pose_rows.size()) + " pose lines (" +
                                    std::to_string(a.metric_poses) + " metric), ") +
         (a.window_rows.empty() ? std::string()
                                : std::to_string(a.window_rows.size()) + " window lines, ") +
         std::to_string(a.errors) + " errors, " + jsonNumber(a.time_span_s, 6) + " s\n";
    if (a.last_scale && a.last_scale->scale) {
        const auto& l = *a.last_scale;
        s += "last scale " + jsonNumber(*l.scale, 6) + " m/unit";
        if (l.ci95_lo && l.ci95_hi) {
            s += " (95% " + jsonNumber(*l.ci95_lo, 5) + " .. " + jsonNumber(*l.ci95_hi, 5) + ")";
        }
        s += ", " + l.state + ", epoch " + std::to_string(l.epoch) + ", frame " +
             std::to_string(l.frame_id) + "\n";
    } else {
        s += "no scale in the log\n";
    }
    if (!a.last_error.empty()) {
        s += "last error: " + a.last_error + "\n";
    }
    return s;
}

Status writeFieldLogOutputs(const FieldLogAnalysis& a, const std::string& out_dir) {
    if (auto ok = createOutputDir(out_dir); !ok) {
        return ok;
    }
    const std::filesystem::path dir(out_dir);
    const auto write = [&](const char* name, const char* header,
                           const std::vector<std::string>& rows) -> Status {
        const std::filesystem::path path = dir / name;
        std::ofstream out(path);
        if (!out) {
            return makeError(ErrorCode::kIo,
                             path.string() + ": cannot create: " + drivers::base::errnoText(errno));
        }
        if (header != nullptr) {
            out << header << '\n';
        }
        for (const auto& r : rows) {
            out << r << '\n';
        }
        out.close();
        if (out.fail()) {
            return makeError(ErrorCode::kIo,
                             path.string() + ": write failed: " + drivers::base::errnoText(errno));
        }
        return {};
    };
    if (auto ok = write("frames.csv", kFramesHeader, a.frame_rows); !ok) {
        return ok;
    }
    if (auto ok = write("updates.csv", kUpdatesHeader, a.update_rows); !ok) {
        return ok;
    }
    if (auto ok = write("observations.csv", kObservationsHeader, a.observation_rows); !ok) {
        return ok;
    }
    if (auto ok = write("objects.csv", kObjectsHeader, a.object_rows); !ok) {
        return ok;
    }
    if (auto ok = write("poses.csv", kPosesHeader, a.pose_rows); !ok) {
        return ok;
    }
    if (auto ok = write("windows.csv", kWindowsHeader, a.window_rows); !ok) {
        return ok;
    }
    for (const auto& t : a.trajectories) {
        if (auto ok = drivers::dataset::writeTumTrajectory(dir / t.file, t.t_ns, t.poses); !ok) {
            return ok;
        }
    }
    if (a.main_trajectory) {
        const auto& t = a.trajectories[*a.main_trajectory];
        if (auto ok = drivers::dataset::writeTumTrajectory(dir / kMainTrajectory, t.t_ns, t.poses);
            !ok) {
            return ok;
        }
    }
    return write("summary.json", nullptr, {toJson(a)});
}

}  // namespace scaled::tools
