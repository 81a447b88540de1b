#pragma once

// The libcamera driver's pixel work, kept apart from libcamera itself so the
// host tests can check it without a camera: which formats scaled converts,
// how a buffer's planes map onto a format's planes, and the conversion to gray
// + BGR.
//
// Names and byte orders follow libcamera (which follows DRM): a format name
// gives the components of a little-endian word from the most significant
// byte, so libcamera's RGB888 is B, G, R in memory (OpenCV's BGR) and BGR888
// is R, G, B.

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include <scaled/core/result.h>

namespace scaled::drivers::libcam {

enum class RawFormat : std::uint8_t {
    kYuyv,      // packed 4:2:2, Y0 U Y1 V
    kNv12,      // Y plane, then interleaved U V at half resolution
    kYuv420,    // Y, U, V planes (I420); U and V rows are half the Y stride
    kRgb888,    // B, G, R
    kBgr888,    // R, G, B
    kXrgb8888,  // B, G, R, X
    kXbgr8888,  // R, G, B, X
};

// libcamera's name of the format ("YUYV", "NV12", "YUV420", "RGB888", ...).
const char* formatName(RawFormat format);
// Every convertible format, in the order the driver prefers them when the
// options leave the choice to it: YUV first (gray is the Y plane, no
// arithmetic), then the RGB layouts.
const std::vector<RawFormat>& preferredFormats();

// One image plane in mapped memory.
struct PlaneView {
    const std::uint8_t* data = nullptr;
    std::size_t stride_bytes = 0;  // bytes from one row to the next
    std::size_t size_bytes = 0;    // bytes readable from data
};

// One plane of a libcamera FrameBuffer, already mapped.
struct BufferPlane {
    const std::uint8_t* data = nullptr;
    std::size_t length_bytes = 0;
};

// The format's planes in a buffer of width x height with the stream's stride
// (of the first plane). Buffers carry either one plane per format plane, or
// a single plane holding them one after another (the chroma planes of NV12
// use the Y stride, those of YUV420 half of it). Errors: a plane count that
// fits neither layout, a plane shorter than its rows, odd sizes for the
// subsampled formats.
core::Result<std::vector<PlaneView>> layoutPlanes(RawFormat format, int width_px, int height_px,
                                                  std::size_t stride_bytes,
                                                  const std::vector<BufferPlane>& planes);

// Converts one image to a new CV_8UC1 gray and a new CV_8UC3 BGR image (never
// writes into memory the caller may still hold from an earlier frame). The
// planes come from layoutPlanes() (their sizes are checked again here).
core::Result<bool> convertToGrayBgr(RawFormat format, int width_px, int height_px,
                                    const std::vector<PlaneView>& planes, cv::Mat& gray,
                                    cv::Mat& bgr);

}  // namespace scaled::drivers::libcam
