#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include <scaled/drivers/camera/pixel_convert.h>

namespace scaled::drivers::camera {
namespace {

using core::ErrorCode;
using core::makeError;

// Bytes of one packed row of the first (or only) plane; 0 for formats without
// a fixed layout.
std::size_t rowBytes(PixelFormat format, int width_px) {
    const auto w = static_cast<std::size_t>(width_px);
    switch (format) {
        case PixelFormat::kYuyv:
            return 2 * w;
        case PixelFormat::kGrey:
        case PixelFormat::kNv12:
        case PixelFormat::kYuv420:
            return w;
        case PixelFormat::kRgb888:
        case PixelFormat::kBgr888:
            return 3 * w;
        case PixelFormat::kXrgb8888:
        case PixelFormat::kXbgr8888:
            return 4 * w;
        case PixelFormat::kAuto:
        case PixelFormat::kMjpeg:
            break;
    }
    return 0;
}

// Chroma subsampled 2x horizontally / vertically: the size must be even.
bool evenWidth(PixelFormat format) {
    return format == PixelFormat::kYuyv || format == PixelFormat::kNv12 ||
           format == PixelFormat::kYuv420;
}
bool evenHeight(PixelFormat format) {
    return format == PixelFormat::kNv12 || format == PixelFormat::kYuv420;
}

std::string sizeText(int width_px, int height_px) {
    return std::to_string(width_px) + "x" + std::to_string(height_px);
}

// The mutable pointer cv::Mat's constructor wants; the Mats built on it are
// only ever read (sources of cvtColor/copyTo/extractChannel).
void* readOnly(const std::uint8_t* data) {
    return const_cast<std::uint8_t*>(data);  // NOLINT(cppcoreguidelines-pro-type-const-cast)
}

// Where one plane's rows are.
struct PlaneLayout {
    const std::uint8_t* data = nullptr;
    std::size_t stride = 0;  // bytes from row to row
    std::size_t rows = 0;
    std::size_t row_bytes = 0;  // bytes of pixels in a row
    std::size_t size = 0;       // bytes readable at data
    bool apart = false;         // given in RawImage::chroma (not within the buffer before it)

