#include "scalectl.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>
#include <poll.h>
#include <sstream>
#include <sys/socket.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>
#include <utility>

#include <scaled/drivers/base/errno_text.h>

#include "sysexits.h"

namespace scaled::tools::scalectl {

namespace {

using core::ErrorCode;
using core::makeError;
using nlohmann::json;

core::Error parseError(std::string message) {
    return makeError(ErrorCode::kParse, std::move(message));
}

// `value` with `decimals` digits after the point.
std::string fixed(double value, int decimals) {
    std::array<char, 64> buf{};
    std::snprintf(buf.data(), buf.size(), "%.*f", decimals, value);
    return buf.data();
}

// The line as a JSON object with a string "class".
core::Result<json> parseObject(std::string_view line) {
    json doc = json::parse(line, nullptr, false);
    if (doc.is_discarded()) {
        return parseError("malformed reply (not JSON): " + std::string(line.substr(0, 200)));
    }
    if (!doc.is_object()) {
        return parseError("malformed reply (not a JSON object): " +
                          std::string(line.substr(0, 200)));
    }
    const auto it = doc.find("class");
    if (it == doc.end() || !it->is_string()) {
        return parseError("malformed reply (no \"class\"): " + std::string(line.substr(0, 200)));
    }
    return doc;
}

// The object of class `expected`; an ERROR reply or another class is an error.
core::Result<json> expectClass(std::string_view line, const char* expected) {
    auto doc = parseObject(line);
    if (!doc) {
        return doc.error();
    }
    const auto& cls = (*doc)["class"].get_ref<const std::string&>();
    if (cls == "ERROR") {
        const auto it = doc->find("message");
        const std::string message =
            it != doc->end() && it->is_string() ? it->get<std::string>() : "(no message)";
        return parseError("the daemon replied ERROR: " + message);
    }
    if (cls != expected) {
        return parseError("expected a " + std::string(expected) + " reply, got " + cls);
    }
    return doc;
}

// Field readers: false when present with the wrong type. `out` is left alone
// when the field is absent (or null, for the optional ones).
bool readOptionalNumber(const json& doc, const char* key, std::optional<double>& out) {
    const auto it = doc.find(key);
    if (it == doc.end() || it->is_null()) {
        out.reset();
        return true;
    }
    if (!it->is_number()) {
        return false;
    }
    out = it->get<double>();
    return true;
}

bool readInteger(const json& doc, const char* key, bool required, std::int64_t& out) {
    const auto it = doc.find(key);
    if (it == doc.end()) {
        return !required;
    }
    if (it->is_number_integer()) {
        out = it->get<std::int64_t>();
        return true;
    }
    return false;
}

bool readInterval(const json& doc, const char* key, std::optional<Interval>& out) {
    const auto it = doc.find(key);
    if (it == doc.end() || it->is_null()) {
        out.reset();
        return true;
    }
    if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number() || !(*it)[1].is_number()) {
        return false;
    }
    out = Interval{(*it)[0].get<double>(), (*it)[1].get<double>()};
    return true;
}

// The value at a path of keys, or nullptr.
const json* at(const json& doc, std::initializer_list<const char*> keys) {
    const json* node = &doc;
    for (const char* key : keys) {
        if (!node->is_object()) {
            return nullptr;
        }
        const auto it = node->find(key);
        if (it == node->end()) {
            return nullptr;
        }
        node = &*it;
    }
    return node;
}

// A value for the STATUS summary: numbers with `decimals` digits after the
// point (integers as integers), strings as they are, booleans as yes/no, `-`
// when absent or null.
std::string show(const json& doc, std::initializer_list<const char*> keys, int decimals = 1) {
    const json* v = at(doc, keys);
    if (v == nullptr || v->is_null()) {
        return "-";
    }
    if (v->is_number_integer()) {
        return std::to_string(v->get<std::int64_t>());
    }
    if (v->is_number_unsigned()) {
        return std::to_string(v->get<std::uint64_t>());
    }
    if (v->is_number()) {
        std::array<char, 64> buf{};
        std::snprintf(buf.data(), buf.size(), "%.*f", decimals, v->get<double>());
        return buf.data();
    }
    if (v->is_boolean()) {
        return v->get<bool>() ? "yes" : "no";
    }
    if (v->is_string()) {
        return v->get<std::string>();
    }
    return v->dump();
}

// STATUS.timing (proto_minor 2; absent from older daemons: nothing printed):
// one row per stage, the known stages in pipeline order, then any stage a
// newer daemon adds.
void formatTiming(const json& doc, std::ostream& o) {
    const json* timing = at(doc, {"timing"});
    if (timing == nullptr || !timing->is_object() || timing->empty()) {
        return;
    }
    static constexpr std::array<const char*, 11> kKnown = {
        "predict",    "search",         "match",       "update",       "map",          "tracking",
        "detect_pre", "detect_forward", "detect_post", "scale_update", "scale_publish"};
    std::array<char, 160> row{};
    std::snprintf(row.data(), row.size(), "%-15s%-16s%9s%9s%9s%9s\n", "timing (ms)", "", "last",
                  "mean", "max", "samples");
    o << row.data();
    auto print = [&](const std::string& name) {
        // Milliseconds always with 3 decimals (the daemon writes 4 significant
        // digits, so 4.0 arrives as the integer 4).
        const auto ms = [&](const char* field) {
            const json* v = at(*timing, {name.c_str(), field});
            return v != nullptr && v->is_number() ? fixed(v->get<double>(), 3) : std::string("-");
        };
        std::snprintf(row.data(), row.size(), "%-15s%-16s%9s%9s%9s%9s\n", "", name.c_str(),
                      ms("last_ms").c_str(), ms("mean_ms").c_str(), ms("max_ms").c_str(),
                      show(*timing, {name.c_str(), "samples"}).c_str());
        o << row.data();
    };
    for (const char* name : kKnown) {
        if (timing->contains(name)) {
            print(name);
        }
    }
    for (const auto& [name, value] : timing->items()) {
        if (std::find(kKnown.begin(), kKnown.end(), std::string_view(name)) == kKnown.end()) {
            print(name);
        }
    }
}

core::Status waitUntil(int fd, short events, int interrupt_fd,
                       std::optional<Clock::time_point> deadline) {
    for (;;) {
        int timeout_ms = -1;
        if (deadline) {
            const auto left =
                std::chrono::ceil<std::chrono::milliseconds>(*deadline - Clock::now());
            timeout_ms = static_cast<int>(std::max<std::int64_t>(0, left.count()));
        }
        std::array<pollfd, 2> fds{};
        fds[0] = pollfd{fd, events, 0};
        fds[1] = pollfd{interrupt_fd, POLLIN, 0};
        const nfds_t n = interrupt_fd >= 0 ? 2 : 1;
        const int rc = ::poll(fds.data(), n, timeout_ms);
        if (rc < 0) {
            if (errno == EINTR) {
                continue;  // a signal handler wrote to the interrupt fd, or an unrelated one
            }
            return makeError(ErrorCode::kIo,
                             std::string("poll: ") + drivers::base::errnoText(errno));
        }
        if (n == 2 && (fds[1].revents & (POLLIN | POLLHUP)) != 0) {
            return makeError(ErrorCode::kDegenerate, "interrupted");
        }
        if (fds[0].revents != 0) {
            return {};  // ready, or an error/hangup the next recv/send reports
        }
        if (rc == 0) {
            return makeError(ErrorCode::kIo, "timed out waiting for the daemon");
        }
    }
}

}  // namespace

