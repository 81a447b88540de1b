#include "frame_convert.h"

#include <algorithm>
#include <array>
#include <string>

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;
using core::makeError;

constexpr std::array<camera::PixelFormat, 7> kPreferred{
    camera::PixelFormat::kYuyv,     camera::PixelFormat::kNv12,   camera::PixelFormat::kYuv420,
    camera::PixelFormat::kRgb888,   camera::PixelFormat::kBgr888, camera::PixelFormat::kXrgb8888,
    camera::PixelFormat::kXbgr8888,
};

// Format planes: 1, or 2 (NV12) and 3 (YUV420) with their chroma.
std::size_t planeCount(camera::PixelFormat format) {
    switch (format) {
        case camera::PixelFormat::kNv12:
            return 2;
        case camera::PixelFormat::kYuv420:
            return 3;
        default:
            return 1;
    }
}

}  // namespace

std::span<const camera::PixelFormat> preferredFormats() {
    return kPreferred;
}

core::Result<camera::RawImage> describeBuffer(camera::PixelFormat format, int width_px,
                                              int height_px, std::size_t stride_bytes,
                                              std::span<const BufferPlane> planes) {
    const std::string name = toString(format);
    if (std::find(kPreferred.begin(), kPreferred.end(), format) == kPreferred.end()) {
        return makeError(ErrorCode::kInvalidArgument,
                         name + ": not a format the libcamera driver converts");
    }
    const std::size_t count = planeCount(format);
    camera::RawImage raw;
    raw.format = format;
    raw.width_px = width_px;
    raw.height_px = height_px;
    raw.stride_bytes = stride_bytes;
    if (planes.size() == count) {
        // One buffer plane per format plane, each with the format's stride.
        raw.data = planes[0].data;
        raw.size_bytes = planes[0].length_bytes;
        const std::size_t chroma_stride =
            format == camera::PixelFormat::kYuv420 ? stride_bytes / 2 : stride_bytes;
        for (std::size_t i = 1; i < count; ++i) {
            raw.chroma.at(i - 1) = {planes[i].data, chroma_stride, planes[i].length_bytes};
            if (planes[i].data == nullptr) {
                return makeError(ErrorCode::kInvalidArgument,
                                 name + ": plane " + std::to_string(i) + " is not mapped");
            }
        }
    } else if (planes.size() == 1) {
        // One plane holding all of them, one after another: convertRawImage's
        // default layout.
        raw.data = planes[0].data;
        raw.size_bytes = planes[0].length_bytes;
    } else {
        return makeError(ErrorCode::kInvalidArgument,
                         name + ": the buffer has " + std::to_string(planes.size()) +
                             " planes, the format " + std::to_string(count));
    }
    if (raw.data == nullptr) {
        return makeError(ErrorCode::kInvalidArgument, name + ": plane 0 is not mapped");
    }
    // The same checks as every frame's conversion; a buffer that fails them
    // would fail every frame, so it is an error of the configuration.
    auto checked = camera::checkRawImage(raw, name);
    if (!checked) {
        return makeError(ErrorCode::kInvalidArgument, checked.error().message);
    }
    return raw;
}

}  // namespace scaled::drivers::libcam
