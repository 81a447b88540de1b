#pragma once

// The daemon's pipeline: three threads joined by bounded hand-overs.
//
//   capture   reads the source (a paced replay, the sim, later a camera) into
//             a ring of capture_queue_frames frames. When the ring is full a
//             live or real-time source drops its oldest queued frame (counted);
//             a fast replay waits instead (nothing is dropped, the run is
//             deterministic).
//   tracking  runs the EKF MonoSLAM on every frame. On every Nth frame of a
//             map (or once per detection.period_s) it captures a SlamSnapshot
//             and a copy of the image into the detection mailbox: a single
//             slot, latest wins, so detection never blocks tracking (a frame
//             replaced before the detector took it is counted as skipped; in a
//             fast replay tracking waits for the slot instead). It sends the
//             watchdog heartbeat.
//   detection runs the detector on the mailbox's frame, then the scale update
//             against that frame's snapshot (not the current map), and
//             publishes the report.
//
// Epochs: when SLAM loses its map and starts a new one, the scale starts anew.
// The tracking thread bumps the epoch; the report's scale is cleared at once,
// a detection whose snapshot belongs to an older epoch is dropped, and the
// estimator is reset before the first update of the new epoch. Every report
// carries the epoch.
//
// The per-frame path allocates nothing once running: the ring, the snapshots,
// the image copies and the estimator's buffers are sized at start().

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/slam/slam_snapshot.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/frame_step.h>
#include <scaled/daemon/imu_service.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/report.h>
#include <scaled/daemon/window_ba_worker.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/imu/gyro_feed.h>
#include <scaled/drivers/imu/map_gravity.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::daemon {

// What the pipeline reports as it goes (the field log implements it). Called
// from the pipeline's threads; implementations must be thread-safe and must
// not block (the log queues and drops).
class PipelineEvents {
public:
    PipelineEvents() = default;
    PipelineEvents(const PipelineEvents&) = delete;
    PipelineEvents& operator=(const PipelineEvents&) = delete;
    PipelineEvents(PipelineEvents&&) = delete;
    PipelineEvents& operator=(PipelineEvents&&) = delete;
    virtual ~PipelineEvents() = default;

    struct Frame {
        std::int64_t frame_id = 0;
        std::int64_t t_ns = 0;
        std::uint64_t epoch = 0;
        const char* health = "";
        int features = 0;
        int tracked = 0;
        double ms = 0;
        std::uint64_t dropped = 0;
        // This frame's tracker stages, microseconds (0: the stage did not
        // run on this frame).
        drivers::vision::StageTimes stage_us;
    };
    struct Scale {
        const ScaleReport* report = nullptr;
        int new_observations = 0;
        int detections = 0;
        std::span<const core::ObservationRecord> records;
        std::span<const core::Detection> detections_used;  // records index into this
        bool paper_variance = false;  // sigma_D is the paper's (else propagated)
        // The object table after this update (estimator.model "object"; empty
        // with the paper model). An object whose last_frame is the report's
        // frame_id received a view in this update.
        std::span<const ObjectReport> objects;
    };
    // A window optimisation and the frame that took its result.
    struct WindowBa {
        std::int64_t frame_id = -1;
        std::int64_t t_ns = 0;
        std::uint64_t epoch = 0;
        const core::slam::WindowBaReport* report = nullptr;
    };
    // The pose of a tracked frame (the one published to the hub) with its
    // metric part at the scale the daemon serves at that moment.
    struct Pose {
        const PoseReport* pose = nullptr;
        MetricPose metric;  // metricPose(*pose, the latest scale report)
        DaemonState state = DaemonState::kInitialising;  // that report's
    };

    // Every LogConfig::frame_every tracked frames.
    virtual void onFrame(const Frame& frame) = 0;
    // Every tracked frame, on the tracking thread (the receiver thins them:
    // LogEvents to LogConfig::pose_rate_hz). Must not block or allocate.
    virtual void onPose(const Pose& pose) = 0;
    virtual void onDetection(const drivers::detector::DetectionResult& result, std::uint64_t epoch,
                             double latency_ms) = 0;
    virtual void onScale(const Scale& scale) = 0;
    // Every window optimisation (tracker.window_ba), on the tracking thread.
    // Must not block or allocate.
    virtual void onWindowBa(const WindowBa& window) = 0;
    virtual void onState(DaemonState from, DaemonState to, std::uint64_t epoch,
                         std::int64_t frame_id, const char* reason) = 0;
    virtual void onError(const char* where, const std::string& message) = 0;
};

