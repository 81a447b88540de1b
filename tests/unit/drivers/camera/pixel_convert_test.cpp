// Camera buffers to gray + BGR (pixel_convert.h): strides larger than a row,
// planes apart, libcamera's YUV420 and RGB layouts, buffer re-use without
// allocation, MJPEG decode and its errors. The references are OpenCV's own
// conversions of the same pixels packed without padding.

#include <allocation_counter.h>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/camera/pixel_convert.h>

namespace scaled::drivers::camera {
namespace {

using core::ErrorCode;

constexpr std::uint8_t kPadding = 0xEE;  // what a stride-blind conversion would read
const std::string kSource = "/dev/video7 (test): buffer 3";

// Copies `packed` (rows of `row` bytes) into a buffer with `stride` bytes per
// row, the gap filled with kPadding.
std::vector<std::uint8_t> withStride(const std::vector<std::uint8_t>& packed, std::size_t row,
                                     std::size_t stride) {
    const std::size_t rows = packed.size() / row;
    std::vector<std::uint8_t> out(rows * stride, kPadding);
    for (std::size_t r = 0; r < rows; ++r) {
        std::copy_n(packed.begin() + static_cast<std::ptrdiff_t>(r * row), row,
                    out.begin() + static_cast<std::ptrdiff_t>(r * stride));
    }
    return out;
}

// A YUYV image with varying luma and chroma: colour matters in the check.
std::vector<std::uint8_t> yuyvPixels(int w, int h) {
    std::vector<std::uint8_t> p;
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; x += 2) {
            p.push_back(static_cast<std::uint8_t>(20 + 7 * x + 11 * y));      // Y0
            p.push_back(static_cast<std::uint8_t>(60 + 13 * x));              // U
            p.push_back(static_cast<std::uint8_t>(25 + 7 * x + 11 * y + 3));  // Y1
            p.push_back(static_cast<std::uint8_t>(200 - 9 * y));              // V
        }
    }
    return p;
}

double maxDiff(const cv::Mat& a, const cv::Mat& b) {
    if (a.size() != b.size() || a.type() != b.type()) {
        return 1e9;
    }
    return cv::norm(a, b, cv::NORM_INF);
}

RawImage raw(PixelFormat f, int w, int h, std::size_t stride, const std::vector<std::uint8_t>& d) {
    RawImage r;
    r.format = f;
    r.width_px = w;
    r.height_px = h;
    r.stride_bytes = stride;
    r.data = d.data();
    r.size_bytes = d.size();
    return r;
}

TEST(PixelConvert, YuyvHonoursTheStride) {
    const int w = 8;
    const int h = 6;
    const std::vector<std::uint8_t> packed = yuyvPixels(w, h);
    const std::size_t row = 2 * static_cast<std::size_t>(w);
    const std::vector<std::uint8_t> padded = withStride(packed, row, row + 12);
    cv::Mat gray;
    cv::Mat color;
    auto ok =
        convertRawImage(raw(PixelFormat::kYuyv, w, h, row + 12, padded), kSource, gray, color);
    ASSERT_TRUE(ok) << ok.error().message;

    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-const-cast)
    const cv::Mat ref_yuyv(h, w, CV_8UC2, const_cast<std::uint8_t*>(packed.data()));
    cv::Mat ref_color;
    cv::cvtColor(ref_yuyv, ref_color, cv::COLOR_YUV2BGR_YUYV);
    EXPECT_EQ(maxDiff(color, ref_color), 0.0);
    ASSERT_EQ(gray.type(), CV_8UC1);
    ASSERT_EQ(gray.size(), cv::Size(w, h));
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            EXPECT_EQ(gray.at<std::uint8_t>(y, x),
                      packed[static_cast<std::size_t>(y * 2 * w + 2 * x)])
                << "at " << x << "," << y;
        }
    }
    // The chroma is not neutral: the colour image is not gray.
    std::vector<cv::Mat> ch;
    cv::split(color, ch);
    EXPECT_GT(cv::norm(ch[0], ch[2], cv::NORM_INF), 20.0);
}

