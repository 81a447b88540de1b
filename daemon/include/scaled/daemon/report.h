#pragma once

// What the daemon tells the outside world: the scale report, the pipeline's
// health, the posterior grid, the object table and the camera pose, and ReportHub, the one place
// the pipeline publishes them and every reader (socket, field log, status line, sd_notify) takes
// them from.
//
// Threads: the pipeline's threads publish; the socket thread, the main thread
// and the log read. Every call is thread-safe and short (a mutex around a copy
// into storage reserved at construction); a reader never blocks a writer for
// longer than one copy.

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/scale/object_evidence.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/types.h>
#include <scaled/drivers/base/unique_fd.h>

namespace scaled::daemon {

// The state of the scale, as clients and LEDs see it.
enum class DaemonState : std::uint8_t {
    kInitialising,  // no map yet (start-up, or a new map being made after a loss)
    kTracking,      // map tracked, no scale evidence yet in this epoch
    kConverging,    // evidence, 95% interval still wider than estimator.converged_rel_width
    kConverged,     // 95% interval narrower than that
    kLost,          // SLAM lost the map; a new one (new epoch) follows
    kFault,         // the pipeline cannot produce scales (source or detector failed)
};
const char* toString(DaemonState state);

// One scale report (protocol class SCALE).
// The scale of an earlier map (protocol: SCALE.previous): a new map has a
// scale of its own, so its evidence starts again; the previous map's last
// estimate shows the client where the break is and what was known before it.
struct PreviousScale {
    bool present = false;     // false until a map with a scale was replaced
    std::uint64_t epoch = 0;  // the latest earlier epoch that had a scale
    double scale = 0;         // its last MAP, metres per (its) SLAM unit
    double ci95_lo = 0;
    double ci95_hi = 0;
    int observations = 0;
    std::int64_t frame_id = -1;  // the frame of its last update
};

struct ScaleReport {
    bool has_scale = false;  // false until the first observation of the epoch
    double scale = 0;        // metres per SLAM unit: the posterior mode (MAP)
    double mean = 0;         // posterior mean
    double ci68_lo = 0;
    double ci68_hi = 0;
    double ci95_lo = 0;
    double ci95_hi = 0;
    // The scale is known too loosely to put poses in metres (its 95% interval
    // wider than estimator.pose_max_rel_width95 times it; wideForPoses() in
    // pipeline_config.h): POSE's metric members stay null. Not in SCALE lines.
    bool wide_for_poses = false;
    DaemonState state = DaemonState::kInitialising;
    std::uint64_t epoch = 0;     // bumped whenever SLAM starts a new map (its scale is new)
    int observations = 0;        // in this epoch
    std::int64_t frame_id = -1;  // frame the latest scale update was computed on (-1: none)
    std::int64_t t_ns = 0;       // that frame's timestamp (source clock)
    // CLOCK_MONOTONIC time of the latest scale update (0: none): age = now - this.
    std::int64_t updated_mono_ns = 0;
    // Set when something is wrong that does not stop the scale (e.g. the field
    // log stopped: "log: No space left on device"). Empty when all is well.
    std::string fault;
    PreviousScale previous;
};

// Wall-time statistics of one pipeline stage (protocol: an entry of
// STATUS.timing). Fixed size: add() never allocates.
struct StageTiming {
    // The mean follows the recent samples: the exact mean of the first
    // kMeanWindow, then an exponential average with weight 1/kMeanWindow (a
    // time constant of kMeanWindow samples), as tracking_ms_mean always was:
    // it settles after start-up and follows a change of load within seconds.
    static constexpr std::uint64_t kMeanWindow = 100;

    std::uint64_t samples = 0;  // times the stage ran since the pipeline started
    double last_ms = 0;         // the latest sample
    double mean_ms = 0;         // see kMeanWindow
    double max_ms = 0;          // since the pipeline started (map building included)

