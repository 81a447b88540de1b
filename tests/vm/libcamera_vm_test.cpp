// The libcamera driver against a real pipeline: vimc (the kernel's virtual
// media controller driver) inside the test VM (tests/vm/run-vm.sh), where
// libcamera 0.0.3 lists one camera, "platform/vimc.0 Sensor B", whose
// viewfinder turns 640x480 into 636x480. Runs only with SCALED_VM=1 (else
// every test skips); in the VM a missing camera fails.

#include <cstdint>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/libcamera/libcamera_camera.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;

constexpr const char* kVimcId = "platform/vimc.0 Sensor B";

bool inVm() {
    const char* vm = std::getenv("SCALED_VM");
    return vm != nullptr && std::string(vm) == "1";
}

#define REQUIRE_VM()                                                                    \
    do {                                                                                \
        if (!inVm()) {                                                                  \
            GTEST_SKIP() << "runs inside the VM (tests/vm/run-vm.sh) with SCALED_VM=1"; \
        }                                                                               \
    } while (false)

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

camera::CameraOptions vimcOptions(const std::string& device) {
    camera::CameraOptions options;
    options.device = device;
    options.width_px = 640;
    options.height_px = 480;
    options.fps = 30;
    options.buffers = 4;
    // The VM emulates its CPU (no KVM): vimc's test pattern comes slowly.
    options.frame_timeout_s = 20;
    return options;
}

std::unique_ptr<camera::LiveCamera> openOrFail(const std::string& device) {
    auto opened = openLibcameraCamera(vimcOptions(device));
    EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
    return opened.ok() ? std::move(*opened) : nullptr;
}

