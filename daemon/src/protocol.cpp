#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <span>

#include <scaled/daemon/pose.h>
#include <scaled/daemon/protocol.h>

namespace scaled::daemon {
namespace {

void appendBool(std::string& out, bool value) {
    out += value ? "true" : "false";
}

// `,"name":` (or `{"name":` style is written by the caller).
void key(std::string& out, std::string_view name) {
    appendJsonKey(out, name);
}

void appendArray(std::string& out, std::span<const double> values) {
    out += '[';
    for (std::size_t i = 0; i < values.size(); ++i) {
        if (i > 0) {
            out += ',';
        }
        appendJsonNumber(out, values[i]);
    }
    out += ']';
}

// [x,y,z] (or [w,x,y,z]) with `digits` significant digits, or null.
template <std::size_t N>
void appendVector(std::string& out, bool present, const std::array<double, N>& v, int digits) {
    if (!present) {
        out += "null";
        return;
    }
    out += '[';
    for (std::size_t i = 0; i < N; ++i) {
        if (i > 0) {
            out += ',';
        }
        appendJsonNumber(out, v[i], digits);
    }
    out += ']';
}

// A row-major 3x3 matrix as [[a,b,c],[d,e,f],[g,h,i]], or null.
void appendMatrix(std::string& out, bool present, const std::array<double, 9>& m, int digits) {
    if (!present) {
        out += "null";
        return;
    }
    out += '[';
    for (std::size_t r = 0; r < 3; ++r) {
        out += r == 0 ? "[" : ",[";
        for (std::size_t c = 0; c < 3; ++c) {
            if (c > 0) {
                out += ',';
            }
            appendJsonNumber(out, m[3 * r + c], digits);
        }
        out += ']';
    }
    out += ']';
}

// Euclidean norm without overflow for huge components.
double safeNorm(const std::array<double, 3>& v) {
    const double m = std::max({std::fabs(v[0]), std::fabs(v[1]), std::fabs(v[2])});
    if (m == 0 || !std::isfinite(m)) {
        return m;
    }
    const double a = v[0] / m;
    const double b = v[1] / m;
    const double c = v[2] / m;
    return m * std::sqrt(a * a + b * b + c * c);
}

// STATUS.timing: the stages in the order clients print them.
struct NamedStage {
    const char* name;
    using Stage = StageTiming PipelineTiming::*;
    Stage stage;
};
constexpr std::array<NamedStage, 11> kStages{{
    {"predict", &PipelineTiming::predict},
    {"search", &PipelineTiming::search},
    {"match", &PipelineTiming::match},
    {"update", &PipelineTiming::update},
    {"map", &PipelineTiming::map},
    {"tracking", &PipelineTiming::tracking},
    {"detect_pre", &PipelineTiming::detect_pre},
    {"detect_forward", &PipelineTiming::detect_forward},
    {"detect_post", &PipelineTiming::detect_post},
    {"scale_update", &PipelineTiming::scale_update},
    {"scale_publish", &PipelineTiming::scale_publish},
}};

// ,"timing":{"predict":{"samples":N,"last_ms":x,"mean_ms":x,"max_ms":x},...}
// Times with 4 significant digits: plenty for a duration, and 11 stages stay
// short on a line clients may ask for every second.
void appendTiming(std::string& out, const PipelineTiming& timing) {
    constexpr int kDigits = 4;
    key(out, "timing");
    char open = '{';
    for (const NamedStage& s : kStages) {
        out += open;
        open = ',';
        appendJsonString(out, s.name);
        const StageTiming& t = timing.*s.stage;
        out += R"(:{"samples":)";
        appendJsonInt(out, t.samples);
        key(out, "last_ms");
        appendJsonNumber(out, t.last_ms, kDigits);
        key(out, "mean_ms");
        appendJsonNumber(out, t.mean_ms, kDigits);
        key(out, "max_ms");
        appendJsonNumber(out, t.max_ms, kDigits);
        out += '}';
    }
    out += '}';
}

Request invalid(std::string cmd, std::string message) {
    Request r;
    r.cmd = std::move(cmd);
    r.error = std::move(message);
    return r;
}

// The length of the JSON number at the start of `s` (RFC 8259:
// -?(0|[1-9][0-9]*)(.[0-9]+)?([eE][+-]?[0-9]+)?), 0 when none starts there.
std::size_t jsonNumberLength(std::string_view s) {
    std::size_t i = 0;
    const auto digits = [&] {
        const std::size_t start = i;
        while (i < s.size() && s[i] >= '0' && s[i] <= '9') {
            ++i;
        }
        return i - start;
    };
    if (i < s.size() && s[i] == '-') {
        ++i;
    }
    if (i < s.size() && s[i] == '0') {
        ++i;
    } else if (digits() == 0) {
        return 0;
    }
    if (i < s.size() && s[i] == '.') {
        ++i;
        if (digits() == 0) {
            return 0;
        }
    }
    if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
        ++i;
        if (i < s.size() && (s[i] == '+' || s[i] == '-')) {
            ++i;
        }
        if (digits() == 0) {
            return 0;
        }
    }
    return i;
}

// nlohmann::json refuses a number that overflows a double ("number
// overflow", 1e400) as a parse error. Writes `line` to `out` with every such
// number outside strings replaced by null, so the request is read and the
// member's own check answers; false (and `out` untouched) when there is none.
// Only run on a line that did not parse: the cost stays off the normal path.
bool nullOverflowingNumbers(std::string_view line, std::string& out) {
    bool changed = false;
    bool in_string = false;
    std::size_t copied = 0;
    std::string token;
    for (std::size_t i = 0; i < line.size();) {
        const char c = line[i];
        if (in_string) {
            if (c == '\\') {
                i += 2;
                continue;
            }
            in_string = c != '"';
            ++i;
            continue;
        }
        if (c == '"') {
            in_string = true;
            ++i;
            continue;
        }
        const std::size_t n =
            (c == '-' || (c >= '0' && c <= '9')) ? jsonNumberLength(line.substr(i)) : 0;
        if (n == 0) {
            ++i;
            continue;
        }
        token.assign(line.substr(i, n));
        if (std::isinf(std::strtod(token.c_str(), nullptr))) {
            out.append(line.substr(copied, i - copied));
            out += "null";
            copied = i + n;
            changed = true;
        }
        i += n;
    }
    if (changed) {
        out.append(line.substr(copied));
    }
    return changed;
}

// The length of the longest prefix of `s` of at most `max_bytes` bytes that
// does not cut a UTF-8 sequence.
std::size_t utf8Prefix(std::string_view s, std::size_t max_bytes) {
    if (s.size() <= max_bytes) {
        return s.size();
    }
    std::size_t n = max_bytes;
    while (n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0U) == 0x80U) {
        --n;
    }
    return n;
}

}  // namespace

