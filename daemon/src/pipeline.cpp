#include <algorithm>
#include <chrono>
#include <cmath>
#include <pthread.h>
#include <utility>

#include <scaled/daemon/pipeline.h>
#include <scaled/daemon/pose.h>
#include <scaled/drivers/detector/thread_priority.h>
#include <scaled/drivers/imu/map_gravity.h>

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

// How long an idle loop waits before it looks at the stop flag again and
// bumps the heartbeat.
constexpr auto kIdleTick = std::chrono::milliseconds(200);
constexpr std::int64_t kStatusPeriodNs = 200'000'000;
constexpr std::size_t kMaxRecords = 512;

double msBetween(std::int64_t a_ns, std::int64_t b_ns) {
    return static_cast<double>(b_ns - a_ns) * 1e-6;
}

// A tracker stage's time of one frame; 0 means the stage did not run on that
// frame (TrackStats) and adds no sample.
void addStage(StageTiming& stage, double us) {
    if (us > 0) {
        stage.add(us * 1e-3);
    }
}

}  // namespace

Result<std::unique_ptr<Pipeline>> Pipeline::create(const DaemonConfig& config, PipelineParts parts,
                                                   ReportHub& hub, PipelineEvents* events) {
    if (!parts.source) {
        return makeError(ErrorCode::kInvalidArgument, "pipeline: no frame source");
    }
    if (!parts.detector) {
        return makeError(ErrorCode::kInvalidArgument, "pipeline: no detector");
    }
    const auto& info = parts.source->info();
    if (!info.has_intrinsics) {
        return makeError(ErrorCode::kInvalidArgument,
                         parts.source_name + ": the source gives no camera intrinsics");
    }
    auto camera = core::PinholeRadialCamera::create(info.intrinsics);
    if (!camera) {
        return camera.error();
    }
    if (config.queues.capture_queue_frames < 1) {
        return makeError(ErrorCode::kInvalidArgument,
                         "pipeline.capture_queue_frames: must be at least 1");
    }
    // A replayed sequence's maps take their vertical as slam-run and
    // scale-eval do: its accelerometer log, its gravity and ground truth, a
    // level camera (drivers::imu::MapGravitySelector).
    // A live source has no log: the selector then takes the frame's gravity
    // or a level camera.
    drivers::imu::MapGravitySelector gravity;
    if (parts.live == nullptr && !info.dir.empty()) {
        auto g = drivers::imu::MapGravitySelector::forDataset(info.dir);
        if (!g) {
            return g.error();
        }
        gravity = std::move(*g);
    }
    core::PriorTable priors = std::move(parts.priors);
    std::unique_ptr<Pipeline> p(new Pipeline(config, std::move(parts), hub, events, *camera));
    p->gravity_selector_ = std::move(gravity);
    // A replayed sequence's IMU log with a gyroscope feeds the gyro prior, as
    // in scale-eval and slam-run (drivers/imu/gyro_feed.h).
    auto feed = drivers::imu::GyroFeed::create(p->gravity_selector_, std::nullopt);
    if (!feed) {
        return feed.error();
    }
    p->gyro_feed_ = std::move(*feed);
    if (p->imu_ == nullptr && p->gyro_feed_.active()) {
        p->status_.gyro.present = true;
        p->status_.gyro.source = p->gyro_feed_.source();
    }
    auto tracker = drivers::vision::MonoTracker::create(*camera, config.pipeline.tracker);
    if (!tracker) {
        return tracker.error();
    }
    p->tracker_.emplace(std::move(*tracker));
    p->ba_worker_ = WindowBaWorker::attachTo(*p->tracker_);
    auto estimator =
        core::ScaleEstimator::create(config.pipeline.estimator, std::move(priors), *camera);
    if (!estimator) {
        return estimator.error();
    }
    p->estimator_.emplace(std::move(*estimator));

    // Every buffer of the per-frame path, sized once.
    const int max_features = config.pipeline.tracker.slam.max_features;
    if (auto r = p->pending_.snapshot.reserve(max_features); !r) {
        return r.error();
    }
    p->ring_.resize(static_cast<std::size_t>(config.queues.capture_queue_frames));
    const auto& grid = p->estimator_->posterior().grid();
    p->grid_d_.resize(grid.size());
    for (std::size_t j = 0; j < grid.size(); ++j) {
        p->grid_d_[j] = static_cast<double>(grid.d(j));
    }
    p->log_p_.resize(grid.size());
    const core::ObjectEvidence* objects = p->estimator_->objects();
    const std::size_t max_objects = objects != nullptr ? objects->capacity() : 0;
    p->objects_.model = config.pipeline.estimator.model;
    p->objects_.objects.reserve(max_objects);
    hub.setObjectModel(config.pipeline.estimator.model, max_objects);
    return p;
}