std::string defaultSocketPath() {
    const char* env = std::getenv("SCALED_SOCKET");  // NOLINT(concurrency-mt-unsafe)
    if (env != nullptr && *env != '\0') {
        return env;
    }
    return kDefaultSocket;
}

// ---- reply lines ----------------------------------------------------------

core::Result<std::string> replyClass(std::string_view line) {
    auto doc = parseObject(line);
    if (!doc) {
        return doc.error();
    }
    return (*doc)["class"].get<std::string>();
}

core::Result<VersionReply> parseVersion(std::string_view line) {
    auto doc = expectClass(line, "VERSION");
    if (!doc) {
        return doc.error();
    }
    VersionReply v;
    std::int64_t major = -1;
    std::int64_t minor = 0;
    if (!readInteger(*doc, "proto_major", true, major) ||
        !readInteger(*doc, "proto_minor", false, minor)) {
        return parseError("malformed VERSION (proto_major/proto_minor): " +
                          std::string(line.substr(0, 200)));
    }
    if (const auto it = doc->find("release"); it != doc->end() && it->is_string()) {
        v.release = it->get<std::string>();
    }
    v.proto_major = static_cast<int>(major);
    v.proto_minor = static_cast<int>(minor);
    if (v.proto_major != kProtoMajor) {
        return parseError("the daemon speaks protocol " + std::to_string(v.proto_major) + "." +
                          std::to_string(v.proto_minor) + ", scalectl speaks " +
                          std::to_string(kProtoMajor) + ".x");
    }
    return v;
}

core::Result<ScaleReply> parseScale(std::string_view line) {
    auto doc = expectClass(line, "SCALE");
    if (!doc) {
        return doc.error();
    }
    ScaleReply s;
    const auto state = doc->find("state");
    if (state == doc->end() || !state->is_string()) {
        return parseError("malformed SCALE (no \"state\"): " + std::string(line.substr(0, 200)));
    }
    s.state = state->get<std::string>();
    if (!readOptionalNumber(*doc, "scale", s.scale) || !readOptionalNumber(*doc, "mean", s.mean) ||
        !readInterval(*doc, "ci68", s.ci68) || !readInterval(*doc, "ci95", s.ci95) ||
        !readOptionalNumber(*doc, "age_s", s.age_s) || !readInteger(*doc, "epoch", true, s.epoch) ||
        !readInteger(*doc, "observations", true, s.observations) ||
        !readInteger(*doc, "frame_id", false, s.frame_id)) {
        return parseError("malformed SCALE (a field has the wrong type or is missing): " +
                          std::string(line.substr(0, 200)));
    }
    if (const auto it = doc->find("fault"); it != doc->end() && it->is_string()) {
        s.fault = it->get<std::string>();
    }
    return s;
}

