#pragma once

// A camera buffer to the gray + BGR pair a Frame carries. Used by the V4L2 and
// libcamera drivers; written against plain memory so any capture backend can
// use it.
//
//   YUYV      gray = the Y samples (no colour conversion needed), BGR by
//             cv::COLOR_YUV2BGR_YUYV. Width even.
//   NV12      the Y plane (height rows), then the interleaved CbCr plane
//             (height / 2 rows): gray = Y plane, BGR by cv::COLOR_YUV2BGR_NV12.
//             Width and height even.
//   YUV420    I420: the Y plane, then the Cb and Cr planes (height / 2 rows of
//             width / 2): gray = Y plane, BGR by cv::COLOR_YUV2BGR_I420.
//             Width and height even.
//   GREY      gray = the samples, BGR = gray expanded to three channels.
//   RGB888, BGR888, XRGB8888, XBGR8888 (libcamera's names, camera.h has their
//             byte orders): BGR and gray by cv::cvtColor.
//   MJPEG     one JPEG image, decoded by cv::imdecode to BGR (gray from it); it
//             must decode to width x height.
//
// Rows are stride_bytes apart (V4L2 bytesperline, libcamera's stride), which
// may be larger than the packed row; the last row need not be padded. The
// chroma planes of NV12 and YUV420 either follow the Y plane in the same
// buffer (V4L2's single-planar layout, libcamera's one-plane buffers: NV12's
// CbCr plane with the Y stride, YUV420's Cb then Cr with half of it) or are
// given apart in RawImage::chroma (buffers with one memory plane per format
// plane).
//
// The outputs are written in place: cv::Mat::create() with the size and type
// a Mat already has is a no-op, so a caller that passes the same Mats every
// frame (Frame's mats, swapped back and forth with the pipeline's) allocates
// nothing once running for every format but MJPEG (YUV420 packs its planes
// into a per-thread scratch image, sized on the first frame). MJPEG decodes
// into `color` too, but the decoder may allocate. Do not pass Mats whose
// pixels someone else still reads: they are overwritten.

#include <array>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>

namespace scaled::drivers::camera {

// A plane stored apart from the first one (see RawImage::chroma).
struct RawPlane {
    const std::uint8_t* data = nullptr;
    std::size_t stride_bytes = 0;  // bytes from one row to the next; 0: packed rows
    std::size_t size_bytes = 0;    // valid bytes at data
};

struct RawImage {
    PixelFormat format = PixelFormat::kAuto;  // kAuto is not a buffer format: an error
    int width_px = 0;
    int height_px = 0;
    std::size_t stride_bytes = 0;        // bytes from one row to the next; 0: packed rows
    const std::uint8_t* data = nullptr;  // the (first) plane
    std::size_t size_bytes = 0;          // valid bytes at data (V4L2 bytesused)
    // NV12 (chroma[0] = CbCr) and YUV420 (chroma[0] = Cb, chroma[1] = Cr) only:
    // chroma planes stored apart from the Y plane. A plane left unset (data
    // null) follows the one before it in `data` (the layout described above).
    // A fixed array, so that describing a buffer never allocates.
    std::array<RawPlane, 2> chroma{};
};

// Bytes a buffer holding the whole image (every plane one after another, as
// described above) of that size and stride (0: packed) needs; 0 for MJPEG,
// kAuto and non-positive sizes (no fixed size).
std::size_t rawImageBytes(PixelFormat format, int width_px, int height_px,
                          std::size_t stride_bytes);

// Converts `raw` into gray (CV_8UC1) and color (CV_8UC3 BGR), both
// width x height. Errors start with `source` (e.g. `/dev/video0 (vivid):
// buffer 2`): kIo for a buffer (or plane) shorter than the image or MJPEG data
// that does not decode (or decodes to another size); kInvalidArgument for a
// bad description (kAuto, non-positive or odd sizes where the format needs
// even ones, a stride shorter than a row, no data). OpenCV exceptions are
// caught here; nothing throws.
core::Status convertRawImage(const RawImage& raw, const std::string& source, cv::Mat& gray,
                             cv::Mat& color);

// The checks of convertRawImage() alone (same errors), for a backend that
// describes its buffers once, when it maps them. MJPEG data is only checked
// for presence (it is not decoded).
core::Status checkRawImage(const RawImage& raw, const std::string& source);

}  // namespace scaled::drivers::camera