void collectObjects(const core::ScaleEstimator& estimator, const core::ScaleSummary& posterior,
                    ObjectsSnapshot& out) {
    out.objects.clear();
    const core::ObjectEvidence* table = estimator.objects();
    if (table == nullptr) {
        return;
    }
    const auto priors = estimator.priors().priors();
    const int n = std::min(table->activeCount(), static_cast<int>(out.objects.capacity()));
    for (int k = 0; k < n; ++k) {
        const core::ObjectSummary s = table->summary(k, posterior);
        ObjectReport& o = out.objects.emplace_back();
        o.id = s.id;
        const auto c = static_cast<std::size_t>(s.class_index);
        o.setClassName(s.class_index >= 0 && c < priors.size() ? priors[c].className() : "?");
        o.state = s.state;
        o.anchor = {static_cast<double>(s.p_AinW.x()), static_cast<double>(s.p_AinW.y()),
                    static_cast<double>(s.p_AinW.z())};
        o.anchor_rel_sigma = static_cast<double>(s.anchor_rel_sigma);
        o.detections = s.detections;
        o.views = s.views;
        o.views_used = s.views_used;
        o.first_frame = s.first_frame;
        o.last_frame = s.last_frame;
        o.local_estimate = static_cast<double>(s.local_estimate);
        // The core reports 0 when the object is unused or the posterior empty.
        o.has_height = s.state == core::ObjectState::kUsed && s.height_m > 0;
        o.height_m = static_cast<double>(s.height_m);
        o.height_ci95_lo_m = static_cast<double>(s.height_ci95_m.lo);
        o.height_ci95_hi_m = static_cast<double>(s.height_ci95_m.hi);
    }
}

Pipeline::Pipeline(const DaemonConfig& config, PipelineParts parts, ReportHub& hub,
                   PipelineEvents* events, const core::PinholeRadialCamera& camera)
    : config_(config),
      hub_(hub),
      events_(events),
      source_(std::move(parts.source)),
      live_(parts.live),
      source_name_(std::move(parts.source_name)),
      detector_(std::move(parts.detector)),
      schedule_(config.pipeline.detection),
      lossless_(parts.lossless) {
    imu_ = parts.imu;
    status_.source = source_name_;
    status_.frames_total = static_cast<std::int64_t>(source_->info().frame_count);
    if (live_ != nullptr) {
        status_.live = true;
        status_.camera_device = live_->describe();
        status_.camera_mode = live_->mode();
    }
    report_.fault.reserve(256);
    const core::slam::WindowBaConfig& ba = config.pipeline.tracker.window_ba;
    WindowBaStatus& w = status_.window_ba;
    w.present = ba.enabled;
    w.rolling_shutter_estimated = core::slam::estimatesReadout(ba);
    w.focal_estimated = core::slam::estimatesFocal(ba);
    w.k1_estimated = core::slam::estimatesK1(ba);
    w.rolling_shutter_s = static_cast<double>(ba.rolling_shutter_s);
    w.k1 = static_cast<double>(camera.intrinsics().k1);
    if (imu_ != nullptr) {
        status_.imu = imu_->status();
        imu_label_ = status_.imu.device;
        imu_samples_.reserve(imu_->capacity());
        if (imu_->hasGyro()) {
            gyro_samples_.reserve(imu_->capacity());
            status_.gyro.present = true;
            status_.gyro.source = imu_label_;
        }
    } else if (!config.imu.device.empty()) {
        status_.imu.configured = true;
        status_.imu.device = config.imu.device;
        status_.imu.mode = toString(config.imu.mode);
        status_.imu.error = parts.imu_error;
    }
}

Pipeline::~Pipeline() {
    stop();
}

Status Pipeline::start() {
    if (started_.exchange(true)) {
        return makeError(ErrorCode::kInvalidArgument, "pipeline: already started");
    }
    start_mono_ns_ = monotonicNowNs();
    fps_window_start_ns_ = start_mono_ns_;
    {
        const std::lock_guard lock(report_mutex_);
        publishLocked({}, {});
    }
    publishStatus(true);
    detection_thread_ = std::thread([this] { detectionLoop(); });
    tracking_thread_ = std::thread([this] { trackingLoop(); });
    capture_thread_ = std::thread([this] { captureLoop(); });
    // Names for top -H, ps -L and the tests (15 characters at most).
    ::pthread_setname_np(detection_thread_.native_handle(), "scaled-detect");
    ::pthread_setname_np(tracking_thread_.native_handle(), "scaled-track");
    ::pthread_setname_np(capture_thread_.native_handle(), "scaled-capture");
    return {};
}

void Pipeline::stop() {
    {
        const std::lock_guard lock(stop_mutex_);
        stop_.store(true);
    }
    stop_cv_.notify_all();
    if (live_ != nullptr) {
        live_->stop();  // a capture blocked in the camera's poll returns at once
    }
    ring_not_empty_.notify_all();
    ring_not_full_.notify_all();
    job_ready_.notify_all();
    job_taken_.notify_all();
    for (std::thread* t : {&capture_thread_, &tracking_thread_, &detection_thread_}) {
        if (t->joinable()) {
            t->join();
        }
    }
}

std::optional<core::Error> Pipeline::failure() const {
    const std::lock_guard lock(report_mutex_);
    return failure_;
}

void Pipeline::reload(core::PriorTable priors,
                      std::unique_ptr<drivers::detector::ObjectDetector> detector,
                      const DetectionSchedule& schedule) {
    const std::lock_guard lock(job_mutex_);
    reload_priors_ = std::move(priors);
    reload_detector_ = std::move(detector);
    schedule_ = schedule;
}