core::Result<PosteriorReply> parsePosterior(std::string_view line) {
    auto doc = expectClass(line, "POSTERIOR");
    if (!doc) {
        return doc.error();
    }
    PosteriorReply p;
    const auto d = doc->find("d");
    const auto log_p = doc->find("log_p");
    const bool ok = readInteger(*doc, "epoch", false, p.epoch) &&
                    readInteger(*doc, "frame_id", false, p.frame_id) &&
                    readInteger(*doc, "observations", false, p.observations) && d != doc->end() &&
                    d->is_array() && log_p != doc->end() && log_p->is_array() &&
                    d->size() == log_p->size();
    if (!ok) {
        return parseError("malformed POSTERIOR (d and log_p must be arrays of one length): " +
                          std::string(line.substr(0, 200)));
    }
    p.d.reserve(d->size());
    p.log_p.reserve(d->size());
    for (std::size_t i = 0; i < d->size(); ++i) {
        const json& di = (*d)[i];
        const json& li = (*log_p)[i];
        // log p of an impossible value is -inf, which JSON spells null.
        if (!di.is_number() || !(li.is_number() || li.is_null())) {
            return parseError("malformed POSTERIOR (entry " + std::to_string(i) +
                              " is not a number)");
        }
        p.d.push_back(di.get<double>());
        p.log_p.push_back(li.is_null() ? -HUGE_VAL : li.get<double>());
    }
    return p;
}

namespace {

// A fixed-length array of numbers, or absent (null or missing); false when
// present with another shape.
template <std::size_t N>
bool readNumbers(const json& doc, const char* key, std::optional<std::array<double, N>>& out) {
    const auto it = doc.find(key);
    if (it == doc.end() || it->is_null()) {
        out.reset();
        return true;
    }
    if (!it->is_array() || it->size() != N) {
        return false;
    }
    std::array<double, N> v{};
    for (std::size_t i = 0; i < N; ++i) {
        if (!(*it)[i].is_number()) {
            return false;
        }
        v[i] = (*it)[i].get<double>();
    }
    out = v;
    return true;
}

// A 3x3 matrix (rows of three numbers), row-major, or absent.
bool readMatrix3(const json& doc, const char* key, std::optional<std::array<double, 9>>& out) {
    const auto it = doc.find(key);
    if (it == doc.end() || it->is_null()) {
        out.reset();
        return true;
    }
    if (!it->is_array() || it->size() != 3) {
        return false;
    }
    std::array<double, 9> m{};
    for (std::size_t r = 0; r < 3; ++r) {
        const json& row = (*it)[r];
        if (!row.is_array() || row.size() != 3) {
            return false;
        }
        for (std::size_t c = 0; c < 3; ++c) {
            if (!row[c].is_number()) {
                return false;
            }
            m[3 * r + c] = row[c].get<double>();
        }
    }
    out = m;
    return true;
}

// `value` with `decimals` digits, never "-0.0" for a value that rounds to zero.
std::string rounded(double value, int decimals) {
    const double scale = std::pow(10.0, decimals);
    return fixed(std::round(value * scale) / scale + 0.0, decimals);
}

std::string triple(const std::array<double, 3>& v, int decimals) {
    return rounded(v[0], decimals) + " " + rounded(v[1], decimals) + " " + rounded(v[2], decimals);
}

}  // namespace

core::Result<PoseReply> parsePose(std::string_view line) {
    auto doc = expectClass(line, "POSE");
    if (!doc) {
        return doc.error();
    }
    PoseReply p;
    const auto state = doc->find("state");
    const bool ok =
        state != doc->end() && state->is_string() && readInteger(*doc, "epoch", true, p.epoch) &&
        readInteger(*doc, "frame_id", true, p.frame_id) &&
        readOptionalNumber(*doc, "scale", p.scale) &&
        readOptionalNumber(*doc, "scale_sigma", p.scale_sigma) &&
        readNumbers(*doc, "position", p.position) && readNumbers(*doc, "velocity", p.velocity) &&
        readMatrix3(*doc, "position_cov", p.position_cov) &&
        readNumbers(*doc, "orientation", p.orientation) &&
        readNumbers(*doc, "position_map", p.position_map) &&
        readNumbers(*doc, "velocity_map", p.velocity_map);
    if (!ok) {
        return parseError("malformed POSE (a field has the wrong type or is missing): " +
                          std::string(line.substr(0, 200)));
    }
    p.state = state->get<std::string>();
    return p;
}

