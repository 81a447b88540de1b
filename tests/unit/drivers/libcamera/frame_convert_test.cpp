// The libcamera driver's buffers (frame_convert.h) through the common
// conversion (pixel_convert.h): plane layouts with padded strides, one plane
// per format plane or all in one, byte orders, the colours coming out right
// (chroma planes not swapped), conversion in place without allocation. Built
// in both the libcamera and the stub build: it needs no camera.

#include "frame_convert.h"

#include <allocation_counter.h>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/pixel_convert.h>

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

const std::string kSource = "libcamera camera 0 (test): buffer 1";

Converted convertOk(camera::PixelFormat format, const std::vector<BufferPlane>& planes,
                    std::size_t stride) {
    auto raw = describeBuffer(format, kW, kH, stride, planes);
    EXPECT_TRUE(raw.ok()) << (raw.ok() ? "" : raw.error().message);
    Converted out;
    if (!raw.ok()) {
        return out;
    }
    auto converted = camera::convertRawImage(*raw, kSource, out.gray, out.bgr);
    EXPECT_TRUE(converted.ok()) << (converted.ok() ? "" : converted.error().message);
    EXPECT_EQ(out.gray.type(), CV_8UC1);
    EXPECT_EQ(out.bgr.type(), CV_8UC3);
    return out;
}

TEST(FrameConvert, Rgb888IsBgrInMemoryWithPaddedStride) {
    const cv::Mat image = testImage();
    const std::size_t stride = kWBytes * 3 + 8;
    const auto buffer = padded(image.data, kHRows, kWBytes * 3, stride);
    const Converted out =
        convertOk(camera::PixelFormat::kRgb888, {{buffer.data(), buffer.size()}}, stride);
    expectNear(out.bgr, image, 0);
    expectNear(out.gray, grayOf(image), 0);
}

TEST(FrameConvert, Bgr888IsRgbInMemory) {
    const cv::Mat image = testImage();
    cv::Mat rgb;
    cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
    const std::size_t stride = kWBytes * 3;
    const auto buffer = padded(rgb.data, kHRows, kWBytes * 3, stride);
    const Converted out =
        convertOk(camera::PixelFormat::kBgr888, {{buffer.data(), buffer.size()}}, stride);
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
    expectNear(convertOk(camera::PixelFormat::kXrgb8888, {{xrgb.data(), xrgb.size()}}, stride).bgr,
               image, 0);
    expectNear(convertOk(camera::PixelFormat::kXbgr8888, {{xbgr.data(), xbgr.size()}}, stride).bgr,
               image, 0);
}

TEST(FrameConvert, Yuv420ThreePlanesAndOnePlane) {
    const cv::Mat image = testImage();
    const I420 yuv = toI420(image);
    const std::size_t stride = kWBytes + 16;  // chroma stride: half of it
    const auto y = padded(yuv.y.data(), kHRows, kWBytes, stride);
    const auto u = padded(yuv.u.data(), kHRows / 2, kWBytes / 2, stride / 2);
    const auto v = padded(yuv.v.data(), kHRows / 2, kWBytes / 2, stride / 2);
    const Converted three =
        convertOk(camera::PixelFormat::kYuv420,
                  {{y.data(), y.size()}, {u.data(), u.size()}, {v.data(), v.size()}}, stride);
    expectNear(three.bgr, image, 6);
    expectNear(three.gray, cv::Mat(kH, kW, CV_8UC1, const_cast<std::uint8_t*>(yuv.y.data())), 0);

    std::vector<std::uint8_t> one = y;
    one.insert(one.end(), u.begin(), u.end());
    one.insert(one.end(), v.begin(), v.end());
    const Converted single =
        convertOk(camera::PixelFormat::kYuv420, {{one.data(), one.size()}}, stride);
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
    const Converted two = convertOk(camera::PixelFormat::kNv12,
                                    {{y.data(), y.size()}, {uvp.data(), uvp.size()}}, stride);
    expectNear(two.bgr, image, 6);

    std::vector<std::uint8_t> one = y;
    one.insert(one.end(), uvp.begin(), uvp.end());
    const Converted single =
        convertOk(camera::PixelFormat::kNv12, {{one.data(), one.size()}}, stride);
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
    const Converted out =
        convertOk(camera::PixelFormat::kYuyv, {{buffer.data(), buffer.size()}}, stride);
    expectNear(out.bgr, image, 6);
    expectNear(out.gray, cv::Mat(kH, kW, CV_8UC1, const_cast<std::uint8_t*>(yuv.y.data())), 0);
}

