// The live IMU's sampling thread (imu_service.h).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <utility>

#include <scaled/daemon/imu_service.h>
#include <scaled/daemon/report.h>

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

constexpr std::int64_t kRetryNs = 1'000'000'000;  // a failed buffer is restarted after this
constexpr int kBufferPollMs = 100;                // the longest a buffered read waits
constexpr std::size_t kBufferBatch = 64;          // scans taken per read

std::string modeText(const ImuConfig& c) {
    char text[96];
    if (c.mode == ImuMode::kSysfs) {
        std::snprintf(text, sizeof text, "sysfs %g Hz", c.rate_hz);
        return text;
    }
    return c.trigger.empty() ? std::string("buffer") : "buffer (trigger " + c.trigger + ")";
}

}  // namespace

Result<std::unique_ptr<ImuService>> ImuService::open(const ImuConfig& config,
                                                     const drivers::imu::IioOptions& options) {
    if (config.device.empty()) {
        return makeError(ErrorCode::kInvalidArgument, "imu.device is empty");
    }
    auto dev = drivers::imu::IioDevice::open(config.device, options);
    if (!dev) {
        core::Error e = dev.error();
        if (e.message.find(config.device) == std::string::npos) {
            e.message = config.device + ": " + e.message;  // which device, always
        }
        return e;
    }
    if (!dev->hasAccel()) {
        return makeError(
            ErrorCode::kNotFound,
            dev->describe() + ": no accelerometer (needs accel_x, accel_y and accel_z)");
    }
    std::unique_ptr<ImuService> s(new ImuService(config, std::move(*dev)));
    return s;
}

ImuService::ImuService(const ImuConfig& config, drivers::imu::IioDevice device)
    : config_(config), device_(std::move(device)) {
    for (std::size_t r = 0; r < 3; ++r) {
        for (std::size_t c = 0; c < 3; ++c) {
            R_ItoC_(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
                static_cast<core::Scalar>(config.rotation_imu_to_camera[r * 3 + c]);
        }
    }
    const double span_s = std::max(2.0 * config.window_s, 2.0);
    ring_.resize(static_cast<std::size_t>(std::ceil(config.rate_hz * span_s)) + 16);
    status_.configured = true;
    status_.device = device_.sysfsDir().filename().string() + " [" + device_.name() + "]";
    status_.mode = modeText(config);
}

ImuService::~ImuService() {
    stop();
}

void ImuService::start() {
    if (thread_.joinable()) {
        return;
    }
    stop_.store(false);
    thread_ = std::thread([this] { run(); });
}

void ImuService::stop() {
    {
        const std::lock_guard lock(wake_mutex_);
        stop_.store(true);
    }
    wake_.notify_all();
    if (thread_.joinable()) {
        thread_.join();
    }
    if (device_.bufferRunning()) {
        (void)device_.stopBuffer();
    }
}

void ImuService::copyRecent(std::vector<core::ImuSample>& out) const {
    out.clear();
    const std::lock_guard lock(mutex_);
    const std::size_t n = ring_.size();
    for (std::size_t i = 0; i < count_; ++i) {
        out.push_back(ring_[(head_ + n - count_ + i) % n]);
    }
}

void ImuService::copySince(std::int64_t t_ns, std::vector<core::ImuSample>& out) const {
    out.clear();
    const std::lock_guard lock(mutex_);
    const std::size_t n = ring_.size();
    const std::size_t oldest = head_ + n - count_;
    // The last sample before t_ns (it bounds the interval's start), scanning
    // back from the newest: a frame interval is a few samples.
    std::size_t first = count_;
    while (first > 0 && ring_[(oldest + first - 1) % n].t_ns >= t_ns) {
        --first;
    }
    first = first > 0 ? first - 1 : 0;
    for (std::size_t i = first; i < count_; ++i) {
        out.push_back(ring_[(oldest + i) % n]);
    }
}

std::int64_t ImuService::nowNs() const {
    timespec ts{};
    clock_gettime(device_.clockId(), &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

ImuStatus ImuService::status() const {
    const std::lock_guard lock(mutex_);
    return status_;
}

void ImuService::push(const core::ImuSample& sample) {
    {
        const std::lock_guard lock(mutex_);
        ring_[head_] = sample;
        head_ = (head_ + 1) % ring_.size();
        count_ = std::min(count_ + 1, ring_.size());
        ++status_.samples;
        status_.error.clear();
    }
    pushed_.notify_all();
}

bool ImuService::waitForWindow(int timeout_ms) const {
    const auto window_ns = static_cast<std::int64_t>(std::llround(config_.window_s * 1e9));
    std::unique_lock lock(mutex_);
    return pushed_.wait_for(lock, std::chrono::milliseconds(timeout_ms), [&] {
        if (count_ < 2) {
            return false;
        }
        const std::size_t n = ring_.size();
        const std::int64_t oldest = ring_[(head_ + n - count_) % n].t_ns;
        const std::int64_t newest = ring_[(head_ + n - 1) % n].t_ns;
        return newest - oldest >= window_ns;
    });
}

void ImuService::fail(const std::string& message) {
    const std::lock_guard lock(mutex_);
    ++status_.errors;
    status_.error = message;
}

void ImuService::sleepUntil(std::int64_t t_ns) const {
    // steady_clock is CLOCK_MONOTONIC on Linux, the clock of monotonicNowNs().
    const auto wait_ns =
        std::chrono::nanoseconds(std::max<std::int64_t>(0, t_ns - monotonicNowNs()));
    std::unique_lock lock(wake_mutex_);
    wake_.wait_for(lock, wait_ns, [this] { return stop_.load(); });
}

void ImuService::run() {
    if (config_.mode == ImuMode::kSysfs) {
        runSysfs();
    } else {
        runBuffer();
    }
}

void ImuService::runSysfs() {
    const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 / config_.rate_hz));
    std::int64_t next_ns = monotonicNowNs();
    while (!stop_.load()) {
        if (auto s = device_.readOnce()) {
            push(*s);
        } else {
            fail(s.error().message);
        }
        next_ns += period_ns;
        const std::int64_t now_ns = monotonicNowNs();
        if (next_ns < now_ns) {
            next_ns = now_ns;  // late (a slow bus, a loaded system): no burst to catch up
        }
        sleepUntil(next_ns);
    }
}

void ImuService::runBuffer() {
    drivers::imu::IioBufferOptions options;
    options.trigger = config_.trigger;
    options.length = static_cast<unsigned>(config_.buffer_length);
    while (!stop_.load()) {
        if (!device_.bufferRunning()) {
            if (auto ok = device_.startBuffer(options); !ok) {
                fail(ok.error().message);
                sleepUntil(monotonicNowNs() + kRetryNs);
                continue;
            }
        }
        auto samples = device_.readSamples(kBufferBatch, kBufferPollMs);
        if (!samples) {
            fail(samples.error().message);
            (void)device_.stopBuffer();
            sleepUntil(monotonicNowNs() + kRetryNs);
            continue;
        }
        for (const auto& s : *samples) {
            push(s);
        }
    }
}

}  // namespace scaled::daemon
