#pragma once

// The daemon's live camera: a LiveCamera that may not have a device yet.
//
// A USB camera enumerates after the daemon starts, a CSI camera's driver
// loads late, a cable comes loose: none of these should stop the process.
// LiveSource opens the camera through the configured backend; when the
// device is missing (kNotFound, kUnavailable) it starts without one, next()
// reports kUnavailable with the reason, and the pipeline's capture thread
// calls reopen() with its backoff until the camera appears. Every other
// open error (bad size, bad format, permission) is returned by openLive() so
// the daemon exits with a configuration or permission error at start.
//
// SequenceInfo comes from the configuration (the intrinsics are required),
// so the pipeline can be built before the camera exists.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include <scaled/core/result.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/drivers/camera/camera.h>

namespace scaled::daemon {

using CameraOpener = std::function<core::Result<std::unique_ptr<drivers::camera::LiveCamera>>(
    const drivers::camera::CameraOptions&)>;

class LiveSource final : public drivers::camera::LiveCamera {
public:
    LiveSource(CameraOpener opener, drivers::camera::CameraOptions options, std::string name,
               std::unique_ptr<drivers::camera::LiveCamera> camera, std::string missing_reason);

    [[nodiscard]] const drivers::source::SequenceInfo& info() const override { return info_; }
    core::Result<bool> next(drivers::source::Frame& frame) override;
    [[nodiscard]] std::string describe() const override;
    [[nodiscard]] std::string mode() const override;
    [[nodiscard]] std::uint64_t repeatedFrames() const override;
    core::Result<bool> reopen() override;
    void stop() override;

    [[nodiscard]] bool hasCamera() const { return camera_ != nullptr; }

private:
    CameraOpener opener_;
    drivers::camera::CameraOptions options_;
    std::string name_;  // "v4l2:vivid"
    std::unique_ptr<drivers::camera::LiveCamera> camera_;
    std::string missing_reason_;
    drivers::source::SequenceInfo info_;
    // camera_ is replaced by the capture thread (reopen) while stop() may come
    // from the main thread.
    mutable std::mutex mutex_;
    std::atomic<bool> stopped_{false};
};

drivers::camera::CameraOptions cameraOptions(const DaemonConfig& config);

// Opens the configured live camera. A missing device gives a LiveSource
// without a camera (`missing` says why, for one log line); other errors are
// returned.
core::Result<std::unique_ptr<LiveSource>> openLive(const DaemonConfig& config,
                                                   std::string& missing);

}  // namespace scaled::daemon