// The driver hands the Frame's own Mats to the conversion: the next frame
// lands in the same pixels (the pipeline swaps Frames, so nobody else holds
// them), as with V4L2.
TEST(FrameConvert, ConvertsInPlaceIntoTheGivenMats) {
    const cv::Mat image = testImage();
    const std::size_t stride = kWBytes * 3;
    auto buffer = padded(image.data, kHRows, kWBytes * 3, stride);
    const std::vector<BufferPlane> planes{{buffer.data(), buffer.size()}};
    auto raw = describeBuffer(camera::PixelFormat::kRgb888, kW, kH, stride, planes);
    ASSERT_TRUE(raw.ok());
    cv::Mat gray;
    cv::Mat bgr;
    ASSERT_TRUE(camera::convertRawImage(*raw, kSource, gray, bgr).ok());
    expectNear(bgr, image, 0);
    const std::uint8_t* gray_data = gray.data;
    const std::uint8_t* bgr_data = bgr.data;
    std::fill(buffer.begin(), buffer.end(), std::uint8_t{0});
    ASSERT_TRUE(camera::convertRawImage(*raw, kSource, gray, bgr).ok());
    EXPECT_EQ(gray.data, gray_data);
    EXPECT_EQ(bgr.data, bgr_data);
    EXPECT_EQ(cv::countNonZero(bgr.reshape(1)), 0);
}

// Every format, planes apart and in one buffer, at a camera size with padded
// strides: once the Mats have the size, a conversion makes no allocation (no
// per-frame plane list; the packed copy of the planes YUV420 needs is a
// per-thread scratch image kept between calls).
TEST(FrameConvert, SteadyStateConversionMakesNoHeapAllocation) {
    constexpr int w = 640;
    constexpr int h = 480;
    const std::size_t stride = 4 * w + 64;  // room for every format's row, padded
    std::vector<std::uint8_t> y_plane(stride * h, 90);
    std::vector<std::uint8_t> c1(stride * h / 2, 120);
    std::vector<std::uint8_t> c2(stride * h / 2, 140);
    std::vector<std::uint8_t> one(stride * h * 2, 100);
    for (const camera::PixelFormat f : preferredFormats()) {
        std::vector<std::vector<BufferPlane>> layouts{{{one.data(), one.size()}}};
        if (f == camera::PixelFormat::kNv12) {
            layouts.push_back({{y_plane.data(), y_plane.size()}, {c1.data(), c1.size()}});
        } else if (f == camera::PixelFormat::kYuv420) {
            layouts.push_back(
                {{y_plane.data(), y_plane.size()}, {c1.data(), c1.size()}, {c2.data(), c2.size()}});
        }
        for (const auto& planes : layouts) {
            auto raw = describeBuffer(f, w, h, stride, planes);
            ASSERT_TRUE(raw.ok()) << toString(f) << ": " << raw.error().message;
            cv::Mat gray;
            cv::Mat bgr;
            ASSERT_TRUE(camera::convertRawImage(*raw, kSource, gray, bgr).ok()) << toString(f);
            // The calling thread's count: cv::cvtColor runs on OpenCV's
            // thread pool, whose workers allocate their thread-local data
            // the first time they take part in a job, whichever call that is.
            const std::int64_t before = test::allocationCountThisThread();
            const bool ok = camera::convertRawImage(*raw, kSource, gray, bgr).ok();
            const std::int64_t after = test::allocationCountThisThread();
            EXPECT_TRUE(ok) << toString(f);
            EXPECT_EQ(after - before, 0) << toString(f) << ", " << planes.size() << " plane(s)";
            EXPECT_EQ(gray.size(), cv::Size(w, h));
            EXPECT_EQ(bgr.type(), CV_8UC3);
        }
    }
}

