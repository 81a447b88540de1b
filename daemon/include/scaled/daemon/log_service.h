#pragma once

// The daemon's field log (docs/field-log.md): any thread appends JSON lines
// to a bounded in-memory queue; one log thread writes them in batches to
// rotated files (drivers/field_log.h) and fdatasyncs at most every
// log.fsync_interval_ms, so a crash or power cut loses at most one interval.
//
// The log never stops the daemon: when the card is full, read-only or gone,
// the service goes to LogStatus::kFault (one message on stderr, the reason in
// the hub's LogStatus) and every append() returns false and is counted as
// dropped. With log.enabled = false it is kOff and append() does nothing.
//
// The event structs below are what the pipeline fills; each *Event() call
// builds one JSON object line ({"class":..,"mono_ns":..,...}) in a reused
// per-thread buffer and appends it. Text fields are views: they must stay
// valid for the duration of the call only.

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>

#include <scaled/core/result.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/report.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::drivers::fieldlog {
class FieldLogWriter;
}

namespace scaled::daemon {

// --- events -----------------------------------------------------------------
// mono_ns: CLOCK_MONOTONIC nanoseconds of the event; 0 means "now".

// START {release, source, config}
struct StartEvent {
    std::string_view release;      // version()
    std::string_view source;       // "sim", "replay:/path", ...
    std::string_view config_toml;  // toToml(config): the whole configuration
    std::int64_t mono_ns = 0;
};

// STOP {reason}
struct StopEvent {
    std::string_view reason;  // "SIGTERM", "replay finished", ...
    std::int64_t mono_ns = 0;
};

// FRAME {frame_id, t_ns, epoch, health, features, tracked, ms, dropped}:
// every log.frame_every tracked frames (the caller counts).
struct FrameEvent {
    std::int64_t frame_id = -1;
    std::int64_t t_ns = 0;  // the frame's timestamp (source clock)
    std::uint64_t epoch = 0;
    std::string_view health = "ok";  // "ok", "lost", ...
    int features = 0;                // features in the map
    int tracked = 0;                 // measured (inliers) in this frame
    double ms = 0;                   // tracking time of this frame
    std::uint64_t dropped = 0;       // frames dropped so far
    std::int64_t mono_ns = 0;
    // The tracker's stages on this frame, microseconds ("stage_us"; 0: the
    // stage did not run).
    drivers::vision::StageTimes stage_us;
};

// One detector box.
struct LogBox {
    std::string_view class_name;
    double score = 0;
    double x0 = 0;  // pixels
    double y0 = 0;
    double x1 = 0;
    double y1 = 0;
};

// DETECTION {frame_id, t_ns, epoch, latency_ms, boxes:[{class, score, box:[x0,y0,x1,y1]}]}
struct DetectionEvent {
    std::int64_t frame_id = -1;
    std::int64_t t_ns = 0;
    std::uint64_t epoch = 0;
    double latency_ms = 0;
    std::span<const LogBox> boxes;
    std::int64_t mono_ns = 0;
};

// One scale observation (core::ObservationRecord plus its class).
struct LogObservation {
    std::string_view class_name;
    double D = 0;        // NOLINT(readability-identifier-naming): the paper's symbol
    double sigma_D = 0;  // NOLINT(readability-identifier-naming)
    double local = 0;    // local estimate: mode of this observation's likelihood alone
    double weight = 1;
};

// SCALE {frame_id, t_ns, epoch, state, scale|null, mean|null, ci68|null,
// ci95|null, observations, new_observations, detections, obs:[{class, D,
// sigma_D, local, weight}]} (obs: at most kMaxLoggedObservations).
struct ScaleEvent {
    std::int64_t frame_id = -1;
    std::int64_t t_ns = 0;
    std::uint64_t epoch = 0;
    DaemonState state = DaemonState::kInitialising;
    bool has_scale = false;  // false: scale, mean, ci68, ci95 are null
    double scale = 0;        // MAP, metres per SLAM unit
    double mean = 0;
    double ci68_lo = 0;
    double ci68_hi = 0;
    double ci95_lo = 0;
    double ci95_hi = 0;
    int observations = 0;      // in this epoch
    int new_observations = 0;  // added by this update
    int detections = 0;        // boxes of the detector run behind this update
    std::span<const LogObservation> obs;
    std::int64_t mono_ns = 0;
};
inline constexpr std::size_t kMaxLoggedObservations = 64;

// The fields a ScaleReport has (frame, epoch, state, scale, intervals,
// observations); the caller adds new_observations, detections and obs.
ScaleEvent scaleEventFrom(const ScaleReport& report);

// OBJECT {frame_id, t_ns, epoch, id, object_class, state, anchor|null,
// anchor_rel_sigma|null, detections, views, views_used, first_frame,
// last_frame, local_estimate|null, height_m|null, height_ci95_m|null}: one
// object of the table after a scale update (the members of an OBJECTS entry,
// protocol.h appendObjectMembers, with its class as "object_class"). The
// daemon logs, after each SCALE line, the objects that received a view in
// that update.
struct ObjectEvent {
    std::int64_t frame_id = -1;  // the scale update's frame
    std::int64_t t_ns = 0;
    std::uint64_t epoch = 0;
    const ObjectReport* object = nullptr;  // required
    std::int64_t mono_ns = 0;
};

// WINDOW {frame_id, t_ns, epoch, keyframes, free_keyframes, points,
// observations, rms_before_px, rms_px, scale, rolling_shutter_s, focal_scale,
// k1}: a window optimisation (tracker.window_ba), on the frame that took its
// result, with the camera it used (docs/field-log.md).
struct WindowEvent {
    std::int64_t frame_id = -1;
    std::int64_t t_ns = 0;
    std::uint64_t epoch = 0;
    const core::slam::WindowBaReport* report = nullptr;  // required
    std::int64_t mono_ns = 0;
};

// POSE {frame_id, t_ns, epoch, state, scale|null, scale_sigma|null,
// position|null, velocity|null, position_cov|null, orientation,
// attitude_cov, position_map, velocity_map, position_map_cov}: the members
// of the socket's POSE (protocol.h appendPoseMembers; no "time") of a
// tracked frame, numbers with 7 significant digits, the scale with 9.
// LogEvents writes them at most log.pose_rate_hz per second of frame time.
struct PoseEvent {
    const PoseReport* pose = nullptr;                // required
    MetricPose metric;                               // metricPose(*pose, the latest scale report)
    DaemonState state = DaemonState::kInitialising;  // that report's
    std::int64_t mono_ns = 0;
};

// STATE {from, to, epoch, frame_id, reason}
struct StateEvent {
    DaemonState from = DaemonState::kInitialising;
    DaemonState to = DaemonState::kInitialising;
    std::uint64_t epoch = 0;
    std::int64_t frame_id = -1;
    std::string_view reason;
    std::int64_t mono_ns = 0;
};

// ERROR {where, message}
struct ErrorEvent {
    std::string_view where;  // "source", "detector", ...
    std::string_view message;
    std::int64_t mono_ns = 0;
};

// One JSON object (no newline) into `out` (cleared first; its capacity is
// reused). Non-finite numbers are written as null, text is escaped and
// invalid UTF-8 replaced by U+FFFD, so every line is valid JSON.
void formatEvent(const StartEvent& event, std::string& out);
void formatEvent(const StopEvent& event, std::string& out);
void formatEvent(const FrameEvent& event, std::string& out);
void formatEvent(const DetectionEvent& event, std::string& out);
void formatEvent(const ScaleEvent& event, std::string& out);
void formatEvent(const ObjectEvent& event, std::string& out);
void formatEvent(const WindowEvent& event, std::string& out);
void formatEvent(const PoseEvent& event, std::string& out);
void formatEvent(const StateEvent& event, std::string& out);
void formatEvent(const ErrorEvent& event, std::string& out);

// --- the service ------------------------------------------------------------

// For tests: where the files are opened and what time names them.
struct LogServiceHooks {
    std::function<int(const std::filesystem::path&)> open_file;  // see FieldLogWriterOptions
    std::function<std::int64_t()> utc_now_s;
};

class LogService {
public:
    // Opens the log directory and its next file. An unusable directory does
    // not fail: the service exists in kFault (the daemon keeps serving the
    // scale). Fails only on a configuration no service can run with
    // (queue_bytes < 2, fsync_interval_ms < 1).
    static core::Result<std::unique_ptr<LogService>> create(const LogConfig& config, ReportHub& hub,
                                                            LogServiceHooks hooks = {});
    ~LogService();  // stop()
    LogService(const LogService&) = delete;
    LogService& operator=(const LogService&) = delete;
    LogService(LogService&&) = delete;
    LogService& operator=(LogService&&) = delete;

