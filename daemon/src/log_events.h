#pragma once

// PipelineEvents written to the field log: the pipeline's callbacks turned
// into LogService events. Box and observation lists are converted into
// buffers reserved here (the detection thread is their only caller); poses
// are thinned here to log.pose_rate_hz (the tracking thread is onPose's only
// caller).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>

#include <scaled/daemon/log_service.h>
#include <scaled/daemon/pipeline.h>

namespace scaled::daemon {

class LogEvents final : public PipelineEvents {
public:
    explicit LogEvents(LogService& log) : log_(log), pose_limiter_(log.poseRateHz()) {}

    void start(std::string_view release, std::string_view source, const std::string& config) {
        StartEvent e;
        e.release = release;
        e.source = source;
        e.config_toml = config;
        log_.startEvent(e);
    }
    void stop(std::string_view reason) {
        StopEvent e;
        e.reason = reason;
        log_.stopEvent(e);
    }

    void onFrame(const Frame& f) override {
        FrameEvent e;
        e.frame_id = f.frame_id;
        e.t_ns = f.t_ns;
        e.epoch = f.epoch;
        e.health = f.health;
        e.features = f.features;
        e.tracked = f.tracked;
        e.ms = f.ms;
        e.dropped = f.dropped;
        e.stage_us = f.stage_us;
        log_.frameEvent(e);
    }

    void onDetection(const drivers::detector::DetectionResult& r, std::uint64_t epoch,
                     double latency_ms) override {
        const std::size_t n = std::min(r.detections.size(), boxes_.size());
        for (std::size_t i = 0; i < n; ++i) {
            const auto& d = r.detections[i];
            boxes_[i] = LogBox{d.class_name,
                               static_cast<double>(d.score),
                               static_cast<double>(d.box.x_min_px),
                               static_cast<double>(d.box.y_min_px),
                               static_cast<double>(d.box.x_max_px),
                               static_cast<double>(d.box.y_max_px)};
        }
        DetectionEvent e;
        e.frame_id = r.frame_id;
        e.t_ns = r.t_ns;
        e.epoch = epoch;
        e.latency_ms = latency_ms;
        e.boxes = std::span<const LogBox>(boxes_.data(), n);
        log_.detectionEvent(e);
    }

    void onScale(const Scale& s) override {
        ScaleEvent e = scaleEventFrom(*s.report);
        e.new_observations = s.new_observations;
        e.detections = s.detections;
        const std::size_t n = std::min(s.records.size(), obs_.size());
        for (std::size_t i = 0; i < n; ++i) {
            const auto& rec = s.records[i];
            const auto det = static_cast<std::size_t>(rec.detection_index);
            const double sigma = s.paper_variance
                                     ? static_cast<double>(rec.sigma_D_paper)
                                     : std::hypot(static_cast<double>(rec.sigma_D_feature),
                                                  static_cast<double>(rec.sigma_D_box));
            obs_[i] = LogObservation{
                det < s.detections_used.size() ? s.detections_used[det].class_name
                                               : std::string_view("?"),
                static_cast<double>(rec.D), sigma, static_cast<double>(rec.local_estimate),
                static_cast<double>(rec.weight)};
        }
        e.obs = std::span<const LogObservation>(obs_.data(), n);
        log_.scaleEvent(e);
        // The objects this update gave a view to.
        for (const ObjectReport& o : s.objects) {
            if (o.last_frame != e.frame_id) {
                continue;
            }
            ObjectEvent oe;
            oe.frame_id = e.frame_id;
            oe.t_ns = e.t_ns;
            oe.epoch = e.epoch;
            oe.object = &o;
            log_.objectEvent(oe);
        }
    }

    void onWindowBa(const WindowBa& w) override {
        WindowEvent e;
        e.frame_id = w.frame_id;
        e.t_ns = w.t_ns;
        e.epoch = w.epoch;
        e.report = w.report;
        log_.windowEvent(e);
    }

    // At most log.pose_rate_hz lines per second of frame time; none when 0.
    void onPose(const Pose& p) override {
        if (p.pose == nullptr || !(log_.poseRateHz() > 0) ||
            !pose_limiter_.admit(p.pose->epoch, p.pose->t_ns)) {
            return;
        }
        PoseEvent e;
        e.pose = p.pose;
        e.metric = p.metric;
        e.state = p.state;
        log_.poseEvent(e);
    }

    void onState(DaemonState from, DaemonState to, std::uint64_t epoch, std::int64_t frame_id,
                 const char* reason) override {
        StateEvent e;
        e.from = from;
        e.to = to;
        e.epoch = epoch;
        e.frame_id = frame_id;
        e.reason = reason;
        log_.stateEvent(e);
    }

    void onError(const char* where, const std::string& message) override {
        ErrorEvent e;
        e.where = where;
        e.message = message;
        log_.errorEvent(e);
    }

private:
    LogService& log_;
    PoseRateLimiter pose_limiter_;  // onPose: the tracking thread only
    std::array<LogBox, 256> boxes_{};
    std::array<LogObservation, kMaxLoggedObservations> obs_{};
};

}  // namespace scaled::daemon