void Pipeline::setFault(const std::string& fault) {
    const std::lock_guard lock(report_mutex_);
    if (external_fault_ == fault) {
        return;
    }
    external_fault_ = fault;
    publishLocked({}, {});
}

void Pipeline::fail(const core::Error& error) {
    {
        const std::lock_guard lock(report_mutex_);
        if (!failure_) {
            failure_ = error;
        }
        const DaemonState before = published_state_;
        publishLocked({}, {});
        if (events_ != nullptr && before != published_state_) {
            events_->onState(before, published_state_, report_.epoch, report_.frame_id,
                             "source failed");
        }
    }
    if (events_ != nullptr) {
        events_->onError("source", error.message);
    }
    finished_.store(true);
}

// --- capture ----------------------------------------------------------------

bool Pipeline::pushFrame(QueuedFrame& item) {
    std::unique_lock lock(ring_mutex_);
    const std::size_t cap = ring_.size();
    if (ring_count_ == cap) {
        if (lossless_) {
            ring_not_full_.wait(lock, [&] { return stop_.load() || ring_count_ < cap; });
            if (stop_.load()) {
                return false;
            }
        } else {
            // A live camera keeps the freshest frames: the oldest queued one goes.
            ring_head_ = (ring_head_ + 1) % cap;
            --ring_count_;
            dropped_.fetch_add(1);
        }
    }
    std::swap(ring_[(ring_head_ + ring_count_) % cap], item);
    ++ring_count_;
    lock.unlock();
    ring_not_empty_.notify_one();
    return true;
}

bool Pipeline::popFrame(QueuedFrame& item) {
    std::unique_lock lock(ring_mutex_);
    if (!ring_not_empty_.wait_for(lock, kIdleTick,
                                  [&] { return stop_.load() || ring_count_ > 0; }) ||
        ring_count_ == 0) {
        return false;
    }
    std::swap(item, ring_[ring_head_]);
    ring_head_ = (ring_head_ + 1) % ring_.size();
    --ring_count_;
    lock.unlock();
    ring_not_full_.notify_one();
    return true;
}

void Pipeline::captureLoop() {
    QueuedFrame item;
    const std::int64_t max_frames = config_.source.max_frames;
    std::int64_t read = 0;
    // Loop replay: ids and timestamps continue across passes so clients see
    // them increase; the first frame of a pass is marked as a discontinuity.
    std::int64_t id_offset = 0;
    std::int64_t t_offset_ns = 0;
    std::int64_t last_id = -1;
    std::int64_t last_t_ns = 0;
    std::int64_t last_gap_ns = 33'333'333;
    bool restart = false;
    std::uint64_t consecutive_errors = 0;
    while (!stop_.load()) {
        if (max_frames > 0 && read >= max_frames) {
            break;
        }
        auto got = source_->next(item.frame);
        if (!got && live_ != nullptr && got.error().code == ErrorCode::kUnavailable) {
            if (!recoverCamera(got.error())) {
                break;
            }
            restart = true;  // the map cannot continue across the gap: a new epoch
            continue;
        }
        if (!got) {
            // An unreadable frame: logged, skipped (the reader moved past it).
            if (events_ != nullptr) {
                events_->onError("capture", got.error().message);
            }
            if (++consecutive_errors >= 100) {
                fail(makeError(got.error().code,
                               "100 unreadable frames in a row, last: " + got.error().message));
                break;
            }
            continue;
        }
        consecutive_errors = 0;
        if (!*got) {
            if (config_.source.at_end == AtEnd::kLoop && last_id >= 0) {
                if (auto s = source_->seek(0); !s) {
                    fail(s.error());
                    break;
                }
                id_offset = last_id + 1;
                t_offset_ns = last_t_ns + last_gap_ns;
                restart = true;
                continue;
            }
            break;
        }
        if (restart) {
            // The first frame of a new pass defines the offsets.
            t_offset_ns -= item.frame.t_ns;
            id_offset -= item.frame.id;
        }
        item.frame.id += id_offset;
        item.frame.t_ns += t_offset_ns;
        if (last_id >= 0 && item.frame.t_ns > last_t_ns) {
            last_gap_ns = item.frame.t_ns - last_t_ns;
        }
        last_id = item.frame.id;
        last_t_ns = item.frame.t_ns;
        item.restart = restart;
        restart = false;
        ++read;
        captured_.fetch_add(1);
        if (!pushFrame(item)) {
            break;
        }
    }
    source_finished_.store(true);
    {
        const std::lock_guard lock(ring_mutex_);
        capture_done_ = true;
    }
    ring_not_empty_.notify_all();
}

void Pipeline::setSourceFault(const std::string& fault) {
    const std::lock_guard lock(report_mutex_);
    source_fault_ = fault;
    status_.camera_lost = !fault.empty();
    if (live_ != nullptr && fault.empty()) {
        status_.camera_device = live_->describe();
        status_.camera_mode = live_->mode();
    }
    // STATUS shows it at once (the counters in it are as of the last publish).
    hub_.publishStatus(status_);
    const DaemonState before = published_state_;
    publishLocked({}, {});
    if (events_ != nullptr && before != published_state_) {
        events_->onState(before, published_state_, report_.epoch, report_.frame_id,
                         fault.empty() ? "camera back" : "camera lost");
    }
}