TEST(PixelConvert, Nv12HonoursTheStride) {
    const int w = 8;
    const int h = 4;
    std::vector<std::uint8_t> packed;
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            packed.push_back(static_cast<std::uint8_t>(30 + 20 * x + 5 * y));
        }
    }
    for (int y = 0; y < h / 2; ++y) {
        for (int x = 0; x < w / 2; ++x) {
            packed.push_back(static_cast<std::uint8_t>(70 + 30 * x));   // Cb
            packed.push_back(static_cast<std::uint8_t>(190 - 40 * y));  // Cr
        }
    }
    const std::size_t stride = 16;
    const std::vector<std::uint8_t> padded = withStride(packed, w, stride);
    cv::Mat gray;
    cv::Mat color;
    // The last row need not be padded: trim the final gap.
    std::vector<std::uint8_t> trimmed(padded.begin(), padded.end() - (stride - w));
    ASSERT_EQ(trimmed.size(), rawImageBytes(PixelFormat::kNv12, w, h, stride));
    auto ok = convertRawImage(raw(PixelFormat::kNv12, w, h, stride, trimmed), kSource, gray, color);
    ASSERT_TRUE(ok) << ok.error().message;

    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-const-cast)
    const cv::Mat ref_nv12(h + h / 2, w, CV_8UC1, const_cast<std::uint8_t*>(packed.data()));
    cv::Mat ref_color;
    cv::cvtColor(ref_nv12, ref_color, cv::COLOR_YUV2BGR_NV12);
    EXPECT_EQ(maxDiff(color, ref_color), 0.0);
    EXPECT_EQ(maxDiff(gray, ref_nv12.rowRange(0, h)), 0.0);
}

TEST(PixelConvert, GreyHonoursTheStrideAndExpandsToBgr) {
    const int w = 5;
    const int h = 3;
    std::vector<std::uint8_t> packed;
    packed.reserve(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (int i = 0; i < w * h; ++i) {
        packed.push_back(static_cast<std::uint8_t>(10 * i));
    }
    const std::vector<std::uint8_t> padded = withStride(packed, w, 8);
    cv::Mat gray;
    cv::Mat color;
    auto ok = convertRawImage(raw(PixelFormat::kGrey, w, h, 8, padded), kSource, gray, color);
    ASSERT_TRUE(ok) << ok.error().message;
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-const-cast)
    const cv::Mat ref(h, w, CV_8UC1, const_cast<std::uint8_t*>(packed.data()));
    EXPECT_EQ(maxDiff(gray, ref), 0.0);
    ASSERT_EQ(color.type(), CV_8UC3);
    std::vector<cv::Mat> ch;
    cv::split(color, ch);
    for (const cv::Mat& c : ch) {
        EXPECT_EQ(maxDiff(c, ref), 0.0);
    }
}

// The outputs are written in place: no allocation frame to frame.
TEST(PixelConvert, ReusesTheOutputBuffers) {
    const int w = 16;
    const int h = 8;
    const std::vector<std::uint8_t> a = yuyvPixels(w, h);
    std::vector<std::uint8_t> b = a;
    for (auto& v : b) {
        v = static_cast<std::uint8_t>(255 - v);
    }
    for (const PixelFormat f : {PixelFormat::kYuyv, PixelFormat::kGrey, PixelFormat::kNv12}) {
        cv::Mat gray;
        cv::Mat color;
        ASSERT_TRUE(convertRawImage(raw(f, w, h, 0, a), kSource, gray, color));
        const cv::Mat first_gray = gray.clone();
        const std::uint8_t* gray_data = gray.data;
        const std::uint8_t* color_data = color.data;
        ASSERT_TRUE(convertRawImage(raw(f, w, h, 0, b), kSource, gray, color));
        EXPECT_EQ(gray.data, gray_data) << toString(f);
        EXPECT_EQ(color.data, color_data) << toString(f);
        EXPECT_GT(cv::norm(gray, first_gray, cv::NORM_INF), 0.0) << toString(f);
    }
}

