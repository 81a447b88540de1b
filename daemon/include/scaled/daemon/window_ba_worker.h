#pragma once

// WindowBaWorker: the tracker's window bundle adjustment off the tracking
// thread (tracker.window_ba_defer_frames > 0, drivers/vision/mono_tracker.h).
//
// One thread, started at construction, waiting on one job at a time: the
// tracker's start() hands it the WindowBa whose optimisation is due and
// returns; wait(), defer_frames frames later, blocks until runDue() has
// returned (at once, when it ran within those frames). The tracker touches
// nothing of that WindowBa in between, so the poses are the same to the bit
// as when the tracker runs it itself (test DaemonWindowBa.*). The destructor
// waits for a running job, then joins.

#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include <scaled/core/slam/window_ba.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::daemon {

class WindowBaWorker final : public drivers::vision::OptimisationRunner {
public:
    WindowBaWorker();
    ~WindowBaWorker() override;
    WindowBaWorker(const WindowBaWorker&) = delete;
    WindowBaWorker& operator=(const WindowBaWorker&) = delete;

    // A worker for the tracker's deferred optimisations, set as its runner,
    // when its configuration defers them (window_ba on, defer_frames > 0);
    // else nullptr. It must outlive every frame the tracker processes.
    static std::unique_ptr<WindowBaWorker> attachTo(drivers::vision::MonoTracker& tracker);

    void start(core::slam::WindowBa& ba) override;
    core::slam::WindowBaReport wait() override;

private:
    void run();

    std::mutex mutex_;
    std::condition_variable cv_;
    core::slam::WindowBa* job_ = nullptr;  // mutex_: the job to run, until it has run
    bool running_ = false;                 // mutex_: a job was started and not yet waited for
    bool done_ = false;                    // mutex_: it has run
    bool stop_ = false;                    // mutex_
    core::slam::WindowBaReport report_;    // mutex_: its report
    std::thread thread_;                   // last: started once the rest exists
};

}  // namespace scaled::daemon