YawPitchRoll yawPitchRoll(const std::array<double, 4>& q) {
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(n > 0)) {
        return {};
    }
    const double w = q[0] / n;
    const double x = q[1] / n;
    const double y = q[2] / n;
    const double z = q[3] / n;
    // Columns of R_CtoG: the camera's right (x), down (y) and optical axis (z) in G.
    const std::array<double, 3> right{1 - 2 * (y * y + z * z), 2 * (x * y + w * z),
                                      2 * (x * z - w * y)};
    const std::array<double, 3> down{2 * (x * y - w * z), 1 - 2 * (x * x + z * z),
                                     2 * (y * z + w * x)};
    const std::array<double, 3> fwd{2 * (x * z + w * y), 2 * (y * z - w * x),
                                    1 - 2 * (x * x + y * y)};
    constexpr double kDeg = 180.0 / M_PI;
    YawPitchRoll r;
    r.yaw_deg = std::atan2(fwd[1], fwd[0]) * kDeg;
    r.pitch_deg = std::asin(std::clamp(fwd[2], -1.0, 1.0)) * kDeg;
    // Roll of the body (x forward, y left = -right, z up = -down) about x.
    r.roll_deg = std::atan2(-right[2], -down[2]) * kDeg;
    return r;
}

// ---- formatting -----------------------------------------------------------

std::string formatPose(const PoseReply& p) {
    if (p.frame_id < 0 || !p.orientation) {
        return "pose -  " + p.state + "  epoch " + std::to_string(p.epoch);
    }
    std::string out = "pose " + std::to_string(p.frame_id) + "  pos ";
    if (p.position) {
        out += triple(*p.position, 3) + " m";
        if (p.position_cov) {
            const auto& c = *p.position_cov;
            const std::array<double, 3> sigma{std::sqrt(std::max(0.0, c[0])),
                                              std::sqrt(std::max(0.0, c[4])),
                                              std::sqrt(std::max(0.0, c[8]))};
            out += "  1-sigma " + triple(sigma, 3) + " m";
        }
    } else {
        out += "-";
        if (p.position_map) {
            out += " (map " + triple(*p.position_map, 3) + " units)";
        }
    }
    const YawPitchRoll a = yawPitchRoll(*p.orientation);
    out += "  ypr " + rounded(a.yaw_deg, 1) + " " + rounded(a.pitch_deg, 1) + " " +
           rounded(a.roll_deg, 1) + " deg";
    out += "  vel " + (p.velocity ? triple(*p.velocity, 3) + " m/s" : std::string("-"));
    out += "  " + p.state + "  epoch " + std::to_string(p.epoch);
    return out;
}

std::string formatScale(const ScaleReply& s) {
    std::string out = "scale ";
    if (s.scale) {
        out += fixed(*s.scale, 4) + " m/unit";
        if (s.ci95) {
            out += "  95% [" + fixed(s.ci95->lo, 4) + ", " + fixed(s.ci95->hi, 4) + "]";
        }
    } else {
        out += "-";
    }
    out += "  " + s.state;
    out += "  epoch " + std::to_string(s.epoch);
    out += "  obs " + std::to_string(s.observations);
    if (s.age_s) {
        out += "  age " + fixed(*s.age_s, 1) + " s";
    }
    if (!s.fault.empty()) {
        out += "  fault: " + s.fault;
    }
    return out;
}

// STATUS.window_ba (proto_minor 5; absent when the window is off or from an
// older daemon: nothing printed): the camera the window used, "(estimated)"
// after what it estimates, then its latest optimisation.
void formatWindowBa(const json& doc, std::ostream& o) {
    const json* w = at(doc, {"window_ba"});
    if (w == nullptr || !w->is_object()) {
        return;
    }
    const json* estimated = at(*w, {"estimated"});
    const auto mark = [&](const char* name) {
        if (estimated == nullptr || !estimated->is_array()) {
            return "";
        }
        for (const json& e : *estimated) {
            if (e.is_string() && e.get<std::string>() == name) {
                return " (estimated)";
            }
        }
        return "";
    };
    // Numbers with fixed decimals (the daemon writes 1.0 as the integer 1).
    const auto number = [](const json& obj, const char* k, int decimals, double factor = 1) {
        const json* v = at(obj, {k});
        return v != nullptr && v->is_number() ? fixed(v->get<double>() * factor, decimals)
                                              : std::string("-");
    };
    o << "window         optimisations " << show(*w, {"optimisations"}) << "  readout "
      << number(*w, "rolling_shutter_s", 1, 1e3) << " ms" << mark("rolling_shutter_s")
      << "  focal x" << number(*w, "focal_scale", 4) << mark("focal_scale") << "  k1 "
      << number(*w, "k1", 4) << mark("k1") << '\n';
    const json* last = at(*w, {"last"});
    if (last != nullptr && last->is_object()) {
        o << "               last: frame " << show(*last, {"frame_id"}) << "  epoch "
          << show(*last, {"epoch"}) << "  keyframes " << show(*last, {"keyframes"}) << "  points "
          << show(*last, {"points"}) << "  rms " << number(*last, "rms_px", 3) << " px  scale "
          << number(*last, "scale", 4) << '\n';
    }
}