    [[nodiscard]] std::size_t bytesNeeded() const { return stride * (rows - 1) + row_bytes; }
};

// The planes of a fixed-layout image (every format but MJPEG), without
// checking them. A fixed array: describing a frame allocates nothing.
struct Layout {
    std::array<PlaneLayout, 3> planes{};
    std::size_t count = 0;
};

Layout layoutOf(const RawImage& raw) {
    Layout layout;
    const auto w = static_cast<std::size_t>(raw.width_px);
    const auto h = static_cast<std::size_t>(raw.height_px);
    const std::size_t row = rowBytes(raw.format, raw.width_px);
    PlaneLayout& first = layout.planes[0];
    first.data = raw.data;
    first.stride = raw.stride_bytes == 0 ? row : raw.stride_bytes;
    first.rows = h;
    first.row_bytes = row;
    first.size = raw.size_bytes;
    layout.count = 1;
    // Chroma planes: rows, row bytes and the stride they have when they follow
    // the plane before them in the same buffer.
    std::size_t chroma_rows = 0;
    std::size_t chroma_row_bytes = 0;
    std::size_t chroma_stride = 0;
    if (raw.format == PixelFormat::kNv12) {
        layout.count = 2;
        chroma_rows = h / 2;
        chroma_row_bytes = w;
        chroma_stride = first.stride;
    } else if (raw.format == PixelFormat::kYuv420) {
        layout.count = 3;
        chroma_rows = h / 2;
        chroma_row_bytes = w / 2;
        chroma_stride = first.stride / 2;
    }
    for (std::size_t i = 1; i < layout.count; ++i) {
        const RawPlane& given = raw.chroma.at(i - 1);
        PlaneLayout& p = layout.planes.at(i);
        p.rows = chroma_rows;
        p.row_bytes = chroma_row_bytes;
        if (given.data != nullptr) {
            p.data = given.data;
            p.stride = given.stride_bytes == 0 ? chroma_row_bytes : given.stride_bytes;
            p.size = given.size_bytes;
            p.apart = true;
        } else {
            const PlaneLayout& prev = layout.planes.at(i - 1);
            const std::size_t offset = prev.stride * prev.rows;
            p.data = prev.data == nullptr ? nullptr : prev.data + std::min(offset, prev.size);
            p.stride = chroma_stride;
            p.size = prev.size > offset ? prev.size - offset : 0;
        }
    }
    return layout;
}

core::Status checkRaw(const RawImage& raw, const std::string& source) {
    const char* name = toString(raw.format);
    if (raw.format == PixelFormat::kAuto) {
        return makeError(ErrorCode::kInvalidArgument,
                         source + ": no pixel format given (auto is not a buffer format)");
    }
    if (raw.width_px <= 0 || raw.height_px <= 0) {
        return makeError(
            ErrorCode::kInvalidArgument,
            source + ": invalid " + name + " image size " + sizeText(raw.width_px, raw.height_px));
    }
    if (evenWidth(raw.format) && raw.width_px % 2 != 0) {
        return makeError(
            ErrorCode::kInvalidArgument,
            source + ": " + name + " needs an even width, not " + std::to_string(raw.width_px));
    }
    if (evenHeight(raw.format) && raw.height_px % 2 != 0) {
        return makeError(
            ErrorCode::kInvalidArgument,
            source + ": " + name + " needs an even height, not " + std::to_string(raw.height_px));
    }
    if (raw.data == nullptr) {
        return makeError(ErrorCode::kInvalidArgument, source + ": no data");
    }
    if (raw.format == PixelFormat::kMjpeg) {
        return {};
    }
    const Layout layout = layoutOf(raw);
    for (std::size_t i = 0; i < layout.count; ++i) {
        const PlaneLayout& p = layout.planes.at(i);
        if (p.stride < p.row_bytes) {
            std::string message = source + ": " + name;
            if (i > 0) {
                message += " plane " + std::to_string(i);
            }
            message += " row stride " + std::to_string(p.stride) +
                       " bytes is shorter than a row of " + std::to_string(p.row_bytes) + " bytes";
            return makeError(ErrorCode::kInvalidArgument, message);
        }
    }
    // One buffer holding every plane: its size against the whole image (the
    // message V4L2 users know); planes given apart: each against its rows.
    bool apart = false;
    for (std::size_t i = 1; i < layout.count; ++i) {
        apart = apart || layout.planes.at(i).apart;
    }
    if (!apart) {
        const std::size_t need =
            rawImageBytes(raw.format, raw.width_px, raw.height_px, raw.stride_bytes);
        if (raw.size_bytes < need) {
            return makeError(ErrorCode::kIo, source + ": short " + name + " buffer: " +
                                                 std::to_string(raw.size_bytes) + " bytes, a " +
                                                 sizeText(raw.width_px, raw.height_px) +
                                                 " image needs " + std::to_string(need));
        }
        return {};
    }
    for (std::size_t i = 0; i < layout.count; ++i) {
        const PlaneLayout& p = layout.planes.at(i);
        if (p.data == nullptr) {
            return makeError(ErrorCode::kInvalidArgument,
                             source + ": " + name + " plane " + std::to_string(i) + ": no data");
        }
        if (p.size < p.bytesNeeded()) {
            return makeError(ErrorCode::kIo, source + ": short " + name + " buffer: plane " +
                                                 std::to_string(i) + " has " +
                                                 std::to_string(p.size) + " bytes, a " +
                                                 sizeText(raw.width_px, raw.height_px) +
                                                 " image needs " + std::to_string(p.bytesNeeded()));
        }
    }
    return {};
}

// A Mat over a plane's rows (read only).
cv::Mat planeMat(const PlaneLayout& p, int cols, int type) {
    return {static_cast<int>(p.rows), cols, type, readOnly(p.data), p.stride};
}

// The planes of a 4:2:0 image copied without padding, one after another (the
// layout cv::COLOR_YUV2BGR_I420 / _NV12 read from a single Mat), into a
// per-thread scratch image kept between calls: only needed when a buffer's own
// layout is not that one, and sized once per image size.
cv::Mat& packPlanes(const Layout& layout, int width_px, int height_px) {
    thread_local cv::Mat packed;
    packed.create(height_px + height_px / 2, width_px, CV_8UC1);
    std::uint8_t* out = packed.data;
    for (std::size_t i = 0; i < layout.count; ++i) {
        const PlaneLayout& p = layout.planes.at(i);
        for (std::size_t r = 0; r < p.rows; ++r) {
            std::memcpy(out, p.data + r * p.stride, p.row_bytes);
            out += p.row_bytes;
        }
    }
    return packed;
}

// Whether the planes already sit as packPlanes() would put them.
bool isPacked(const Layout& layout) {
    const std::uint8_t* expected = layout.planes[0].data;
    for (std::size_t i = 0; i < layout.count; ++i) {
        const PlaneLayout& p = layout.planes.at(i);
        if (p.data != expected || p.stride != p.row_bytes) {
            return false;
        }
        expected += p.row_bytes * p.rows;
    }
    return true;
}

core::Status convertYuv420(const RawImage& raw, const Layout& layout, cv::Mat& gray,
                           cv::Mat& color) {
    const int w = raw.width_px;
    const int h = raw.height_px;
    planeMat(layout.planes[0], w, CV_8UC1).copyTo(gray);
    if (raw.format == PixelFormat::kNv12) {
        const PlaneLayout& y = layout.planes[0];
        const PlaneLayout& uv = layout.planes[1];
        if (!uv.apart && uv.stride == y.stride) {
            // One Mat over both planes (V4L2's single-planar NV12): OpenCV
            // finds the CbCr plane height rows of `stride` after the Y plane.
            const cv::Mat nv12(h + h / 2, w, CV_8UC1, readOnly(y.data), y.stride);
            cv::cvtColor(nv12, color, cv::COLOR_YUV2BGR_NV12);
        } else if (uv.stride == y.stride) {
            // Planes apart with one stride: OpenCV reads them in place
            // (with different strides it would copy, allocating).
            cv::cvtColorTwoPlane(planeMat(y, w, CV_8UC1), planeMat(uv, w / 2, CV_8UC2), color,
                                 cv::COLOR_YUV2BGR_NV12);
        } else {
            cv::cvtColor(packPlanes(layout, w, h), color, cv::COLOR_YUV2BGR_NV12);
        }
        return {};
    }
    // I420. OpenCV reads the chroma rows of a strided I420 Mat two to a Y
    // stride, not at half the Y stride as these buffers have them: unless
    // the planes are packed, pack them.
    if (isPacked(layout)) {
        const cv::Mat i420(h + h / 2, w, CV_8UC1, readOnly(raw.data));
        cv::cvtColor(i420, color, cv::COLOR_YUV2BGR_I420);
    } else {
        cv::cvtColor(packPlanes(layout, w, h), color, cv::COLOR_YUV2BGR_I420);
    }
    return {};
}

core::Status decodeMjpeg(const RawImage& raw, const std::string& source, cv::Mat& gray,
                         cv::Mat& color) {
    const cv::Mat encoded(1, static_cast<int>(raw.size_bytes), CV_8UC1, readOnly(raw.data));
    // imdecode writes into `color` (re-using its buffer when the decoder allows).
    cv::imdecode(encoded, cv::IMREAD_COLOR, &color);
    if (color.empty()) {
        return makeError(ErrorCode::kIo, source + ": MJPEG buffer of " +
                                             std::to_string(raw.size_bytes) +
                                             " bytes does not decode (corrupt or truncated)");
    }
    if (color.cols != raw.width_px || color.rows != raw.height_px || color.type() != CV_8UC3) {
        const std::string got = sizeText(color.cols, color.rows);
        color.release();
        return makeError(ErrorCode::kIo, source + ": MJPEG buffer decodes to a " + got +
                                             " image, expected " +
                                             sizeText(raw.width_px, raw.height_px));
    }
    cv::cvtColor(color, gray, cv::COLOR_BGR2GRAY);
    return {};
}

}  // namespace

std::size_t rawImageBytes(PixelFormat format, int width_px, int height_px,
                          std::size_t stride_bytes) {
    if (width_px <= 0 || height_px <= 0 || rowBytes(format, width_px) == 0) {
        return 0;
    }
    RawImage raw;
    raw.format = format;
    raw.width_px = width_px;
    raw.height_px = height_px;
    raw.stride_bytes = stride_bytes;
    const Layout layout = layoutOf(raw);  // planes one after another from offset 0
    std::size_t offset = 0;
    for (std::size_t i = 0; i + 1 < layout.count; ++i) {
        offset += layout.planes.at(i).stride * layout.planes.at(i).rows;
    }
    return offset + layout.planes.at(layout.count - 1).bytesNeeded();
}

core::Status checkRawImage(const RawImage& raw, const std::string& source) {
    return checkRaw(raw, source);
}

core::Status convertRawImage(const RawImage& raw, const std::string& source, cv::Mat& gray,
                             cv::Mat& color) {
    auto checked = checkRaw(raw, source);
    if (!checked) {
        return checked.error();
    }
    // OpenCV reports failures by exception; none may cross this boundary.
    try {
        const int w = raw.width_px;
        if (raw.format == PixelFormat::kMjpeg) {
            return decodeMjpeg(raw, source, gray, color);
        }
        const Layout layout = layoutOf(raw);
        const PlaneLayout& first = layout.planes[0];
        switch (raw.format) {
            case PixelFormat::kYuyv: {
                const cv::Mat yuyv = planeMat(first, w, CV_8UC2);
                cv::extractChannel(yuyv, gray, 0);
                cv::cvtColor(yuyv, color, cv::COLOR_YUV2BGR_YUYV);
                return {};
            }
            case PixelFormat::kNv12:
            case PixelFormat::kYuv420:
                return convertYuv420(raw, layout, gray, color);
            case PixelFormat::kGrey: {
                planeMat(first, w, CV_8UC1).copyTo(gray);
                cv::cvtColor(gray, color, cv::COLOR_GRAY2BGR);
                return {};
            }
            case PixelFormat::kRgb888: {  // B, G, R: OpenCV's order
                const cv::Mat bgr = planeMat(first, w, CV_8UC3);
                bgr.copyTo(color);
                cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
                return {};
            }
            case PixelFormat::kBgr888: {  // R, G, B
                const cv::Mat rgb = planeMat(first, w, CV_8UC3);
                cv::cvtColor(rgb, color, cv::COLOR_RGB2BGR);
                cv::cvtColor(rgb, gray, cv::COLOR_RGB2GRAY);
                return {};
            }
            case PixelFormat::kXrgb8888: {  // B, G, R, X
                const cv::Mat bgrx = planeMat(first, w, CV_8UC4);
                cv::cvtColor(bgrx, color, cv::COLOR_BGRA2BGR);
                cv::cvtColor(bgrx, gray, cv::COLOR_BGRA2GRAY);
                return {};
            }
            case PixelFormat::kXbgr8888: {  // R, G, B, X
                const cv::Mat rgbx = planeMat(first, w, CV_8UC4);
                cv::cvtColor(rgbx, color, cv::COLOR_RGBA2BGR);
                cv::cvtColor(rgbx, gray, cv::COLOR_RGBA2GRAY);
                return {};
            }
            case PixelFormat::kMjpeg:
            case PixelFormat::kAuto:
                break;
        }
    } catch (const cv::Exception& e) {
        return makeError(ErrorCode::kIo, source + ": cannot convert the " +
                                             std::string(toString(raw.format)) +
                                             " buffer: " + e.what());
    }
    return makeError(ErrorCode::kInvalidArgument, source + ": unknown pixel format");
}

}  // namespace scaled::drivers::camera