const char* toString(Command command) {
    switch (command) {
        case Command::kInvalid:
            return "";
        case Command::kPoll:
            return "poll";
        case Command::kWatch:
            return "watch";
        case Command::kStatus:
            return "status";
        case Command::kPosterior:
            return "posterior";
        case Command::kSetGravity:
            return "set_gravity";
        case Command::kObjects:
            return "objects";
        case Command::kPose:
            return "pose";
    }
    return "";
}

void appendVersion(std::string& out, std::string_view release) {
    out += R"({"class":"VERSION","release":)";
    appendJsonString(out, release);
    key(out, "proto_major");
    appendJsonInt(out, kProtoMajor);
    key(out, "proto_minor");
    appendJsonInt(out, kProtoMinor);
    out += "}\n";
}

void appendScale(std::string& out, const ScaleReport& r, std::int64_t now_mono_ns) {
    out += R"({"class":"SCALE","scale":)";
    appendJsonNumberOr(out, r.has_scale, r.scale);
    key(out, "mean");
    appendJsonNumberOr(out, r.has_scale, r.mean);
    key(out, "ci68");
    appendJsonInterval(out, r.has_scale, r.ci68_lo, r.ci68_hi);
    key(out, "ci95");
    appendJsonInterval(out, r.has_scale, r.ci95_lo, r.ci95_hi);
    key(out, "state");
    appendJsonString(out, toString(r.state));
    key(out, "epoch");
    appendJsonInt(out, r.epoch);
    key(out, "observations");
    appendJsonInt(out, r.observations);
    key(out, "frame_id");
    appendJsonInt(out, r.frame_id);
    key(out, "t_ns");
    appendJsonInt(out, r.t_ns);
    key(out, "time");
    appendJsonNumber(out, static_cast<double>(r.t_ns) * 1e-9);
    key(out, "age_s");
    if (r.updated_mono_ns == 0) {
        out += "null";
    } else {
        appendJsonNumber(out, static_cast<double>(now_mono_ns - r.updated_mono_ns) * 1e-9);
    }
    if (!r.fault.empty()) {
        key(out, "fault");
        appendJsonString(out, r.fault);
    }
    if (r.previous.present) {
        out += R"(,"previous":{"epoch":)";
        appendJsonInt(out, r.previous.epoch);
        key(out, "scale");
        appendJsonNumber(out, r.previous.scale);
        key(out, "ci95");
        appendJsonInterval(out, true, r.previous.ci95_lo, r.previous.ci95_hi);
        key(out, "observations");
        appendJsonInt(out, r.previous.observations);
        key(out, "frame_id");
        appendJsonInt(out, r.previous.frame_id);
        out += '}';
    }
    out += "}\n";
}