core::Result<std::string> formatStatus(std::string_view line) {
    auto parsed = expectClass(line, "STATUS");
    if (!parsed) {
        return parsed.error();
    }
    const json& j = *parsed;
    std::ostringstream o;
    const json* finished = at(j, {"source_finished"});
    const bool done = finished != nullptr && finished->is_boolean() && finished->get<bool>();
    o << "source         " << show(j, {"source"}) << (done ? " (finished)" : "") << '\n';
    o << "uptime         " << show(j, {"uptime_s"}) << " s\n";
    o << "frames         captured " << show(j, {"frames", "captured"}) << "  tracked "
      << show(j, {"frames", "tracked"}) << "  dropped " << show(j, {"frames", "dropped"})
      << "  (frame " << show(j, {"frame_id"}) << " of " << show(j, {"frames_total"}) << ", "
      << show(j, {"fps"}) << " fps)\n";
    o << "tracking       " << show(j, {"tracking_ms_mean"}) << " ms per frame  features in map "
      << show(j, {"features", "in_map"}) << "  tracked " << show(j, {"features", "tracked"})
      << '\n';
    o << "detector       runs " << show(j, {"detector", "runs"}) << "  skipped "
      << show(j, {"detector", "skipped"}) << "  latency last "
      << show(j, {"detector", "latency_ms", "last"}) << " ms  mean "
      << show(j, {"detector", "latency_ms", "mean"}) << " ms  max "
      << show(j, {"detector", "latency_ms", "max"}) << " ms\n";
    o << "scale          updates " << show(j, {"scale_updates"}) << "  epoch " << show(j, {"epoch"})
      << '\n';
    formatWindowBa(j, o);
    formatTiming(j, o);
    // max: socket.max_clients; reserved: further connections kept for queries
    // (a daemon before issue 22 has neither reserved nor the counters after it).
    o << "clients        connected " << show(j, {"clients", "connected"}) << "/"
      << show(j, {"clients", "max"}) << "+" << show(j, {"clients", "reserved"}) << "  watchers "
      << show(j, {"clients", "watchers"}) << "  accepted " << show(j, {"clients", "accepted"})
      << "  rejected " << show(j, {"clients", "rejected"}) << "  detached "
      << show(j, {"clients", "detached"}) << "  timed out " << show(j, {"clients", "timed_out"})
      << "  evicted " << show(j, {"clients", "evicted"}) << '\n';
    o << "log            " << show(j, {"log", "state"}) << "  lines " << show(j, {"log", "lines"})
      << "  dropped " << show(j, {"log", "dropped"}) << "  bytes " << show(j, {"log", "bytes"});
    const json* log_error = at(j, {"log", "error"});
    if (log_error != nullptr && log_error->is_string() && !log_error->get<std::string>().empty()) {
        o << "  error: " << log_error->get<std::string>();
    }
    o << '\n';
    return o.str();
}

core::Result<std::string> formatObjects(std::string_view line) {
    auto parsed = expectClass(line, "OBJECTS");
    if (!parsed) {
        return parsed.error();
    }
    const json& j = *parsed;
    const json* objects = at(j, {"objects"});
    if (objects == nullptr || !objects->is_array() ||
        !std::all_of(objects->begin(), objects->end(),
                     [](const json& o) { return o.is_object(); })) {
        return parseError("malformed OBJECTS (objects must be an array of objects): " +
                          std::string(line.substr(0, 200)));
    }
    const auto number = [](const json& o, const char* k, int decimals) {
        const json* v = at(o, {k});
        return v != nullptr && v->is_number() ? fixed(v->get<double>(), decimals)
                                              : std::string("-");
    };
    const std::string model = show(j, {"model"});
    std::size_t used = 0;
    for (const json& o : *objects) {
        const json* state = at(o, {"state"});
        if (state != nullptr && state->is_string() && state->get<std::string>() == "used") {
            ++used;
        }
    }
    std::ostringstream out;
    out << "model " << model << "  epoch " << show(j, {"epoch"}) << "  frame "
        << show(j, {"frame_id"}) << "  objects " << objects->size() << "  used " << used << '\n';
    if (objects->empty()) {
        out << (model == "paper" ? "no object table: the paper model uses every feature in a box "
                                   "(estimator.model = \"object\" keeps one)\n"
                                 : "no objects yet in this epoch\n");
        return out.str();
    }
    std::array<char, 256> row{};
    std::snprintf(row.data(), row.size(), "%4s  %-14s  %-9s  %9s  %8s  %-22s  %-26s  %9s\n", "id",
                  "class", "state", "views/det", "local", "height m [95%]", "anchor (map units)",
                  "rel.sigma");
    out << row.data();
    for (const json& o : *objects) {
        const std::string views = show(o, {"views_used"}) + "/" + show(o, {"detections"});
        std::string height = number(o, "height_m", 3);
        const json* ci = at(o, {"height_ci95_m"});
        if (height != "-" && ci != nullptr && ci->is_array() && ci->size() == 2 &&
            (*ci)[0].is_number() && (*ci)[1].is_number()) {
            height += " [" + fixed((*ci)[0].get<double>(), 3) + ", " +
                      fixed((*ci)[1].get<double>(), 3) + "]";
        }
        std::string anchor = "-";
        const json* a = at(o, {"anchor"});
        if (a != nullptr && a->is_array() && a->size() == 3 &&
            std::all_of(a->begin(), a->end(), [](const json& v) { return v.is_number(); })) {
            anchor = "(" + fixed((*a)[0].get<double>(), 3) + ", " +
                     fixed((*a)[1].get<double>(), 3) + ", " + fixed((*a)[2].get<double>(), 3) + ")";
        }
        std::snprintf(row.data(), row.size(), "%4s  %-14s  %-9s  %9s  %8s  %-22s  %-26s  %9s\n",
                      show(o, {"id"}).c_str(), show(o, {"class"}).c_str(),
                      show(o, {"state"}).c_str(), views.c_str(),
                      number(o, "local_estimate", 4).c_str(), height.c_str(), anchor.c_str(),
                      number(o, "anchor_rel_sigma", 3).c_str());
        out << row.data();
    }
    return out.str();
}