bool Pipeline::recoverCamera(const core::Error& error) {
    if (events_ != nullptr) {
        events_->onError("camera", error.message);
    }
    setSourceFault("camera: " + error.message);
    const auto& c = config_.camera;
    double wait_s = c.retry_initial_s;
    std::string last_message = error.message;
    while (!stop_.load()) {
        {
            std::unique_lock lock(stop_mutex_);
            stop_cv_.wait_for(lock, std::chrono::duration<double>(wait_s),
                              [&] { return stop_.load(); });
        }
        if (stop_.load()) {
            return false;
        }
        auto reopened = live_->reopen();
        if (reopened && *reopened) {
            {
                const std::lock_guard lock(report_mutex_);
                ++status_.camera_reconnects;
            }
            setSourceFault({});
            return true;
        }
        if (!reopened && reopened.error().message != last_message) {
            // Logged when the reason changes, not at every attempt.
            last_message = reopened.error().message;
            if (events_ != nullptr) {
                events_->onError("camera", last_message);
            }
            setSourceFault("camera: " + last_message);
        }
        wait_s = std::min(wait_s * 2, c.retry_max_s);
    }
    return false;
}

// --- tracking ---------------------------------------------------------------

void Pipeline::setSlamState(DaemonState state, std::int64_t frame_id, std::int64_t t_ns,
                            const char* reason, bool new_epoch) {
    const std::lock_guard lock(report_mutex_);
    if (!new_epoch && state == slam_state_) {
        return;
    }
    slam_state_ = state;
    if (new_epoch) {
        if (report_.has_scale) {
            // The map that ends had a scale: keep its last one for the clients.
            report_.previous = {true,
                                report_.epoch,
                                report_.scale,
                                report_.ci95_lo,
                                report_.ci95_hi,
                                report_.observations,
                                report_.frame_id};
        }
        report_.epoch += 1;
        report_.has_scale = false;
        report_.wide_for_poses = false;
        report_.scale = report_.mean = 0;
        report_.ci68_lo = report_.ci68_hi = report_.ci95_lo = report_.ci95_hi = 0;
        report_.observations = 0;
        report_.frame_id = frame_id;
        report_.t_ns = t_ns;
        report_.updated_mono_ns = 0;
        scale_state_ = core::ScaleState::kNoData;
    }
    const DaemonState before = published_state_;
    publishLocked({}, {});
    if (events_ != nullptr && (before != published_state_ || new_epoch)) {
        events_->onState(before, published_state_, report_.epoch, frame_id, reason);
    }
}

// The tracking thread's own state between frames.
struct Pipeline::TrackingState {
    explicit TrackingState(drivers::vision::MonoTracker& tracker) : step(tracker) {}

    FrameStep step;
    core::slam::SlamSnapshot staging;  // the next detection job, filled here, swapped in
    cv::Mat staging_image;
    std::optional<core::Vec3> gravity_override;  // a client's set_gravity
    std::int64_t last_t_ns = 0;
    bool have_last = false;
    std::uint64_t tracked = 0;
};

void Pipeline::trackingLoop() {
    TrackingState state(*tracker_);
    if (!state.staging.reserve(config_.pipeline.tracker.slam.max_features)) {
        fail(makeError(ErrorCode::kInvalidArgument, "cannot reserve the SLAM snapshot"));
        return;
    }
    QueuedFrame item;
    while (!stop_.load()) {
        heartbeat_.fetch_add(1);
        if (auto g = hub_.takeGravityRequest()) {
            state.gravity_override = *g;
        }
        if (!popFrame(item)) {
            // At the end of a replay with at_end = exit the loop ends; else it
            // idles (and keeps the watchdog fed) until stop().
            bool done = false;
            {
                const std::lock_guard lock(ring_mutex_);
                done = capture_done_ && ring_count_ == 0;
            }
            if (done && (config_.source.at_end == AtEnd::kExit || finished_.load())) {
                break;
            }
            publishStatus(false);
            continue;
        }
        trackFrame(state, item);
        publishStatus(false);
    }
    {
        const std::lock_guard lock(job_mutex_);
        tracking_done_ = true;
    }
    job_ready_.notify_all();
    publishStatus(true);
}