namespace {

// STATUS: the vertical, the IMU and the gyro prior.
void appendStatusSensors(std::string& out, const PipelineStatus& s) {
    if (!s.gravity_source.empty()) {
        key(out, "gravity_source");
        appendJsonString(out, s.gravity_source);
    }
    if (s.gravity_down_C) {
        key(out, "gravity_down_C");
        appendArray(out, *s.gravity_down_C);
    }
    if (s.imu.configured) {
        out += R"(,"imu":{"device":)";
        appendJsonString(out, s.imu.device);
        key(out, "mode");
        appendJsonString(out, s.imu.mode);
        key(out, "samples");
        appendJsonInt(out, s.imu.samples);
        key(out, "errors");
        appendJsonInt(out, s.imu.errors);
        if (!s.imu.error.empty()) {
            key(out, "error");
            appendJsonString(out, s.imu.error);
        }
        out += '}';
    }
    if (s.gyro.present) {
        out += R"(,"gyro":{"source":)";
        appendJsonString(out, s.gyro.source);
        key(out, "frames");
        appendJsonInt(out, s.gyro.frames);
        key(out, "bias_C_radps");
        appendArray(out, s.gyro.bias_C_radps);
        out += '}';
    }
}

// STATUS: frames, detector, features, scale updates.
void appendStatusCounters(std::string& out, const PipelineStatus& s) {
    key(out, "uptime_s");
    appendJsonNumber(out, s.uptime_s);
    key(out, "fps");
    appendJsonNumber(out, s.fps);
    key(out, "frame_id");
    appendJsonInt(out, s.frame_id);
    key(out, "frames_total");
    appendJsonInt(out, s.frames_total);
    key(out, "source_finished");
    appendBool(out, s.source_finished);
    out += R"(,"frames":{"captured":)";
    appendJsonInt(out, s.frames_captured);
    key(out, "tracked");
    appendJsonInt(out, s.frames_tracked);
    key(out, "dropped");
    appendJsonInt(out, s.frames_dropped);
    out += R"(},"detector":{"runs":)";
    appendJsonInt(out, s.detections_run);
    key(out, "skipped");
    appendJsonInt(out, s.detections_skipped);
    out += R"(,"latency_ms":{"last":)";
    appendJsonNumber(out, s.detector_latency_ms_last);
    key(out, "mean");
    appendJsonNumber(out, s.detector_latency_ms_mean);
    key(out, "max");
    appendJsonNumber(out, s.detector_latency_ms_max);
    out += "}}";
    key(out, "tracking_ms_mean");
    appendJsonNumber(out, s.tracking_ms_mean);
    out += R"(,"features":{"in_map":)";
    appendJsonInt(out, s.features_in_map);
    key(out, "tracked");
    appendJsonInt(out, s.features_tracked);
    out += '}';
    key(out, "scale_updates");
    appendJsonInt(out, s.scale_updates);
    key(out, "epoch");
    appendJsonInt(out, s.epoch);
}

// STATUS.window_ba (proto_minor 5): the camera the window used and its
// latest optimisation ("last": null before the first).
void appendStatusWindowBa(std::string& out, const WindowBaStatus& w) {
    out += R"(,"window_ba":{"optimisations":)";
    appendJsonInt(out, w.optimisations);
    key(out, "estimated");
    out += '[';
    bool first = true;
    for (const auto& [name, on] :
         {std::pair{"rolling_shutter_s", w.rolling_shutter_estimated},
          std::pair{"focal_scale", w.focal_estimated}, std::pair{"k1", w.k1_estimated}}) {
        if (on) {
            out += first ? "" : ",";
            appendJsonString(out, name);
            first = false;
        }
    }
    out += ']';
    key(out, "rolling_shutter_s");
    appendJsonNumber(out, w.rolling_shutter_s);
    key(out, "focal_scale");
    appendJsonNumber(out, w.focal_scale);
    key(out, "k1");
    appendJsonNumber(out, w.k1);
    key(out, "last");
    if (w.optimisations == 0) {
        out += "null}";
        return;
    }
    out += R"({"frame_id":)";
    appendJsonInt(out, w.frame_id);
    key(out, "epoch");
    appendJsonInt(out, w.epoch);
    key(out, "keyframes");
    appendJsonInt(out, w.keyframes);
    key(out, "points");
    appendJsonInt(out, w.points);
    key(out, "observations");
    appendJsonInt(out, w.observations);
    key(out, "rms_px");
    appendJsonNumber(out, w.rms_px);
    key(out, "scale");
    appendJsonNumber(out, w.scale);
    out += "}}";
}

// STATUS: the socket's clients and the field log.
void appendStatusService(std::string& out, const LogStatus& log, const ClientCounts& clients) {
    out += R"(,"clients":{"connected":)";
    appendJsonInt(out, clients.connected);
    key(out, "max");
    appendJsonInt(out, clients.max);
    key(out, "accepted");
    appendJsonInt(out, clients.accepted);
    key(out, "rejected");
    appendJsonInt(out, clients.rejected);
    key(out, "detached");
    appendJsonInt(out, clients.detached);
    key(out, "watchers");
    appendJsonInt(out, clients.watchers);
    key(out, "reserved");
    appendJsonInt(out, clients.reserved);
    key(out, "timed_out");
    appendJsonInt(out, clients.timed_out);
    key(out, "evicted");
    appendJsonInt(out, clients.evicted);
    out += R"(},"log":{"state":)";
    appendJsonString(out, toString(log.state));
    key(out, "lines");
    appendJsonInt(out, log.lines_written);
    key(out, "dropped");
    appendJsonInt(out, log.lines_dropped);
    key(out, "bytes");
    appendJsonInt(out, log.bytes_written);
    if (!log.error.empty()) {
        key(out, "error");
        appendJsonString(out, log.error);
    }
}

}  // namespace