struct PipelineParts {
    std::unique_ptr<drivers::source::FrameSource> source;  // paced already when it should be
    std::unique_ptr<drivers::detector::ObjectDetector> detector;
    core::PriorTable priors;
    std::string source_name;  // for STATUS ("sim", "replay:/data/redkitchen")
    // Set when `source` is a live camera (it points into `source`): a
    // kUnavailable error of next() (device lost, no frame in time) is then a
    // fault the capture thread recovers from by calling reopen() with a
    // backoff (camera.retry_initial_s doubling to retry_max_s), not a failure.
    drivers::camera::LiveCamera* live = nullptr;
    // Fast replay: capture waits for tracking and tracking for the detector
    // (nothing dropped, deterministic). Else frames are dropped when late.
    bool lossless = false;
    // The live IMU ([imu]) when one is configured and open: each new map
    // takes its vertical from the accelerometer first. Not owned; it must
    // outlive the pipeline.
    ImuService* imu = nullptr;
    // imu.device is set but could not be opened: why (STATUS.imu.error).
    std::string imu_error;
};

// The estimator's object table into out.objects (cleared first), at most its
// capacity: with storage reserved for the table (ScaleEstimator::objects()->
// capacity()) nothing is allocated. Heights at `posterior` (the estimator's
// summary). Empty with the paper model; epoch, frame_id and model are left
// to the caller.
void collectObjects(const core::ScaleEstimator& estimator, const core::ScaleSummary& posterior,
                    ObjectsSnapshot& out);

class Pipeline {
public:
    // Checks the parts (intrinsics, priors, detector present) and sizes every
    // buffer. `events` may be null; it must outlive the pipeline.
    static core::Result<std::unique_ptr<Pipeline>> create(const DaemonConfig& config,
                                                          PipelineParts parts, ReportHub& hub,
                                                          PipelineEvents* events);
    ~Pipeline();
    Pipeline(const Pipeline&) = delete;
    Pipeline& operator=(const Pipeline&) = delete;
    Pipeline(Pipeline&&) = delete;
    Pipeline& operator=(Pipeline&&) = delete;

    // Starts the threads (once).
    core::Status start();
    // Stops and joins the threads (idempotent). Frames still queued are dropped.
    void stop();

    // The source ended with at_end = exit and everything queued was
    // processed, or the source failed: the daemon should stop.
    [[nodiscard]] bool finished() const { return finished_.load(); }
    // Why the pipeline failed, if it did (source error).
    [[nodiscard]] std::optional<core::Error> failure() const;
    // Increases while the tracking loop is alive (every frame, and every
    // 200 ms when idle): the watchdog sends WATCHDOG=1 only while it moves.
    [[nodiscard]] std::uint64_t heartbeat() const { return heartbeat_.load(); }

    // SIGHUP: new priors and detector, new detection schedule. Applied by the
    // detection thread before its next run; the posterior is kept.
    void reload(core::PriorTable priors,
                std::unique_ptr<drivers::detector::ObjectDetector> detector,
                const DetectionSchedule& schedule);
    // A problem outside the pipeline that clients should see in SCALE.fault
    // (e.g. the field log stopped); empty clears it.
    void setFault(const std::string& fault);

private:
    Pipeline(const DaemonConfig& config, PipelineParts parts, ReportHub& hub,
             PipelineEvents* events, const core::PinholeRadialCamera& camera);

    struct QueuedFrame {
        drivers::source::Frame frame;
        bool restart = false;  // first frame after a loop or a reconnect: a discontinuity
    };
    struct DetectionJob {
        core::slam::SlamSnapshot snapshot;
        cv::Mat image;  // the frame's colour image (copied into reserved storage)
        std::int64_t t_ns = 0;
    };

    void captureLoop();
    // The live camera stopped (kUnavailable): fault, reopen with backoff.
    // false when stopping.
    bool recoverCamera(const core::Error& error);
    void setSourceFault(const std::string& fault);
    // The tracking thread: one frame step per frame (frame_step.h), then
    // the daemon's part (state, status, pose, detection job, events).
    struct TrackingState;
    void trackingLoop();
    void trackFrame(TrackingState& state, QueuedFrame& item);
    const core::slam::ImuWindow* gyroWindow(const drivers::source::Frame& frame,
                                            const TrackingState& state);
    drivers::imu::MapGravity selectGravity(const drivers::source::Frame& frame,
                                           const std::optional<core::Vec3>& override_down_C);
    void recordGravity(const drivers::imu::MapGravity& g);
    std::uint64_t recordTracked(const FrameStepResult& r, std::int64_t frame_id,
                                std::uint64_t tracked);
    void recordWindowBa(const core::slam::WindowBaReport& ba, std::int64_t frame_id,
                        std::uint64_t epoch);
    void trackerEvents(const drivers::vision::TrackStats& stats,
                       const drivers::source::Frame& frame, std::uint64_t epoch);
    void publishPose(const TrackingState& state, const drivers::source::Frame& frame,
                     std::uint64_t epoch);
    void handToDetector(TrackingState& state, const drivers::source::Frame& frame,
                        std::uint64_t epoch);
    // The detection thread: a job from the tracking thread, the detector,
    // the estimator of the job's map.
    struct DetectionState;
    void detectionLoop();
    bool takeJob(DetectionState& state);
    void recordDetectorRun(DetectionState& state, const std::optional<core::Error>& error,
                           double latency_ms);
    void updateScale(DetectionState& state);