void Pipeline::trackFrame(TrackingState& state, QueuedFrame& item) {
    const drivers::source::Frame& frame = item.frame;
    if (item.restart || (state.have_last && frame.t_ns <= state.last_t_ns)) {
        // A discontinuity (replay loop): the map cannot continue.
        state.step.restart();
        setSlamState(DaemonState::kInitialising, frame.id, frame.t_ns,
                     live_ != nullptr ? "camera reconnected" : "replay restarted", false);
    }
    const core::slam::ImuWindow* gyro = gyroWindow(frame, state);
    state.have_last = true;
    state.last_t_ns = frame.t_ns;
    const FrameStepResult r = state.step.track(frame, gyro, [&](const drivers::source::Frame& f) {
        return selectGravity(f, state.gravity_override);
    });
    if (r.gravity != nullptr) {
        recordGravity(*r.gravity);
    }
    ++state.tracked;
    const drivers::vision::TrackStats& stats = r.stats;
    if (r.map_started) {
        setSlamState(DaemonState::kTracking, frame.id, frame.t_ns, "new map", true);
    } else if (r.ok) {
        setSlamState(DaemonState::kTracking, frame.id, frame.t_ns,
                     stats.relocalised ? "relocalised" : "tracking", false);
    }
    const std::uint64_t epoch = recordTracked(r, frame.id, state.tracked);
    trackerEvents(stats, frame, epoch);
    ++fps_window_frames_;
    if (r.ok) {
        publishPose(state, frame, epoch);
    }
    if (r.ok && r.frames_in_map > 1) {
        // Only a tracked frame past the map's first can be due (no lock
        // otherwise: a SIGHUP reload holds it while it swaps the detector).
        DetectionSchedule schedule;
        {
            const std::lock_guard lock(job_mutex_);
            schedule = schedule_;
        }
        if (state.step.detectionDue(r, schedule, frame.t_ns)) {
            handToDetector(state, item.frame, epoch);
        }
    }
    if (events_ != nullptr && config_.log.frame_every > 0 &&
        state.tracked % static_cast<std::uint64_t>(config_.log.frame_every) == 0) {
        PipelineEvents::Frame e;
        e.frame_id = frame.id;
        e.t_ns = frame.t_ns;
        e.epoch = epoch;
        e.health = core::slam::toString(stats.health);
        e.features = stats.features;
        e.tracked = stats.inliers + stats.rescued;
        e.ms = r.track_ms;
        e.dropped = dropped_.load();
        e.stage_us = stats.stage_us;
        events_->onFrame(e);
    }
    if (stats.health == core::slam::SlamHealth::kRelocalising) {
        // Lost, the map kept: the tracker looks for the camera in it for
        // up to tracker.relocalise_s; the epoch and the scale stay.
        setSlamState(DaemonState::kLost, frame.id, frame.t_ns, "relocalising", false);
    } else if (r.map_lost) {
        // Lost or diverged (the frame step reset the tracker): the next frame
        // starts a new map with a new, unrelated scale; the epoch moves when
        // it does.
        setSlamState(DaemonState::kLost, frame.id, frame.t_ns, core::slam::toString(stats.health),
                     false);
    }
}

// The gyro prior's samples for the interval since the previous frame: the
// live IMU's (on the frames' clock, CLOCK_MONOTONIC), else a replayed log's.
// Samples on another clock cover no interval: the tracker then predicts with
// constant velocity.
const core::slam::ImuWindow* Pipeline::gyroWindow(const drivers::source::Frame& frame,
                                                  const TrackingState& state) {
    if (imu_ == nullptr) {
        return gyro_feed_.forFrame(frame);
    }
    if (!status_.gyro.present || !state.have_last || !config_.pipeline.tracker.use_gyro) {
        return nullptr;
    }
    imu_->copySince(state.last_t_ns, gyro_samples_);
    imu_window_.samples = gyro_samples_;
    imu_window_.R_ItoC = imu_->rotationImuToCamera();
    return &imu_window_;
}

// The vertical of a map that starts at this frame: a client's set_gravity,
// else the live accelerometer's last window, else the replayed sequence's.
drivers::imu::MapGravity Pipeline::selectGravity(const drivers::source::Frame& frame,
                                                 const std::optional<core::Vec3>& override_down_C) {
    if (override_down_C) {
        drivers::imu::MapGravity g;
        g.down_C = *override_down_C;
        g.source = "set_gravity request";
        return g;
    }
    if (imu_ == nullptr) {
        return gravity_selector_.atMapStart(frame);
    }
    imu_->copyRecent(imu_samples_);
    drivers::imu::LiveAccelerometer live;
    live.samples = imu_samples_;
    live.R_ItoC = imu_->rotationImuToCamera();
    live.label = imu_label_;
    live.now_ns = imu_->nowNs();
    live.window_s = imu_->windowS();
    return gravity_selector_.atMapStart(frame, live);
}

void Pipeline::recordGravity(const drivers::imu::MapGravity& g) {
    const std::lock_guard lock(report_mutex_);
    status_.gravity_source = g.source;
    status_.gravity_down_C =
        std::array<double, 3>{static_cast<double>(g.down_C.x()), static_cast<double>(g.down_C.y()),
                              static_cast<double>(g.down_C.z())};
}

// The frame's counters and stage times into status_; the map's epoch.
std::uint64_t Pipeline::recordTracked(const FrameStepResult& r, std::int64_t frame_id,
                                      std::uint64_t tracked) {
    const drivers::vision::TrackStats& stats = r.stats;
    const std::lock_guard lock(report_mutex_);
    const std::uint64_t epoch = report_.epoch;
    status_.frame_id = frame_id;
    status_.frames_tracked = tracked;
    status_.features_in_map = stats.features;
    status_.features_tracked = stats.inliers + stats.rescued;
    if (stats.gyro == core::slam::GyroCoverage::kOk) {
        ++status_.gyro.frames;
        const core::Vec3& b = tracker_->gyroBiasC();
        status_.gyro.bias_C_radps = {static_cast<double>(b.x()), static_cast<double>(b.y()),
                                     static_cast<double>(b.z())};
    }
    // Stage statistics live in status_ itself (a few flops under the lock
    // taken anyway): publishStatus copies them to the hub.
    PipelineTiming& timing = status_.timing;
    addStage(timing.predict, stats.stage_us.predict);
    addStage(timing.search, stats.stage_us.search);
    addStage(timing.match, stats.stage_us.match);
    addStage(timing.update, stats.stage_us.update);
    addStage(timing.map, stats.stage_us.map);
    timing.tracking.add(r.track_ms);
    status_.tracking_ms_mean = timing.tracking.mean_ms;
    status_.epoch = epoch;
    if (stats.window_ba.optimised) {
        recordWindowBa(stats.window_ba, frame_id, epoch);
    }
    return epoch;
}

