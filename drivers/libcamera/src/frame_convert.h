#pragma once

// The libcamera driver's buffer description, kept apart from libcamera itself
// so that the host tests can check it without a camera: which formats the
// driver asks libcamera for, and how a FrameBuffer's planes map onto the
// planes of a format. The conversion to gray + BGR is pixel_convert.h's
// convertRawImage(), the V4L2 driver's: it writes into the Frame's own Mats
// and, for every format here, allocates nothing per frame once running.
//
// Names and byte orders follow libcamera (which follows DRM): camera.h lists
// them (libcamera's RGB888 is B, G, R in memory, OpenCV's BGR).

#include <cstddef>
#include <cstdint>
#include <span>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/camera/pixel_convert.h>

namespace scaled::drivers::libcam {

// Every format the driver converts, in the order it prefers them when the
// options leave the choice to it: YUV first (gray is the Y plane, no
// arithmetic), then the RGB layouts: YUYV, NV12, YUV420, RGB888, BGR888,
// XRGB8888, XBGR8888.
std::span<const camera::PixelFormat> preferredFormats();

// One plane of a libcamera FrameBuffer, already mapped.
struct BufferPlane {
    const std::uint8_t* data = nullptr;
    std::size_t length_bytes = 0;
};

// The image in a buffer of width x height with the stream's stride (of the
// first plane), for convertRawImage(). Buffers carry either one plane per
// format plane (the chroma planes then go to RawImage::chroma), or a single
// plane holding them one after another (the chroma planes of NV12 use the Y
// stride, those of YUV420 half of it). kInvalidArgument, naming the format,
// for: a format the driver does not convert, a plane count that fits neither
// layout, an unmapped plane or one shorter than its rows, a stride shorter
// than a row, odd sizes for the subsampled formats. Called once per buffer
// when the buffers are mapped; convertRawImage() checks the sizes again.
core::Result<camera::RawImage> describeBuffer(camera::PixelFormat format, int width_px,
                                              int height_px, std::size_t stride_bytes,
                                              std::span<const BufferPlane> planes);

}  // namespace scaled::drivers::libcam
