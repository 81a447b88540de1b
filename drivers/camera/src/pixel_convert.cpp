#include <cstddef>
#include <cstdint>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include <scaled/drivers/pixel_convert.h>

namespace scaled::drivers {
namespace {

using core::ErrorCode;
using core::makeError;

// Bytes of one packed row of the first (or only) plane.
std::size_t rowBytes(PixelFormat format, int width_px) {
    const auto w = static_cast<std::size_t>(width_px);
    switch (format) {
        case PixelFormat::kYuyv:
            return 2 * w;
        case PixelFormat::kGrey:
        case PixelFormat::kNv12:
            return w;
        case PixelFormat::kAuto:
        case PixelFormat::kMjpeg:
            break;
    }
    return 0;
}

std::string sizeText(int width_px, int height_px) {
    return std::to_string(width_px) + "x" + std::to_string(height_px);
}

// The mutable pointer cv::Mat's constructor wants; the Mats built on it are
// only ever read (sources of cvtColor/copyTo/extractChannel).
void* readOnly(const std::uint8_t* data) {
    return const_cast<std::uint8_t*>(data);  // NOLINT(cppcoreguidelines-pro-type-const-cast)
}

core::Result<bool> checkRaw(const RawImage& raw, const std::string& source) {
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
    if ((raw.format == PixelFormat::kYuyv || raw.format == PixelFormat::kNv12) &&
        raw.width_px % 2 != 0) {
        return makeError(
            ErrorCode::kInvalidArgument,
            source + ": " + name + " needs an even width, not " + std::to_string(raw.width_px));
    }
    if (raw.format == PixelFormat::kNv12 && raw.height_px % 2 != 0) {
        return makeError(ErrorCode::kInvalidArgument, source + ": NV12 needs an even height, not " +
                                                          std::to_string(raw.height_px));
    }
    if (raw.data == nullptr) {
        return makeError(ErrorCode::kInvalidArgument, source + ": no data");
    }
    if (raw.format == PixelFormat::kMjpeg) {
        return true;
    }
    const std::size_t row = rowBytes(raw.format, raw.width_px);
    if (raw.stride_bytes != 0 && raw.stride_bytes < row) {
        return makeError(ErrorCode::kInvalidArgument,
                         source + ": " + name + " row stride " + std::to_string(raw.stride_bytes) +
                             " bytes is shorter than a row of " + std::to_string(row) + " bytes");
    }
    const std::size_t need =
        rawImageBytes(raw.format, raw.width_px, raw.height_px, raw.stride_bytes);
    if (raw.size_bytes < need) {
        return makeError(ErrorCode::kIo, source + ": short " + name +
                                             " buffer: " + std::to_string(raw.size_bytes) +
                                             " bytes, a " + sizeText(raw.width_px, raw.height_px) +
                                             " image needs " + std::to_string(need));
    }
    return true;
}

core::Result<bool> decodeMjpeg(const RawImage& raw, const std::string& source, cv::Mat& gray,
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
    return true;
}

}  // namespace

std::size_t rawImageBytes(PixelFormat format, int width_px, int height_px,
                          std::size_t stride_bytes) {
    if (width_px <= 0 || height_px <= 0) {
        return 0;
    }
    const std::size_t row = rowBytes(format, width_px);
    if (row == 0) {
        return 0;
    }
    const std::size_t stride = stride_bytes == 0 ? row : stride_bytes;
    auto rows = static_cast<std::size_t>(height_px);
    if (format == PixelFormat::kNv12) {
        rows += static_cast<std::size_t>(height_px) / 2;  // the CbCr plane
    }
    return stride * (rows - 1) + row;
}

core::Result<bool> convertRawImage(const RawImage& raw, const std::string& source, cv::Mat& gray,
                                   cv::Mat& color) {
    auto checked = checkRaw(raw, source);
    if (!checked) {
        return checked.error();
    }
    // OpenCV reports failures by exception; none may cross this boundary.
    try {
        const int w = raw.width_px;
        const int h = raw.height_px;
        const std::size_t stride =
            raw.stride_bytes == 0 ? rowBytes(raw.format, w) : raw.stride_bytes;
        switch (raw.format) {
            case PixelFormat::kYuyv: {
                const cv::Mat yuyv(h, w, CV_8UC2, readOnly(raw.data), stride);
                cv::extractChannel(yuyv, gray, 0);
                cv::cvtColor(yuyv, color, cv::COLOR_YUV2BGR_YUYV);
                return true;
            }
            case PixelFormat::kNv12: {
                // One Mat over both planes: OpenCV finds the CbCr plane at
                // height rows of `stride` after the Y plane, as V4L2 lays it out.
                const cv::Mat nv12(h + h / 2, w, CV_8UC1, readOnly(raw.data), stride);
                nv12.rowRange(0, h).copyTo(gray);
                cv::cvtColor(nv12, color, cv::COLOR_YUV2BGR_NV12);
                return true;
            }
            case PixelFormat::kGrey: {
                const cv::Mat grey(h, w, CV_8UC1, readOnly(raw.data), stride);
                grey.copyTo(gray);
                cv::cvtColor(gray, color, cv::COLOR_GRAY2BGR);
                return true;
            }
            case PixelFormat::kMjpeg:
                return decodeMjpeg(raw, source, gray, color);
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

}  // namespace scaled::drivers
