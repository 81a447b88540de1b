// vivid_feed: plays a recorded sequence into the kernel's vivid video OUTPUT
// and loops it back to vivid's capture (its "Loop Video" control, as a cable
// from an HDMI output to an HDMI input), so that a V4L2 client of the capture
// device, the daemon, sees the sequence's real pixels through a real kernel
// driver. For the VM test vm.daemon_loop (daemon_loop_vm_test.sh).
//
//   vivid_feed gravity DATASET
//       prints the first frame's gravity (down, camera frame) from the
//       dataset's gravity and ground truth: "down_C X Y Z"
//   vivid_feed play DATASET FRAMES FPS HOLD_FILE STOP_FILE
//       sets both sides up (HDMI input and output, 640x480p59.94, YUYV, Loop
//       Video on, OSD text off), shows the first frame until HOLD_FILE
//       exists (a camera at rest while its client starts: one bit of one
//       pixel flipped every other period, a sensor's noise), then the first
//       FRAMES frames in order, each for round(59.94 / FPS) output periods;
//       prints "frame K queued at T ns" (CLOCK_MONOTONIC) when frame K's
//       first buffer is queued, "played N frames" after the last, shows the last
//       frame until STOP_FILE exists, and puts vivid back (input and output
//       0, Loop Video off, OSD on).
//
// FPS is a rate the emulated machine can track (TCG: 0.75 to 1.5 frames a
// second), not the sequence's 30 Hz: the motion between consecutive frames
// is the sequence's, only slower in time. The capture runs at 59.94 Hz, so
// it copies each frame several times; the daemon's
// camera.drop_repeated_frames keeps the first copy (its timestamp is when the
// frame appeared) and drops the rest.
// Pixels: Y is the sequence's grey image exactly (what the daemon tracks is
// what a replay tracks), Cb/Cr from BT.601. Exit: 0 done, 1 error (named),
// 2 usage.

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <linux/v4l2-dv-timings.h>
#include <linux/videodev2.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>
#include <vector>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 640;
constexpr int kHeight = 480;
// vivid's private controls (VIVID_CID_*: drivers/media/test-drivers/vivid,
// the "Vivid" class), as `v4l2-ctl -l` lists them.
constexpr std::uint32_t kCidOsdTextMode = 0x00f0f001;  // 2: none
constexpr std::uint32_t kCidLoopVideo = 0x00f0f025;

std::int64_t monotonicNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

int fail(const std::string& what) {
    std::fprintf(stderr, "vivid_feed: %s\n", what.c_str());
    return 1;
}

std::string errnoText(const char* call) {
    return std::string(call) + ": " + std::strerror(errno);
}

int xioctl(int fd, unsigned long request, void* arg) {
    int r = 0;
    do {
        r = ::ioctl(fd, request, arg);
    } while (r < 0 && errno == EINTR);
    return r;
}

// /dev/videoN of the node whose sysfs name is `name` ("vivid-000-vid-out").
std::string nodeNamed(const std::string& name) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator("/sys/class/video4linux", ec)) {
        std::ifstream in(e.path() / "name");
        std::string n;
        std::getline(in, n);
        if (n == name) {
            return "/dev/" + e.path().filename().string();
        }
    }
    return {};
}

// 640x480p59.94 (CEA-861), the one 640x480 progressive timing vivid takes
// (custom timings must be CVT or GTF, and those cannot go below vivid's
// 14 MHz pixel clock at 640x480: no slow custom rate).
constexpr double kOutputHz = 59.94;
v4l2_dv_timings outputTimings() {
    const v4l2_dv_timings t = V4L2_DV_BT_CEA_640X480P59_94;
    return t;
}

// Selects the HDMI input (capture) or output and sets the timings.
bool selectHdmi(int fd, bool output, const v4l2_dv_timings& timings, std::string& why) {
    for (std::uint32_t i = 0; i < 16; ++i) {
        char name[32] = {};
        if (output) {
            v4l2_output o{};
            o.index = i;
            if (xioctl(fd, VIDIOC_ENUMOUTPUT, &o) != 0) {
                break;
            }
            std::memcpy(name, o.name, sizeof name - 1);
        } else {
            v4l2_input in{};
            in.index = i;
            if (xioctl(fd, VIDIOC_ENUMINPUT, &in) != 0) {
                break;
            }
            std::memcpy(name, in.name, sizeof name - 1);
        }
        if (std::strncmp(name, "HDMI", 4) != 0) {
            continue;
        }
        int index = static_cast<int>(i);
        if (xioctl(fd, output ? VIDIOC_S_OUTPUT : VIDIOC_S_INPUT, &index) != 0) {
            why = errnoText(output ? "VIDIOC_S_OUTPUT" : "VIDIOC_S_INPUT");
            return false;
        }
        v4l2_dv_timings t = timings;
        if (xioctl(fd, VIDIOC_S_DV_TIMINGS, &t) != 0) {
            why = errnoText("VIDIOC_S_DV_TIMINGS");
            return false;
        }
        return true;
    }
    why = std::string("no HDMI ") + (output ? "output" : "input");
    return false;
}

