#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <ctime>
#include <sys/eventfd.h>
#include <type_traits>
#include <unistd.h>

#include <scaled/daemon/report.h>

namespace scaled::daemon {

const char* toString(DaemonState state) {
    switch (state) {
        case DaemonState::kInitialising:
            return "initialising";
        case DaemonState::kTracking:
            return "tracking";
        case DaemonState::kConverging:
            return "converging";
        case DaemonState::kConverged:
            return "converged";
        case DaemonState::kLost:
            return "lost";
        case DaemonState::kFault:
            return "fault";
    }
    return "fault";
}

const char* toString(LogStatus::State state) {
    switch (state) {
        case LogStatus::State::kOff:
            return "off";
        case LogStatus::State::kOk:
            return "ok";
        case LogStatus::State::kFault:
            return "fault";
    }
    return "fault";
}

void StageTiming::add(double ms) {
    ++samples;
    last_ms = ms;
    mean_ms += (ms - mean_ms) / static_cast<double>(std::min(samples, kMeanWindow));
    max_ms = std::max(max_ms, ms);
}

// publishObjects() copies within reserved storage only while this holds.
static_assert(std::is_trivially_copyable_v<ObjectReport>);
// publishPose() and pose() copy without allocating.
static_assert(std::is_trivially_copyable_v<PoseReport>);

std::string_view ObjectReport::className() const {
    return {class_name.data(), std::find(class_name.begin(), class_name.end(), '\0')};
}

void ObjectReport::setClassName(std::string_view name) {
    std::size_t n = std::min(name.size(), class_name.size() - 1);
    if (n < name.size()) {
        // Cut before a continuation byte (10xxxxxx): no half character.
        while (n > 0 && (static_cast<unsigned char>(name[n]) & 0xC0U) == 0x80U) {
            --n;
        }
    }
    std::copy_n(name.begin(), n, class_name.begin());
    std::fill(class_name.begin() + static_cast<std::ptrdiff_t>(n), class_name.end(), '\0');
}

std::int64_t monotonicNowNs() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

ReportHub::ReportHub(std::size_t grid_bins) : wake_fd_(eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) {
    posterior_.d.reserve(grid_bins);
    posterior_.log_p.reserve(grid_bins);
    scale_.fault.reserve(256);
}

ReportHub::~ReportHub() = default;

void ReportHub::publishScale(const ScaleReport& report, std::span<const double> grid_d,
                             std::span<const double> log_p) {
    {
        const std::lock_guard lock(mutex_);
        scale_ = report;
        if (report.epoch != posterior_.epoch) {
            // A new map: the old posterior is about a scale that no longer exists.
            has_posterior_ = false;
            posterior_.epoch = report.epoch;
        }
        if (report.epoch != objects_.epoch) {
            // ... and the old objects are anchored in a map that no longer exists.
            objects_.objects.clear();
            objects_.epoch = report.epoch;
            objects_.frame_id = -1;
        }
        if (!grid_d.empty() && grid_d.size() == log_p.size() &&
            grid_d.size() <= posterior_.d.capacity()) {
            posterior_.d.assign(grid_d.begin(), grid_d.end());
            posterior_.log_p.assign(log_p.begin(), log_p.end());
            posterior_.epoch = report.epoch;
            posterior_.frame_id = report.frame_id;
            posterior_.observations = report.observations;
            has_posterior_ = true;
        }
    }
    scale_seq_.fetch_add(1);
    wake();
}

void ReportHub::wake() const {
    if (wake_fd_.isValid()) {
        const std::uint64_t one = 1;
        // Non-blocking: a full counter (never in practice) only means "already awake".
        [[maybe_unused]] const ssize_t n = write(wake_fd_.get(), &one, sizeof one);
    }
}

void ReportHub::publishStatus(const PipelineStatus& status) {
    const std::lock_guard lock(mutex_);
    status_ = status;
}

void ReportHub::publishLogStatus(const LogStatus& status) {
    const std::lock_guard lock(mutex_);
    log_status_ = status;
}

void ReportHub::setObjectModel(core::EstimatorModel model, std::size_t max_objects) {
    const std::lock_guard lock(mutex_);
    objects_.model = model;
    objects_.objects.clear();
    objects_.objects.reserve(max_objects);
}

void ReportHub::publishObjects(const ObjectsSnapshot& objects) {
    const std::lock_guard lock(mutex_);
    objects_.epoch = objects.epoch;
    objects_.frame_id = objects.frame_id;
    objects_.model = objects.model;
    // Within the reserved capacity: assign() of trivially copyable entries
    // does not allocate.
    const std::size_t n = std::min(objects.objects.size(), objects_.objects.capacity());
    objects_.objects.assign(objects.objects.begin(),
                            objects.objects.begin() + static_cast<std::ptrdiff_t>(n));
}

void ReportHub::publishPose(const PoseReport& pose) {
    {
        const std::lock_guard lock(mutex_);
        pose_ = pose;
    }
    pose_seq_.fetch_add(1);
    wake();
}

PoseReport ReportHub::pose() const {
    const std::lock_guard lock(mutex_);
    return pose_;
}

ScaleReport ReportHub::scale() const {
    const std::lock_guard lock(mutex_);
    return scale_;
}

PipelineStatus ReportHub::status() const {
    const std::lock_guard lock(mutex_);
    return status_;
}

LogStatus ReportHub::logStatus() const {
    const std::lock_guard lock(mutex_);
    return log_status_;
}

bool ReportHub::posterior(PosteriorSnapshot& out) const {
    const std::lock_guard lock(mutex_);
    if (!has_posterior_) {
        return false;
    }
    out = posterior_;
    return true;
}

void ReportHub::objects(ObjectsSnapshot& out) const {
    const std::lock_guard lock(mutex_);
    out.epoch = objects_.epoch;
    out.frame_id = objects_.frame_id;
    out.model = objects_.model;
    out.objects.assign(objects_.objects.begin(), objects_.objects.end());
}

void ReportHub::consumeWake() const {
    if (wake_fd_.isValid()) {
        std::uint64_t v = 0;
        [[maybe_unused]] const ssize_t n = read(wake_fd_.get(), &v, sizeof v);
    }
}

void ReportHub::requestGravity(const core::Vec3& down_C) {
    const std::lock_guard lock(mutex_);
    gravity_request_ = down_C;
}

std::optional<core::Vec3> ReportHub::takeGravityRequest() {
    const std::lock_guard lock(mutex_);
    auto r = gravity_request_;
    gravity_request_.reset();
    return r;
}

}  // namespace scaled::daemon