std::string formatPosterior(const PosteriorReply& p) {
    std::string out;
    out.reserve(p.d.size() * 24);
    std::array<char, 80> buf{};
    for (std::size_t i = 0; i < p.d.size(); ++i) {
        std::snprintf(buf.data(), buf.size(), "%.6g\t%.6g\n", p.d[i], p.log_p[i]);
        out += buf.data();
    }
    return out;
}

// ---- exit codes -----------------------------------------------------------

int exitCodeFor(const core::Error& error) {
    switch (error.code) {
        case ErrorCode::kParse:
            return kExProtocol;
        case ErrorCode::kInvalidArgument:
            return kExUsage;
        default:
            return kExUnavailable;
    }
}

int getExitCode(const ScaleReply& scale, bool require_converged) {
    if (require_converged && scale.state != "converged") {
        return kExTempFail;
    }
    return 0;
}

// ---- the connection -------------------------------------------------------

core::Result<Client> Client::connect(const std::string& path,
                                     std::optional<Clock::time_point> deadline) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.empty() || path.size() >= sizeof(addr.sun_path)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "socket path '" + path + "' is empty or longer than " +
                             std::to_string(sizeof(addr.sun_path) - 1) + " bytes");
    }
    std::memcpy(static_cast<void*>(addr.sun_path), path.data(), path.size());
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) {
        return makeError(ErrorCode::kIo, std::string("socket: ") + drivers::base::errnoText(errno));
    }
    Client client(fd);
    for (;;) {
        // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast): the sockets API
        if (::connect(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)) == 0) {
            return client;
        }
        const int err = errno;
        if (err == EINTR) {
            continue;
        }
        if (err == EAGAIN) {
            // The listen backlog is full: the daemon is alive but busy. Retry.
            if (deadline && Clock::now() >= *deadline) {
                return makeError(ErrorCode::kIo, "timed out connecting to " + path +
                                                     " (the daemon's backlog is full)");
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
            continue;
        }
        if (err == EINPROGRESS) {
            auto ready = client.waitFor(POLLOUT, deadline);
            if (!ready) {
                return ready.error();
            }
            int so_error = 0;
            socklen_t len = sizeof(so_error);
            ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &so_error, &len);
            if (so_error == 0) {
                return client;
            }
            errno = so_error;
            return makeError(ErrorCode::kIo, "cannot connect to " + path + ": " +
                                                 drivers::base::errnoText(so_error));
        }
        if (err == ENOENT) {
            return makeError(
                ErrorCode::kNotFound,
                "no socket at " + path + " (is scaled running? --socket, SCALED_SOCKET)");
        }
        if (err == ECONNREFUSED) {
            return makeError(ErrorCode::kIo,
                             "connection refused at " + path + " (is scaled running?)");
        }
        if (err == EACCES) {
            return makeError(ErrorCode::kIo, "permission denied on " + path +
                                                 " (is this user in the group scaled?)");
        }
        return makeError(ErrorCode::kIo,
                         "cannot connect to " + path + ": " + drivers::base::errnoText(err));
    }
}

core::Status Client::waitFor(short events, std::optional<Clock::time_point> deadline) {
    return waitUntil(fd_.get(), events, interrupt_fd_, deadline);
}

