// The field log thread and the event formatters (docs/field-log.md).

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <utility>

#include <scaled/daemon/json_write.h>
#include <scaled/daemon/log_service.h>
#include <scaled/daemon/protocol.h>
#include <scaled/drivers/base/log.h>
#include <scaled/drivers/fieldlog/field_log.h>

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

// --- JSON pieces --------------------------------------------------------------

// Numbers in the log keep 9 significant digits unless a field says otherwise.
constexpr int kLogDigits = 9;

void key(std::string& out, const char* name) {
    appendJsonKey(out, name);
}

void begin(std::string& out, const char* cls, std::int64_t mono_ns) {
    out.clear();
    out += "{\"class\":\"";
    out += cls;
    out += "\",\"mono_ns\":";
    appendJsonInt(out, mono_ns != 0 ? mono_ns : monotonicNowNs());
}

void frameFields(std::string& out, std::int64_t frame_id, std::int64_t t_ns, std::uint64_t epoch) {
    key(out, "frame_id");
    appendJsonInt(out, frame_id);
    key(out, "t_ns");
    appendJsonInt(out, t_ns);
    key(out, "epoch");
    appendJsonInt(out, epoch);
}

// The buffer the *Event() members format into (one per thread, reused).
std::string& lineBuffer() {
    thread_local std::string buffer = [] {
        std::string s;
        s.reserve(8192);
        return s;
    }();
    return buffer;
}

}  // namespace

// --- formatters ------------------------------------------------------------------

ScaleEvent scaleEventFrom(const ScaleReport& report) {
    ScaleEvent e;
    e.frame_id = report.frame_id;
    e.t_ns = report.t_ns;
    e.epoch = report.epoch;
    e.state = report.state;
    e.has_scale = report.has_scale;
    e.scale = report.scale;
    e.mean = report.mean;
    e.ci68_lo = report.ci68_lo;
    e.ci68_hi = report.ci68_hi;
    e.ci95_lo = report.ci95_lo;
    e.ci95_hi = report.ci95_hi;
    e.observations = report.observations;
    return e;
}

void formatEvent(const StartEvent& event, std::string& out) {
    begin(out, "START", event.mono_ns);
    key(out, "release");
    appendJsonString(out, event.release);
    key(out, "source");
    appendJsonString(out, event.source);
    key(out, "config");
    appendJsonString(out, event.config_toml);
    out += '}';
}

void formatEvent(const StopEvent& event, std::string& out) {
    begin(out, "STOP", event.mono_ns);
    key(out, "reason");
    appendJsonString(out, event.reason);
    out += '}';
}

void formatEvent(const FrameEvent& event, std::string& out) {
    begin(out, "FRAME", event.mono_ns);
    frameFields(out, event.frame_id, event.t_ns, event.epoch);
    key(out, "health");
    appendJsonString(out, event.health);
    key(out, "features");
    appendJsonInt(out, event.features);
    key(out, "tracked");
    appendJsonInt(out, event.tracked);
    key(out, "ms");
    appendJsonNumber(out, event.ms, 5);
    key(out, "dropped");
    appendJsonInt(out, event.dropped);
    out += R"(,"stage_us":{"predict":)";
    appendJsonNumber(out, event.stage_us.predict, 4);
    key(out, "search");
    appendJsonNumber(out, event.stage_us.search, 4);
    key(out, "match");
    appendJsonNumber(out, event.stage_us.match, 4);
    key(out, "update");
    appendJsonNumber(out, event.stage_us.update, 4);
    key(out, "map");
    appendJsonNumber(out, event.stage_us.map, 4);
    out += "}}";
}

void formatEvent(const DetectionEvent& event, std::string& out) {
    begin(out, "DETECTION", event.mono_ns);
    frameFields(out, event.frame_id, event.t_ns, event.epoch);
    key(out, "latency_ms");
    appendJsonNumber(out, event.latency_ms, 5);
    key(out, "boxes");
    out += '[';
    bool first = true;
    for (const LogBox& b : event.boxes) {
        out += first ? "{\"class\":" : ",{\"class\":";
        first = false;
        appendJsonString(out, b.class_name);
        key(out, "score");
        appendJsonNumber(out, b.score, 4);
        key(out, "box");
        out += '[';
        appendJsonNumber(out, b.x0, 6);
        out += ',';
        appendJsonNumber(out, b.y0, 6);
        out += ',';
        appendJsonNumber(out, b.x1, 6);
        out += ',';
        appendJsonNumber(out, b.y1, 6);
        out += "]}";
    }
    out += "]}";
}

