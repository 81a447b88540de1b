// The libcamera driver's pixel work (frame_convert.h): plane layouts with
// padded strides, one plane per format plane or all in one, byte orders, and
// the colours coming out right (chroma planes not swapped). Built in both the
// libcamera and the stub build: it needs no camera.

#include "frame_convert.h"

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;

constexpr int kW = 16;
constexpr int kH = 8;
constexpr std::size_t kWBytes = kW;  // the same sizes for byte arithmetic
constexpr std::size_t kHRows = kH;
constexpr std::uint8_t kPad = 0x5A;  // fills the stride padding

// Left half red, right half blue, a green band in rows 4..5 (all edges on
// even pixels, so 2x2 chroma subsampling keeps every colour exact).
cv::Mat testImage() {
    cv::Mat bgr(kH, kW, CV_8UC3, cv::Scalar(0, 0, 255));
    bgr(cv::Rect(kW / 2, 0, kW / 2, kH)).setTo(cv::Scalar(255, 0, 0));
    bgr(cv::Rect(0, 4, kW, 2)).setTo(cv::Scalar(0, 200, 0));
    return bgr;
}

// `rows` rows of `row_bytes` from `src` (contiguous) into a buffer with
// `stride` bytes per row; the padding holds kPad.
std::vector<std::uint8_t> padded(const std::uint8_t* src, std::size_t rows, std::size_t row_bytes,
                                 std::size_t stride) {
    std::vector<std::uint8_t> out(rows * stride, kPad);
    for (std::size_t r = 0; r < rows; ++r) {
        std::copy(src + r * row_bytes, src + (r + 1) * row_bytes, out.data() + r * stride);
    }
    return out;
}

// I420 planes of testImage(), contiguous: Y (kW x kH), U, V (kW/2 x kH/2).
struct I420 {
    std::vector<std::uint8_t> y, u, v;
};

I420 toI420(const cv::Mat& bgr) {
    cv::Mat yuv;
    cv::cvtColor(bgr, yuv, cv::COLOR_BGR2YUV_I420);
    const std::size_t ny = kWBytes * kHRows;
    const std::size_t nc = ny / 4;
    const std::uint8_t* p = yuv.ptr<std::uint8_t>();
    return {{p, p + ny}, {p + ny, p + ny + nc}, {p + ny + nc, p + ny + 2 * nc}};
}

// Every pixel within `tolerance` per channel (YUV rounding).
void expectNear(const cv::Mat& actual, const cv::Mat& expected, int tolerance) {
    ASSERT_EQ(actual.size(), expected.size());
    ASSERT_EQ(actual.type(), expected.type());
    cv::Mat diff;
    cv::absdiff(actual, expected, diff);
    double max_diff = 0;
    cv::minMaxLoc(diff.reshape(1), nullptr, &max_diff);
    EXPECT_LE(max_diff, tolerance);
}

cv::Mat grayOf(const cv::Mat& bgr) {
    cv::Mat gray;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    return gray;
}

struct Converted {
    cv::Mat gray, bgr;
};

Converted convertOk(RawFormat format, const std::vector<BufferPlane>& planes, std::size_t stride) {
    auto views = layoutPlanes(format, kW, kH, stride, planes);
    EXPECT_TRUE(views.ok()) << (views.ok() ? "" : views.error().message);
    Converted out;
    if (!views.ok()) {
        return out;
    }
    auto converted = convertToGrayBgr(format, kW, kH, *views, out.gray, out.bgr);
    EXPECT_TRUE(converted.ok()) << (converted.ok() ? "" : converted.error().message);
    EXPECT_EQ(out.gray.type(), CV_8UC1);
    EXPECT_EQ(out.bgr.type(), CV_8UC3);
    return out;
}

TEST(FrameConvert, Rgb888IsBgrInMemoryWithPaddedStride) {
    const cv::Mat image = testImage();
    const std::size_t stride = kWBytes * 3 + 8;
    const auto buffer = padded(image.data, kHRows, kWBytes * 3, stride);
    const Converted out = convertOk(RawFormat::kRgb888, {{buffer.data(), buffer.size()}}, stride);
    expectNear(out.bgr, image, 0);
    expectNear(out.gray, grayOf(image), 0);
}

TEST(FrameConvert, Bgr888IsRgbInMemory) {
    const cv::Mat image = testImage();
    cv::Mat rgb;
    cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
    const std::size_t stride = kWBytes * 3;
    const auto buffer = padded(rgb.data, kHRows, kWBytes * 3, stride);
    const Converted out = convertOk(RawFormat::kBgr888, {{buffer.data(), buffer.size()}}, stride);
    expectNear(out.bgr, image, 0);
    expectNear(out.gray, grayOf(image), 0);
}