// A camera-sized frame, converted again into the same Mats: no operator new
// (the Mats' pixels are checked by ReusesTheOutputBuffers: cv::Mat allocates
// with cv::fastMalloc, not operator new).
TEST(PixelConvert, SteadyStateMakesNoHeapAllocation) {
    const int w = 640;
    const int h = 480;
    // Enough bytes for every format (XRGB8888: 4 per pixel).
    std::vector<std::uint8_t> pixels = yuyvPixels(w, h);
    pixels.resize(pixels.size() * 2, 77);
    const std::string source = kSource;
    for (const PixelFormat f : {PixelFormat::kYuyv, PixelFormat::kGrey, PixelFormat::kNv12,
                                PixelFormat::kYuv420, PixelFormat::kRgb888, PixelFormat::kBgr888,
                                PixelFormat::kXrgb8888, PixelFormat::kXbgr8888}) {
        cv::Mat gray;
        cv::Mat color;
        const RawImage image = raw(f, w, h, 0, pixels);
        ASSERT_TRUE(convertRawImage(image, source, gray, color));  // allocates the Mats
        // The calling thread's count: cv::cvtColor runs on OpenCV's thread
        // pool, whose workers allocate their thread-local data the first
        // time they take part in a job, whichever call that is.
        const std::int64_t before = test::allocationCountThisThread();
        const bool ok = convertRawImage(image, source, gray, color).ok();
        const std::int64_t after = test::allocationCountThisThread();
        EXPECT_TRUE(ok);
        EXPECT_EQ(after - before, 0) << toString(f);
    }
}

// A BGR picture with varied colours and the other layouts of its pixels.
cv::Mat colourPicture(int w, int h) {
    cv::Mat bgr(h, w, CV_8UC3);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            bgr.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<std::uint8_t>(13 * x + 3 * y),
                                                static_cast<std::uint8_t>(200 - 5 * y),
                                                static_cast<std::uint8_t>(7 * x * y + 40));
        }
    }
    return bgr;
}

std::vector<std::uint8_t> bytesOf(const cv::Mat& m) {
    const cv::Mat c = m.isContinuous() ? m : m.clone();
    std::vector<std::uint8_t> bytes(c.total() * c.elemSize());
    if (!bytes.empty()) {  // (GCC 14 -O3 sees a null c.data in the range constructor)
        std::memcpy(bytes.data(), c.data, bytes.size());
    }
    return bytes;
}

// libcamera's RGB layouts (names from the most significant byte of a
// little-endian word): each to the same BGR and gray as OpenCV's conversion
// of the picture, through a padded stride.
TEST(PixelConvert, RgbLayoutsHonourTheStrideAndByteOrder) {
    const int w = 10;
    const int h = 6;
    const cv::Mat bgr = colourPicture(w, h);
    cv::Mat ref_gray;
    cv::cvtColor(bgr, ref_gray, cv::COLOR_BGR2GRAY);
    cv::Mat rgb;
    cv::Mat bgra;
    cv::Mat rgba;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
    cv::cvtColor(bgr, rgba, cv::COLOR_BGR2RGBA);
    struct Case {
        PixelFormat format;
        const cv::Mat* memory;
    };
    for (const Case c :
         {Case{PixelFormat::kRgb888, &bgr}, Case{PixelFormat::kBgr888, &rgb},
          Case{PixelFormat::kXrgb8888, &bgra}, Case{PixelFormat::kXbgr8888, &rgba}}) {
        const std::size_t row = static_cast<std::size_t>(w) * c.memory->elemSize();
        const auto data = withStride(bytesOf(*c.memory), row, row + 12);
        cv::Mat gray;
        cv::Mat color;
        auto ok = convertRawImage(raw(c.format, w, h, row + 12, data), kSource, gray, color);
        ASSERT_TRUE(ok) << toString(c.format) << ": " << ok.error().message;
        EXPECT_EQ(maxDiff(color, bgr), 0.0) << toString(c.format);
        // Gray straight from the camera's layout may round differently from
        // gray of the BGR copy by one level.
        EXPECT_LE(maxDiff(gray, ref_gray), 1.0) << toString(c.format);
        EXPECT_EQ(rawImageBytes(c.format, w, h, row + 12), (row + 12) * (h - 1) + row);
    }
}

// I420 planes of a picture: Y (w x h), then U and V (w/2 x h/2), packed.
std::vector<std::uint8_t> i420Of(const cv::Mat& bgr) {
    cv::Mat yuv;
    cv::cvtColor(bgr, yuv, cv::COLOR_BGR2YUV_I420);
    return bytesOf(yuv);
}

