#include "frame_convert.h"

#include <array>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <utility>

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;
using core::makeError;

struct FormatEntry {
    RawFormat format;
    const char* name;
};

constexpr std::array<FormatEntry, 7> kFormats{{
    {RawFormat::kYuyv, "YUYV"},
    {RawFormat::kNv12, "NV12"},
    {RawFormat::kYuv420, "YUV420"},
    {RawFormat::kRgb888, "RGB888"},
    {RawFormat::kBgr888, "BGR888"},
    {RawFormat::kXrgb8888, "XRGB8888"},
    {RawFormat::kXbgr8888, "XBGR8888"},
}};

// What one plane of a format holds at a given size.
struct PlaneSpec {
    std::size_t rows = 0;
    std::size_t row_bytes = 0;  // bytes of pixel data in one row
    std::size_t stride_bytes = 0;
};

std::size_t bytesNeeded(const PlaneSpec& spec) {
    return spec.stride_bytes * (spec.rows - 1) + spec.row_bytes;
}

std::string sizeText(int width_px, int height_px) {
    return std::to_string(width_px) + "x" + std::to_string(height_px);
}

// The planes of `format` at width x height with the first plane's stride.
core::Result<std::vector<PlaneSpec>> planeSpecs(RawFormat format, int width_px, int height_px,
                                                std::size_t stride_bytes) {
    if (width_px <= 0 || height_px <= 0) {
        return makeError(ErrorCode::kInvalidArgument, std::string(formatName(format)) +
                                                          ": invalid image size " +
                                                          sizeText(width_px, height_px));
    }
    const auto w = static_cast<std::size_t>(width_px);
    const auto h = static_cast<std::size_t>(height_px);
    const bool subsampled_x =
        format == RawFormat::kYuyv || format == RawFormat::kNv12 || format == RawFormat::kYuv420;
    const bool subsampled_y = format == RawFormat::kNv12 || format == RawFormat::kYuv420;
    if ((subsampled_x && w % 2 != 0) || (subsampled_y && h % 2 != 0)) {
        return makeError(ErrorCode::kInvalidArgument,
                         std::string(formatName(format)) + ": size " +
                             sizeText(width_px, height_px) +
                             " is odd where the format subsamples chroma");
    }
    std::vector<PlaneSpec> specs;
    switch (format) {
        case RawFormat::kYuyv:
            specs = {{h, 2 * w, stride_bytes}};
            break;
        case RawFormat::kNv12:
            specs = {{h, w, stride_bytes}, {h / 2, w, stride_bytes}};
            break;
        case RawFormat::kYuv420:
            specs = {{h, w, stride_bytes},
                     {h / 2, w / 2, stride_bytes / 2},
                     {h / 2, w / 2, stride_bytes / 2}};
            break;
        case RawFormat::kRgb888:
        case RawFormat::kBgr888:
            specs = {{h, 3 * w, stride_bytes}};
            break;
        case RawFormat::kXrgb8888:
        case RawFormat::kXbgr8888:
            specs = {{h, 4 * w, stride_bytes}};
            break;
    }
    for (const PlaneSpec& spec : specs) {
        if (spec.stride_bytes < spec.row_bytes) {
            return makeError(ErrorCode::kInvalidArgument,
                             std::string(formatName(format)) + " " + sizeText(width_px, height_px) +
                                 ": stride " + std::to_string(stride_bytes) +
                                 " is shorter than a row (" +
                                 std::to_string(specs.front().row_bytes) + " bytes)");
        }
    }
    return specs;
}

core::Error tooShort(RawFormat format, std::size_t plane, std::size_t have, std::size_t need) {
    return makeError(ErrorCode::kInvalidArgument,
                     std::string(formatName(format)) + ": plane " + std::to_string(plane) +
                         " has " + std::to_string(have) + " bytes, the image needs " +
                         std::to_string(need));
}

// A read-only view as a cv::Mat header (OpenCV has no const Mat constructor;
// the converters below only read through it).
cv::Mat wrap(const PlaneView& plane, int rows, int cols, int type) {
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-const-cast)
    return {rows, cols, type, const_cast<std::uint8_t*>(plane.data), plane.stride_bytes};
}

// I420 with arbitrary strides -> the contiguous (h * 3/2) x w layout
// cv::cvtColor expects.
cv::Mat packI420(const std::vector<PlaneView>& planes, int width_px, int height_px) {
    const auto w = static_cast<std::size_t>(width_px);
    const auto h = static_cast<std::size_t>(height_px);
    cv::Mat packed(height_px * 3 / 2, width_px, CV_8UC1);
    std::uint8_t* out = packed.data;
    const std::array<std::pair<std::size_t, std::size_t>, 3> rows_cols{
        {{h, w}, {h / 2, w / 2}, {h / 2, w / 2}}};
    for (std::size_t p = 0; p < 3; ++p) {
        const auto [rows, cols] = rows_cols.at(p);
        for (std::size_t r = 0; r < rows; ++r) {
            std::memcpy(out, planes[p].data + r * planes[p].stride_bytes, cols);
            out += cols;
        }
    }
    return packed;
}

}  // namespace

const char* formatName(RawFormat format) {
    for (const FormatEntry& entry : kFormats) {
        if (entry.format == format) {
            return entry.name;
        }
    }
    return "?";
}

const std::vector<RawFormat>& preferredFormats() {
    static const std::vector<RawFormat> formats{
        RawFormat::kYuyv,   RawFormat::kNv12,     RawFormat::kYuv420,   RawFormat::kRgb888,
        RawFormat::kBgr888, RawFormat::kXrgb8888, RawFormat::kXbgr8888,
    };
    return formats;
}