    void add(double ms);
};

// Where the pipeline's time goes, stage by stage (docs/protocol.md,
// STATUS.timing, says exactly what each stage covers). The tracking thread
// fills the first six on every tracked frame (a stage that did not run on a
// frame adds no sample), the detection thread the others on every detector
// run (detect_*) and every scale update (scale_*).
struct PipelineTiming {
    StageTiming predict;         // EKF prediction (drivers::vision::TrackStats::predict_us)
    StageTiming search;          // predicted measurements, patch warping (search_us)
    StageTiming match;           // NCC matching (match_us)
    StageTiming update;          // 1-point RANSAC and EKF updates (update_us)
    StageTiming map;             // map management and new features (map_us)
    StageTiming tracking;        // the whole MonoTracker::processFrame call
    StageTiming detect_pre;      // detector pre-processing (DetectionTiming::pre_ms)
    StageTiming detect_forward;  // the network (forward_ms)
    StageTiming detect_post;     // decoding, thresholds, NMS (post_ms)
    StageTiming scale_update;    // ScaleEstimator::update
    // The posterior's copy for the hub, ScaleEstimator::summary and the
    // publication of the report (hub, field-log event).
    StageTiming scale_publish;
};

// The live IMU (imu_service.h; protocol: STATUS.imu).
struct ImuStatus {
    bool configured = false;  // imu.device set
    std::string device;       // "iio:device0 [mpu6050]", or imu.device when it never opened
    std::string mode;         // "sysfs 100 Hz", "buffer (trigger mpu6050-dev0)"
    std::uint64_t samples = 0;
    std::uint64_t errors = 0;  // failed reads
    std::string error;         // the latest failure while it lasts; empty once reads succeed
};

// The gyro motion prior (STATUS.gyro): what feeds it and how often it served.
struct GyroStatus {
    bool present = false;                  // a gyro can feed the prior (STATUS has a gyro object)
    std::string source;                    // "iio:device0 [mpu6050]", or the replayed log's path
    std::uint64_t frames = 0;              // frames predicted with the gyro
    std::array<double, 3> bias_C_radps{};  // the on-line bias estimate, camera frame
};

// The window bundle adjustment (protocol: STATUS.window_ba, proto_minor 5;
// the field log's WINDOW lines): its latest optimisation and the camera it
// used. The readout time, focal factor and k1 are the camera's (a new map
// keeps them), so they are reported across epochs.
struct WindowBaStatus {
    bool present = false;  // tracker.window_ba is on (STATUS has a window_ba object)
    // What the window estimates (its *_sigma keys > 0); the rest is given.
    bool rolling_shutter_estimated = false;
    bool focal_estimated = false;
    bool k1_estimated = false;
    std::uint64_t optimisations = 0;  // so far, every epoch
    // The latest optimisation (valid once optimisations > 0).
    std::int64_t frame_id = -1;  // the frame that took its result
    std::uint64_t epoch = 0;
    int keyframes = 0;
    int points = 0;
    int observations = 0;
    double rms_px = 0;  // reprojection RMS after it
    double scale = 1;   // its scale correction of the filter's map
    // The camera the window used: given until the first optimisation.
    double rolling_shutter_s = 0;
    double focal_scale = 1;  // over the camera file's focal length
    double k1 = 0;
};

// Pipeline health (protocol class STATUS).
struct PipelineStatus {
    std::string source;  // "sim", "replay:/path/to/dir", ...
    // Where the current map's vertical came from ("accelerometer (...)",
    // "dataset gravity and ground-truth pose", "set_gravity request",
    // "assumed level camera (down = +y)"); empty before the first map.
    std::string gravity_source;
    // That vertical, the unit down direction in the map's first camera frame.
    std::optional<std::array<double, 3>> gravity_down_C;
    ImuStatus imu;  // imu.configured false: no [imu] device (STATUS has no imu object)
    GyroStatus gyro;
    std::int64_t frame_id = -1;     // last tracked frame
    std::int64_t frames_total = 0;  // frames the source has (replay), 0 when unbounded
    bool source_finished = false;   // replay reached its end (the daemon keeps serving)
    double fps = 0;                 // tracked frames per second, recent window
    std::uint64_t frames_captured = 0;
    std::uint64_t frames_tracked = 0;
    std::uint64_t frames_dropped = 0;      // capture queue full (live/paced sources)
    std::uint64_t detections_run = 0;      // detector runs
    std::uint64_t detections_skipped = 0;  // frames replaced in the detection slot before it ran
    std::uint64_t scale_updates = 0;
    double detector_latency_ms_last = 0;
    double detector_latency_ms_mean = 0;
    double detector_latency_ms_max = 0;
    double tracking_ms_mean = 0;  // = timing.tracking.mean_ms
    int features_in_map = 0;
    int features_tracked = 0;  // measured (inliers) in the last frame
    std::uint64_t epoch = 0;
    double uptime_s = 0;
    // Live cameras only (protocol: the optional "camera" object).
    bool live = false;
    bool camera_lost = false;             // waiting for the camera to come back
    std::uint64_t camera_reconnects = 0;  // times it was lost and came back
    std::uint64_t camera_repeated = 0;  // buffers dropped as repeats (camera.drop_repeated_frames)
    std::string camera_device;          // "/dev/video0 (vivid)"
    std::string camera_mode;            // "YUYV 640x480 @ 30"; empty while lost
    PipelineTiming timing;              // protocol: STATUS.timing (proto_minor 2)
    WindowBaStatus window_ba;           // protocol: STATUS.window_ba (proto_minor 5)
};

// Field-log health, published by the log service.
struct LogStatus {
    enum class State : std::uint8_t { kOff, kOk, kFault };
    State state = State::kOff;
    std::uint64_t lines_written = 0;
    std::uint64_t lines_dropped = 0;  // queue full or log faulted
    std::uint64_t bytes_written = 0;
    std::string error;  // why it is in kFault
};
const char* toString(LogStatus::State state);

// The posterior on the grid (protocol class POSTERIOR).
struct PosteriorSnapshot {
    std::uint64_t epoch = 0;
    std::int64_t frame_id = -1;
    int observations = 0;
    std::vector<double> d;      // grid values of d (metres per SLAM unit), increasing
    std::vector<double> log_p;  // normalised log density (max 0), same size
};

// Bytes of an object's class name in ObjectReport, the terminating NUL
// included: longer names are cut (at a UTF-8 character boundary).
inline constexpr std::size_t kObjectClassChars = 32;

// One object of the estimator's object table (protocol class OBJECTS, the
// field log's OBJECT lines): core::ObjectSummary with its class name copied
// into fixed storage, so a table of them is copied without allocating.
struct ObjectReport {
    int id = 0;                                        // stable within the epoch, from 1
    std::array<char, kObjectClassChars> class_name{};  // NUL-terminated
    core::ObjectState state = core::ObjectState::kTentative;
    std::array<double, 3> anchor{0, 0, 0};  // p_AinW, SLAM units (not valid while tentative)
    double anchor_rel_sigma = 0;            // depth std / distance of the anchor
    int detections = 0;                     // associated so far
    int views = 0;                          // kept
    int views_used = 0;                     // in its likelihood
    std::int64_t first_frame = 0;
    std::int64_t last_frame = 0;  // the latest frame that gave it a view
    double local_estimate = 0;    // this object's own scale (m per SLAM unit); 0: none
    // Its height at the posterior's MAP and 95% bounds, metres; has_height is
    // false unless the object is used and the posterior has evidence.
    bool has_height = false;
    double height_m = 0;
    double height_ci95_lo_m = 0;
    double height_ci95_hi_m = 0;