bool setControl(int fd, std::uint32_t id, int value, std::string& why) {
    v4l2_control c{};
    c.id = id;
    c.value = value;
    if (xioctl(fd, VIDIOC_S_CTRL, &c) != 0) {
        why = errnoText("VIDIOC_S_CTRL");
        return false;
    }
    return true;
}

// The frame as YUYV: Y the grey image, Cb/Cr (BT.601) averaged over each pair.
void toYuyv(const scaled::drivers::source::Frame& f, std::uint8_t* out) {
    for (int y = 0; y < kHeight; ++y) {
        const auto* g = f.gray.ptr<std::uint8_t>(y);
        const auto* c = f.color.ptr<cv::Vec3b>(y);
        std::uint8_t* o = out + static_cast<std::ptrdiff_t>(y) * kWidth * 2;
        for (std::ptrdiff_t x = 0; x < kWidth; x += 2) {
            double cb = 0;
            double cr = 0;
            for (std::ptrdiff_t k = 0; k < 2; ++k) {
                const double b = c[x + k][0];
                const double gg = c[x + k][1];
                const double r = c[x + k][2];
                cb += 128 - 0.148 * r - 0.291 * gg + 0.439 * b;
                cr += 128 + 0.439 * r - 0.368 * gg - 0.071 * b;
            }
            o[2 * x] = g[x];
            o[2 * x + 1] = static_cast<std::uint8_t>(std::clamp(std::lround(cb / 2), 0L, 255L));
            o[2 * x + 2] = g[x + 1];
            o[2 * x + 3] = static_cast<std::uint8_t>(std::clamp(std::lround(cr / 2), 0L, 255L));
        }
    }
}

// Puts vivid back as the other VM tests expect it: input and output 0, Loop
// Video off, the OSD text on (best effort: the run's result is already made).
void restoreVivid(const std::string& cap_node, const std::string& out_node) {
    std::string why;
    int zero = 0;
    if (const int cap = ::open(cap_node.c_str(), O_RDWR); cap >= 0) {
        setControl(cap, kCidLoopVideo, 0, why);
        setControl(cap, kCidOsdTextMode, 0, why);
        xioctl(cap, VIDIOC_S_INPUT, &zero);
        ::close(cap);
    }
    if (const int out = ::open(out_node.c_str(), O_RDWR); out >= 0) {
        xioctl(out, VIDIOC_S_OUTPUT, &zero);
        ::close(out);
    }
}

int printGravity(const fs::path& dataset) {
    auto src = scaled::drivers::dataset::openDataset(dataset);
    if (!src) {
        return fail(src.error().message);
    }
    scaled::drivers::source::Frame f;
    auto ok = (*src)->next(f);
    if (!ok || !*ok) {
        return fail(dataset.string() + ": no first frame");
    }
    if (!f.gravity_down_C) {
        return fail(dataset.string() + ": no gravity (gravity.txt and ground truth)");
    }
    std::printf("down_C %.6f %.6f %.6f\n", static_cast<double>(f.gravity_down_C->x()),
                static_cast<double>(f.gravity_down_C->y()),
                static_cast<double>(f.gravity_down_C->z()));
    return 0;
}

struct Buffer {
    void* data = MAP_FAILED;
    std::size_t length = 0;
};