int64_t monotonicNowNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Reads `count` frames and checks each; updates the last id and timestamp.
void expectFrames(camera::LiveCamera& camera, int count, int64_t& last_id, int64_t& last_t_ns) {
    for (int i = 0; i < count; ++i) {
        source::Frame frame;
        auto got = camera.next(frame);
        ASSERT_TRUE(got.ok()) << got.error().message;
        ASSERT_TRUE(*got);
        EXPECT_EQ(frame.id, last_id + 1);
        EXPECT_GT(frame.t_ns, last_t_ns);
        // CLOCK_MONOTONIC: in the past, and recent (generous: emulated CPU).
        const int64_t now_ns = monotonicNowNs();
        EXPECT_LE(frame.t_ns, now_ns);
        EXPECT_GT(frame.t_ns, now_ns - 60'000'000'000);
        last_id = frame.id;
        last_t_ns = frame.t_ns;
        ASSERT_EQ(frame.gray.type(), CV_8UC1);
        ASSERT_EQ(frame.color.type(), CV_8UC3);
        EXPECT_EQ(frame.gray.cols, 636);
        EXPECT_EQ(frame.gray.rows, 480);
        EXPECT_EQ(frame.color.size(), frame.gray.size());
        // vimc's test pattern (colour bars): far from uniform.
        double lo = 0;
        double hi = 0;
        cv::minMaxLoc(frame.gray, &lo, &hi);
        EXPECT_GT(hi - lo, 50) << "frame " << frame.id;
        cv::Scalar mean;
        cv::Scalar stddev;
        cv::meanStdDev(frame.color, mean, stddev);
        EXPECT_GT(stddev[0] + stddev[1] + stddev[2], 10) << "frame " << frame.id;
    }
}

// vimc's pattern: eight vertical bars, white, yellow, cyan, green, magenta,
// red, blue, black; its bottom rows are free of the text overlay. Checks the
// byte order of the format the driver chose.
void expectColourBars(const cv::Mat& bgr) {
    ASSERT_FALSE(bgr.empty());
    const int y = bgr.rows - 8;
    const auto bar = [&](int index) {
        const int x = (2 * index + 1) * bgr.cols / 16;
        return bgr.at<cv::Vec3b>(y, x);
    };
    const auto high = [](std::uint8_t v) { return v > 150; };
    const auto low = [](std::uint8_t v) { return v < 80; };
    const cv::Vec3b yellow = bar(1);
    const cv::Vec3b red = bar(5);
    const cv::Vec3b blue = bar(6);
    EXPECT_TRUE(low(yellow[0]) && high(yellow[1]) && high(yellow[2])) << "yellow bar: " << yellow;
    EXPECT_TRUE(low(red[0]) && low(red[1]) && high(red[2])) << "red bar: " << red;
    EXPECT_TRUE(high(blue[0]) && low(blue[1]) && low(blue[2])) << "blue bar: " << blue;
}

TEST(LibcameraVm, ListShowsVimc) {
    REQUIRE_VM();
    const std::vector<camera::CameraDescription> cameras = listLibcameraCameras();
    ASSERT_FALSE(cameras.empty()) << "libcamera lists no camera (vimc loaded? udev markers?)";
    bool found = false;
    for (const camera::CameraDescription& camera : cameras) {
        EXPECT_EQ(camera.backend, "libcamera");
        if (contains(camera.device, kVimcId)) {
            found = true;
            EXPECT_FALSE(camera.formats.empty()) << camera.note;
            EXPECT_TRUE(camera.note.empty()) << camera.note;
        }
    }
    EXPECT_TRUE(found);
}

TEST(LibcameraVm, CapturesTenFramesByIndex) {
    REQUIRE_VM();
    auto camera = openOrFail("0");
    ASSERT_NE(camera, nullptr);
    EXPECT_TRUE(contains(camera->describe(), kVimcId)) << camera->describe();
    EXPECT_TRUE(contains(camera->mode(), "636x480")) << camera->mode();
    bool noted = false;
    for (const std::string& note : camera->info().notes) {
        noted = noted || (contains(note, "640x480") && contains(note, "636x480"));
    }
    EXPECT_TRUE(noted) << "no note about the adjusted size";
    int64_t last_id = -1;
    int64_t last_t_ns = 0;
    expectFrames(*camera, 10, last_id, last_t_ns);
    source::Frame frame;
    auto got = camera->next(frame);
    ASSERT_TRUE(got.ok()) << got.error().message;
    expectColourBars(frame.color);
}

TEST(LibcameraVm, OpensByIdSubstringAndRefusesASecondUser) {
    REQUIRE_VM();
    auto camera = openOrFail("Sensor B");
    ASSERT_NE(camera, nullptr);
    int64_t last_id = -1;
    int64_t last_t_ns = 0;
    expectFrames(*camera, 2, last_id, last_t_ns);

    auto second = openLibcameraCamera(vimcOptions(kVimcId));
    ASSERT_FALSE(second.ok());
    EXPECT_EQ(second.error().code, ErrorCode::kUnavailable);
    EXPECT_TRUE(contains(second.error().message, "camera busy")) << second.error().message;
    EXPECT_TRUE(contains(second.error().message, kVimcId)) << second.error().message;

    // The first one is not disturbed by the refused open.
    expectFrames(*camera, 2, last_id, last_t_ns);
}

TEST(LibcameraVm, StopThenReopenDeliversAgain) {
    REQUIRE_VM();
    auto camera = openOrFail("0");
    ASSERT_NE(camera, nullptr);
    int64_t last_id = -1;
    int64_t last_t_ns = 0;
    expectFrames(*camera, 3, last_id, last_t_ns);

    camera->stop();
    source::Frame frame;
    auto stopped = camera->next(frame);
    ASSERT_TRUE(stopped.ok()) << stopped.error().message;
    EXPECT_FALSE(*stopped);

    auto reopened = camera->reopen();
    ASSERT_TRUE(reopened.ok()) << reopened.error().message;
    // Ids go on counting and timestamps keep increasing across the reopen.
    expectFrames(*camera, 3, last_id, last_t_ns);
    EXPECT_EQ(last_id, 5);
}

TEST(LibcameraVm, UnknownIdListsTheCameras) {
    REQUIRE_VM();
    auto opened = openLibcameraCamera(vimcOptions("no such camera"));
    ASSERT_FALSE(opened.ok());
    EXPECT_EQ(opened.error().code, ErrorCode::kNotFound);
    EXPECT_TRUE(contains(opened.error().message, kVimcId)) << opened.error().message;
    auto index = openLibcameraCamera(vimcOptions("9"));
    ASSERT_FALSE(index.ok());
    EXPECT_EQ(index.error().code, ErrorCode::kNotFound);
    EXPECT_TRUE(contains(index.error().message, "index")) << index.error().message;
}

}  // namespace
}  // namespace scaled::drivers::libcam