    // class_name as a view (up to its NUL).
    [[nodiscard]] std::string_view className() const;
    // Copies `name` into class_name, cut to kObjectClassChars - 1 bytes
    // without splitting a UTF-8 sequence.
    void setClassName(std::string_view name);
};

// The object table after the latest scale update (protocol class OBJECTS).
struct ObjectsSnapshot {
    std::uint64_t epoch = 0;
    std::int64_t frame_id = -1;  // frame of the scale update it was taken at (-1: none this epoch)
    core::EstimatorModel model = core::EstimatorModel::kPaper;
    std::vector<ObjectReport> objects;  // empty with the paper model
};

// One camera pose of the tracking thread (protocol class POSE, proto_minor 4),
// in map units: the tracker knows no scale. The encoder combines it with the
// latest ScaleReport into metres (appendPose, metricPose in pose.h). The
// frame G is gravity-aligned (z up), its origin the first camera of the
// epoch, its x axis the horizontal projection of that camera's optical axis,
// y = z cross x (docs/protocol.md, POSE). Fixed size: copies never allocate.
struct PoseReport {
    std::uint64_t epoch = 0;
    std::int64_t frame_id = -1;                   // the tracked frame (-1: no pose yet)
    std::int64_t t_ns = 0;                        // its timestamp (source clock)
    std::array<double, 3> position_map{0, 0, 0};  // p_CinG, SLAM units
    std::array<double, 3> velocity_map{0, 0, 0};  // SLAM units per second, G axes
    // R_CtoG as a unit quaternion [w, x, y, z] (w >= 0); the camera frame is
    // x right, y down, z forward (optical axis).
    std::array<double, 4> orientation_wxyz{1, 0, 0, 0};
    // Row-major 3x3 covariances in G axes: the position's (SLAM units^2) and
    // the attitude's (rad^2, of the small rotation e with
    // R_CtoG,true = Exp(e) R_CtoG).
    std::array<double, 9> position_cov_map{};
    std::array<double, 9> attitude_cov_rad2{};
};

class ReportHub {
public:
    // grid_bins: size of the posterior grid (buffers are reserved for it).
    explicit ReportHub(std::size_t grid_bins);
    ~ReportHub();
    ReportHub(const ReportHub&) = delete;
    ReportHub& operator=(const ReportHub&) = delete;
    ReportHub(ReportHub&&) = delete;
    ReportHub& operator=(ReportHub&&) = delete;

