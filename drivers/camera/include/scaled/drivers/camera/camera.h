#pragma once

// Live cameras (V4L2, libcamera) as FrameSources, and what the daemon needs to
// keep one running on a robot: a description for `scaled --list-cameras`, and
// reconnection after the device goes away.
//
// Contract of LiveCamera::next():
//   true    a frame: id counts frames delivered since open (across reopen()),
//           t_ns is the driver's CLOCK_MONOTONIC timestamp of the buffer,
//           gray is CV_8UC1 and color CV_8UC3 BGR, both width x height.
//   false   never (a live camera has no end) unless stop() was called.
//   Error   kUnavailable: the device is gone (ENODEV, EIO, unplugged, module
//           unloaded) or sent no frame within frame_timeout_s. The camera has
//           closed the device; the caller reports a fault and calls reopen()
//           with a backoff until it succeeds. Other codes: one bad frame (e.g.
//           an undecodable MJPEG buffer); the caller may go on with next().
// Every message names the device, e.g. `/dev/video0 (vivid): device lost:
// No such device` or `camera "Sensor B" (libcamera): no frame for 2.0 s`.

#include <cstdint>
#include <string>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::camera {

// Pixel formats the drivers can convert to gray + BGR (pixel_convert.h). For
// V4L2, kAuto picks, in this order, the first the device offers at the
// requested size: YUYV, NV12, GREY, MJPEG (MJPEG last: decoding costs CPU).
// YUV420 and the RGB layouts are libcamera's (libcamera_camera.h has its
// order); their names are libcamera's (DRM's), which give the components of a
// little-endian word from the most significant byte: RGB888 is B, G, R in
// memory (OpenCV's BGR), BGR888 is R, G, B, XRGB8888 is B, G, R, X and
// XBGR8888 is R, G, B, X. YUV420 is I420: Y, then U and V planes at half
// resolution in both directions.
enum class PixelFormat : std::uint8_t {
    kAuto,
    kYuyv,
    kMjpeg,
    kGrey,
    kNv12,
    kYuv420,
    kRgb888,
    kBgr888,
    kXrgb8888,
    kXbgr8888,
};
// "auto", "YUYV", "MJPEG", "GREY", "NV12", "YUV420", "RGB888", "BGR888",
// "XRGB8888", "XBGR8888".
const char* toString(PixelFormat f);
// Parses the names above (case-insensitive; also "MJPG", V4L2's fourcc, for
// kMjpeg); false when unknown (out untouched).
bool parsePixelFormat(const std::string& text, PixelFormat& out);

struct CameraOptions {
    // V4L2: a device path (/dev/video0, /dev/v4l/by-id/...) or the card name
    // reported by VIDIOC_QUERYCAP (exact match first, then a unique
    // substring), searched among /dev/video*. libcamera: an index ("0") or a
    // camera id (exact, then a unique substring).
    std::string device;
    int width_px = 640;
    int height_px = 480;
    double fps = 30.0;
    PixelFormat pixel_format = PixelFormat::kAuto;
    int buffers = 4;               // V4L2 mmap buffers / libcamera requests, 2..32
    double frame_timeout_s = 2.0;  // no frame for this long: kUnavailable
    // A buffer whose pixels equal the previous buffer's (rawSignature) is not
    // a frame: it goes back to the driver and next() waits for the next one
    // within the same frame_timeout_s (so a camera that repeats one image
    // that long is reported like a silent one). For a capture faster than
    // its source: an HDMI or analogue grabber at 60 Hz behind a 30 Hz
    // camera, a loopback device, vivid's Loop Video; not for a plain camera,
    // whose clipped (black) images can repeat exactly (docs/cameras.md).
    // V4L2 only; off by default.
    bool drop_repeated_frames = false;
    // The camera's calibration; used as the SequenceInfo intrinsics. Width and
    // height must equal the negotiated size (else open fails, naming both).
    core::CameraIntrinsics intrinsics{};
    bool has_intrinsics = false;
};

// One line of `scaled --list-cameras`.
struct CameraDescription {
    std::string backend;               // "v4l2" or "libcamera"
    std::string device;                // what to put in source.device: path or id
    std::string name;                  // card name / camera model
    std::string bus;                   // bus_info / location, may be empty
    std::vector<std::string> formats;  // "YUYV 640x480 @ 30 25 15", one per size
    std::string note;                  // e.g. "busy", "permission denied", "not a capture device"
};

class LiveCamera : public source::FrameSource {
public:
    // What the camera is, for messages and STATUS: `/dev/video0 (vivid)`.
    [[nodiscard]] virtual std::string describe() const = 0;
    // The negotiated mode, e.g. "YUYV 640x480 @ 30".
    [[nodiscard]] virtual std::string mode() const = 0;
    // After a kUnavailable error of next(): looks the device up again (by card
    // name or id when it was opened that way; the node number may change) and
    // starts streaming with the same options. kUnavailable while it is still
    // missing; other errors when it came back different (e.g. no such format).
    // true: streaming again; false: stop() was called (the daemon's wrapper
    // answers so while shutting down), nothing to retry.
    virtual core::Result<bool> reopen() = 0;
    // Makes a blocked next() return false soon (at most ~100 ms) and every
    // later call return false. Thread-safe; for shutdown.
    virtual void stop() = 0;
    // Live cameras cannot seek: kInvalidArgument.
    core::Result<bool> seek(std::size_t index) override;
    // Buffers not delivered because they repeated the previous one
    // (CameraOptions::drop_repeated_frames), since open, across reopen().
    // Thread-safe.
    [[nodiscard]] virtual std::uint64_t repeatedFrames() const { return 0; }
};

// A signature of a raw buffer's bytes for telling a repeated buffer from a new
// one: FNV-1a over the size and every 61st byte (about 10,000 bytes of a
// 640x480 YUYV buffer: cheap at 60 Hz on a small board; 61 is prime, so the
// samples walk through every byte position of the pixel formats' pixel
// groups). Equal buffers give equal signatures; two images of a real sensor
// differ in nearly every sampled byte.
[[nodiscard]] std::uint64_t rawSignature(const std::uint8_t* data, std::size_t size_bytes);

}  // namespace scaled::drivers::camera