void formatEvent(const ScaleEvent& event, std::string& out) {
    begin(out, "SCALE", event.mono_ns);
    frameFields(out, event.frame_id, event.t_ns, event.epoch);
    key(out, "state");
    appendJsonString(out, toString(event.state));
    key(out, "scale");
    appendJsonNumberOr(out, event.has_scale, event.scale, kLogDigits);
    key(out, "mean");
    appendJsonNumberOr(out, event.has_scale, event.mean, kLogDigits);
    key(out, "ci68");
    appendJsonInterval(out, event.has_scale, event.ci68_lo, event.ci68_hi, kLogDigits);
    key(out, "ci95");
    appendJsonInterval(out, event.has_scale, event.ci95_lo, event.ci95_hi, kLogDigits);
    key(out, "observations");
    appendJsonInt(out, event.observations);
    key(out, "new_observations");
    appendJsonInt(out, event.new_observations);
    key(out, "detections");
    appendJsonInt(out, event.detections);
    key(out, "obs");
    out += '[';
    const std::size_t n = std::min(event.obs.size(), kMaxLoggedObservations);
    for (std::size_t i = 0; i < n; ++i) {
        const LogObservation& o = event.obs[i];
        out += i == 0 ? "{\"class\":" : ",{\"class\":";
        appendJsonString(out, o.class_name);
        key(out, "D");
        appendJsonNumber(out, o.D, 7);
        key(out, "sigma_D");
        appendJsonNumber(out, o.sigma_D, 5);
        key(out, "local");
        appendJsonNumber(out, o.local, 6);
        key(out, "weight");
        appendJsonNumber(out, o.weight, 4);
        out += '}';
    }
    out += "]}";
}

void formatEvent(const ObjectEvent& event, std::string& out) {
    begin(out, "OBJECT", event.mono_ns);
    frameFields(out, event.frame_id, event.t_ns, event.epoch);
    if (event.object != nullptr) {
        out += ',';
        appendObjectMembers(out, *event.object, "object_class", kLogDigits);
    }
    out += '}';
}

void formatEvent(const WindowEvent& event, std::string& out) {
    begin(out, "WINDOW", event.mono_ns);
    frameFields(out, event.frame_id, event.t_ns, event.epoch);
    if (event.report != nullptr) {
        const core::slam::WindowBaReport& r = *event.report;
        key(out, "keyframes");
        appendJsonInt(out, r.keyframes);
        key(out, "free_keyframes");
        appendJsonInt(out, r.free_keyframes);
        key(out, "points");
        appendJsonInt(out, r.points);
        key(out, "observations");
        appendJsonInt(out, r.observations);
        key(out, "rms_before_px");
        appendJsonNumber(out, static_cast<double>(r.rms_before_px), kLogDigits);
        key(out, "rms_px");
        appendJsonNumber(out, static_cast<double>(r.rms_after_px), kLogDigits);
        key(out, "scale");
        appendJsonNumber(out, static_cast<double>(r.scale), kLogDigits);
        key(out, "rolling_shutter_s");
        appendJsonNumber(out, static_cast<double>(r.rolling_shutter_s), kLogDigits);
        key(out, "focal_scale");
        appendJsonNumber(out, static_cast<double>(r.focal_scale), kLogDigits);
        key(out, "k1");
        appendJsonNumber(out, static_cast<double>(r.k1), kLogDigits);
    }
    out += '}';
}

void formatEvent(const PoseEvent& event, std::string& out) {
    // As the socket's POSE: 0.1 mm at 1 km; the scale with the log's digits.
    constexpr int kPoseDigits = 7;
    begin(out, "POSE", event.mono_ns);
    if (event.pose != nullptr) {
        frameFields(out, event.pose->frame_id, event.pose->t_ns, event.pose->epoch);
        appendPoseMembers(out, *event.pose, event.metric, event.state, kPoseDigits, kLogDigits);
    }
    out += '}';
}