// What the tracker did on this frame beyond tracking it: a window
// optimisation taken (WINDOW), the map's start begun again.
void Pipeline::trackerEvents(const drivers::vision::TrackStats& stats,
                             const drivers::source::Frame& frame, std::uint64_t epoch) {
    if (events_ == nullptr) {
        return;
    }
    if (stats.window_ba.optimised) {
        PipelineEvents::WindowBa e;
        e.frame_id = frame.id;
        e.t_ns = frame.t_ns;
        e.epoch = epoch;
        e.report = &stats.window_ba;
        events_->onWindowBa(e);
    }
    if (stats.start_redone) {
        // The start check began the map again in the same frame and unit
        // (tracker.start_check_s): the pose jumps once, the epoch goes on.
        events_->onState(DaemonState::kTracking, DaemonState::kTracking, epoch, frame.id,
                         "start begun again");
    }
}

// STATUS.window_ba: the optimisation this frame took (report_mutex_ held).
void Pipeline::recordWindowBa(const core::slam::WindowBaReport& ba, std::int64_t frame_id,
                              std::uint64_t epoch) {
    WindowBaStatus& w = status_.window_ba;
    ++w.optimisations;
    w.frame_id = frame_id;
    w.epoch = epoch;
    w.keyframes = ba.keyframes;
    w.points = ba.points;
    w.observations = ba.observations;
    w.rms_px = static_cast<double>(ba.rms_after_px);
    w.scale = static_cast<double>(ba.scale);
    w.rolling_shutter_s = static_cast<double>(ba.rolling_shutter_s);
    w.focal_scale = static_cast<double>(ba.focal_scale);
    w.k1 = static_cast<double>(ba.k1);
}

// POSE: fixed-size arithmetic and a copy into the hub, no allocation.
void Pipeline::publishPose(const TrackingState& state, const drivers::source::Frame& frame,
                           std::uint64_t epoch) {
    // The filter's pose, velocity, covariance and vertical in the map the
    // scale is estimated in (estimator.map): with tracker.window_ba the
    // served pose's frame and unit, so the metric pose is d times it. The
    // adjusted world is turned against the filter's (its first window is
    // fitted to the filter's positions: 45 degrees on redkitchen), so the
    // vertical turns with it; each optimisation moves that turn by up to
    // about a degree, and G with it (docs/protocol.md).
    const core::slam::EkfSlam& filter = tracker_->filter();
    const core::slam::Sim3 T = state.step.estimatorFromFilter(config_.pipeline.estimator_map);
    const PoseReport pose =
        makePoseReport(T.apply(filter.pose()), T.scale * (T.R * filter.velocityW()),
                       T.applyToPoseCovariance(filter.poseCovariance()), T.R * filter.upW(), epoch,
                       frame.id, frame.t_ns);
    hub_.publishPose(pose);
    if (events_ == nullptr) {
        return;
    }
    PipelineEvents::Pose e;
    e.pose = &pose;
    {
        // The scale as published (publishLocked keeps report_ and the hub's
        // in step under this lock).
        const std::lock_guard lock(report_mutex_);
        e.metric = metricPose(pose, report_);
        e.state = report_.state;
    }
    events_->onPose(e);
}

// Into the detection mailbox (latest wins; lossless replays wait for the
// detector to take the previous job).
void Pipeline::handToDetector(TrackingState& state, const drivers::source::Frame& frame,
                              std::uint64_t epoch) {
    state.staging.capture(tracker_->filter(), frame.id, epoch,
                          state.step.estimatorFromFilter(config_.pipeline.estimator_map));
    frame.color.copyTo(state.staging_image);
    std::unique_lock lock(job_mutex_);
    if (lossless_) {
        job_taken_.wait(lock, [&] { return stop_.load() || !pending_full_; });
    }
    if (pending_full_) {
        const std::lock_guard slock(report_mutex_);
        ++status_.detections_skipped;
    }
    std::swap(pending_.snapshot, state.staging);
    std::swap(pending_.image, state.staging_image);
    pending_.t_ns = frame.t_ns;
    pending_full_ = true;
    lock.unlock();
    job_ready_.notify_one();
}

// --- detection and scale ----------------------------------------------------

DaemonState Pipeline::deriveState() const {
    if (failure_ || !source_fault_.empty()) {
        return DaemonState::kFault;
    }
    if (slam_state_ != DaemonState::kTracking) {
        return slam_state_;
    }
    switch (scale_state_) {
        case core::ScaleState::kNoData:
            return DaemonState::kTracking;
        case core::ScaleState::kConverging:
            return DaemonState::kConverging;
        case core::ScaleState::kConverged:
            return DaemonState::kConverged;
    }
    return DaemonState::kTracking;
}