    // Capture ring.
    bool pushFrame(QueuedFrame& item);  // false: stopping
    bool popFrame(QueuedFrame& item);   // false: nothing within the idle tick, or stopping

    // Tracking side of the state machine.
    void setSlamState(DaemonState state, std::int64_t frame_id, std::int64_t t_ns,
                      const char* reason, bool new_epoch);
    // Detection side: false when the update belongs to an old epoch.
    bool publishUpdate(const core::ScaleSummary& summary, std::uint64_t epoch,
                       std::int64_t frame_id, std::int64_t t_ns, int new_observations,
                       int detections, std::span<const core::ObservationRecord> records,
                       std::span<const core::Detection> dets);
    DaemonState deriveState() const;  // report_mutex_ held
    void publishLocked(std::span<const double> d, std::span<const double> log_p);
    void publishStatus(bool force);
    void fail(const core::Error& error);

    DaemonConfig config_;
    ReportHub& hub_;
    PipelineEvents* events_;
    std::unique_ptr<drivers::source::FrameSource> source_;
    drivers::camera::LiveCamera* live_ = nullptr;  // source_ when it is a live camera
    std::string source_name_;
    // The vertical of each new map (a replayed sequence's IMU log first).
    drivers::imu::MapGravitySelector gravity_selector_;
    ImuService* imu_ = nullptr;
    std::string imu_label_;
    std::vector<core::ImuSample> imu_samples_;  // the ring's copy at a map's start (reserved)
    // The gyro prior's samples: a replayed sequence's own log (gyro_feed_), or
    // the live IMU's ring since the previous frame (imu_window_ over
    // gyro_samples_, reserved to the ring's capacity).
    drivers::imu::GyroFeed gyro_feed_;
    std::vector<core::ImuSample> gyro_samples_;
    core::slam::ImuWindow imu_window_;
    // Wakes the capture thread's reconnect backoff at stop().
    std::mutex stop_mutex_;
    std::condition_variable stop_cv_;
    std::optional<drivers::vision::MonoTracker> tracker_;
    // Runs tracker_'s deferred window optimisations; after tracker_, so it is
    // destroyed first (it waits for a running one).
    std::unique_ptr<WindowBaWorker> ba_worker_;
    std::optional<core::ScaleEstimator> estimator_;
    std::unique_ptr<drivers::detector::ObjectDetector> detector_;

    std::atomic<std::uint64_t> heartbeat_{0};
    std::int64_t start_mono_ns_ = 0;

    // Capture ring (capture -> tracking).
    std::mutex ring_mutex_;
    std::condition_variable ring_not_empty_;
    std::condition_variable ring_not_full_;
    std::vector<QueuedFrame> ring_;
    std::size_t ring_head_ = 0;
    std::size_t ring_count_ = 0;

    // Detection mailbox (tracking -> detection): latest wins.
    std::mutex job_mutex_;
    std::condition_variable job_ready_;
    std::condition_variable job_taken_;
    DetectionJob pending_;
    // SIGHUP reload, applied by the detection thread.
    std::optional<core::PriorTable> reload_priors_;
    std::unique_ptr<drivers::detector::ObjectDetector> reload_detector_;
    DetectionSchedule schedule_;  // job_mutex_

    // Report and state (both threads).
    mutable std::mutex report_mutex_;
    ScaleReport report_;
    std::optional<core::Error> failure_;
    std::string external_fault_;
    std::string detector_fault_;
    std::string source_fault_;  // the live camera is lost; cleared when it is back

    // Status counters (report_mutex_ for the few the detection thread writes).
    PipelineStatus status_;
    std::int64_t last_status_publish_ns_ = 0;
    std::int64_t fps_window_start_ns_ = 0;
    std::uint64_t fps_window_frames_ = 0;
    std::atomic<std::uint64_t> captured_{0};
    std::atomic<std::uint64_t> dropped_{0};

    // Posterior copy in doubles for the hub (detection thread).
    std::vector<double> grid_d_;
    std::vector<double> log_p_;
    // The object table for the hub and the log (detection thread; reserved
    // for the estimator's table in create()).
    ObjectsSnapshot objects_;

    std::thread capture_thread_;
    std::thread tracking_thread_;
    std::thread detection_thread_;

    // Flags and small states, together (padding).
    std::atomic<bool> stop_{false};
    std::atomic<bool> finished_{false};
    std::atomic<bool> started_{false};
    std::atomic<bool> source_finished_{false};
    bool lossless_ = false;
    bool capture_done_ = false;   // ring_mutex_: the source ended or failed; nothing more will come
    bool pending_full_ = false;   // job_mutex_
    bool tracking_done_ = false;  // job_mutex_
    DaemonState slam_state_ = DaemonState::kInitialising;       // report_mutex_
    DaemonState published_state_ = DaemonState::kInitialising;  // report_mutex_
    core::ScaleState scale_state_ = core::ScaleState::kNoData;  // report_mutex_
};

}  // namespace scaled::daemon
