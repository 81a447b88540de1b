// The libcamera driver on a host without cameras (the build machines): the
// errors of openLibcameraCamera(), the listing, the shared CameraManager and
// the log-level default; in a build without libcamera, the stub. Capture
// itself is tested in the VM (tests/vm/libcamera_vm_test.cpp, vimc).

#include <cmath>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/libcamera/libcamera_camera.h>

namespace scaled::drivers::libcam {
namespace {

using core::ErrorCode;

bool contains(const std::string& text, const std::string& part) {
    return text.find(part) != std::string::npos;
}

camera::CameraOptions optionsFor(const std::string& device) {
    camera::CameraOptions options;
    options.device = device;
    return options;
}

TEST(LibcameraDriver, AvailabilityMatchesTheBuild) {
#ifdef SCALED_HAVE_LIBCAMERA
    EXPECT_TRUE(libcameraAvailable());
#else
    EXPECT_FALSE(libcameraAvailable());
#endif
}

#ifdef SCALED_HAVE_LIBCAMERA

// The no-camera tests assume a machine without cameras; on one with cameras
// (a developer's Raspberry Pi) they say so and skip.
#define SKIP_IF_CAMERAS()                                                              \
    do {                                                                               \
        if (!listLibcameraCameras().empty()) {                                         \
            GTEST_SKIP() << "this machine has libcamera cameras; the test needs none"; \
        }                                                                              \
    } while (false)

TEST(LibcameraDriver, NoCamerasByIndexOrId) {
    SKIP_IF_CAMERAS();
    for (const std::string device : {"0", "7", "platform/vimc.0 Sensor B", "Sensor B", ""}) {
        auto opened = openLibcameraCamera(optionsFor(device));
        ASSERT_FALSE(opened.ok()) << device;
        EXPECT_EQ(opened.error().code, ErrorCode::kNotFound) << device;
        const std::string& message = opened.error().message;
        EXPECT_TRUE(contains(message, "no cameras")) << message;
        EXPECT_TRUE(contains(message, "libcamera")) << message;
        EXPECT_TRUE(contains(message, "udev")) << message;
        EXPECT_TRUE(contains(message, "\"" + device + "\"")) << message;
    }
}

TEST(LibcameraDriver, ListIsEmptyWithoutCameras) {
    SKIP_IF_CAMERAS();
    // Twice: the CameraManager is stopped after the first listing and a new
    // one started for the second.
    EXPECT_TRUE(listLibcameraCameras().empty());
    EXPECT_TRUE(listLibcameraCameras().empty());
}

TEST(LibcameraDriver, BadOptionsAreRejectedNamingTheCamera) {
    struct Case {
        const char* what;
        camera::CameraOptions options;
    };
    std::vector<Case> cases;
    cases.push_back({"buffers", optionsFor("0")});
    cases.back().options.buffers = 1;
    cases.push_back({"buffers", optionsFor("0")});
    cases.back().options.buffers = 33;
    cases.push_back({"size", optionsFor("0")});
    cases.back().options.width_px = 0;
    cases.push_back({"size", optionsFor("0")});
    cases.back().options.height_px = -480;
    cases.push_back({"frame rate", optionsFor("0")});
    cases.back().options.fps = 0;
    cases.push_back({"frame rate", optionsFor("0")});
    cases.back().options.fps = std::nan("");
    cases.push_back({"timeout", optionsFor("0")});
    cases.back().options.frame_timeout_s = -1;
    for (const Case& c : cases) {
        auto opened = openLibcameraCamera(c.options);
        ASSERT_FALSE(opened.ok()) << c.what;
        EXPECT_EQ(opened.error().code, ErrorCode::kInvalidArgument) << c.what;
        EXPECT_TRUE(contains(opened.error().message, c.what)) << opened.error().message;
        EXPECT_TRUE(contains(opened.error().message, "libcamera camera \"0\""))
            << opened.error().message;
    }
}

TEST(LibcameraDriver, OneCameraManagerAcrossThreads) {
    // libcamera aborts the process when a second CameraManager exists; the
    // driver's shared manager must never make one while another lives, also
    // when several threads list and open at once and managers come and go.
    std::vector<std::thread> threads;
    std::vector<int> failures(4, 0);
    for (std::size_t t = 0; t < failures.size(); ++t) {
        threads.emplace_back([t, &failures] {
            for (int i = 0; i < 5; ++i) {
                (void)listLibcameraCameras();
                auto opened = openLibcameraCamera(optionsFor("nothing-like-this"));
                if (opened.ok() || opened.error().code == ErrorCode::kInvalidArgument) {
                    ++failures[t];
                }
            }
        });
    }
    for (std::thread& thread : threads) {
        thread.join();
    }
    for (const int f : failures) {
        EXPECT_EQ(f, 0);
    }
}

TEST(LibcameraDriver, QuietsLibcameraLogsUnlessTheUserChose) {
    const char* before = std::getenv("LIBCAMERA_LOG_LEVELS");
    const std::string user = before != nullptr ? before : "";
    (void)listLibcameraCameras();
    const char* after = std::getenv("LIBCAMERA_LOG_LEVELS");
    ASSERT_NE(after, nullptr);
    EXPECT_EQ(std::string(after), before != nullptr ? user : std::string("*:ERROR"));
}

#else  // the stub

TEST(LibcameraDriver, StubSaysTheBuildHasNoLibcamera) {
    auto opened = openLibcameraCamera(optionsFor("0"));
    ASSERT_FALSE(opened.ok());
    EXPECT_EQ(opened.error().code, ErrorCode::kUnavailable);
    EXPECT_TRUE(contains(opened.error().message, "no libcamera support")) << opened.error().message;
    EXPECT_TRUE(contains(opened.error().message, "libcamera-dev")) << opened.error().message;
    EXPECT_TRUE(listLibcameraCameras().empty());
}

#endif

}  // namespace
}  // namespace scaled::drivers::libcam