// `rows` rows of `row` bytes from `src` into `dst` at `stride`, padding kPadding.
void putRows(const std::uint8_t* src, std::size_t rows, std::size_t row, std::size_t stride,
             std::vector<std::uint8_t>& dst) {
    for (std::size_t r = 0; r < rows; ++r) {
        dst.insert(dst.end(), src + r * row, src + (r + 1) * row);
        dst.insert(dst.end(), stride - row, kPadding);
    }
}

// YUV420 as libcamera lays it out (chroma rows at half the Y stride, planes
// one after another or apart) converts exactly as OpenCV converts the packed
// planes; gray is the Y plane.
TEST(PixelConvert, Yuv420PlanesTogetherOrApartHonourTheStrides) {
    const int w = 12;
    const int h = 10;  // h % 4 == 2: the case OpenCV's strided I420 gets wrong
    const auto uw = static_cast<std::size_t>(w);
    const auto uh = static_cast<std::size_t>(h);
    const std::vector<std::uint8_t> packed = i420Of(colourPicture(w, h));
    cv::Mat ref_color;
    cv::cvtColor(cv::Mat(h + h / 2, w, CV_8UC1, const_cast<std::uint8_t*>(packed.data())),
                 ref_color, cv::COLOR_YUV2BGR_I420);
    const cv::Mat ref_gray(h, w, CV_8UC1, const_cast<std::uint8_t*>(packed.data()));
    const std::uint8_t* y = packed.data();
    const std::uint8_t* u = y + uw * uh;
    const std::uint8_t* v = u + (uw / 2) * (uh / 2);

    // Packed, no stride: read in place.
    {
        cv::Mat gray;
        cv::Mat color;
        ASSERT_TRUE(
            convertRawImage(raw(PixelFormat::kYuv420, w, h, 0, packed), kSource, gray, color));
        EXPECT_EQ(maxDiff(color, ref_color), 0.0);
        EXPECT_EQ(maxDiff(gray, ref_gray), 0.0);
        EXPECT_EQ(rawImageBytes(PixelFormat::kYuv420, w, h, 0), packed.size());
    }
    // One buffer, Y stride 20, chroma stride 10.
    const std::size_t stride = 20;
    std::vector<std::uint8_t> one;
    putRows(y, uh, uw, stride, one);
    putRows(u, uh / 2, uw / 2, stride / 2, one);
    putRows(v, uh / 2, uw / 2, stride / 2, one);
    one.resize(one.size() - (stride / 2 - uw / 2));  // the last row need not be padded
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuv420, w, h, stride), one.size());
    {
        cv::Mat gray;
        cv::Mat color;
        auto ok =
            convertRawImage(raw(PixelFormat::kYuv420, w, h, stride, one), kSource, gray, color);
        ASSERT_TRUE(ok) << ok.error().message;
        EXPECT_EQ(maxDiff(color, ref_color), 0.0);
        EXPECT_EQ(maxDiff(gray, ref_gray), 0.0);
        one.pop_back();
        auto short_one =
            convertRawImage(raw(PixelFormat::kYuv420, w, h, stride, one), kSource, gray, color);
        ASSERT_FALSE(short_one);
        EXPECT_EQ(short_one.error().code, ErrorCode::kIo);
    }
    // Three planes apart, each with its own stride.
    std::vector<std::uint8_t> yp;
    std::vector<std::uint8_t> up;
    std::vector<std::uint8_t> vp;
    putRows(y, uh, uw, stride, yp);
    putRows(u, uh / 2, uw / 2, 8, up);
    putRows(v, uh / 2, uw / 2, 16, vp);
    RawImage apart = raw(PixelFormat::kYuv420, w, h, stride, yp);
    apart.chroma[0] = {up.data(), 8, up.size()};
    apart.chroma[1] = {vp.data(), 16, vp.size()};
    cv::Mat gray;
    cv::Mat color;
    auto ok = convertRawImage(apart, kSource, gray, color);
    ASSERT_TRUE(ok) << ok.error().message;
    EXPECT_EQ(maxDiff(color, ref_color), 0.0);  // U and V not swapped
    EXPECT_EQ(maxDiff(gray, ref_gray), 0.0);
    apart.chroma[1].size_bytes = 16 * (uh / 2 - 1) + uw / 2 - 1;
    auto short_v = convertRawImage(apart, kSource, gray, color);
    ASSERT_FALSE(short_v);
    EXPECT_EQ(short_v.error().code, ErrorCode::kIo);
    EXPECT_NE(short_v.error().message.find("plane 2"), std::string::npos)
        << short_v.error().message;
    apart.chroma[1].size_bytes = vp.size();
    apart.chroma[1].stride_bytes = 4;  // shorter than a chroma row
    EXPECT_FALSE(convertRawImage(apart, kSource, gray, color));
}

