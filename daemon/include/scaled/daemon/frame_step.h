#pragma once

// The frame step: what happens to one camera frame between the source and the
// map, written once for the daemon's tracking thread (daemon/src/pipeline.cpp),
// scale-eval and slam-run, so that the tools measure what the daemon runs.
//
//   frame ─▶ [vertical of a new map] ─▶ MonoTracker::processFrame ─▶ map
//            (selectGravity, only when       │ lost or diverged:
//             the frame starts a map)        ▼ reset, the next frame starts a map
//                                        detectionDue: every Nth frame of a map, or by period
//
// What is around it differs and stays with the caller: where the gyro window
// and the vertical come from (live IMU, a client's set_gravity, a dataset's log),
// the ring and threads of the daemon, the ground truth of the tools. No threads,
// no allocation per frame (a new map copies its vertical's source text).

#include <cstdint>
#include <utility>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/imu/map_gravity.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::daemon {

struct FrameStepResult {
    drivers::vision::TrackStats stats;  // the tracker's, stage times included
    double track_ms = 0;                // wall time of processFrame (steady clock)
    bool ok = false;                    // tracked: stats.health == kOk
    bool map_started = false;           // ok, and this frame started a map
    // Lost or diverged (not relocalising): the map is gone, the tracker was
    // reset and the next frame starts a new map with a new vertical.
    bool map_lost = false;
    // The vertical this frame's map was given (selectGravity's), when the
    // frame asked for one; else nullptr. Valid until the next track().
    const drivers::imu::MapGravity* gravity = nullptr;
    // Frames of the current map since its first, this one included: tracked
    // ones and those spent relocalising in it.
    std::int64_t frames_in_map = 0;
};

class FrameStep {
public:
    explicit FrameStep(drivers::vision::MonoTracker& tracker) : tracker_(&tracker) {}

    // Tracks one frame with the gyro window for the interval since the
    // previous frame (nullptr: constant velocity). When the frame may start a
    // map (the first frame, after a loss, after restart()), selectGravity(frame)
    // gives that map's vertical (a drivers::imu::MapGravity) before the tracker
    // sees the frame.
    template <typename SelectGravity>
    [[nodiscard]] FrameStepResult track(const drivers::source::Frame& frame,
                                        const core::slam::ImuWindow* gyro,
                                        SelectGravity&& selectGravity) {
        const drivers::imu::MapGravity* gravity = nullptr;
        if (need_gravity_) {
            gravity_ = std::forward<SelectGravity>(selectGravity)(frame);
            gravity = &gravity_;
        }
        return trackWith(frame, gyro, gravity);
    }

    // A break in the frames (a replay that restarts, a reconnected camera):
    // the map cannot continue; the next frame starts a new one.
    void restart();

    // Whether the frame just tracked goes to the detector: a tracked frame,
    // not the map's first, at least min_map_age_s of frame time into the map
    // (the map's unit is still settling before), and due by schedule: the
    // every_frames-th frame of the map from frame 1 + phase_frames (frames
    // spent relocalising count, so a relocalisation keeps the phase), or
    // period_s of frame time since the last one handed over.
    [[nodiscard]] bool detectionDue(const FrameStepResult& result,
                                    const DetectionSchedule& schedule, std::int64_t t_ns);

    // The tracker's world carried into the map the scale estimator measures
    // (estimator.map): the served pose's, or identity for the filter's. The
    // detection snapshot, the POSE report and scale-eval's trajectory all
    // take it, so a scale and the positions it multiplies share one unit.
    [[nodiscard]] core::slam::Sim3 estimatorFromFilter(EstimatorMap map) const {
        return map == EstimatorMap::kServed ? tracker_->servedFromFilter() : core::slam::Sim3{};
    }

    [[nodiscard]] drivers::vision::MonoTracker& tracker() { return *tracker_; }
    [[nodiscard]] const drivers::vision::MonoTracker& tracker() const { return *tracker_; }

private:
    FrameStepResult trackWith(const drivers::source::Frame& frame,
                              const core::slam::ImuWindow* gyro,
                              const drivers::imu::MapGravity* gravity);
    void loseMap();

    drivers::vision::MonoTracker* tracker_;
    drivers::imu::MapGravity gravity_;
    bool need_gravity_ = true;
    std::int64_t frames_in_map_ = 0;
    std::int64_t last_detection_t_ns_ = 0;
    std::int64_t map_start_t_ns_ = 0;  // frame time of the current map's first frame
};

}  // namespace scaled::daemon