void appendStatus(std::string& out, const PipelineStatus& s, const LogStatus& log,
                  const ClientCounts& clients) {
    out += R"({"class":"STATUS","source":)";
    appendJsonString(out, s.source);
    appendStatusSensors(out, s);
    appendStatusCounters(out, s);
    if (s.live) {
        out += R"(,"camera":{"device":)";
        appendJsonString(out, s.camera_device);
        key(out, "mode");
        appendJsonString(out, s.camera_mode);
        key(out, "lost");
        appendBool(out, s.camera_lost);
        key(out, "reconnects");
        appendJsonInt(out, s.camera_reconnects);
        key(out, "repeated");
        appendJsonInt(out, s.camera_repeated);
        out += '}';
    }
    appendTiming(out, s.timing);
    if (s.window_ba.present) {
        appendStatusWindowBa(out, s.window_ba);
    }
    appendStatusService(out, log, clients);
    out += "}}\n";
}

void appendPosterior(std::string& out, const PosteriorSnapshot& p) {
    out += R"({"class":"POSTERIOR","epoch":)";
    appendJsonInt(out, p.epoch);
    key(out, "frame_id");
    appendJsonInt(out, p.frame_id);
    key(out, "observations");
    appendJsonInt(out, p.observations);
    const std::size_t n = std::min(p.d.size(), p.log_p.size());
    key(out, "d");
    appendArray(out, std::span<const double>(p.d.data(), n));
    key(out, "log_p");
    appendArray(out, std::span<const double>(p.log_p.data(), n));
    out += "}\n";
}

