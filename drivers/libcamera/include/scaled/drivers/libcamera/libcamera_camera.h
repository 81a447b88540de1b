#pragma once

// libcamera capture (optional: built when libcamera is found, see
// SCALED_WITH_LIBCAMERA). See camera.h for the LiveCamera contract.
//
// A viewfinder stream (a video-recording stream when the camera has no
// viewfinder) at the requested size (the pipeline may adjust it: vimc's
// 640x480 becomes 636x480; the adjusted size is used and logged in
// SequenceInfo::notes), converted to gray and BGR. Pixel formats, in the
// order kAuto tries those the stream offers: YUYV, NV12, YUV420, RGB888,
// BGR888, XRGB8888, XBGR8888 (libcamera's names); any of these PixelFormats
// forces one, kMjpeg and kGrey are not supported (kInvalidArgument).
// next() converts (pixel_convert.h) into the Mats of the Frame it is given,
// in place, as the V4L2 driver does: hand it back the same Frame (or swapped
// Mats) and the conversion allocates nothing per frame.
// The frame rate is set through FrameDurationLimits when the camera has that
// control (clamped to its range, with a note), else the camera runs at its
// own rate (noted).
//
// A request loop recycles CameraOptions::buffers requests; no completed
// request for frame_timeout_s -> kUnavailable, and reopen() stops and
// restarts the camera (as rpicam-apps does), finding it again by its id.
// Frame timestamps are the SensorTimestamp metadata (the buffer's timestamp
// when the pipeline sets none), CLOCK_MONOTONIC on Linux's V4L2 drivers.
//
// Errors: "no cameras" (kNotFound), "camera busy" (kUnavailable), no such
// index/id (kNotFound, listing the cameras); every message names the camera.
//
// Refinements of camera.h for this driver:
//  - reopen() after stop() restarts the camera and next() delivers frames
//    again (stop() only holds until the next reopen()).
//  - One libcamera CameraManager serves the whole process (libcamera allows
//    only one); it lives while a camera is open or a listing runs.
//  - LIBCAMERA_LOG_LEVELS defaults to "*:ERROR" (set in the environment
//    before libcamera starts, only when the user has not set it), so
//    libcamera's INFO/WARN lines do not flood the daemon's stderr.

#include <memory>
#include <vector>

#include <scaled/drivers/camera/camera.h>

namespace scaled::drivers::libcam {

// True when this build has libcamera support.
bool libcameraAvailable();

// options.device: an index ("0": the first camera CameraManager lists, the
// order of `cam -l`, which counts from 1) or a camera id (exact, then a unique
// substring). Without libcamera support: kUnavailable "this build of scaled
// has no libcamera support".
core::Result<std::unique_ptr<camera::LiveCamera>> openLibcameraCamera(
    const camera::CameraOptions& options);

// Every camera libcamera's CameraManager lists: device = the camera id, name =
// its model, bus = its location (front/back/external), formats = "FMT WxH"
// for each size of each convertible format of its viewfinder stream, note =
// "busy" when another user holds it. Empty without libcamera support or when
// libcamera cannot start. Never fails.
std::vector<camera::CameraDescription> listLibcameraCameras();

}  // namespace scaled::drivers::libcam