void formatEvent(const StateEvent& event, std::string& out) {
    begin(out, "STATE", event.mono_ns);
    key(out, "from");
    appendJsonString(out, toString(event.from));
    key(out, "to");
    appendJsonString(out, toString(event.to));
    key(out, "epoch");
    appendJsonInt(out, event.epoch);
    key(out, "frame_id");
    appendJsonInt(out, event.frame_id);
    key(out, "reason");
    appendJsonString(out, event.reason);
    out += '}';
}

void formatEvent(const ErrorEvent& event, std::string& out) {
    begin(out, "ERROR", event.mono_ns);
    key(out, "where");
    appendJsonString(out, event.where);
    key(out, "message");
    appendJsonString(out, event.message);
    out += '}';
}

// --- the service -------------------------------------------------------------------

LogService::LogService(const LogConfig& config, ReportHub& hub) : config_(config), hub_(hub) {}

Result<std::unique_ptr<LogService>> LogService::create(const LogConfig& config, ReportHub& hub,
                                                       LogServiceHooks hooks) {
    if (config.enabled && config.queue_bytes < 2) {
        return makeError(ErrorCode::kInvalidArgument, "log.queue_bytes: must be at least 2 (got " +
                                                          std::to_string(config.queue_bytes) + ")");
    }
    if (config.enabled && config.fsync_interval_ms < 1) {
        return makeError(ErrorCode::kInvalidArgument,
                         "log.fsync_interval_ms: must be at least 1 (got " +
                             std::to_string(config.fsync_interval_ms) + ")");
    }
    std::unique_ptr<LogService> s(new LogService(config, hub));
    if (config.enabled) {
        s->half_bytes_ = config.queue_bytes / 2;
        for (auto& b : s->buf_) {
            b = std::make_unique<char[]>(s->half_bytes_);  // NOLINT(*-avoid-c-arrays)
        }
        drivers::fieldlog::FieldLogWriterOptions options;
        options.dir = config.dir;
        options.max_file_bytes = config.max_file_bytes;
        options.max_total_bytes = config.max_total_bytes;
        options.open_file = std::move(hooks.open_file);
        options.utc_now_s = std::move(hooks.utc_now_s);
        auto writer = drivers::fieldlog::FieldLogWriter::open(std::move(options));
        const std::lock_guard io(s->io_mutex_);
        if (writer) {
            s->writer_ = std::move(*writer);
        } else {
            s->setFault(writer.error().message);
        }
        s->last_sync_mono_ns_ = monotonicNowNs();
    }
    s->publish();
    return s;
}

LogService::~LogService() {
    stop();
}

void LogService::start() {
    if (!config_.enabled || thread_.joinable()) {
        return;
    }
    {
        const std::lock_guard lock(mutex_);
        if (stopped_) {
            return;
        }
    }
    thread_ = std::thread([this] { run(); });
}

void LogService::stop() {
    if (!config_.enabled) {
        return;
    }
    {
        const std::lock_guard lock(mutex_);
        if (stopped_) {
            return;
        }
        stop_requested_ = true;
        stopped_ = true;  // from here appends are refused; the last drain takes the rest
    }
    cv_.notify_one();
    if (thread_.joinable()) {
        thread_.join();  // its last drain wrote and synced everything
    } else {
        drain(true);
    }
}

void LogService::run() {
    const auto interval = std::chrono::milliseconds(config_.fsync_interval_ms);
    std::unique_lock lock(mutex_);
    while (!stop_requested_) {
        cv_.wait_for(lock, interval, [this] { return stop_requested_ || wake_; });
        wake_ = false;
        if (stop_requested_) {
            break;
        }
        lock.unlock();
        drain(false);
        lock.lock();
    }
    lock.unlock();
    drain(true);
}

