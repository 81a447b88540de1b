// What the V4L2 driver does without a camera: pixel format names, option
// checks, open errors (missing node, /dev/null, a regular file, an unknown
// card name), seek, and listV4l2Cameras(). Capture itself is tested in the VM
// (tests/vm/v4l2_vm_test.cpp, vivid).

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <system_error>
#include <temp_dir.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/camera/v4l2_camera.h>

namespace scaled::drivers::camera {
namespace {

using core::ErrorCode;

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

int videoNodeCount() {
    int n = 0;
    std::error_code ec;
    for (std::filesystem::directory_iterator it("/dev", ec);
         !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.size() > 5 && name.compare(0, 5, "video") == 0 &&
            name.find_first_not_of("0123456789", 5) == std::string::npos) {
            ++n;
        }
    }
    return n;
}

TEST(PixelFormatNames, RoundTrip) {
    for (const PixelFormat f :
         {PixelFormat::kAuto, PixelFormat::kYuyv, PixelFormat::kMjpeg, PixelFormat::kGrey,
          PixelFormat::kNv12, PixelFormat::kYuv420, PixelFormat::kRgb888, PixelFormat::kBgr888,
          PixelFormat::kXrgb8888, PixelFormat::kXbgr8888}) {
        PixelFormat parsed = PixelFormat::kAuto;
        ASSERT_TRUE(parsePixelFormat(toString(f), parsed)) << toString(f);
        EXPECT_EQ(parsed, f);
    }
    EXPECT_STREQ(toString(PixelFormat::kMjpeg), "MJPEG");
    EXPECT_STREQ(toString(PixelFormat::kAuto), "auto");
}

// drop_repeated_frames tells a repeated buffer by rawSignature: equal bytes,
// equal signatures; a change of any sampled byte, or of the size, changes it.
TEST(RawSignature, EqualBuffersOnlyShareASignature) {
    std::vector<std::uint8_t> a(640 * 480 * 2);
    for (std::size_t i = 0; i < a.size(); ++i) {
        a[i] = static_cast<std::uint8_t>((i * 7919U) >> 3U);
    }
    const std::vector<std::uint8_t> b = a;
    const std::uint64_t sig = rawSignature(a.data(), a.size());
    EXPECT_EQ(sig, rawSignature(b.data(), b.size()));
    std::vector<std::uint8_t> c = a;
    c[61 * 1000] ^= 1U;  // a sampled byte, one bit
    EXPECT_NE(sig, rawSignature(c.data(), c.size()));
    EXPECT_NE(sig, rawSignature(a.data(), a.size() - 1));
    std::vector<std::uint8_t> black(a.size(), 0);
    std::vector<std::uint8_t> grey(a.size(), 1);
    EXPECT_NE(rawSignature(black.data(), black.size()), rawSignature(grey.data(), grey.size()));
    EXPECT_EQ(rawSignature(nullptr, 0), rawSignature(a.data(), 0));
}

TEST(PixelFormatNames, CaseInsensitiveWithV4l2Alias) {
    PixelFormat f = PixelFormat::kAuto;
    ASSERT_TRUE(parsePixelFormat("yuyv", f));
    EXPECT_EQ(f, PixelFormat::kYuyv);
    ASSERT_TRUE(parsePixelFormat("Nv12", f));
    EXPECT_EQ(f, PixelFormat::kNv12);
    ASSERT_TRUE(parsePixelFormat("mjpg", f));
    EXPECT_EQ(f, PixelFormat::kMjpeg);
    ASSERT_TRUE(parsePixelFormat("AUTO", f));
    EXPECT_EQ(f, PixelFormat::kAuto);
}

TEST(PixelFormatNames, UnknownLeavesTheOutputAlone) {
    PixelFormat f = PixelFormat::kGrey;
    EXPECT_FALSE(parsePixelFormat("H264", f));
    EXPECT_FALSE(parsePixelFormat("", f));
    EXPECT_FALSE(parsePixelFormat("yuyv ", f));
    EXPECT_EQ(f, PixelFormat::kGrey);
}

CameraOptions optionsFor(const std::string& device) {
    CameraOptions o;
    o.device = device;
    return o;
}

TEST(V4l2Open, MissingPathIsNotFoundAndNamed) {
    const std::string path = "/dev/video-scaled-test-does-not-exist";
    auto r = openV4l2Camera(optionsFor(path));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    EXPECT_TRUE(contains(r.error().message, path)) << r.error().message;
    EXPECT_TRUE(contains(r.error().message, "no such device")) << r.error().message;
}

TEST(V4l2Open, DevNullIsNotAV4l2Device) {
    auto r = openV4l2Camera(optionsFor("/dev/null"));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(r.error().message, "/dev/null: not a V4L2 device")) << r.error().message;
}

