#include <pthread.h>

#include <scaled/daemon/window_ba_worker.h>

namespace scaled::daemon {

WindowBaWorker::WindowBaWorker() : thread_([this] { run(); }) {
    ::pthread_setname_np(thread_.native_handle(), "scaled-ba");
}

std::unique_ptr<WindowBaWorker> WindowBaWorker::attachTo(drivers::vision::MonoTracker& tracker) {
    const core::slam::WindowBaConfig& c = tracker.config().window_ba;
    if (!c.enabled || c.defer_frames <= 0) {
        return nullptr;
    }
    auto worker = std::make_unique<WindowBaWorker>();
    tracker.setOptimisationRunner(worker.get());
    return worker;
}

WindowBaWorker::~WindowBaWorker() {
    {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [this] { return job_ == nullptr; });
        stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
}

void WindowBaWorker::start(core::slam::WindowBa& ba) {
    {
        const std::lock_guard lock(mutex_);
        job_ = &ba;
        running_ = true;
        done_ = false;
    }
    cv_.notify_all();
}

core::slam::WindowBaReport WindowBaWorker::wait() {
    std::unique_lock lock(mutex_);
    if (!running_) {
        return {};
    }
    cv_.wait(lock, [this] { return done_; });
    running_ = false;
    return report_;
}

void WindowBaWorker::run() {
    std::unique_lock lock(mutex_);
    for (;;) {
        cv_.wait(lock, [this] { return stop_ || job_ != nullptr; });
        if (job_ == nullptr) {
            return;  // stop_, nothing left to run
        }
        core::slam::WindowBa* ba = job_;
        lock.unlock();
        const core::slam::WindowBaReport report = ba->runDue();
        lock.lock();
        report_ = report;
        job_ = nullptr;
        done_ = true;
        cv_.notify_all();
    }
}

}  // namespace scaled::daemon