    // --- writers ------------------------------------------------------------
    // A new scale report (an update or a state change); the posterior is
    // copied when given (sizes must match the grid, else it is ignored). Bumps
    // scaleSequence() and makes wakeFd() readable.
    void publishScale(const ScaleReport& report, std::span<const double> grid_d = {},
                      std::span<const double> log_p = {});
    void publishStatus(const PipelineStatus& status);
    void publishLogStatus(const LogStatus& status);
    // The estimator's model and the size of the object table (max_objects;
    // 0 with the paper model). Pipeline::create calls it before any thread
    // runs; it allocates, publishObjects() then does not.
    void setObjectModel(core::EstimatorModel model, std::size_t max_objects);
    // The object table after a scale update; entries beyond the size given
    // to setObjectModel() are left out. A later publishScale() of another
    // epoch empties it (its objects belonged to the old map).
    void publishObjects(const ObjectsSnapshot& objects);
    // The pose of a tracked frame (the tracking thread, every tracked frame).
    // Bumps poseSequence() and makes wakeFd() readable. Never allocates.
    void publishPose(const PoseReport& pose);

    // --- readers ------------------------------------------------------------
    [[nodiscard]] ScaleReport scale() const;
    [[nodiscard]] PipelineStatus status() const;
    [[nodiscard]] LogStatus logStatus() const;
    // false when no posterior was published yet.
    bool posterior(PosteriorSnapshot& out) const;
    // The latest object table (empty before the first update of the epoch);
    // `out` keeps its capacity when it suffices.
    void objects(ObjectsSnapshot& out) const;
    // Increases with every publishScale().
    [[nodiscard]] std::uint64_t scaleSequence() const { return scale_seq_.load(); }
    // The latest pose (frame_id -1 before the first).
    [[nodiscard]] PoseReport pose() const;
    // Increases with every publishPose().
    [[nodiscard]] std::uint64_t poseSequence() const { return pose_seq_.load(); }

    // An eventfd that becomes readable after publishScale() and publishPose(); a poll() loop
    // waits on it and calls consumeWake() before reading. -1 if eventfd failed
    // (then readers must poll scaleSequence()). It has ONE reader, the socket
    // service: a second consumer would steal its wakes. Others (the main
    // loop, LEDs) poll scaleSequence().
    [[nodiscard]] int wakeFd() const { return wake_fd_.get(); }
    void consumeWake() const;

    // --- commands from clients to the pipeline ------------------------------
    // set_gravity: unit gravity ("down") in the current camera frame.
    void requestGravity(const core::Vec3& down_C);
    std::optional<core::Vec3> takeGravityRequest();

private:
    void wake() const;

    mutable std::mutex mutex_;
    ScaleReport scale_;
    PipelineStatus status_;
    LogStatus log_status_;
    PosteriorSnapshot posterior_;
    bool has_posterior_ = false;
    ObjectsSnapshot objects_;
    PoseReport pose_;
    std::optional<core::Vec3> gravity_request_;
    std::atomic<std::uint64_t> scale_seq_{0};
    std::atomic<std::uint64_t> pose_seq_{0};
    drivers::base::UniqueFd wake_fd_;
};

// CLOCK_MONOTONIC now, nanoseconds.
std::int64_t monotonicNowNs();

}  // namespace scaled::daemon
