#include "live_source.h"

#include <utility>

#include <scaled/drivers/camera/v4l2_camera.h>
#include <scaled/drivers/libcamera/libcamera_camera.h>

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;

LiveSource::LiveSource(CameraOpener opener, drivers::camera::CameraOptions options,
                       std::string name, std::unique_ptr<drivers::camera::LiveCamera> camera,
                       std::string missing_reason)
    : opener_(std::move(opener)),
      options_(std::move(options)),
      name_(std::move(name)),
      camera_(std::move(camera)),
      missing_reason_(std::move(missing_reason)) {
    if (camera_) {
        info_ = camera_->info();
    } else {
        info_.name = name_;
        info_.intrinsics = options_.intrinsics;
        info_.has_intrinsics = options_.has_intrinsics;
    }
}

Result<bool> LiveSource::next(drivers::source::Frame& frame) {
    if (stopped_.load()) {
        return false;
    }
    if (!camera_) {
        return makeError(ErrorCode::kUnavailable, missing_reason_);
    }
    return camera_->next(frame);
}

std::string LiveSource::describe() const {
    return camera_ ? camera_->describe() : name_ + " (not found)";
}

std::uint64_t LiveSource::repeatedFrames() const {
    const std::lock_guard lock(mutex_);  // reopen() may be setting camera_
    return camera_ ? camera_->repeatedFrames() : 0;
}

std::string LiveSource::mode() const {
    return camera_ ? camera_->mode() : std::string();
}

Result<bool> LiveSource::reopen() {
    if (stopped_.load()) {
        return false;
    }
    if (camera_) {
        return camera_->reopen();
    }
    auto opened = opener_(options_);
    if (!opened) {
        missing_reason_ = opened.error().message;
        // Whatever the cause, a camera the daemon is waiting for stays a fault
        // to retry: the device may come back right (a different camera on the
        // same port, a permission fixed by udev a moment later).
        return makeError(ErrorCode::kUnavailable, missing_reason_);
    }
    const std::lock_guard lock(mutex_);
    camera_ = std::move(*opened);
    if (stopped_.load()) {
        camera_->stop();
    }
    return true;
}

void LiveSource::stop() {
    const std::lock_guard lock(mutex_);
    stopped_.store(true);
    if (camera_) {
        camera_->stop();
    }
}

drivers::camera::CameraOptions cameraOptions(const DaemonConfig& config) {
    const auto& c = config.camera;
    drivers::camera::CameraOptions o;
    o.device = config.source.device;
    o.width_px = c.width_px;
    o.height_px = c.height_px;
    o.fps = c.fps;
    o.pixel_format = c.pixel_format;
    o.buffers = c.buffers;
    o.frame_timeout_s = c.frame_timeout_s;
    o.drop_repeated_frames = c.drop_repeated_frames;
    o.intrinsics.fx = static_cast<core::Scalar>(c.fx_px);
    o.intrinsics.fy = static_cast<core::Scalar>(c.fy_px);
    o.intrinsics.cx = static_cast<core::Scalar>(c.cx_px);
    o.intrinsics.cy = static_cast<core::Scalar>(c.cy_px);
    o.intrinsics.k1 = static_cast<core::Scalar>(c.k1);
    o.intrinsics.k2 = static_cast<core::Scalar>(c.k2);
    o.intrinsics.width_px = c.width_px;
    o.intrinsics.height_px = c.height_px;
    o.has_intrinsics = c.fx_px > 0;
    return o;
}

Result<std::unique_ptr<LiveSource>> openLive(const DaemonConfig& config, std::string& missing) {
    CameraOpener opener;
    std::string name;
    if (config.source.kind == SourceKind::kLibcamera) {
        if (!drivers::libcam::libcameraAvailable()) {
            return makeError(ErrorCode::kUnavailable,
                             "source libcamera:" + config.source.device +
                                 ": this build of scaled has no libcamera support (rebuild "
                                 "with libcamera-dev installed, or use a v4l2 source)");
        }
        opener = drivers::libcam::openLibcameraCamera;
        name = "libcamera:" + config.source.device;
    } else {
        opener = drivers::camera::openV4l2Camera;
        name = "v4l2:" + config.source.device;
    }
    auto options = cameraOptions(config);
    auto opened = opener(options);
    missing.clear();
    if (!opened) {
        const auto code = opened.error().code;
        if (code != ErrorCode::kNotFound && code != ErrorCode::kUnavailable) {
            return opened.error();
        }
        missing = opened.error().message;
        return std::make_unique<LiveSource>(std::move(opener), std::move(options), std::move(name),
                                            nullptr, missing);
    }
    return std::make_unique<LiveSource>(std::move(opener), std::move(options), std::move(name),
                                        std::move(*opened), std::string());
}

}  // namespace scaled::daemon