void Pipeline::publishLocked(std::span<const double> d, std::span<const double> log_p) {
    report_.state = deriveState();
    published_state_ = report_.state;
    // Faults in order of importance; assign() keeps the reserved capacity.
    if (failure_) {
        report_.fault.assign("source: ");
        report_.fault.append(failure_->message);
    } else if (!source_fault_.empty()) {
        report_.fault.assign(source_fault_);
    } else if (!detector_fault_.empty()) {
        report_.fault.assign(detector_fault_);
    } else {
        report_.fault.assign(external_fault_);
    }
    hub_.publishScale(report_, d, log_p);
}

bool Pipeline::publishUpdate(const core::ScaleSummary& summary, std::uint64_t epoch,
                             std::int64_t frame_id, std::int64_t t_ns, int new_observations,
                             int detections, std::span<const core::ObservationRecord> records,
                             std::span<const core::Detection> dets) {
    const std::lock_guard lock(report_mutex_);
    if (epoch != report_.epoch) {
        return false;
    }
    const DaemonState before = published_state_;
    report_.has_scale = summary.state != core::ScaleState::kNoData;
    report_.scale = static_cast<double>(summary.map);
    report_.mean = static_cast<double>(summary.mean);
    report_.ci68_lo = static_cast<double>(summary.ci68.lo);
    report_.ci68_hi = static_cast<double>(summary.ci68.hi);
    report_.ci95_lo = static_cast<double>(summary.ci95.lo);
    report_.ci95_hi = static_cast<double>(summary.ci95.hi);
    report_.wide_for_poses = report_.has_scale && wideForPoses(config_.pipeline, report_.scale,
                                                               report_.ci95_lo, report_.ci95_hi);
    report_.observations = summary.observations;
    report_.frame_id = frame_id;
    report_.t_ns = t_ns;
    report_.updated_mono_ns = monotonicNowNs();
    scale_state_ = summary.state;
    ++status_.scale_updates;
    // The objects first: a client woken by the SCALE finds the table of the
    // same update.
    objects_.epoch = epoch;
    objects_.frame_id = frame_id;
    hub_.publishObjects(objects_);
    publishLocked(grid_d_, log_p_);
    if (events_ != nullptr) {
        PipelineEvents::Scale e;
        e.report = &report_;
        e.new_observations = new_observations;
        e.detections = detections;
        e.records = records;
        e.detections_used = dets;
        e.paper_variance =
            config_.pipeline.estimator.likelihood.variance_model == core::VarianceModel::kPaper;
        e.objects = objects_.objects;
        events_->onScale(e);
        if (before != published_state_) {
            events_->onState(before, published_state_, epoch, frame_id, "scale update");
        }
    }
    return true;
}

// The detection thread's own state between jobs.
struct Pipeline::DetectionState {
    DetectionJob job;
    drivers::detector::DetectionResult boxes;
    std::vector<core::Detection> dets;
    std::vector<core::ObservationRecord> records;
    std::uint64_t estimator_epoch = 0;
    std::uint64_t runs = 0;
    double latency_sum_ms = 0;
    double latency_max_ms = 0;
};

void Pipeline::detectionLoop() {
    // Below the tracker and the socket (thread_priority.h); the daemon made
    // OpenCV's workers at this value before the pipeline started.
    if (auto ok = drivers::detector::setThreadNice(config_.pipeline.detector.nice);
        !ok && events_ != nullptr) {
        events_->onError("detector priority", ok.error().message);
    }
    DetectionState state;
    if (!state.job.snapshot.reserve(config_.pipeline.tracker.slam.max_features)) {
        return;
    }
    state.dets.resize(
        static_cast<std::size_t>(std::max(1, config_.pipeline.detector.max_detections)));
    state.records.resize(kMaxRecords);

    while (takeJob(state)) {
        job_taken_.notify_one();
        const std::int64_t t0 = monotonicNowNs();
        auto det = detector_->detect(state.job.image, state.job.snapshot.frameId(), state.job.t_ns,
                                     state.boxes);
        const double latency_ms = msBetween(t0, monotonicNowNs());
        recordDetectorRun(state, det ? std::optional<core::Error>() : det.error(), latency_ms);
        if (!det) {
            if (events_ != nullptr) {
                events_->onError("detector", det.error().message);
            }
            continue;
        }
        if (events_ != nullptr) {
            events_->onDetection(state.boxes, state.job.snapshot.epoch(), latency_ms);
        }
        updateScale(state);
    }
    if (!stop_.load() && config_.source.at_end == AtEnd::kExit) {
        // Everything the source gave was tracked and detected: done.
        publishStatus(true);
        finished_.store(true);
    }
}

