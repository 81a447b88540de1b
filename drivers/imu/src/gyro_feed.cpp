#include <algorithm>

#include <scaled/drivers/imu/gyro_feed.h>

namespace scaled::drivers::imu {

core::Result<GyroFeed> GyroFeed::create(const MapGravitySelector& dataset,
                                        const std::optional<SimulatedGyroOptions>& simulated) {
    GyroFeed feed;
    if (simulated) {
        auto sim = SimulatedGyro::create(*simulated);
        if (!sim) {
            return sim.error();
        }
        feed.source_ = sim->describe();
        feed.simulated_ = std::move(*sim);
        return feed;
    }
    const ImuLog* log = dataset.imuLog();
    const bool has_gyro =
        log != nullptr && std::any_of(log->samples.begin(), log->samples.end(),
                                      [](const core::ImuSample& s) { return s.gyro_radps; });
    if (has_gyro && !log->R_ItoC_known) {
        // A gyro about unknown axes would turn the camera the wrong way with
        // confidence: constant velocity instead, and the reason said.
        feed.source_ = "none (" + dataset.imuLogPath().string() +
                       " has a gyroscope but no camera-IMU rotation: " + log->R_ItoC_source + ")";
        return feed;
    }
    if (has_gyro) {
        core::slam::ImuWindow w;
        w.samples = log->samples;
        w.R_ItoC = log->R_ItoC;
        feed.log_window_ = w;
        feed.source_ = dataset.imuLogPath().string() + " (R_ItoC: " + log->R_ItoC_source + ")";
    }
    return feed;
}

const core::slam::ImuWindow* GyroFeed::forFrame(const source::Frame& frame) {
    if (log_window_) {
        return &*log_window_;
    }
    if (!simulated_) {
        return nullptr;
    }
    if (!frame.T_CtoW_gt) {
        have_prev_ = false;
        return nullptr;
    }
    const bool had_prev = have_prev_;
    const std::int64_t t0 = prev_t_ns_;
    const core::Mat3 R0 = prev_R_;
    have_prev_ = true;
    prev_t_ns_ = frame.t_ns;
    prev_R_ = frame.T_CtoW_gt->R_CtoW;
    if (!had_prev || frame.t_ns <= t0) {
        return nullptr;
    }
    window_.samples = simulated_->between(t0, R0, frame.t_ns, frame.T_CtoW_gt->R_CtoW);
    window_.R_ItoC = core::Mat3::Identity();
    return &window_;
}

}  // namespace scaled::drivers::imu