void appendObjectMembers(std::string& out, const ObjectReport& o, std::string_view class_key,
                         int digits) {
    const bool anchored = o.state != core::ObjectState::kTentative;
    out += R"("id":)";
    appendJsonInt(out, o.id);
    key(out, class_key);
    appendJsonString(out, o.className());
    key(out, "state");
    appendJsonString(out, core::toString(o.state));
    key(out, "anchor");
    if (anchored) {
        out += '[';
        appendJsonNumber(out, o.anchor[0], digits);
        out += ',';
        appendJsonNumber(out, o.anchor[1], digits);
        out += ',';
        appendJsonNumber(out, o.anchor[2], digits);
        out += ']';
    } else {
        out += "null";
    }
    key(out, "anchor_rel_sigma");
    appendJsonNumberOr(out, anchored, o.anchor_rel_sigma, digits);
    key(out, "detections");
    appendJsonInt(out, o.detections);
    key(out, "views");
    appendJsonInt(out, o.views);
    key(out, "views_used");
    appendJsonInt(out, o.views_used);
    key(out, "first_frame");
    appendJsonInt(out, o.first_frame);
    key(out, "last_frame");
    appendJsonInt(out, o.last_frame);
    key(out, "local_estimate");
    appendJsonNumberOr(out, o.local_estimate != 0, o.local_estimate, digits);
    key(out, "height_m");
    appendJsonNumberOr(out, o.has_height, o.height_m, digits);
    key(out, "height_ci95_m");
    appendJsonInterval(out, o.has_height, o.height_ci95_lo_m, o.height_ci95_hi_m, digits);
}

void appendObjects(std::string& out, const ObjectsSnapshot& s) {
    // 7 significant digits: more than a SLAM anchor or a height carries.
    constexpr int kDigits = 7;
    out += R"({"class":"OBJECTS","epoch":)";
    appendJsonInt(out, s.epoch);
    key(out, "frame_id");
    appendJsonInt(out, s.frame_id);
    key(out, "model");
    appendJsonString(out, core::toString(s.model));
    key(out, "objects");
    out += '[';
    bool first = true;
    for (const ObjectReport& o : s.objects) {
        out += first ? "{" : ",{";
        first = false;
        appendObjectMembers(out, o, "class", kDigits);
        out += '}';
    }
    out += "]}\n";
}

void appendPoseMembers(std::string& out, const PoseReport& pose, const MetricPose& m,
                       DaemonState state, int digits, int scale_digits) {
    const bool has_pose = pose.frame_id >= 0;
    key(out, "state");
    appendJsonString(out, toString(state));
    key(out, "scale");
    appendJsonNumberOr(out, m.has_scale, m.scale, scale_digits);
    key(out, "scale_sigma");
    appendJsonNumberOr(out, m.has_scale, m.scale_sigma, digits);
    key(out, "position");
    appendVector(out, m.has_scale, m.position_m, digits);
    key(out, "velocity");
    appendVector(out, m.has_scale, m.velocity_mps, digits);
    key(out, "position_cov");
    appendMatrix(out, m.has_scale, m.position_cov_m2, digits);
    key(out, "orientation");
    appendVector(out, has_pose, pose.orientation_wxyz, digits);
    key(out, "attitude_cov");
    appendMatrix(out, has_pose, pose.attitude_cov_rad2, digits);
    key(out, "position_map");
    appendVector(out, has_pose, pose.position_map, digits);
    key(out, "velocity_map");
    appendVector(out, has_pose, pose.velocity_map, digits);
    key(out, "position_map_cov");
    appendMatrix(out, has_pose, pose.position_cov_map, digits);
}

void appendPose(std::string& out, const PoseReport& pose, const ScaleReport& scale) {
    // 7 significant digits: 0.1 mm at 1 km, far below what the map knows.
    constexpr int kDigits = 7;
    const bool has_pose = pose.frame_id >= 0;
    const MetricPose m = metricPose(pose, scale);
    out += R"({"class":"POSE","epoch":)";
    appendJsonInt(out, pose.epoch);
    key(out, "frame_id");
    appendJsonInt(out, has_pose ? pose.frame_id : -1);
    key(out, "t_ns");
    appendJsonInt(out, has_pose ? pose.t_ns : 0);
    key(out, "time");
    appendJsonNumber(out, has_pose ? static_cast<double>(pose.t_ns) * 1e-9 : 0.0);
    appendPoseMembers(out, pose, m, scale.state, kDigits, 0);
    out += "}\n";
}

void appendWatch(std::string& out, bool enable, bool pose) {
    out += R"({"class":"WATCH","enable":)";
    appendBool(out, enable);
    key(out, "pose");
    appendBool(out, pose);
    out += "}\n";
}