    // Starts the log thread (no-op when off, or already started).
    void start();
    // Writes everything queued, fdatasyncs, joins the thread and publishes
    // the final LogStatus. Later appends are dropped. Idempotent.
    void stop();

    // Queues one line (a JSON object without newline; one trailing '\n' is
    // allowed). Any thread; never blocks on I/O and allocates nothing. false
    // when it was not queued: queue full, log faulted or stopped (counted as
    // dropped), line containing a newline (dropped), log off (not counted).
    bool append(std::string_view line);

    // Writes everything queued so far and fdatasyncs it, on the calling
    // thread (blocks for the I/O; tests and shutdown paths). false when the
    // log is faulted or off.
    bool flush();

    // The current status (also published to the hub after every batch).
    [[nodiscard]] LogStatus status() const;
    [[nodiscard]] bool enabled() const { return config_.enabled; }
    [[nodiscard]] int frameEvery() const { return config_.frame_every; }
    [[nodiscard]] double poseRateHz() const { return config_.pose_rate_hz; }

    // Format into a per-thread buffer and append(); the result of append().
    bool startEvent(const StartEvent& event);
    bool stopEvent(const StopEvent& event);
    bool frameEvent(const FrameEvent& event);
    bool detectionEvent(const DetectionEvent& event);
    bool scaleEvent(const ScaleEvent& event);
    bool objectEvent(const ObjectEvent& event);
    bool windowEvent(const WindowEvent& event);
    bool poseEvent(const PoseEvent& event);
    bool stateEvent(const StateEvent& event);
    bool errorEvent(const ErrorEvent& event);

private:
    LogService(const LogConfig& config, ReportHub& hub);
    void run();
    // Swaps the queue, writes the batch, fdatasyncs when due (or `force`) and
    // publishes the status. Serialised by io_mutex_.
    void drain(bool force_sync);
    void setFault(const std::string& message);  // io_mutex_ held
    void publish();

    LogConfig config_;
    ReportHub& hub_;
    std::unique_ptr<drivers::fieldlog::FieldLogWriter> writer_;  // null when off or not opened

    // The queue: two halves of queue_bytes; appends fill active_, the log
    // thread swaps and writes the other one.
    mutable std::mutex mutex_;
    std::condition_variable cv_;
    std::array<std::unique_ptr<char[]>, 2> buf_;
    std::array<std::size_t, 2> used_{};
    std::array<std::uint64_t, 2> lines_{};
    std::size_t half_bytes_ = 0;
    int active_ = 0;
    bool wake_ = false;  // the thread should drain now
    bool stop_requested_ = false;
    bool stopped_ = false;  // appends are refused
    bool faulted_ = false;
    std::string error_;

    std::mutex io_mutex_;
    std::thread thread_;
    bool unsynced_ = false;               // io_mutex_
    std::int64_t last_sync_mono_ns_ = 0;  // io_mutex_
    std::atomic<std::uint64_t> lines_written_{0};
    std::atomic<std::uint64_t> lines_dropped_{0};
    std::atomic<std::uint64_t> bytes_written_{0};
};

}  // namespace scaled::daemon