TEST(V4l2Open, RegularFileIsNotAV4l2Device) {
    const test::TempDir dir("v4l2");
    const std::filesystem::path file = dir.path() / "video0";
    std::ofstream(file) << "not a camera\n";
    auto r = openV4l2Camera(optionsFor(file.string()));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(r.error().message, file.string() + ": not a V4L2 device"))
        << r.error().message;
    EXPECT_TRUE(contains(r.error().message, "regular file")) << r.error().message;
}

TEST(V4l2Open, DirectoryIsNotAV4l2Device) {
    const test::TempDir dir("v4l2");
    auto r = openV4l2Camera(optionsFor(dir.path().string()));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(r.error().message, "directory")) << r.error().message;
}

TEST(V4l2Open, UnknownCardNameIsNotFoundAndSaysWhatExists) {
    const std::string name = "No Such Camera 7f3a";
    auto r = openV4l2Camera(optionsFor(name));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kNotFound);
    const std::string& msg = r.error().message;
    EXPECT_TRUE(contains(msg, "camera \"" + name + "\"")) << msg;
    if (videoNodeCount() == 0) {
        EXPECT_TRUE(contains(msg, "there is no /dev/video* node")) << msg;
    } else {
        EXPECT_TRUE(contains(msg, "capture devices: ") || contains(msg, "no capture device among"))
            << msg;
    }
}

TEST(V4l2Open, InvalidOptionsAreRejectedBeforeTouchingTheDevice) {
    CameraOptions o = optionsFor("/dev/null");
    o.buffers = 1;
    auto r = openV4l2Camera(o);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(r.error().message, "buffers")) << r.error().message;

    o = optionsFor("/dev/null");
    o.fps = 0;
    r = openV4l2Camera(o);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.error().message, "frame rate")) << r.error().message;

    o = optionsFor("/dev/null");
    o.frame_timeout_s = -1;
    r = openV4l2Camera(o);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.error().message, "timeout")) << r.error().message;

    o = optionsFor("/dev/null");
    o.width_px = 0;
    r = openV4l2Camera(o);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.error().message, "size")) << r.error().message;

    r = openV4l2Camera(optionsFor(""));
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
}

// LiveCamera::seek is the same for every backend.
class NamedCamera final : public LiveCamera {
public:
    [[nodiscard]] const source::SequenceInfo& info() const override { return info_; }
    core::Result<bool> next(source::Frame& /*frame*/) override { return false; }
    [[nodiscard]] std::string describe() const override { return "/dev/video9 (fake)"; }
    [[nodiscard]] std::string mode() const override { return "YUYV 640x480 @ 30"; }
    core::Result<bool> reopen() override { return true; }
    void stop() override {}

private:
    source::SequenceInfo info_;
};

TEST(LiveCameraSeek, IsAnInvalidArgumentNamingTheCamera) {
    NamedCamera camera;
    auto r = camera.seek(0);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_TRUE(contains(r.error().message, "a live camera cannot seek")) << r.error().message;
    EXPECT_TRUE(contains(r.error().message, "/dev/video9 (fake)")) << r.error().message;
}

TEST(V4l2List, NeverFailsAndListsOnlyVideoNodes) {
    const auto cameras = listV4l2Cameras();
    EXPECT_LE(static_cast<int>(cameras.size()), videoNodeCount());
    for (const CameraDescription& c : cameras) {
        EXPECT_EQ(c.backend, "v4l2");
        EXPECT_EQ(c.device.rfind("/dev/video", 0), 0U) << c.device;
        // A node is either described (a card name) or explained (a note).
        EXPECT_TRUE(!c.name.empty() || !c.note.empty()) << c.device;
    }
}

}  // namespace
}  // namespace scaled::drivers::camera