core::Result<std::vector<PlaneView>> layoutPlanes(RawFormat format, int width_px, int height_px,
                                                  std::size_t stride_bytes,
                                                  const std::vector<BufferPlane>& planes) {
    auto specs = planeSpecs(format, width_px, height_px, stride_bytes);
    if (!specs) {
        return specs.error();
    }
    std::vector<PlaneView> views;
    if (planes.size() == specs->size()) {
        for (std::size_t i = 0; i < planes.size(); ++i) {
            views.push_back({planes[i].data, (*specs)[i].stride_bytes, planes[i].length_bytes});
        }
    } else if (planes.size() == 1) {
        // One plane holding all of them, one after another.
        std::size_t offset = 0;
        for (const PlaneSpec& spec : *specs) {
            const std::size_t left =
                offset < planes[0].length_bytes ? planes[0].length_bytes - offset : 0;
            views.push_back({planes[0].data + offset, spec.stride_bytes, left});
            offset += spec.stride_bytes * spec.rows;
        }
    } else {
        return makeError(ErrorCode::kInvalidArgument,
                         std::string(formatName(format)) + ": the buffer has " +
                             std::to_string(planes.size()) + " planes, the format " +
                             std::to_string(specs->size()));
    }
    for (std::size_t i = 0; i < views.size(); ++i) {
        if (views[i].data == nullptr) {
            return makeError(ErrorCode::kInvalidArgument, std::string(formatName(format)) +
                                                              ": plane " + std::to_string(i) +
                                                              " is not mapped");
        }
        const std::size_t need = bytesNeeded((*specs)[i]);
        if (views[i].size_bytes < need) {
            return tooShort(format, i, views[i].size_bytes, need);
        }
    }
    return views;
}

core::Result<bool> convertToGrayBgr(RawFormat format, int width_px, int height_px,
                                    const std::vector<PlaneView>& planes, cv::Mat& gray,
                                    cv::Mat& bgr) {
    if (planes.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         std::string(formatName(format)) + ": no planes");
    }
    auto specs = planeSpecs(format, width_px, height_px, planes.front().stride_bytes);
    if (!specs) {
        return specs.error();
    }
    if (planes.size() != specs->size()) {
        return makeError(ErrorCode::kInvalidArgument,
                         std::string(formatName(format)) + ": " + std::to_string(planes.size()) +
                             " planes given, the format has " + std::to_string(specs->size()));
    }
    for (std::size_t i = 0; i < planes.size(); ++i) {
        PlaneSpec spec = (*specs)[i];
        spec.stride_bytes = planes[i].stride_bytes;
        if (planes[i].data == nullptr || spec.stride_bytes < spec.row_bytes) {
            return makeError(ErrorCode::kInvalidArgument, std::string(formatName(format)) +
                                                              ": plane " + std::to_string(i) +
                                                              " is missing or its stride short");
        }
        if (planes[i].size_bytes < bytesNeeded(spec)) {
            return tooShort(format, i, planes[i].size_bytes, bytesNeeded(spec));
        }
    }

    // Fresh images every frame: the caller may still hold the previous ones.
    cv::Mat out_gray;
    cv::Mat out_bgr;
    const int w = width_px;
    const int h = height_px;
    switch (format) {
        case RawFormat::kYuyv: {
            const cv::Mat src = wrap(planes[0], h, w, CV_8UC2);
            cv::cvtColor(src, out_bgr, cv::COLOR_YUV2BGR_YUYV);
            cv::cvtColor(src, out_gray, cv::COLOR_YUV2GRAY_YUYV);
            break;
        }
        case RawFormat::kNv12: {
            const cv::Mat y = wrap(planes[0], h, w, CV_8UC1);
            const cv::Mat uv = wrap(planes[1], h / 2, w / 2, CV_8UC2);
            cv::cvtColorTwoPlane(y, uv, out_bgr, cv::COLOR_YUV2BGR_NV12);
            out_gray = y.clone();
            break;
        }
        case RawFormat::kYuv420: {
            cv::cvtColor(packI420(planes, w, h), out_bgr, cv::COLOR_YUV2BGR_I420);
            out_gray = wrap(planes[0], h, w, CV_8UC1).clone();
            break;
        }
        case RawFormat::kRgb888: {
            const cv::Mat src = wrap(planes[0], h, w, CV_8UC3);
            out_bgr = src.clone();
            cv::cvtColor(src, out_gray, cv::COLOR_BGR2GRAY);
            break;
        }
        case RawFormat::kBgr888: {
            const cv::Mat src = wrap(planes[0], h, w, CV_8UC3);
            cv::cvtColor(src, out_bgr, cv::COLOR_RGB2BGR);
            cv::cvtColor(src, out_gray, cv::COLOR_RGB2GRAY);
            break;
        }
        case RawFormat::kXrgb8888: {
            const cv::Mat src = wrap(planes[0], h, w, CV_8UC4);
            cv::cvtColor(src, out_bgr, cv::COLOR_BGRA2BGR);
            cv::cvtColor(src, out_gray, cv::COLOR_BGRA2GRAY);
            break;
        }
        case RawFormat::kXbgr8888: {
            const cv::Mat src = wrap(planes[0], h, w, CV_8UC4);
            cv::cvtColor(src, out_bgr, cv::COLOR_RGBA2BGR);
            cv::cvtColor(src, out_gray, cv::COLOR_RGBA2GRAY);
            break;
        }
    }
    gray = out_gray;
    bgr = out_bgr;
    return true;
}

}  // namespace scaled::drivers::libcam
