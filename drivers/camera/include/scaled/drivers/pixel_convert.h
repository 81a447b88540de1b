#pragma once

// A camera buffer to the gray + BGR pair a Frame carries. Used by the V4L2
// driver; written against plain memory so any capture backend can use it.
//
//   YUYV   gray = the Y samples (no colour conversion needed), BGR by
//          cv::COLOR_YUV2BGR_YUYV. Width even.
//   NV12   the Y plane (height rows) followed by the interleaved CbCr plane
//          (height / 2 rows) with the same stride, as V4L2's single-planar
//          NV12: gray = Y plane, BGR by cv::COLOR_YUV2BGR_NV12. Width and
//          height even.
//   GREY   gray = the samples, BGR = gray expanded to three channels.
//   MJPEG  one JPEG image, decoded by cv::imdecode to BGR (gray from it); it
//          must decode to width x height.
//
// Rows of YUYV, NV12 and GREY are stride_bytes apart (V4L2 bytesperline), which
// may be larger than the packed row; the last row need not be padded.
//
// The outputs are written in place: cv::Mat::create() with the size and type
// a Mat already has is a no-op, so a caller that passes the same Mats every
// frame (Frame's mats, swapped back and forth with the pipeline's) allocates
// nothing once running for YUYV, NV12 and GREY. MJPEG decodes into `color`
// too, but the decoder may allocate. Do not pass Mats whose pixels someone
// else still reads: they are overwritten.

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include <scaled/core/result.h>
#include <scaled/drivers/camera.h>

namespace scaled::drivers {

struct RawImage {
    PixelFormat format = PixelFormat::kAuto;  // kAuto is not a buffer format: an error
    int width_px = 0;
    int height_px = 0;
    std::size_t stride_bytes = 0;  // bytes from one row to the next; 0: packed rows
    const std::uint8_t* data = nullptr;
    std::size_t size_bytes = 0;  // valid bytes at data (V4L2 bytesused)
};

// Bytes a YUYV, NV12 or GREY image of that size and stride (0: packed) needs;
// 0 for MJPEG and kAuto (no fixed size).
std::size_t rawImageBytes(PixelFormat format, int width_px, int height_px,
                          std::size_t stride_bytes);

// Converts `raw` into gray (CV_8UC1) and color (CV_8UC3 BGR), both
// width x height. Errors start with `source` (e.g. `/dev/video0 (vivid):
// buffer 2`): kIo for a buffer shorter than the image or MJPEG data that does
// not decode (or decodes to another size); kInvalidArgument for a bad
// description (kAuto, non-positive or odd sizes where the format needs even
// ones, a stride shorter than a row, no data). OpenCV exceptions are caught
// here; nothing throws.
core::Result<bool> convertRawImage(const RawImage& raw, const std::string& source, cv::Mat& gray,
                                   cv::Mat& color);

}  // namespace scaled::drivers