// Waits for the tracking thread's next job and takes it, with a SIGHUP
// reload if one waits; false when stopping or when tracking ended and no
// job is left.
bool Pipeline::takeJob(DetectionState& state) {
    std::unique_lock lock(job_mutex_);
    job_ready_.wait(lock, [&] { return stop_.load() || pending_full_ || tracking_done_; });
    if (stop_.load() || (!pending_full_ && tracking_done_)) {
        return false;
    }
    std::swap(state.job.snapshot, pending_.snapshot);
    std::swap(state.job.image, pending_.image);
    state.job.t_ns = pending_.t_ns;
    pending_full_ = false;
    if (reload_priors_) {
        if (auto ok = estimator_->setPriors(std::move(*reload_priors_));
            !ok && events_ != nullptr) {
            // The old priors stay; the evidence is kept either way.
            events_->onError("priors reload", ok.error().message);
        }
        reload_priors_.reset();
    }
    if (reload_detector_) {
        detector_ = std::move(reload_detector_);
        state.dets.resize(
            static_cast<std::size_t>(std::max(1, config_.pipeline.detector.max_detections)));
    }
    return true;
}

// The detector's latency and timing into status_; a failing detector is a
// fault clients see (cleared by its next success).
void Pipeline::recordDetectorRun(DetectionState& state, const std::optional<core::Error>& error,
                                 double latency_ms) {
    ++state.runs;
    state.latency_sum_ms += latency_ms;
    state.latency_max_ms = std::max(state.latency_max_ms, latency_ms);
    const std::lock_guard lock(report_mutex_);
    status_.detections_run = state.runs;
    status_.detector_latency_ms_last = latency_ms;
    status_.detector_latency_ms_mean = state.latency_sum_ms / static_cast<double>(state.runs);
    status_.detector_latency_ms_max = state.latency_max_ms;
    if (!error) {
        // The detector's own split of the call (a detector that does not
        // measure a part reports 0 for it).
        status_.timing.detect_pre.add(state.boxes.timing.pre_ms);
        status_.timing.detect_forward.add(state.boxes.timing.forward_ms);
        status_.timing.detect_post.add(state.boxes.timing.post_ms);
    }
    const bool had_fault = !detector_fault_.empty();
    if (error) {
        detector_fault_ = "detector: " + error->message;
    } else {
        detector_fault_.clear();
    }
    if (had_fault != !detector_fault_.empty()) {
        publishLocked({}, {});
    }
}

// The job's detections into the estimator of its map, and the result out.
void Pipeline::updateScale(DetectionState& state) {
    const core::slam::SlamSnapshot& snapshot = state.job.snapshot;
    if (!snapshot.valid()) {
        return;
    }
    {
        const std::lock_guard lock(report_mutex_);
        if (snapshot.epoch() != report_.epoch) {
            return;  // the map this frame belongs to is gone
        }
    }
    auto& estimator = *estimator_;
    if (snapshot.epoch() != state.estimator_epoch) {
        estimator.reset();
        state.estimator_epoch = snapshot.epoch();
    }
    const std::size_t n = drivers::detector::toEstimatorDetections(state.boxes, state.dets);
    const std::int64_t update_start_ns = monotonicNowNs();
    const core::UpdateStats u =
        estimator.update(snapshot.view(), std::span(state.dets.data(), n), state.records);
    const std::int64_t publish_start_ns = monotonicNowNs();
    const auto log_p = estimator.posterior().logDensity();
    for (std::size_t j = 0; j < log_p.size() && j < log_p_.size(); ++j) {
        log_p_[j] = static_cast<double>(log_p[j]);
    }
    const core::ScaleSummary summary = estimator.summary();
    collectObjects(estimator, summary, objects_);
    publishUpdate(summary, snapshot.epoch(), snapshot.frameId(), snapshot.timestampNs(),
                  u.observations, static_cast<int>(n),
                  std::span(state.records.data(), static_cast<std::size_t>(u.records_written)),
                  std::span(state.dets.data(), n));
    const std::int64_t publish_end_ns = monotonicNowNs();
    const std::lock_guard lock(report_mutex_);
    status_.timing.scale_update.add(msBetween(update_start_ns, publish_start_ns));
    status_.timing.scale_publish.add(msBetween(publish_start_ns, publish_end_ns));
}

void Pipeline::publishStatus(bool force) {
    const std::int64_t now = monotonicNowNs();
    // Under the lock: the tracking thread and, at the end, the detection
    // thread both publish (ThreadSanitizer, preset tsan).
    const std::lock_guard lock(report_mutex_);
    if (!force && now - last_status_publish_ns_ < kStatusPeriodNs) {
        return;
    }
    const double window_s = static_cast<double>(now - fps_window_start_ns_) * 1e-9;
    if (window_s >= 1.0 || force) {
        if (window_s > 0) {
            status_.fps = static_cast<double>(fps_window_frames_) / window_s;
        }
        fps_window_frames_ = 0;
        fps_window_start_ns_ = now;
    }
    last_status_publish_ns_ = now;
    status_.frames_captured = captured_.load();
    status_.frames_dropped = dropped_.load();
    if (live_ != nullptr) {
        status_.camera_repeated = live_->repeatedFrames();
    }
    status_.source_finished = source_finished_.load();
    status_.uptime_s = static_cast<double>(now - start_mono_ns_) * 1e-9;
    if (imu_ != nullptr) {
        status_.imu = imu_->status();
    }
    hub_.publishStatus(status_);
}

}  // namespace scaled::daemon