TEST(FrameConvert, RejectsShortPlanesOddSizesAndBadStrides) {
    std::vector<std::uint8_t> buffer(kWBytes * kHRows * 4, 0);
    const BufferPlane whole{buffer.data(), buffer.size()};
    using Planes = std::vector<BufferPlane>;

    // One byte short of the last row.
    auto short_plane = describeBuffer(camera::PixelFormat::kRgb888, kW, kH, kWBytes * 3,
                                      Planes{{buffer.data(), kWBytes * 3 * kHRows - 1}});
    ASSERT_FALSE(short_plane.ok());
    EXPECT_EQ(short_plane.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(short_plane.error().message.find("RGB888"), std::string::npos);

    // NV12 in one plane that ends inside the chroma; in two, a short chroma plane.
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kNv12, kW, kH, kWBytes,
                                Planes{{buffer.data(), kWBytes * kHRows + 8}})
                     .ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kNv12, kW, kH, kWBytes,
                                Planes{whole, {buffer.data(), kWBytes * (kHRows / 2) - 1}})
                     .ok());

    auto odd = describeBuffer(camera::PixelFormat::kNv12, kW - 1, kH, kWBytes, Planes{whole});
    ASSERT_FALSE(odd.ok());
    EXPECT_NE(odd.error().message.find("even"), std::string::npos) << odd.error().message;
    EXPECT_FALSE(
        describeBuffer(camera::PixelFormat::kYuv420, kW, kH - 1, kWBytes, Planes{whole}).ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kYuyv, kW, kH, kWBytes, Planes{whole})
                     .ok());  // stride < 2 * width
    EXPECT_FALSE(
        describeBuffer(camera::PixelFormat::kYuyv, kW, kH, kWBytes * 2, Planes{whole, whole}).ok());
    EXPECT_FALSE(
        describeBuffer(camera::PixelFormat::kYuv420, kW, kH, kWBytes, Planes{whole, whole}).ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kYuv420, kW, kH, kWBytes,
                                Planes{whole, whole, {nullptr, 100}})
                     .ok());
    EXPECT_FALSE(
        describeBuffer(camera::PixelFormat::kRgb888, 0, kH, kWBytes * 3, Planes{whole}).ok());
    EXPECT_FALSE(
        describeBuffer(camera::PixelFormat::kRgb888, kW, kH, kWBytes * 3, Planes{{nullptr, 100000}})
            .ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kYuyv, kW, kH, kWBytes * 2, Planes{}).ok());
    // Formats the driver does not ask libcamera for.
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kGrey, kW, kH, kWBytes, Planes{whole}).ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kMjpeg, kW, kH, kWBytes, Planes{whole}).ok());
    EXPECT_FALSE(describeBuffer(camera::PixelFormat::kAuto, kW, kH, kWBytes, Planes{whole}).ok());
}

TEST(FrameConvert, NamesAreLibcamerasAndEveryFormatIsPreferredOnce) {
    const auto formats = preferredFormats();
    ASSERT_EQ(formats.size(), 7U);
    EXPECT_EQ(formats.front(), camera::PixelFormat::kYuyv);
    EXPECT_STREQ(toString(camera::PixelFormat::kYuv420), "YUV420");
    EXPECT_STREQ(toString(camera::PixelFormat::kRgb888), "RGB888");
    EXPECT_STREQ(toString(camera::PixelFormat::kBgr888), "BGR888");
    EXPECT_STREQ(toString(camera::PixelFormat::kXrgb8888), "XRGB8888");
    EXPECT_STREQ(toString(camera::PixelFormat::kXbgr8888), "XBGR8888");
    for (std::size_t i = 0; i < formats.size(); ++i) {
        for (std::size_t j = i + 1; j < formats.size(); ++j) {
            EXPECT_NE(formats[i], formats[j]);
        }
    }
}

}  // namespace
}  // namespace scaled::drivers::libcam