int play(const fs::path& dataset, int frames, double fps, const fs::path& hold_file,
         const fs::path& stop_file) {
    auto src = scaled::drivers::dataset::openDataset(dataset);
    if (!src) {
        return fail(src.error().message);
    }
    const std::string cap_node = nodeNamed("vivid-000-vid-cap");
    const std::string out_node = nodeNamed("vivid-000-vid-out");
    if (cap_node.empty() || out_node.empty()) {
        return fail("no vivid-000-vid-cap / vivid-000-vid-out node (vivid not loaded?)");
    }
    const v4l2_dv_timings timings = outputTimings();
    // Each frame is shown for `repeat` output periods: FPS frames a second.
    const int repeat = std::max(1, static_cast<int>(std::lround(kOutputHz / fps)));
    std::string why;
    {
        const int cap = ::open(cap_node.c_str(), O_RDWR);
        if (cap < 0) {
            return fail(cap_node + ": " + errnoText("open"));
        }
        const bool ok = selectHdmi(cap, false, timings, why) &&
                        setControl(cap, kCidLoopVideo, 1, why) &&
                        setControl(cap, kCidOsdTextMode, 2, why);
        ::close(cap);
        if (!ok) {
            return fail(cap_node + ": " + why);
        }
    }
    const int out = ::open(out_node.c_str(), O_RDWR);
    if (out < 0) {
        return fail(out_node + ": " + errnoText("open"));
    }
    if (!selectHdmi(out, true, timings, why)) {
        return fail(out_node + ": " + why);
    }
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    fmt.fmt.pix.width = kWidth;
    fmt.fmt.pix.height = kHeight;
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_YUYV;
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (xioctl(out, VIDIOC_S_FMT, &fmt) != 0 || fmt.fmt.pix.width != kWidth ||
        fmt.fmt.pix.height != kHeight || fmt.fmt.pix.pixelformat != V4L2_PIX_FMT_YUYV) {
        return fail(out_node + ": cannot output YUYV 640x480");
    }
    v4l2_requestbuffers req{};
    req.count = 4;
    req.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    req.memory = V4L2_MEMORY_MMAP;
    if (xioctl(out, VIDIOC_REQBUFS, &req) != 0 || req.count < 2) {
        return fail(out_node + ": " + errnoText("VIDIOC_REQBUFS"));
    }
    std::vector<Buffer> bufs(req.count);
    for (std::uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer b{};
        b.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
        b.memory = V4L2_MEMORY_MMAP;
        b.index = i;
        if (xioctl(out, VIDIOC_QUERYBUF, &b) != 0) {
            return fail(out_node + ": " + errnoText("VIDIOC_QUERYBUF"));
        }
        bufs[i].length = b.length;
        bufs[i].data =
            ::mmap(nullptr, b.length, PROT_READ | PROT_WRITE, MAP_SHARED, out, b.m.offset);
        if (bufs[i].data == MAP_FAILED || b.length < kWidth * kHeight * 2) {
            return fail(out_node + ": " + errnoText("mmap"));
        }
    }

    // Frames in order, each converted to YUYV once: the one shown and the
    // next, read and converted while the one shown repeats (an emulated CPU
    // decodes a JPEG in tens of ms; the output must be fed every 1/59.94 s,
    // and the queued buffers cover a few periods only).
    const std::size_t yuyv_bytes = static_cast<std::size_t>(kWidth) * kHeight * 2;
    std::vector<std::uint8_t> shown_yuyv(yuyv_bytes);
    std::vector<std::uint8_t> next_yuyv(yuyv_bytes);
    scaled::drivers::source::Frame frame;
    if (auto ok = (*src)->next(frame); !ok || !*ok) {
        return fail(dataset.string() + ": no first frame");
    }
    if (frame.gray.cols != kWidth || frame.gray.rows != kHeight) {
        return fail(dataset.string() + ": frames are not 640x480");
    }
    toYuyv(frame, shown_yuyv.data());
    int played = 1;  // sequence frames started (the first is shown from the start)
    int held = 0;    // periods the first frame was shown before HOLD_FILE
    int shown = 0;   // periods the current frame was shown
    bool have_next = false;
    bool released = false;  // HOLD_FILE seen
    bool dither = false;    // while holding: flip one bit of the first pixel's Y
    bool done = false;
    // Reads and converts the next frame while the current one repeats.
    auto prepare = [&](std::string& err) -> bool {
        if (have_next || played >= frames) {
            return true;
        }
        auto ok = (*src)->next(frame);
        if (!ok || !*ok) {
            err = ok ? "the sequence ended after " + std::to_string(played) + " frames"
                     : ok.error().message;
            return false;
        }
        toYuyv(frame, next_yuyv.data());
        have_next = true;
        return true;
    };
    // The pixels of the next output period; nullptr once STOP_FILE exists
    // after the last frame (or on an error, in err).
    auto pick = [&](std::string& err) -> const std::uint8_t* {
        if (!released) {
            released = fs::exists(hold_file);
            if (!released) {
                // A camera at rest: the first frame with a sensor's noise (one
                // pixel's least significant bit, every other period), so that
                // its client sees images come at the capture's rate, not one
                // image and then nothing until the sequence starts.
                ++held;
                dither = (held % 2) == 1;
                return shown_yuyv.data();
            }
            dither = false;
        }
        if (shown < repeat) {
            ++shown;
            return shown_yuyv.data();
        }
        if (played < frames) {
            if (!prepare(err)) {
                return nullptr;
            }
            std::swap(shown_yuyv, next_yuyv);
            have_next = false;
            ++played;
            shown = 1;
            // When the frame was queued: the output shows it after the
            // buffers queued before it, the capture copies it after that.
            std::printf("frame %d queued at %lld ns\n", played - 1,
                        static_cast<long long>(monotonicNs()));
            std::fflush(stdout);
            return shown_yuyv.data();
        }
        // Done: say so once, then keep showing the last frame (vivid keeps the
        // last buffer shown; without a next one the capture would fall back
        // to its test pattern) until STOP_FILE exists.
        if (!done) {
            done = true;
            std::printf(
                "played %d frames at %g fps (%d output periods of 1/%g s each; the first "
                "held for %d more periods)\n",
                played, kOutputHz / repeat, repeat, kOutputHz, held);
            std::fflush(stdout);
        }
        return fs::exists(stop_file) ? nullptr : shown_yuyv.data();
    };
    auto queue = [&](std::uint32_t index, const std::uint8_t* pixels) -> bool {
        std::memcpy(bufs[index].data, pixels, yuyv_bytes);
        if (dither) {
            static_cast<std::uint8_t*>(bufs[index].data)[0] ^= 1U;
        }
        v4l2_buffer b{};
        b.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
        b.memory = V4L2_MEMORY_MMAP;
        b.index = index;
        b.bytesused = static_cast<std::uint32_t>(yuyv_bytes);
        b.field = V4L2_FIELD_NONE;
        return xioctl(out, VIDIOC_QBUF, &b) == 0;
    };
    std::uint32_t queued = 0;
    for (std::uint32_t i = 0; i < req.count; ++i) {
        const std::uint8_t* pixels = pick(why);
        if (pixels == nullptr) {
            break;
        }
        if (!queue(i, pixels)) {
            return fail(out_node + ": " + errnoText("VIDIOC_QBUF"));
        }
        ++queued;
    }
    int type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    if (xioctl(out, VIDIOC_STREAMON, &type) != 0) {
        return fail(out_node + ": " + errnoText("VIDIOC_STREAMON"));
    }
    std::printf("streaming %s -> %s at %g fps\n", out_node.c_str(), cap_node.c_str(),
                kOutputHz / repeat);
    std::fflush(stdout);
    // Each DQBUF returns a buffer the output has shown (one per 1/59.94 s):
    // it takes the next period's pixels until STOP_FILE; vivid keeps the last
    // buffer shown, so the queue drains to one and STREAMOFF returns it.
    while (queued > 1) {
        v4l2_buffer b{};
        b.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
        b.memory = V4L2_MEMORY_MMAP;
        if (xioctl(out, VIDIOC_DQBUF, &b) != 0) {
            return fail(out_node + ": " + errnoText("VIDIOC_DQBUF"));
        }
        --queued;
        if (const std::uint8_t* pixels = pick(why)) {
            if (!queue(b.index, pixels)) {
                return fail(out_node + ": " + errnoText("VIDIOC_QBUF"));
            }
            ++queued;
        }
        if (!why.empty() || !prepare(why)) {
            break;
        }
    }
    xioctl(out, VIDIOC_STREAMOFF, &type);
    for (auto& b : bufs) {
        ::munmap(b.data, b.length);
    }
    ::close(out);
    restoreVivid(cap_node, out_node);
    if (!why.empty()) {
        return fail(dataset.string() + ": " + why);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    const std::vector<std::string> a(argv + 1, argv + argc);
    if (a.size() == 2 && a[0] == "gravity") {
        return printGravity(a[1]);
    }
    if (a.size() == 6 && a[0] == "play") {
        char* end_frames = nullptr;
        char* end_fps = nullptr;
        const long frames = std::strtol(a[2].c_str(), &end_frames, 10);
        const double fps = std::strtod(a[3].c_str(), &end_fps);
        if (*end_frames != '\0' || *end_fps != '\0' || frames < 1 || frames > 100000 ||
            !(fps >= 0.5 && fps <= 30)) {
            return fail("FRAMES must be >= 1 and FPS in [0.5, 30]");
        }
        return play(a[1], static_cast<int>(frames), fps, a[4], a[5]);
    }
    std::fprintf(stderr,
                 "usage: vivid_feed gravity DATASET\n"
                 "       vivid_feed play DATASET FRAMES FPS HOLD_FILE STOP_FILE\n");
    return 2;
}