TEST(FrameConvert, Xrgb8888AndXbgr8888) {
    const cv::Mat image = testImage();
    cv::Mat bgra;
    cv::Mat rgba;
    cv::cvtColor(image, bgra, cv::COLOR_BGR2BGRA);
    cv::cvtColor(image, rgba, cv::COLOR_BGR2RGBA);
    const std::size_t stride = kWBytes * 4 + 16;
    const auto xrgb = padded(bgra.data, kHRows, kWBytes * 4, stride);
    const auto xbgr = padded(rgba.data, kHRows, kWBytes * 4, stride);
    expectNear(convertOk(RawFormat::kXrgb8888, {{xrgb.data(), xrgb.size()}}, stride).bgr, image, 0);
    expectNear(convertOk(RawFormat::kXbgr8888, {{xbgr.data(), xbgr.size()}}, stride).bgr, image, 0);
}

TEST(FrameConvert, Yuv420ThreePlanesAndOnePlane) {
    const cv::Mat image = testImage();
    const I420 yuv = toI420(image);
    const std::size_t stride = kWBytes + 16;  // chroma stride: half of it
    const auto y = padded(yuv.y.data(), kHRows, kWBytes, stride);
    const auto u = padded(yuv.u.data(), kHRows / 2, kWBytes / 2, stride / 2);
    const auto v = padded(yuv.v.data(), kHRows / 2, kWBytes / 2, stride / 2);
    const Converted three =
        convertOk(RawFormat::kYuv420,
                  {{y.data(), y.size()}, {u.data(), u.size()}, {v.data(), v.size()}}, stride);
    expectNear(three.bgr, image, 6);
    expectNear(three.gray, cv::Mat(kH, kW, CV_8UC1, const_cast<std::uint8_t*>(yuv.y.data())), 0);

    std::vector<std::uint8_t> one = y;
    one.insert(one.end(), u.begin(), u.end());
    one.insert(one.end(), v.begin(), v.end());
    const Converted single = convertOk(RawFormat::kYuv420, {{one.data(), one.size()}}, stride);
    expectNear(single.bgr, three.bgr, 0);
    expectNear(single.gray, three.gray, 0);
}

TEST(FrameConvert, Nv12TwoPlanesAndOnePlane) {
    const cv::Mat image = testImage();
    const I420 yuv = toI420(image);
    std::vector<std::uint8_t> uv;
    for (std::size_t i = 0; i < yuv.u.size(); ++i) {
        uv.push_back(yuv.u[i]);
        uv.push_back(yuv.v[i]);
    }
    const std::size_t stride = kWBytes + 32;
    const auto y = padded(yuv.y.data(), kHRows, kWBytes, stride);
    const auto uvp = padded(uv.data(), kHRows / 2, kWBytes, stride);
    const Converted two =
        convertOk(RawFormat::kNv12, {{y.data(), y.size()}, {uvp.data(), uvp.size()}}, stride);
    expectNear(two.bgr, image, 6);

    std::vector<std::uint8_t> one = y;
    one.insert(one.end(), uvp.begin(), uvp.end());
    const Converted single = convertOk(RawFormat::kNv12, {{one.data(), one.size()}}, stride);
    expectNear(single.bgr, two.bgr, 0);
    expectNear(single.gray, two.gray, 0);
}

TEST(FrameConvert, YuyvWithPaddedStride) {
    const cv::Mat image = testImage();
    const I420 yuv = toI420(image);
    std::vector<std::uint8_t> yuyv;
    for (std::size_t r = 0; r < kHRows; ++r) {
        for (std::size_t c = 0; c < kWBytes; c += 2) {
            const std::size_t yi = r * kWBytes + c;
            const std::size_t ci = (r / 2) * (kWBytes / 2) + c / 2;
            yuyv.insert(yuyv.end(), {yuv.y[yi], yuv.u[ci], yuv.y[yi + 1], yuv.v[ci]});
        }
    }
    const std::size_t stride = kWBytes * 2 + 8;
    const auto buffer = padded(yuyv.data(), kHRows, kWBytes * 2, stride);
    const Converted out = convertOk(RawFormat::kYuyv, {{buffer.data(), buffer.size()}}, stride);
    expectNear(out.bgr, image, 6);
    expectNear(out.gray, cv::Mat(kH, kW, CV_8UC1, const_cast<std::uint8_t*>(yuv.y.data())), 0);
}