core::Status Client::sendLine(std::string_view line, std::optional<Clock::time_point> deadline) {
    std::string data(line);
    data += '\n';
    std::size_t sent = 0;
    while (sent < data.size()) {
        const ssize_t n = ::send(fd_.get(), data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
        if (n >= 0) {
            sent += static_cast<std::size_t>(n);
            continue;
        }
        if (errno == EINTR) {
            continue;
        }
        if (errno == EAGAIN || errno == EWOULDBLOCK) {
            auto ready = waitFor(POLLOUT, deadline);
            if (!ready) {
                return ready.error();
            }
            continue;
        }
        if (errno == EPIPE || errno == ECONNRESET) {
            return makeError(ErrorCode::kIo, "the daemon closed the connection");
        }
        return makeError(ErrorCode::kIo, std::string("send: ") + drivers::base::errnoText(errno));
    }
    return {};
}

core::Result<std::string> Client::readLine(std::optional<Clock::time_point> deadline) {
    for (;;) {
        if (const auto nl = buffer_.find('\n'); nl != std::string::npos) {
            std::string line = buffer_.substr(0, nl);
            buffer_.erase(0, nl + 1);
            if (!line.empty() && line.back() == '\r') {
                line.pop_back();
            }
            return line;
        }
        if (buffer_.size() > kMaxLineBytes) {
            return parseError("a reply line is longer than " + std::to_string(kMaxLineBytes) +
                              " bytes");
        }
        if (eof_) {
            return makeError(ErrorCode::kIo, buffer_.empty()
                                                 ? "the daemon closed the connection"
                                                 : "the daemon closed the connection mid-line");
        }
        auto ready = waitFor(POLLIN, deadline);
        if (!ready) {
            return ready.error();
        }
        std::array<char, 65536> chunk{};
        const ssize_t n = ::recv(fd_.get(), chunk.data(), chunk.size(), 0);
        if (n > 0) {
            buffer_.append(chunk.data(), static_cast<std::size_t>(n));
        } else if (n == 0 || errno == ECONNRESET) {
            eof_ = true;  // closed (a reset, too, ends the stream)
        } else if (errno != EINTR && errno != EAGAIN && errno != EWOULDBLOCK) {
            return makeError(ErrorCode::kIo,
                             std::string("recv: ") + drivers::base::errnoText(errno));
        }
    }
}

// ---- the commands ---------------------------------------------------------

namespace {

class Session {
public:
    Session(const Options& options, std::ostream& out, std::ostream& err)
        : options_(options), out_(out), err_(err) {}

    int run() {
        auto connected = Client::connect(options_.socket_path, replyDeadline());
        if (!connected) {
            return fail(connected.error());
        }
        client_ = std::move(*connected);
        client_.setInterruptFd(options_.interrupt_fd);

        auto greeting = client_.readLine(replyDeadline());
        if (!greeting) {
            return fail(greeting.error(), "before its VERSION greeting");
        }
        auto version = parseVersion(*greeting);
        if (!version) {
            return fail(version.error());
        }
        switch (options_.command) {
            case Command::kGet:
                return get();
            case Command::kWatch:
                return watch(*version);
            case Command::kStatus:
                return status();
            case Command::kPosterior:
                return posterior();
            case Command::kObjects:
                return objects(*version);
            case Command::kPose:
                return pose(*version);
        }
        return kExSoftware;
    }

private:
    [[nodiscard]] Clock::time_point deadlineIn(double seconds) const {
        return Clock::now() +
               std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    }
    // Connecting, the greeting and one reply: --timeout, 5 s by default.
    [[nodiscard]] Clock::time_point replyDeadline() const {
        return deadlineIn(options_.timeout_s.value_or(kDefaultTimeoutS));
    }

    int fail(const core::Error& error, const char* context = nullptr) {
        err_ << "scalectl: " << error.message;
        if (context != nullptr && client_.eof()) {
            err_ << " " << context;
        }
        err_ << '\n';
        return exitCodeFor(error);
    }

    // Sends `request` and returns the first reply of class `cls` (other
    // classes are skipped: the schema is additive; ERROR is an error).
    core::Result<std::string> request(const char* cmd_line, const char* cls) {
        const auto deadline = replyDeadline();
        auto sent = client_.sendLine(cmd_line, deadline);
        if (!sent) {
            return sent.error();
        }
        for (;;) {
            auto line = client_.readLine(deadline);
            if (!line) {
                return line.error();
            }
            auto got = replyClass(*line);
            if (!got) {
                return got.error();
            }
            if (*got == cls || *got == "ERROR") {
                return line;
            }
        }
    }

    void print(const std::string& text) {
        out_ << text;
        if (text.empty() || text.back() != '\n') {
            out_ << '\n';
        }
        out_.flush();
    }

    int get() {
        auto line = request(R"({"cmd":"poll"})", "SCALE");
        if (!line) {
            return fail(line.error(), "before replying");
        }
        auto scale = parseScale(*line);
        if (!scale) {
            return fail(scale.error());
        }
        print(options_.json ? *line : formatScale(*scale));
        const int code = getExitCode(*scale, options_.require_converged);
        if (code != 0) {
            err_ << "scalectl: not converged (state " << scale->state << ")\n";
        }
        return code;
    }

    int status() {
        auto line = request(R"({"cmd":"status"})", "STATUS");
        if (!line) {
            return fail(line.error(), "before replying");
        }
        auto text = formatStatus(*line);
        if (!text) {
            return fail(text.error());
        }
        print(options_.json ? *line : *text);
        return 0;
    }

    int posterior() {
        auto line = request(R"({"cmd":"posterior"})", "POSTERIOR");
        if (!line) {
            return fail(line.error(), "before replying");
        }
        auto p = parsePosterior(*line);
        if (!p) {
            return fail(p.error());
        }
        if (options_.json) {
            print(*line);
        } else {
            out_ << formatPosterior(*p);
            out_.flush();
        }
        return 0;
    }

    int objects(const VersionReply& version) {
        if (!speaks(version, kObjectsProtoMinor, "objects", "object table")) {
            return kExProtocol;
        }
        auto line = request(R"({"cmd":"objects"})", "OBJECTS");
        if (!line) {
            return fail(line.error(), "before replying");
        }
        auto text = formatObjects(*line);
        if (!text) {
            return fail(text.error());
        }
        print(options_.json ? *line : *text);
        return 0;
    }

    // false (and a message) when the daemon is older than protocol 1.`minor`.
    bool speaks(const VersionReply& version, int minor, const char* what, const char* lacks) {
        if (version.proto_minor >= minor) {
            return true;
        }
        err_ << "scalectl: the daemon speaks protocol " << version.proto_major << "."
             << version.proto_minor << "; " << what << " needs 1." << minor << " (scaled "
             << version.release << " has no " << lacks << ")\n";
        return false;
    }

    int pose(const VersionReply& version) {
        if (!speaks(version, kPoseProtoMinor, "pose", "POSE")) {
            return kExProtocol;
        }
        auto line = request(R"({"cmd":"pose"})", "POSE");
        if (!line) {
            return fail(line.error(), "before replying");
        }
        auto p = parsePose(*line);
        if (!p) {
            return fail(p.error());
        }
        print(options_.json ? *line : formatPose(*p));
        return 0;
    }

    int watch(const VersionReply& version) {
        if (options_.count && *options_.count <= 0) {
            return 0;
        }
        if (options_.pose && !speaks(version, kPoseProtoMinor, "watch --pose", "POSE")) {
            return kExProtocol;
        }
        // --pose: the POSE stream only; else the SCALE stream.
        const char* streamed = options_.pose ? "POSE" : "SCALE";
        auto sent = client_.sendLine(options_.pose ? R"({"cmd":"watch","enable":false,"pose":true})"
                                                   : R"({"cmd":"watch","enable":true})",
                                     replyDeadline());
        if (!sent) {
            return fail(sent.error());
        }
        bool acknowledged = false;
        std::int64_t printed = 0;
        // Until the WATCH acknowledgement: the reply timeout; then --timeout
        // between lines when it was given, else no bound.
        auto deadline = std::optional<Clock::time_point>(replyDeadline());
        for (;;) {
            auto line = client_.readLine(deadline);
            if (!line) {
                const core::Error& e = line.error();
                if (e.code == ErrorCode::kDegenerate) {
                    return 0;  // SIGINT/SIGTERM: the user stopped watching
                }
                if (client_.eof() && acknowledged && !options_.count) {
                    return 0;  // the stream ended (the daemon stopped)
                }
                if (client_.eof() && options_.count) {
                    err_ << "scalectl: the daemon closed the connection after " << printed << " of "
                         << *options_.count << " lines\n";
                    return kExUnavailable;
                }
                return fail(e, acknowledged ? nullptr : "before acknowledging watch");
            }
            auto cls = replyClass(*line);
            if (!cls) {
                return fail(cls.error());
            }
            if (*cls == "ERROR") {
                return fail(expectClass(*line, streamed).error());
            }
            if (*cls == "WATCH") {
                acknowledged = true;
            } else if (*cls == streamed) {
                if (options_.pose) {
                    auto p = parsePose(*line);
                    if (!p) {
                        return fail(p.error());
                    }
                    print(options_.json ? *line : formatPose(*p));
                } else {
                    auto scale = parseScale(*line);
                    if (!scale) {
                        return fail(scale.error());
                    }
                    print(options_.json ? *line : formatScale(*scale));
                }
                ++printed;
                if (options_.count && printed >= *options_.count) {
                    return 0;
                }
            }
            if (acknowledged || printed > 0) {
                deadline.reset();
                if (options_.timeout_s) {
                    deadline = deadlineIn(*options_.timeout_s);
                }
            }
        }
    }

    const Options& options_;
    std::ostream& out_;
    std::ostream& err_;
    Client client_;
};

}  // namespace

int run(const Options& options, std::ostream& out, std::ostream& err) {
    Session session(options, out, err);
    return session.run();
}

}  // namespace scaled::tools::scalectl
