#pragma once

// The live IMU ([imu] in the configuration, docs/imu.md): a thread of its own
// reads the accelerometer (and gyro) through Linux IIO
// (drivers::imu::IioDevice), by sysfs polling at imu.rate_hz or from the
// buffered character device, into a fixed ring of the last few seconds of
// samples. The tracking thread copies the ring when a map starts and takes
// the map's vertical from it (drivers::imu::MapGravitySelector::atMapStart),
// and, when the device has a gyroscope, copies each frame interval's samples
// for the gyro motion prior (copySince; core/slam/gyro_prior.h).
//
// A read that fails is counted and its message kept (STATUS.imu); the thread
// keeps trying (sysfs: at the polling rate; buffer: the buffer is restarted
// after a second), so a device that comes back is used again. Samples carry
// the device's timestamps on CLOCK_MONOTONIC (IioOptions::timestamp_clock),
// the clock of monotonicNowNs() and of live camera frames; nowNs() reads the
// samples' clock whichever it is.
//
// Start-up order (app.cpp): after the configuration and the field log, before
// the pipeline that reads it; stopped after the pipeline.

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/report.h>
#include <scaled/drivers/imu/iio_device.h>

namespace scaled::daemon {

class ImuService {
public:
    // Opens the device (an error names it and why: missing, no accel_x/y/z,
    // ...) and sizes the ring to rate_hz * max(2 window_s, 2 s) samples.
    // Does not start the thread.
    [[nodiscard]] static core::Result<std::unique_ptr<ImuService>> open(
        const ImuConfig& config, const drivers::imu::IioOptions& options = {});

    ImuService(const ImuService&) = delete;
    ImuService& operator=(const ImuService&) = delete;
    ImuService(ImuService&&) = delete;
    ImuService& operator=(ImuService&&) = delete;
    ~ImuService();  // stop()

    void start();
    void stop();  // joins the thread; the buffer is disabled

    // Blocks until the ring spans the gravity window (window_s of samples)
    // or `timeout_ms` passed; true when it does. The daemon calls it once
    // after start() so that its first map has the accelerometer's vertical.
    [[nodiscard]] bool waitForWindow(int timeout_ms) const;

    // The ring's samples, oldest first, into `out` (cleared; with
    // out.capacity() >= capacity() nothing is allocated).
    void copyRecent(std::vector<core::ImuSample>& out) const;
    // The ring's samples from the last one before `t_ns` on, oldest first,
    // into `out` (cleared; no allocation with out.capacity() >= capacity()):
    // the gyro prior's samples for a frame interval that starts at t_ns.
    void copySince(std::int64_t t_ns, std::vector<core::ImuSample>& out) const;
    [[nodiscard]] std::size_t capacity() const { return ring_.size(); }
    // The device has a gyroscope (anglvel_x/y/z): its samples carry rates.
    [[nodiscard]] bool hasGyro() const { return device_.hasGyro(); }
    [[nodiscard]] const core::Mat3& rotationImuToCamera() const { return R_ItoC_; }
    [[nodiscard]] double windowS() const { return config_.window_s; }
    // Now on the samples' clock (the device's timestamp clock: monotonic
    // unless the kernel has no current_timestamp_clock, then realtime).
    [[nodiscard]] std::int64_t nowNs() const;
    [[nodiscard]] ImuStatus status() const;

private:
    ImuService(const ImuConfig& config, drivers::imu::IioDevice device);
    void run();
    void runSysfs();
    void runBuffer();
    void push(const core::ImuSample& sample);
    void fail(const std::string& message);
    // Sleeps until `t_ns` (CLOCK_MONOTONIC) or stop(), whichever is first.
    void sleepUntil(std::int64_t t_ns) const;

    ImuConfig config_;
    drivers::imu::IioDevice device_;
    core::Mat3 R_ItoC_ = core::Mat3::Identity();
    std::thread thread_;
    std::atomic<bool> stop_{false};
    mutable std::mutex wake_mutex_;
    mutable std::condition_variable wake_;  // stop() wakes sleepUntil()

    mutable std::mutex mutex_;  // guards everything below
    mutable std::condition_variable pushed_;
    std::vector<core::ImuSample> ring_;
    std::size_t head_ = 0;  // next slot written
    std::size_t count_ = 0;
    ImuStatus status_;
};

}  // namespace scaled::daemon