bool LogService::append(std::string_view line) {
    if (!config_.enabled) {
        return false;
    }
    if (!line.empty() && line.back() == '\n') {
        line.remove_suffix(1);
    }
    if (line.empty() || std::memchr(line.data(), '\n', line.size()) != nullptr) {
        lines_dropped_.fetch_add(1, std::memory_order_relaxed);
        return false;
    }
    bool notify = false;
    {
        const std::lock_guard lock(mutex_);
        const auto a = static_cast<std::size_t>(active_);
        if (faulted_ || stopped_ || used_[a] + line.size() + 1 > half_bytes_) {
            lines_dropped_.fetch_add(1, std::memory_order_relaxed);
            return false;
        }
        char* dst = buf_[a].get() + used_[a];
        std::memcpy(dst, line.data(), line.size());
        dst[line.size()] = '\n';  // NOLINT(cppcoreguidelines-pro-bounds-pointer-arithmetic)
        const std::size_t before = used_[a];
        used_[a] += line.size() + 1;
        ++lines_[a];
        // Wake the thread once when the half passes half full.
        notify = before <= half_bytes_ / 2 && used_[a] > half_bytes_ / 2 && !wake_;
        if (notify) {
            wake_ = true;
        }
    }
    if (notify) {
        cv_.notify_one();
    }
    return true;
}

bool LogService::flush() {
    if (!config_.enabled) {
        return false;
    }
    drain(true);
    const std::lock_guard lock(mutex_);
    return !faulted_;
}

void LogService::setFault(const std::string& message) {
    {
        const std::lock_guard lock(mutex_);
        if (faulted_) {
            return;
        }
        faulted_ = true;
        error_ = message;
    }
    drivers::base::logError(drivers::base::LogCategory{"scaled"},
                            "field log stopped: " + message + " (the daemon keeps running)");
}

void LogService::drain(bool force_sync) {
    const std::lock_guard io(io_mutex_);
    std::size_t idx = 0;
    {
        const std::lock_guard lock(mutex_);
        idx = static_cast<std::size_t>(active_);
        active_ ^= 1;
    }
    // Appends go to the other half now; this one is ours until the next swap
    // (which needs io_mutex_).
    const std::string_view batch(buf_[idx].get(), used_[idx]);
    const std::uint64_t lines = lines_[idx];
    if (!batch.empty()) {
        if (writer_ != nullptr && !writer_->faulted()) {
            if (auto ok = writer_->write(batch); ok) {
                lines_written_.fetch_add(lines, std::memory_order_relaxed);
                unsynced_ = true;
            } else {
                lines_dropped_.fetch_add(lines, std::memory_order_relaxed);
                setFault(ok.error().message);
            }
        } else {
            lines_dropped_.fetch_add(lines, std::memory_order_relaxed);
        }
    }
    {
        const std::lock_guard lock(mutex_);
        used_[idx] = 0;
        lines_[idx] = 0;
    }
    const std::int64_t now = monotonicNowNs();
    const std::int64_t interval_ns = std::int64_t{config_.fsync_interval_ms} * 1'000'000;
    if (writer_ != nullptr && !writer_->faulted() && unsynced_ &&
        (force_sync || now - last_sync_mono_ns_ >= interval_ns)) {
        if (auto ok = writer_->sync(); !ok) {
            setFault(ok.error().message);
        }
        unsynced_ = false;
        last_sync_mono_ns_ = now;
    }
    if (writer_ != nullptr) {
        bytes_written_.store(writer_->bytesWritten(), std::memory_order_relaxed);
    }
    publish();
}

LogStatus LogService::status() const {
    LogStatus s;
    {
        const std::lock_guard lock(mutex_);
        s.state = !config_.enabled ? LogStatus::State::kOff
                  : faulted_       ? LogStatus::State::kFault
                                   : LogStatus::State::kOk;
        s.error = error_;
    }
    s.lines_written = lines_written_.load(std::memory_order_relaxed);
    s.lines_dropped = lines_dropped_.load(std::memory_order_relaxed);
    s.bytes_written = bytes_written_.load(std::memory_order_relaxed);
    return s;
}

void LogService::publish() {
    hub_.publishLogStatus(status());
}

bool LogService::startEvent(const StartEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::stopEvent(const StopEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::frameEvent(const FrameEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::detectionEvent(const DetectionEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::scaleEvent(const ScaleEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::objectEvent(const ObjectEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::windowEvent(const WindowEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::poseEvent(const PoseEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::stateEvent(const StateEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}
bool LogService::errorEvent(const ErrorEvent& event) {
    formatEvent(event, lineBuffer());
    return append(lineBuffer());
}

}  // namespace scaled::daemon