// NV12 with its CbCr plane apart (libcamera's two-plane buffers), with the Y
// stride or another one: the same as the V4L2 single-buffer layout.
TEST(PixelConvert, Nv12ChromaPlaneApart) {
    const int w = 12;
    const int h = 8;
    const auto uw = static_cast<std::size_t>(w);
    const auto uh = static_cast<std::size_t>(h);
    const std::vector<std::uint8_t> i420 = i420Of(colourPicture(w, h));
    std::vector<std::uint8_t> uv;
    const std::size_t nc = (uw / 2) * (uh / 2);
    for (std::size_t i = 0; i < nc; ++i) {
        uv.push_back(i420[uw * uh + i]);
        uv.push_back(i420[uw * uh + nc + i]);
    }
    std::vector<std::uint8_t> together(i420.begin(),
                                       i420.begin() + static_cast<std::ptrdiff_t>(uw * uh));
    together.insert(together.end(), uv.begin(), uv.end());
    cv::Mat ref_gray;
    cv::Mat ref_color;
    ASSERT_TRUE(
        convertRawImage(raw(PixelFormat::kNv12, w, h, 0, together), kSource, ref_gray, ref_color));
    const std::vector<std::uint8_t> y(together.begin(),
                                      together.begin() + static_cast<std::ptrdiff_t>(uw * uh));
    for (const std::size_t uv_stride : {uw, uw + 6}) {
        const auto uvp = withStride(uv, uw, uv_stride);
        RawImage image = raw(PixelFormat::kNv12, w, h, 0, y);
        image.chroma[0] = {uvp.data(), uv_stride, uvp.size()};
        cv::Mat gray;
        cv::Mat color;
        auto ok = convertRawImage(image, kSource, gray, color);
        ASSERT_TRUE(ok) << ok.error().message;
        EXPECT_EQ(maxDiff(color, ref_color), 0.0) << uv_stride;
        EXPECT_EQ(maxDiff(gray, ref_gray), 0.0) << uv_stride;
    }
}

TEST(PixelConvert, ShortBufferIsAnIoErrorNamingTheSource) {
    const int w = 8;
    const int h = 6;
    std::vector<std::uint8_t> d = yuyvPixels(w, h);
    // One byte short. (pop_back, not resize(size - 1): GCC 12 at -O1 with
    // ASan cannot see that the size is positive and warns about the resize.)
    ASSERT_FALSE(d.empty());
    d.pop_back();
    cv::Mat gray;
    cv::Mat color;
    auto r = convertRawImage(raw(PixelFormat::kYuyv, w, h, 0, d), kSource, gray, color);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_NE(r.error().message.find(kSource), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("short"), std::string::npos) << r.error().message;
}

TEST(PixelConvert, BadDescriptionsAreRejected) {
    const std::vector<std::uint8_t> d(1024, 128);
    cv::Mat gray;
    cv::Mat color;
    auto odd = convertRawImage(raw(PixelFormat::kYuyv, 7, 4, 0, d), kSource, gray, color);
    ASSERT_FALSE(odd);
    EXPECT_EQ(odd.error().code, ErrorCode::kInvalidArgument);
    auto narrow = convertRawImage(raw(PixelFormat::kYuyv, 8, 4, 10, d), kSource, gray, color);
    ASSERT_FALSE(narrow);
    EXPECT_EQ(narrow.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(narrow.error().message.find("stride"), std::string::npos);
    auto odd_nv12 = convertRawImage(raw(PixelFormat::kNv12, 8, 5, 0, d), kSource, gray, color);
    ASSERT_FALSE(odd_nv12);
    auto autofmt = convertRawImage(raw(PixelFormat::kAuto, 8, 4, 0, d), kSource, gray, color);
    ASSERT_FALSE(autofmt);
    EXPECT_EQ(autofmt.error().code, ErrorCode::kInvalidArgument);
}

cv::Mat testPicture(int w, int h) {
    cv::Mat img(h, w, CV_8UC3);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            img.at<cv::Vec3b>(y, x) =
                cv::Vec3b(static_cast<std::uint8_t>(4 * x), static_cast<std::uint8_t>(5 * y),
                          static_cast<std::uint8_t>(x < w / 2 ? 220 : 30));
        }
    }
    return img;
}