TEST(FrameConvert, EachFrameGetsNewImages) {
    const cv::Mat image = testImage();
    const std::size_t stride = kWBytes * 3;
    auto buffer = padded(image.data, kHRows, kWBytes * 3, stride);
    auto views = layoutPlanes(RawFormat::kRgb888, kW, kH, stride, {{buffer.data(), buffer.size()}});
    ASSERT_TRUE(views.ok());
    cv::Mat gray;
    cv::Mat bgr;
    ASSERT_TRUE(convertToGrayBgr(RawFormat::kRgb888, kW, kH, *views, gray, bgr).ok());
    const cv::Mat kept_bgr = bgr;  // a caller holding the previous frame
    const cv::Mat kept_gray = gray;
    std::fill(buffer.begin(), buffer.end(), std::uint8_t{0});
    ASSERT_TRUE(convertToGrayBgr(RawFormat::kRgb888, kW, kH, *views, gray, bgr).ok());
    EXPECT_EQ(cv::countNonZero(bgr.reshape(1)), 0);
    expectNear(kept_bgr, image, 0);
    expectNear(kept_gray, grayOf(image), 0);
}

TEST(FrameConvert, RejectsShortPlanesOddSizesAndBadStrides) {
    std::vector<std::uint8_t> buffer(kWBytes * kHRows * 4, 0);
    const BufferPlane whole{buffer.data(), buffer.size()};

    // One byte short of the last row.
    auto short_plane = layoutPlanes(RawFormat::kRgb888, kW, kH, kWBytes * 3,
                                    {{buffer.data(), kWBytes * 3 * kHRows - 1}});
    ASSERT_FALSE(short_plane.ok());
    EXPECT_EQ(short_plane.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(short_plane.error().message.find("RGB888"), std::string::npos);

    // NV12 in one plane that ends inside the chroma.
    auto short_chroma =
        layoutPlanes(RawFormat::kNv12, kW, kH, kWBytes, {{buffer.data(), kWBytes * kHRows + 8}});
    EXPECT_FALSE(short_chroma.ok());

    auto odd = layoutPlanes(RawFormat::kNv12, kW - 1, kH, kWBytes, {whole});
    ASSERT_FALSE(odd.ok());
    EXPECT_NE(odd.error().message.find("odd"), std::string::npos);
    EXPECT_FALSE(
        layoutPlanes(RawFormat::kYuyv, kW, kH, kWBytes, {whole}).ok());  // stride < 2 * width
    EXPECT_FALSE(layoutPlanes(RawFormat::kYuyv, kW, kH, kWBytes * 2, {whole, whole}).ok());
    EXPECT_FALSE(layoutPlanes(RawFormat::kYuv420, kW, kH, kWBytes, {whole, whole}).ok());
    EXPECT_FALSE(layoutPlanes(RawFormat::kRgb888, 0, kH, kWBytes * 3, {whole}).ok());
    EXPECT_FALSE(layoutPlanes(RawFormat::kRgb888, kW, kH, kWBytes * 3, {{nullptr, 100000}}).ok());

    cv::Mat gray;
    cv::Mat bgr;
    EXPECT_FALSE(convertToGrayBgr(RawFormat::kRgb888, kW, kH, {}, gray, bgr).ok());
    EXPECT_FALSE(
        convertToGrayBgr(RawFormat::kRgb888, kW, kH, {{buffer.data(), kWBytes * 3, 10}}, gray, bgr)
            .ok());
    EXPECT_TRUE(gray.empty());
}

TEST(FrameConvert, NamesAreLibcamerasAndEveryFormatIsPreferredOnce) {
    const std::vector<RawFormat>& formats = preferredFormats();
    ASSERT_EQ(formats.size(), 7U);
    EXPECT_EQ(formats.front(), RawFormat::kYuyv);
    EXPECT_STREQ(formatName(RawFormat::kYuv420), "YUV420");
    EXPECT_STREQ(formatName(RawFormat::kRgb888), "RGB888");
    EXPECT_STREQ(formatName(RawFormat::kXrgb8888), "XRGB8888");
    for (std::size_t i = 0; i < formats.size(); ++i) {
        for (std::size_t j = i + 1; j < formats.size(); ++j) {
            EXPECT_NE(formats[i], formats[j]);
        }
    }
}

}  // namespace
}  // namespace scaled::drivers::libcam