void appendAck(std::string& out, std::string_view cmd) {
    out += R"({"class":"ACK","cmd":)";
    appendJsonString(out, cmd);
    out += "}\n";
}

void appendError(std::string& out, std::string_view message, std::string_view cmd) {
    out += R"({"class":"ERROR","message":)";
    appendJsonString(out, message);
    if (!cmd.empty()) {
        const std::size_t n = utf8Prefix(cmd, kMaxEchoBytes);
        key(out, "cmd");
        appendJsonString(out, cmd.substr(0, n));
        if (n < cmd.size()) {
            key(out, "truncated");
            appendBool(out, true);
        }
    }
    out += "}\n";
}

namespace {

// watch's arguments ("enable", "pose"); nullopt when valid, else what is wrong.
std::optional<std::string> readWatchArguments(const nlohmann::json& doc, Request& r) {
    const auto it = doc.find("enable");
    if (it != doc.end()) {
        if (!it->is_boolean()) {
            return std::string("\"enable\" must be true or false");
        }
        r.enable = it->get<bool>();
    }
    const auto pose_it = doc.find("pose");
    if (pose_it != doc.end()) {
        if (!pose_it->is_boolean()) {
            return std::string("\"pose\" must be true or false");
        }
        r.pose = pose_it->get<bool>();
    }
    return std::nullopt;
}

// set_gravity's "down", normalised; nullopt when valid, else what is wrong.
std::optional<std::string> readGravityArguments(const nlohmann::json& doc, Request& r) {
    using nlohmann::json;
    const auto it = doc.find("down");
    const char* bad = "\"down\" must be an array of 3 finite numbers, not all zero";
    if (it == doc.end() || !it->is_array() || it->size() != 3) {
        return std::string(bad);
    }
    for (std::size_t i = 0; i < 3; ++i) {
        const json& v = (*it)[i];
        if (!v.is_number()) {
            return std::string(bad);
        }
        r.down[i] = v.get<double>();
        if (!std::isfinite(r.down[i])) {
            return std::string(bad);
        }
    }
    const double norm = safeNorm(r.down);
    if (!(norm > 0) || !std::isfinite(norm)) {
        return std::string(bad);
    }
    for (double& v : r.down) {
        v /= norm;
    }
    return std::nullopt;
}

}  // namespace

Request parseRequest(std::string_view line) {
    using nlohmann::json;
    // nlohmann::json stops at a NUL byte as at the end of the input.
    if (line.find('\0') != std::string_view::npos) {
        return invalid({}, "request contains a NUL byte");
    }
    json doc = json::parse(line.begin(), line.end(), nullptr, false);
    if (doc.is_discarded()) {
        std::string nulled;
        if (nullOverflowingNumbers(line, nulled)) {
            doc = json::parse(nulled.begin(), nulled.end(), nullptr, false);
        }
        if (doc.is_discarded()) {
            return invalid({}, "request is not valid JSON");
        }
    }
    if (!doc.is_object()) {
        return invalid({}, "request must be a JSON object");
    }
    const auto cmd_it = doc.find("cmd");
    if (cmd_it == doc.end()) {
        return invalid({}, "request has no \"cmd\"");
    }
    if (!cmd_it->is_string()) {
        return invalid({}, "\"cmd\" must be a string");
    }
    Request r;
    r.cmd = cmd_it->get_ref<const std::string&>();
    if (r.cmd == "poll") {
        r.command = Command::kPoll;
    } else if (r.cmd == "status") {
        r.command = Command::kStatus;
    } else if (r.cmd == "posterior") {
        r.command = Command::kPosterior;
    } else if (r.cmd == "objects") {
        r.command = Command::kObjects;
    } else if (r.cmd == "pose") {
        r.command = Command::kPose;
    } else if (r.cmd == "watch") {
        if (auto bad = readWatchArguments(doc, r)) {
            return invalid(r.cmd, *bad);
        }
        r.command = Command::kWatch;
    } else if (r.cmd == "set_gravity") {
        if (auto bad = readGravityArguments(doc, r)) {
            return invalid(r.cmd, *bad);
        }
        r.command = Command::kSetGravity;
    } else {
        // The name is echoed once, in "cmd" (appendError caps it).
        return invalid(r.cmd,
                       "unknown command (known: poll, watch, status, posterior, objects, pose, "
                       "set_gravity)");
    }
    return r;
}

}  // namespace scaled::daemon
