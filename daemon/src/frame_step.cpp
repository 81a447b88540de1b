#include <chrono>

#include <scaled/daemon/frame_step.h>

namespace scaled::daemon {

FrameStepResult FrameStep::trackWith(const drivers::source::Frame& frame,
                                     const core::slam::ImuWindow* gyro,
                                     const drivers::imu::MapGravity* gravity) {
    if (gravity != nullptr) {
        // The vertical in the frame of the camera that starts the map.
        tracker_->setGravityDownC(gravity->down_C);
        need_gravity_ = false;
    }
    FrameStepResult r;
    r.gravity = gravity;
    const auto t0 = std::chrono::steady_clock::now();
    r.stats = tracker_->processFrame(frame.t_ns, frame.gray, gyro);
    r.track_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    r.ok = r.stats.health == core::slam::SlamHealth::kOk;
    r.map_started = r.ok && r.stats.new_map;
    if (r.map_started) {
        frames_in_map_ = 0;
        map_start_t_ns_ = frame.t_ns;
    }
    const bool relocalising = r.stats.health == core::slam::SlamHealth::kRelocalising;
    if (r.ok || relocalising) {
        // A frame of the map, tracked or not: the detector's schedule keeps
        // its phase through a relocalisation (the same frames are detected
        // as if the camera had not been lost).
        ++frames_in_map_;
    } else {
        // Lost or diverged: the next frame starts a new map with a new,
        // unrelated scale. (Relocalising keeps the map: the tracker looks for
        // the camera in it for up to tracker.relocalise_s.)
        r.map_lost = true;
        loseMap();
    }
    r.frames_in_map = frames_in_map_;
    return r;
}

void FrameStep::restart() {
    loseMap();
}

void FrameStep::loseMap() {
    // reset() keeps the filter's last state and the gyro bias readable.
    tracker_->reset();
    need_gravity_ = true;
    frames_in_map_ = 0;
}

bool FrameStep::detectionDue(const FrameStepResult& result, const DetectionSchedule& schedule,
                             std::int64_t t_ns) {
    if (!result.ok || frames_in_map_ <= 1 ||
        static_cast<double>(t_ns - map_start_t_ns_) * 1e-9 < schedule.min_map_age_s) {
        return false;
    }
    const bool due =
        schedule.period_s > 0
            ? static_cast<double>(t_ns - last_detection_t_ns_) * 1e-9 >= schedule.period_s
            : (frames_in_map_ - 1) % schedule.every_frames == schedule.phase_frames;
    if (due) {
        last_detection_t_ns_ = t_ns;
    }
    return due;
}

}  // namespace scaled::daemon