TEST(PixelConvert, MjpegDecodes) {
    const cv::Mat picture = testPicture(64, 48);
    std::vector<std::uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", picture, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95}));
    cv::Mat gray;
    cv::Mat color;
    auto ok = convertRawImage(raw(PixelFormat::kMjpeg, 64, 48, 0, jpeg), kSource, gray, color);
    ASSERT_TRUE(ok) << ok.error().message;
    ASSERT_EQ(color.type(), CV_8UC3);
    ASSERT_EQ(color.size(), cv::Size(64, 48));
    EXPECT_EQ(maxDiff(color, cv::imdecode(jpeg, cv::IMREAD_COLOR)), 0.0);
    EXPECT_LT(cv::norm(color, picture, cv::NORM_L1) / (64.0 * 48 * 3), 4.0);  // lossy, but close
    cv::Mat ref_gray;
    cv::cvtColor(color, ref_gray, cv::COLOR_BGR2GRAY);
    EXPECT_EQ(maxDiff(gray, ref_gray), 0.0);
}

TEST(PixelConvert, MjpegOfAnotherSizeIsAnError) {
    std::vector<std::uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", testPicture(64, 48), jpeg));
    cv::Mat gray;
    cv::Mat color;
    auto r = convertRawImage(raw(PixelFormat::kMjpeg, 32, 24, 0, jpeg), kSource, gray, color);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_NE(r.error().message.find("64x48"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("32x24"), std::string::npos) << r.error().message;
}

TEST(PixelConvert, CorruptMjpegIsAnErrorNamingTheDeviceAndBuffer) {
    std::vector<std::uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", testPicture(64, 48), jpeg));
    // No start-of-image marker and a scrambled header: nothing decodes it.
    for (std::size_t i = 0; i < 64 && i < jpeg.size(); ++i) {
        jpeg[i] = static_cast<std::uint8_t>(0x5A ^ i);
    }
    cv::Mat gray;
    cv::Mat color;
    auto r = convertRawImage(raw(PixelFormat::kMjpeg, 64, 48, 0, jpeg), kSource, gray, color);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_NE(r.error().message.find("/dev/video7 (test): buffer 3"), std::string::npos)
        << r.error().message;
    EXPECT_NE(r.error().message.find("MJPEG"), std::string::npos) << r.error().message;

    // The next, good buffer converts: one bad frame is not the end.
    std::vector<std::uint8_t> good;
    ASSERT_TRUE(cv::imencode(".jpg", testPicture(64, 48), good));
    EXPECT_TRUE(convertRawImage(raw(PixelFormat::kMjpeg, 64, 48, 0, good), kSource, gray, color));
}

TEST(PixelConvert, RawImageBytes) {
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuyv, 640, 480, 0), 640U * 2 * 480);
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuyv, 640, 480, 1536), 1536U * 479 + 1280);
    EXPECT_EQ(rawImageBytes(PixelFormat::kGrey, 640, 480, 0), 640U * 480);
    EXPECT_EQ(rawImageBytes(PixelFormat::kNv12, 640, 480, 0), 640U * 720);
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuv420, 640, 480, 0), 640U * 720);
    // Chroma rows at half the Y stride; the last row unpadded.
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuv420, 640, 480, 768), 768U * 480 + 384U * 479 + 320);
    EXPECT_EQ(rawImageBytes(PixelFormat::kRgb888, 640, 480, 0), 640U * 3 * 480);
    EXPECT_EQ(rawImageBytes(PixelFormat::kXbgr8888, 640, 480, 0), 640U * 4 * 480);
    EXPECT_EQ(rawImageBytes(PixelFormat::kMjpeg, 640, 480, 0), 0U);
    EXPECT_EQ(rawImageBytes(PixelFormat::kYuyv, 0, 480, 0), 0U);
}

}  // namespace
}  // namespace scaled::drivers::camera
