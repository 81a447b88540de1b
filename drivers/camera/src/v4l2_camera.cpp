#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <filesystem>
#include <functional>
#include <limits>
#include <linux/videodev2.h>
#include <memory>
#include <mutex>
#include <numeric>
#include <optional>
#include <poll.h>
#include <string>
#include <string_view>
#include <sys/eventfd.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/base/unique_fd.h>
#include <scaled/drivers/camera/pixel_convert.h>
#include <scaled/drivers/camera/v4l2_camera.h>

namespace scaled::drivers::camera {
namespace {

using core::ErrorCode;
using core::makeError;

constexpr std::uint32_t kCaptureType = V4L2_BUF_TYPE_VIDEO_CAPTURE;
constexpr int kMinBuffers = 2;
constexpr int kMaxBuffers = 32;

using base::errnoText;

// Every ioctl goes through here: a signal arriving during a blocking driver
// call makes it fail with EINTR, which is not the device's answer.
int xioctl(int fd, unsigned long request, void* arg) {
    int rc = 0;
    do {
        rc = ::ioctl(fd, request, arg);
    } while (rc == -1 && errno == EINTR);
    return rc;
}

std::int64_t monotonicNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// "30", "12.5", "29.97": frame rates as v4l2-ctl prints them.
std::string fpsText(double fps) {
    std::array<char, 32> buf{};
    std::snprintf(buf.data(), buf.size(), "%.2f", fps);
    std::string s(buf.data());
    while (!s.empty() && s.back() == '0') {
        s.pop_back();
    }
    if (!s.empty() && s.back() == '.') {
        s.pop_back();
    }
    return s;
}

std::string secondsText(double s) {
    std::array<char, 32> buf{};
    std::snprintf(buf.data(), buf.size(),
                  std::fabs(s * 10 - std::round(s * 10)) < 1e-9 ? "%.1f" : "%g", s);
    return buf.data();
}

std::string sizeText(std::uint32_t w, std::uint32_t h) {
    return std::to_string(w) + "x" + std::to_string(h);
}

std::string fixedString(const std::uint8_t* text, std::size_t max) {
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    const char* chars = reinterpret_cast<const char*>(text);
    return {chars, ::strnlen(chars, max)};
}

// ---------------------------------------------------------------- formats

std::string fourccText(std::uint32_t fourcc) {
    // Big-endian variants set the top bit of the last character (v4l2_fourcc_be).
    constexpr std::uint32_t kBigEndian = 1U << 31;
    const std::uint32_t code = fourcc & ~kBigEndian;
    std::string s;
    for (int i = 0; i < 4; ++i) {
        const auto c = static_cast<unsigned char>((code >> (8 * i)) & 0xFFU);
        s.push_back(std::isprint(c) != 0 ? static_cast<char>(c) : '?');
    }
    while (!s.empty() && s.back() == ' ') {
        s.pop_back();
    }
    if ((fourcc & kBigEndian) != 0) {
        s += "-BE";
    }
    return s;
}

// The fourccs a PixelFormat stands for. Some webcams call their MJPEG "JPEG".
std::vector<std::uint32_t> fourccsOf(PixelFormat f) {
    switch (f) {
        case PixelFormat::kYuyv:
            return {V4L2_PIX_FMT_YUYV};
        case PixelFormat::kNv12:
            return {V4L2_PIX_FMT_NV12};
        case PixelFormat::kGrey:
            return {V4L2_PIX_FMT_GREY};
        case PixelFormat::kMjpeg:
            return {V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_JPEG};
        case PixelFormat::kAuto:
        // libcamera's buffer formats: this driver does not negotiate them.
        case PixelFormat::kYuv420:
        case PixelFormat::kRgb888:
        case PixelFormat::kBgr888:
        case PixelFormat::kXrgb8888:
        case PixelFormat::kXbgr8888:
            break;
    }
    return {};
}

constexpr std::array<PixelFormat, 4> kAutoOrder = {PixelFormat::kYuyv, PixelFormat::kNv12,
                                                   PixelFormat::kGrey, PixelFormat::kMjpeg};

std::optional<PixelFormat> formatOfFourcc(std::uint32_t fourcc) {
    for (const PixelFormat f : kAutoOrder) {
        const auto codes = fourccsOf(f);
        if (std::find(codes.begin(), codes.end(), fourcc) != codes.end()) {
            return f;
        }
    }
    return std::nullopt;
}

// Our name for the formats we convert ("MJPEG"), the fourcc for the others.
std::string formatName(std::uint32_t fourcc) {
    const auto f = formatOfFourcc(fourcc);
    if (f && fourcc != V4L2_PIX_FMT_JPEG) {
        return toString(*f);
    }
    return fourccText(fourcc);
}

struct FrameSizes {
    enum class Kind : std::uint8_t { kNotListed, kDiscrete, kRange };
    Kind kind = Kind::kNotListed;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> discrete;
    v4l2_frmsize_stepwise range{};  // kRange: stepwise or continuous
    bool continuous = false;
};

struct DeviceFormat {
    std::uint32_t fourcc = 0;
    FrameSizes sizes;
};

FrameSizes enumSizes(int fd, std::uint32_t fourcc) {
    FrameSizes out;
    for (std::uint32_t index = 0; index < 1024; ++index) {
        v4l2_frmsizeenum e{};
        e.index = index;
        e.pixel_format = fourcc;
        if (xioctl(fd, VIDIOC_ENUM_FRAMESIZES, &e) != 0) {
            break;
        }
        if (e.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
            out.kind = FrameSizes::Kind::kDiscrete;
            out.discrete.emplace_back(e.discrete.width, e.discrete.height);
            continue;
        }
        out.kind = FrameSizes::Kind::kRange;
        out.range = e.stepwise;
        out.continuous = e.type == V4L2_FRMSIZE_TYPE_CONTINUOUS;
        break;  // a range is the only entry
    }
    return out;
}

// Every format VIDIOC_ENUM_FMT lists (enumeration stops at the first error:
// EINVAL marks the end, anything else means the list cannot be had).
std::vector<DeviceFormat> enumFormats(int fd) {
    std::vector<DeviceFormat> out;
    for (std::uint32_t index = 0; index < 1024; ++index) {
        v4l2_fmtdesc d{};
        d.index = index;
        d.type = kCaptureType;
        if (xioctl(fd, VIDIOC_ENUM_FMT, &d) != 0) {
            break;
        }
        out.push_back({d.pixelformat, enumSizes(fd, d.pixelformat)});
    }
    return out;
}

enum class Offered : std::uint8_t { kYes, kNo, kUnknown };

Offered offersSize(const FrameSizes& sizes, std::uint32_t w, std::uint32_t h) {
    switch (sizes.kind) {
        case FrameSizes::Kind::kNotListed:
            return Offered::kUnknown;
        case FrameSizes::Kind::kDiscrete:
            return std::find(sizes.discrete.begin(), sizes.discrete.end(), std::make_pair(w, h)) !=
                           sizes.discrete.end()
                       ? Offered::kYes
                       : Offered::kNo;
        case FrameSizes::Kind::kRange: {
            const v4l2_frmsize_stepwise& r = sizes.range;
            const auto fits = [](std::uint32_t v, std::uint32_t lo, std::uint32_t hi,
                                 std::uint32_t step) {
                return v >= lo && v <= hi && (step <= 1 || (v - lo) % step == 0);
            };
            return fits(w, r.min_width, r.max_width, r.step_width) &&
                           fits(h, r.min_height, r.max_height, r.step_height)
                       ? Offered::kYes
                       : Offered::kNo;
        }
    }
    return Offered::kUnknown;
}

std::string sizesText(const FrameSizes& sizes) {
    switch (sizes.kind) {
        case FrameSizes::Kind::kNotListed:
            return "sizes not listed";
        case FrameSizes::Kind::kDiscrete: {
            std::string s;
            for (const auto& [w, h] : sizes.discrete) {
                s += (s.empty() ? "" : " ") + sizeText(w, h);
            }
            return s;
        }
        case FrameSizes::Kind::kRange: {
            const v4l2_frmsize_stepwise& r = sizes.range;
            std::string s =
                sizeText(r.min_width, r.min_height) + " to " + sizeText(r.max_width, r.max_height);
            if (!sizes.continuous && (r.step_width > 1 || r.step_height > 1)) {
                s += " step " + sizeText(r.step_width, r.step_height);
            }
            return s;
        }
    }
    return {};
}

// "YUYV, UYVY, NV12, ..." (every format the device lists).
std::string formatsText(const std::vector<DeviceFormat>& formats) {
    std::string s;
    for (const DeviceFormat& f : formats) {
        s += (s.empty() ? "" : ", ") + formatName(f.fourcc);
    }
    return s.empty() ? "no formats (VIDIOC_ENUM_FMT lists none)" : s;
}

// "YUYV: 320x180 640x480; GREY: ..." for the formats scaled converts.
std::string convertibleSizesText(const std::vector<DeviceFormat>& formats) {
    std::string s;
    for (const DeviceFormat& f : formats) {
        if (formatOfFourcc(f.fourcc)) {
            s += (s.empty() ? "" : "; ") + formatName(f.fourcc) + ": " + sizesText(f.sizes);
        }
    }
    return s;
}

double fpsOf(const v4l2_fract& interval) {
    if (interval.numerator == 0 || interval.denominator == 0) {
        return 0;
    }
    return static_cast<double>(interval.denominator) / static_cast<double>(interval.numerator);
}

struct Intervals {
    std::vector<v4l2_fract> discrete;
    std::optional<v4l2_frmival_stepwise> range;
};

Intervals enumIntervals(int fd, std::uint32_t fourcc, std::uint32_t w, std::uint32_t h) {
    Intervals out;
    for (std::uint32_t index = 0; index < 1024; ++index) {
        v4l2_frmivalenum e{};
        e.index = index;
        e.pixel_format = fourcc;
        e.width = w;
        e.height = h;
        if (xioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &e) != 0) {
            break;
        }
        if (e.type == V4L2_FRMIVAL_TYPE_DISCRETE) {
            out.discrete.push_back(e.discrete);
            continue;
        }
        out.range = e.stepwise;
        break;
    }
    return out;
}

// "25 15 12.5 10" (fastest first, no duplicates), or "1-30" for a range.
std::string intervalsText(const Intervals& iv) {
    if (iv.range) {
        return fpsText(fpsOf(iv.range->max)) + "-" + fpsText(fpsOf(iv.range->min));
    }
    std::vector<double> fps;
    for (const v4l2_fract& f : iv.discrete) {
        if (fpsOf(f) > 0) {
            fps.push_back(fpsOf(f));
        }
    }
    std::sort(fps.begin(), fps.end(), std::greater<>());
    std::string s;
    std::string last;
    for (const double f : fps) {
        const std::string t = fpsText(f);
        if (t != last) {
            s += (s.empty() ? "" : " ") + t;
            last = t;
        }
    }
    return s;
}

// The timeperframe to ask for: 1/fps as a fraction (29.97 -> 100/2997).
v4l2_fract fractionOf(double fps) {
    // Millisecond resolution on the larger side: fps in [0.001, 10000].
    std::uint32_t num = 1000;
    std::uint32_t den = 1000;
    if (fps >= 1) {
        den = static_cast<std::uint32_t>(std::llround(fps * 1000.0));
    } else {
        num = static_cast<std::uint32_t>(std::llround(1000.0 / fps));
    }
    const std::uint32_t g = std::gcd(num, den);
    return {num / g, den / g};
}

// --------------------------------------------------------------- nodes

// /dev/video<N>, in natural order (video2 before video10).
std::vector<std::string> videoNodes() {
    std::vector<std::pair<unsigned long, std::string>> found;
    std::error_code ec;
    std::filesystem::directory_iterator it("/dev", ec);
    for (; !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string();
        const std::string_view prefix = "video";
        if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) {
            continue;
        }
        unsigned long number = 0;
        const char* first = name.data() + prefix.size();
        const char* last = name.data() + name.size();
        const auto [ptr, err] = std::from_chars(first, last, number);
        if (err != std::errc() || ptr != last) {
            continue;
        }
        found.emplace_back(number, it->path().string());
    }
    std::sort(found.begin(), found.end());
    std::vector<std::string> out;
    out.reserve(found.size());
    for (auto& f : found) {
        out.push_back(std::move(f.second));
    }
    return out;
}

std::string permissionHint() {
    return "add the user to the `video` group (usermod -aG video USER, then log in again)";
}

// What open(2) failing with `err` means for a camera node.
core::Error openError(const std::string& path, int err, bool reopening) {
    const std::string why = " (" + errnoText(err) + ")";
    switch (err) {
        case ENOENT:
            return makeError(reopening ? ErrorCode::kUnavailable : ErrorCode::kNotFound,
                             path + ": no such device" + why);
        case ENODEV:
        case ENXIO:
            return makeError(ErrorCode::kUnavailable, path + ": device gone" + why);
        case EACCES:
        case EPERM:
            return makeError(ErrorCode::kIo,
                             path + ": permission denied" + why + ": " + permissionHint());
        case EBUSY:
            return makeError(ErrorCode::kUnavailable,
                             path + ": busy: another program is using it" + why);
        default:
            break;
    }
    return makeError(ErrorCode::kIo, path + ": cannot open" + why);
}

// What an ioctl failing with `err` while setting up means; `who` names the
// device ("/dev/video0 (vivid)").
core::Error ioctlError(const std::string& who, const char* ioctl_name, int err) {
    const std::string why = " (" + std::string(ioctl_name) + ": " + errnoText(err) + ")";
    switch (err) {
        case EBUSY:
            return makeError(ErrorCode::kUnavailable,
                             who + ": busy: another program is using it" + why);
        case ENODEV:
        case ENXIO:
        case EIO:
            return makeError(ErrorCode::kUnavailable, who + ": device lost" + why);
        case EACCES:
        case EPERM:
            return makeError(ErrorCode::kIo,
                             who + ": permission denied" + why + ": " + permissionHint());
        case EPIPE:
            // Media-controller devices (CSI bridges, ISPs) need their
            // pipeline linked and the sensor's format set (media-ctl) first.
            return makeError(ErrorCode::kIo,
                             who +
                                 ": the capture pipeline is not configured: the sensor's "
                                 "format does not match (set it with media-ctl)" +
                                 why);
        default:
            break;
    }
    return makeError(ErrorCode::kIo, who + ":" + why.substr(1, why.size() - 2) + " failed");
}

// device_caps describes the node itself; capabilities the whole driver
// (vivid's card lists capture, output, metadata... on every node).
std::uint32_t nodeCaps(const v4l2_capability& cap) {
    return (cap.capabilities & V4L2_CAP_DEVICE_CAPS) != 0 ? cap.device_caps : cap.capabilities;
}

enum class NodeKind : std::uint8_t { kCapture, kCaptureMplane, kMetadata, kTouch, kOther };

NodeKind kindOf(std::uint32_t caps) {
    // Touch sensors present themselves as video capture devices of
    // V4L2_TCH_FMT_* samples: not cameras.
    if ((caps & V4L2_CAP_TOUCH) != 0) {
        return NodeKind::kTouch;
    }
    if ((caps & V4L2_CAP_VIDEO_CAPTURE) != 0) {
        return NodeKind::kCapture;
    }
    if ((caps & V4L2_CAP_VIDEO_CAPTURE_MPLANE) != 0) {
        return NodeKind::kCaptureMplane;
    }
    if ((caps & V4L2_CAP_META_CAPTURE) != 0) {
        return NodeKind::kMetadata;
    }
    return NodeKind::kOther;
}

// What a node that is not a (single-planar) capture device is, for messages.
std::string kindText(std::uint32_t caps) {
    switch (kindOf(caps)) {
        case NodeKind::kCapture:
            return "a video capture device";
        case NodeKind::kCaptureMplane:
            return "a multi-planar video capture device, which the v4l2 source does not support";
        case NodeKind::kMetadata:
            return "a metadata capture device";
        case NodeKind::kTouch:
            return "a touch sensor";
        case NodeKind::kOther:
            break;
    }
    if ((caps & (V4L2_CAP_VIDEO_M2M | V4L2_CAP_VIDEO_M2M_MPLANE)) != 0) {
        return "a memory-to-memory (codec or converter) device";
    }
    if ((caps & (V4L2_CAP_VIDEO_OUTPUT | V4L2_CAP_VIDEO_OUTPUT_MPLANE)) != 0) {
        return "a video output device";
    }
    if ((caps & V4L2_CAP_META_OUTPUT) != 0) {
        return "a metadata output device";
    }
    if ((caps & (V4L2_CAP_VBI_CAPTURE | V4L2_CAP_SLICED_VBI_CAPTURE)) != 0) {
        return "a VBI capture device";
    }
    if ((caps & V4L2_CAP_SDR_CAPTURE) != 0) {
        return "a software-defined radio";
    }
    std::array<char, 16> hex{};
    std::snprintf(hex.data(), hex.size(), "0x%08x", caps);
    return std::string("a device with capabilities ") + hex.data();
}

// One /dev/video* node, opened and asked VIDIOC_QUERYCAP.
struct NodeProbe {
    std::string path;
    int open_errno = 0;      // open(2) failed
    int querycap_errno = 0;  // open, but VIDIOC_QUERYCAP failed: not V4L2
    std::string card;
    std::string bus;
    std::uint32_t caps = 0;
    base::UniqueFd fd;
};

NodeProbe probeNode(const std::string& path) {
    NodeProbe p;
    p.path = path;
    p.fd.reset(::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC));
    if (!p.fd.isValid()) {
        p.open_errno = errno;
        return p;
    }
    v4l2_capability cap{};
    if (xioctl(p.fd.get(), VIDIOC_QUERYCAP, &cap) != 0) {
        p.querycap_errno = errno;
        return p;
    }
    p.card = fixedString(cap.card, sizeof cap.card);
    p.bus = fixedString(cap.bus_info, sizeof cap.bus_info);
    p.caps = nodeCaps(cap);
    return p;
}

std::string toLower(std::string s) {
    for (char& c : s) {
        c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    }
    return s;
}

std::string openNote(int err) {
    if (err == EACCES || err == EPERM) {
        return "permission denied: " + permissionHint();
    }
    if (err == EBUSY) {
        return "busy";
    }
    return "cannot open: " + errnoText(err);
}

// The /dev/video* nodes probed for findByCard: the single-planar capture
// nodes, and the text naming the others worth mentioning.
struct CaptureNodes {
    std::vector<NodeProbe> capture;
    std::string unchecked;  // nodes that could not be opened, and why
    std::string others;     // multi-planar capture nodes (not supported)
};

// Probes every node in turn (each closed before the next is opened).
CaptureNodes probeCaptureNodes(const std::vector<std::string>& nodes) {
    CaptureNodes found;
    for (const std::string& path : nodes) {
        NodeProbe p = probeNode(path);
        if (p.open_errno != 0) {
            found.unchecked +=
                (found.unchecked.empty() ? "" : ", ") + path + " (" + openNote(p.open_errno) + ")";
            continue;
        }
        if (p.querycap_errno != 0) {
            continue;
        }
        p.fd.reset();
        if (kindOf(p.caps) == NodeKind::kCapture) {
            found.capture.push_back(std::move(p));
        } else if (kindOf(p.caps) == NodeKind::kCaptureMplane) {
            found.others += (found.others.empty() ? "" : ", ") + p.path + " \"" + p.card +
                            "\" (multi-planar: not supported)";
        }
    }
    return found;
}

// `/dev/video0 "card", /dev/video2 "card"`.
std::string cardListing(const std::vector<const NodeProbe*>& list) {
    std::string s;
    for (const NodeProbe* p : list) {
        s += (s.empty() ? "" : ", ") + p->path + " \"" + p->card + "\"";
    }
    return s;
}

// Why no capture node has the card name (`who` names the request).
std::string noSuchCardText(const std::string& who, std::size_t node_count,
                           const CaptureNodes& found) {
    std::vector<const NodeProbe*> all;
    all.reserve(found.capture.size());
    for (const NodeProbe& p : found.capture) {
        all.push_back(&p);
    }
    std::string msg = who + ": no V4L2 capture device has that card name; ";
    if (all.empty()) {
        msg += "there is no capture device among " + std::to_string(node_count) +
               " /dev/video* node(s)";
    } else {
        msg += "capture devices: " + cardListing(all);
    }
    if (!found.others.empty()) {
        msg += "; also " + found.others;
    }
    if (!found.unchecked.empty()) {
        msg += "; could not check " + found.unchecked;
    }
    return msg;
}

// The capture node whose card name is `name`: exact match first, then a
// unique case-insensitive substring. Not found is kNotFound at open and
// kUnavailable at reopen (the device may come back).
core::Result<std::string> findByCard(const std::string& name, bool reopening) {
    const std::string who = "camera \"" + name + "\"";
    const ErrorCode missing = reopening ? ErrorCode::kUnavailable : ErrorCode::kNotFound;
    const std::vector<std::string> nodes = videoNodes();
    if (nodes.empty()) {
        return makeError(missing, who +
                                      ": no V4L2 device: there is no /dev/video* node on this "
                                      "system (is the camera plugged in and its driver "
                                      "loaded?)");
    }
    const CaptureNodes found = probeCaptureNodes(nodes);
    std::vector<const NodeProbe*> exact;
    std::vector<const NodeProbe*> partial;
    const std::string lower = toLower(name);
    for (const NodeProbe& p : found.capture) {
        if (p.card == name) {
            exact.push_back(&p);
        } else if (toLower(p.card).find(lower) != std::string::npos) {
            partial.push_back(&p);
        }
    }
    if (exact.size() == 1) {
        return exact.front()->path;
    }
    if (exact.size() > 1) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": ambiguous: " + std::to_string(exact.size()) +
                             " capture devices have that card name: " + cardListing(exact) +
                             "; give a path instead (e.g. /dev/v4l/by-id/... or "
                             "/dev/v4l/by-path/...)");
    }
    if (partial.size() == 1) {
        return partial.front()->path;
    }
    if (partial.size() > 1) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": ambiguous: it matches the cards of " + cardListing(partial) +
                             "; give the whole card name or a path");
    }
    return makeError(missing, noSuchCardText(who, nodes.size(), found));
}

// ------------------------------------------------------------ streaming

// An open capture node and its mmap'ed buffers. Destruction unmaps the
// buffers, then closes the descriptor (which stops streaming and frees them).
struct CaptureStream {
    CaptureStream() = default;
    CaptureStream(const CaptureStream&) = delete;
    CaptureStream& operator=(const CaptureStream&) = delete;
    CaptureStream(CaptureStream&&) = delete;
    CaptureStream& operator=(CaptureStream&&) = delete;
    ~CaptureStream() {
        for (const Mapping& m : buffers) {
            ::munmap(m.addr, m.length);
        }
    }

    struct Mapping {
        void* addr = nullptr;
        std::size_t length = 0;
    };
    base::UniqueFd fd;
    std::vector<Mapping> buffers;
    // "/dev/video0 (vivid): buffer 2" for each buffer, made once: conversion
    // errors name the buffer, and building the name per frame would allocate.
    std::vector<std::string> buffer_names;
};

// What open negotiated with the device.
struct Negotiated {
    std::string path;
    std::string card;
    std::string bus;
    PixelFormat format = PixelFormat::kAuto;
    std::uint32_t fourcc = 0;
    int width_px = 0;
    int height_px = 0;
    std::size_t stride_bytes = 0;
    double fps = 0;  // 0: the device does not say
    std::vector<std::string> notes;

    [[nodiscard]] std::string who() const { return card.empty() ? path : path + " (" + card + ")"; }
    [[nodiscard]] std::string mode() const {
        return formatName(fourcc) + " " +
               sizeText(static_cast<std::uint32_t>(width_px),
                        static_cast<std::uint32_t>(height_px)) +
               " @ " + (fps > 0 ? fpsText(fps) : std::string("the device's rate"));
    }
};

struct Opened {
    std::unique_ptr<CaptureStream> stream;
    Negotiated neg;
};

// Picks the pixel format (kAuto: the first of kAutoOrder offered at the size)
// and checks the size against what the device lists.
core::Result<std::uint32_t> chooseFourcc(const std::string& who, const CameraOptions& opt,
                                         const std::vector<DeviceFormat>& formats) {
    const auto w = static_cast<std::uint32_t>(opt.width_px);
    const auto h = static_cast<std::uint32_t>(opt.height_px);
    const std::string size = sizeText(w, h);
    const auto find = [&](PixelFormat f) -> const DeviceFormat* {
        for (const std::uint32_t code : fourccsOf(f)) {
            for (const DeviceFormat& d : formats) {
                if (d.fourcc == code) {
                    return &d;
                }
            }
        }
        return nullptr;
    };
    if (opt.pixel_format == PixelFormat::kAuto) {
        for (const PixelFormat f : kAutoOrder) {
            const DeviceFormat* d = find(f);
            if (d != nullptr && offersSize(d->sizes, w, h) != Offered::kNo) {
                return d->fourcc;
            }
        }
        const std::string sizes = convertibleSizesText(formats);
        return makeError(
            ErrorCode::kInvalidArgument,
            who + ": none of YUYV, NV12, GREY, MJPEG is offered at " + size +
                (sizes.empty() ? std::string() : "; sizes of those it offers: " + sizes) +
                "; the device offers the formats " + formatsText(formats));
    }
    if (fourccsOf(opt.pixel_format).empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": pixel format " + toString(opt.pixel_format) +
                             " is not supported by the V4L2 driver (YUYV, NV12, GREY, MJPEG)");
    }
    const DeviceFormat* d = find(opt.pixel_format);
    if (d == nullptr) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": pixel format " + toString(opt.pixel_format) +
                             " is not offered; the device offers " + formatsText(formats));
    }
    if (offersSize(d->sizes, w, h) == Offered::kNo) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": size " + size + " is not offered for " + formatName(d->fourcc) +
                             "; it offers " + sizesText(d->sizes));
    }
    return d->fourcc;
}

// Sets the frame rate: the closest the device lists (S_PARM then picks its
// own closest anyway; asking for a listed one makes the choice ours and
// reportable), read back from the driver's answer.
core::Status setFrameRate(int fd, const std::string& who, const CameraOptions& opt,
                          Negotiated& neg) {
    v4l2_streamparm parm{};
    parm.type = kCaptureType;
    if (xioctl(fd, VIDIOC_G_PARM, &parm) != 0 ||
        (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME) == 0) {
        neg.fps = fpsOf(parm.parm.capture.timeperframe);
        neg.notes.push_back(who + ": the device cannot be asked for a frame rate; it runs at " +
                            (neg.fps > 0 ? fpsText(neg.fps) + " fps" : "its own rate") +
                            " (asked for " + fpsText(opt.fps) + ")");
        return {};
    }
    const Intervals iv = enumIntervals(fd, neg.fourcc, static_cast<std::uint32_t>(neg.width_px),
                                       static_cast<std::uint32_t>(neg.height_px));
    v4l2_fract want = fractionOf(opt.fps);
    if (!iv.discrete.empty()) {
        double best = std::numeric_limits<double>::infinity();
        for (const v4l2_fract& f : iv.discrete) {
            const double d = std::fabs(fpsOf(f) - opt.fps);
            if (fpsOf(f) > 0 && d < best) {
                best = d;
                want = f;
            }
        }
    } else if (iv.range) {
        // Outside the range: its nearer end; inside: the request (the driver
        // rounds it to its step).
        if (opt.fps > fpsOf(iv.range->min)) {
            want = iv.range->min;
        } else if (opt.fps < fpsOf(iv.range->max)) {
            want = iv.range->max;
        }
    }
    parm = v4l2_streamparm{};
    parm.type = kCaptureType;
    parm.parm.capture.timeperframe = want;
    if (xioctl(fd, VIDIOC_S_PARM, &parm) != 0) {
        return ioctlError(who, "VIDIOC_S_PARM", errno);
    }
    neg.fps = fpsOf(parm.parm.capture.timeperframe);
    if (neg.fps <= 0 || std::fabs(neg.fps - opt.fps) > 1e-3 * opt.fps) {
        const std::string offered = intervalsText(iv);
        neg.notes.push_back(
            who + ": " + fpsText(opt.fps) + " fps is not offered for " + formatName(neg.fourcc) +
            " " +
            sizeText(static_cast<std::uint32_t>(neg.width_px),
                     static_cast<std::uint32_t>(neg.height_px)) +
            "; using " + (neg.fps > 0 ? fpsText(neg.fps) + " fps" : "the device's rate") +
            ", the closest" + (offered.empty() ? std::string() : " (offered: " + offered + ")"));
    }
    return {};
}

// Maps the buffers, queues them and starts streaming.
core::Status startStreaming(CaptureStream& s, const std::string& who, const CameraOptions& opt,
                            Negotiated& neg) {
    const int fd = s.fd.get();
    v4l2_requestbuffers req{};
    req.count = static_cast<std::uint32_t>(opt.buffers);
    req.type = kCaptureType;
    req.memory = V4L2_MEMORY_MMAP;
    if (xioctl(fd, VIDIOC_REQBUFS, &req) != 0) {
        const int err = errno;
        if (err == EINVAL) {
            return makeError(
                ErrorCode::kInvalidArgument,
                who + ": does not support mmap streaming (VIDIOC_REQBUFS: " + errnoText(err) + ")");
        }
        return ioctlError(who, "VIDIOC_REQBUFS", err);
    }
    if (req.count < static_cast<std::uint32_t>(kMinBuffers)) {
        return makeError(ErrorCode::kIo, who + ": the driver gave " + std::to_string(req.count) +
                                             " buffer(s), at least 2 are needed (out of memory?)");
    }
    if (req.count != static_cast<std::uint32_t>(opt.buffers)) {
        neg.notes.push_back(who + ": the driver gave " + std::to_string(req.count) +
                            " buffers (asked for " + std::to_string(opt.buffers) + ")");
    }
    bool monotonic = true;
    for (std::uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer buf{};
        buf.type = kCaptureType;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = i;
        if (xioctl(fd, VIDIOC_QUERYBUF, &buf) != 0) {
            return ioctlError(who, "VIDIOC_QUERYBUF", errno);
        }
        void* addr = ::mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd,
                            static_cast<off_t>(buf.m.offset));
        if (addr == MAP_FAILED) {
            return makeError(ErrorCode::kIo, who + ": cannot map buffer " + std::to_string(i) +
                                                 " (" + std::to_string(buf.length) +
                                                 " bytes): " + errnoText(errno));
        }
        s.buffers.push_back({addr, buf.length});
        s.buffer_names.push_back(who + ": buffer " + std::to_string(i));
        const std::size_t need =
            rawImageBytes(neg.format, neg.width_px, neg.height_px, neg.stride_bytes);
        if (buf.length < need) {
            return makeError(ErrorCode::kIo, who + ": buffer " + std::to_string(i) + " holds " +
                                                 std::to_string(buf.length) + " bytes, a " +
                                                 neg.mode() + " frame needs " +
                                                 std::to_string(need));
        }
        if ((buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) != V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
            monotonic = false;
        }
    }
    if (!monotonic) {
        neg.notes.push_back(who +
                            ": the driver's buffer timestamps are not CLOCK_MONOTONIC; frames are "
                            "stamped when dequeued instead (later by the delivery latency)");
    }
    for (std::uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer buf{};
        buf.type = kCaptureType;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = i;
        if (xioctl(fd, VIDIOC_QBUF, &buf) != 0) {
            return ioctlError(who, "VIDIOC_QBUF", errno);
        }
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(fd, VIDIOC_STREAMON, &type) != 0) {
        return ioctlError(who, "VIDIOC_STREAMON", errno);
    }
    return {};
}

// `path` exists and is a character device.
core::Status checkCharDevice(const std::string& path, bool reopening) {
    struct stat st = {};
    if (::stat(path.c_str(), &st) != 0) {
        return openError(path, errno, reopening);
    }
    if (!S_ISCHR(st.st_mode)) {
        const char* what = S_ISREG(st.st_mode)   ? "a regular file"
                           : S_ISDIR(st.st_mode) ? "a directory"
                                                 : "not a character device";
        return makeError(ErrorCode::kInvalidArgument, path + ": not a V4L2 device (" + what + ")");
    }
    return {};
}

// VIDIOC_QUERYCAP: the card and bus into `neg`; a streaming capture node.
core::Status queryCaptureCaps(int fd, const std::string& path, Negotiated& neg) {
    v4l2_capability cap{};
    if (xioctl(fd, VIDIOC_QUERYCAP, &cap) != 0) {
        const int err = errno;
        if (err == ENODEV || err == ENXIO) {
            return makeError(ErrorCode::kUnavailable,
                             path + ": device gone (VIDIOC_QUERYCAP: " + errnoText(err) + ")");
        }
        return makeError(ErrorCode::kInvalidArgument,
                         path + ": not a V4L2 device (VIDIOC_QUERYCAP: " + errnoText(err) + ")");
    }
    neg.card = fixedString(cap.card, sizeof cap.card);
    neg.bus = fixedString(cap.bus_info, sizeof cap.bus_info);
    const std::string who = neg.who();
    const std::uint32_t caps = nodeCaps(cap);
    if (kindOf(caps) != NodeKind::kCapture) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": not a video capture device (it is " + kindText(caps) + ")");
    }
    if ((caps & V4L2_CAP_STREAMING) == 0) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": does not support streaming I/O (read() only)");
    }
    return {};
}

// VIDIOC_S_FMT with `fourcc` at the asked size; the device's answer when it
// kept both.
core::Result<v4l2_pix_format> setPixelFormat(int fd, const std::string& who,
                                             const CameraOptions& opt,
                                             const std::vector<DeviceFormat>& formats,
                                             std::uint32_t fourcc) {
    v4l2_format fmt{};
    fmt.type = kCaptureType;
    fmt.fmt.pix.width = static_cast<std::uint32_t>(opt.width_px);
    fmt.fmt.pix.height = static_cast<std::uint32_t>(opt.height_px);
    fmt.fmt.pix.pixelformat = fourcc;
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (xioctl(fd, VIDIOC_S_FMT, &fmt) != 0) {
        return ioctlError(who, "VIDIOC_S_FMT", errno);
    }
    const v4l2_pix_format& pix = fmt.fmt.pix;
    if (pix.pixelformat != fourcc) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": asked for " + formatName(fourcc) + ", the device set " +
                             formatName(pix.pixelformat) + "; it offers " + formatsText(formats));
    }
    // Strict: a tracker calibrated at one size must not silently get another.
    if (static_cast<int>(pix.width) != opt.width_px ||
        static_cast<int>(pix.height) != opt.height_px) {
        std::string sizes;
        for (const DeviceFormat& d : formats) {
            if (d.fourcc == fourcc) {
                sizes = sizesText(d.sizes);
            }
        }
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": size " +
                             sizeText(static_cast<std::uint32_t>(opt.width_px),
                                      static_cast<std::uint32_t>(opt.height_px)) +
                             " is not offered for " + formatName(fourcc) + ": the device offered " +
                             sizeText(pix.width, pix.height) +
                             (sizes.empty() ? std::string() : "; it lists " + sizes));
    }
    return pix;
}

// The format the device set, into `neg` (format, size, stride, notes);
// checks the stride and the intrinsics' size.
core::Status takePixelFormat(const v4l2_pix_format& pix, const std::string& who,
                             const CameraOptions& opt, Negotiated& neg) {
    neg.fourcc = pix.pixelformat;
    neg.format = *formatOfFourcc(pix.pixelformat);
    neg.width_px = opt.width_px;
    neg.height_px = opt.height_px;
    neg.stride_bytes = pix.bytesperline;
    if (neg.format != PixelFormat::kMjpeg) {
        const std::size_t row = rawImageBytes(neg.format, neg.width_px, 1, 0);
        if (neg.stride_bytes == 0) {
            neg.stride_bytes = row;
        } else if (neg.stride_bytes < row) {
            return makeError(ErrorCode::kIo,
                             who + ": the driver reports " + std::to_string(neg.stride_bytes) +
                                 " bytes per line, less than a row of " + std::to_string(row));
        }
    }
    if (pix.field != V4L2_FIELD_NONE && pix.field != V4L2_FIELD_ANY) {
        neg.notes.push_back(who + ": the device delivers interlaced frames (field order " +
                            std::to_string(pix.field) + "); they are used as they come");
    }
    if (opt.has_intrinsics &&
        (opt.intrinsics.width_px != neg.width_px || opt.intrinsics.height_px != neg.height_px)) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": the intrinsics are for " +
                             std::to_string(opt.intrinsics.width_px) + "x" +
                             std::to_string(opt.intrinsics.height_px) +
                             " images, the camera delivers " + sizeText(pix.width, pix.height));
    }
    return {};
}

// Opens `path`, negotiates format, size and rate, maps the buffers and starts
// streaming. `reopening`: a missing node is kUnavailable (it may come back).
core::Result<Opened> openStream(const std::string& path, const CameraOptions& opt, bool reopening) {
    if (auto ok = checkCharDevice(path, reopening); !ok) {
        return ok.error();
    }
    Opened out;
    out.stream = std::make_unique<CaptureStream>();
    CaptureStream& s = *out.stream;
    Negotiated& neg = out.neg;
    neg.path = path;
    s.fd.reset(::open(path.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC));
    if (!s.fd.isValid()) {
        return openError(path, errno, reopening);
    }
    const int fd = s.fd.get();
    if (auto ok = queryCaptureCaps(fd, path, neg); !ok) {
        return ok.error();
    }
    const std::string who = neg.who();

    const std::vector<DeviceFormat> formats = enumFormats(fd);
    auto fourcc = chooseFourcc(who, opt, formats);
    if (!fourcc) {
        return fourcc.error();
    }
    auto pix = setPixelFormat(fd, who, opt, formats, *fourcc);
    if (!pix) {
        return pix.error();
    }
    if (auto ok = takePixelFormat(*pix, who, opt, neg); !ok) {
        return ok.error();
    }
    auto rate = setFrameRate(fd, who, opt, neg);
    if (!rate) {
        return rate.error();
    }
    // A timeout shorter than a frame period would declare a working camera lost.
    if (neg.fps > 0 && opt.frame_timeout_s * neg.fps <= 1.0) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": the frame timeout of " + secondsText(opt.frame_timeout_s) +
                             " s is not longer than a frame period at " + fpsText(neg.fps) +
                             " fps");
    }
    auto started = startStreaming(s, who, opt, neg);
    if (!started) {
        return started.error();
    }
    return out;
}

core::Status checkOptions(const CameraOptions& o) {
    const std::string who = "camera \"" + o.device + "\"";
    if (o.device.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         "v4l2 camera: no device given (a path such as /dev/video0 or a card "
                         "name)");
    }
    if (o.width_px <= 0 || o.height_px <= 0 || o.width_px > 65536 || o.height_px > 65536) {
        return makeError(ErrorCode::kInvalidArgument, who + ": invalid size " +
                                                          std::to_string(o.width_px) + "x" +
                                                          std::to_string(o.height_px));
    }
    if (!std::isfinite(o.fps) || o.fps < 0.001 || o.fps > 10000) {
        return makeError(
            ErrorCode::kInvalidArgument,
            who + ": invalid frame rate " + std::to_string(o.fps) + " (must be in [0.001, 10000])");
    }
    if (o.buffers < kMinBuffers || o.buffers > kMaxBuffers) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": buffers must be 2..32, not " + std::to_string(o.buffers));
    }
    if (!std::isfinite(o.frame_timeout_s) || o.frame_timeout_s <= 0 || o.frame_timeout_s > 3600) {
        return makeError(ErrorCode::kInvalidArgument, who + ": invalid frame timeout " +
                                                          std::to_string(o.frame_timeout_s) +
                                                          " s (must be in (0, 3600])");
    }
    return {};
}

// ---------------------------------------------------------------- camera

class V4l2Camera final : public LiveCamera {
public:
    V4l2Camera(CameraOptions options, base::UniqueFd stop_fd)
        : options_(std::move(options)),
          by_name_(options_.device.find('/') == std::string::npos),
          stop_fd_(std::move(stop_fd)) {}

    [[nodiscard]] const source::SequenceInfo& info() const override { return info_; }

    [[nodiscard]] std::string describe() const override {
        const std::lock_guard<std::mutex> lock(text_mutex_);
        return describe_;
    }

    [[nodiscard]] std::string mode() const override {
        const std::lock_guard<std::mutex> lock(text_mutex_);
        return mode_;
    }

    // Looks the device up (by card name or path) and starts streaming.
    core::Status start(bool reopening) {
        std::string path = options_.device;
        if (by_name_) {
            auto found = findByCard(options_.device, reopening);
            if (!found) {
                return found.error();
            }
            path = *found;
        }
        auto opened = openStream(path, options_, reopening);
        if (!opened) {
            return opened.error();
        }
        stream_ = std::move(opened->stream);
        neg_ = std::move(opened->neg);
        info_.name = neg_.card;
        info_.dir.clear();
        info_.intrinsics = options_.intrinsics;
        info_.has_intrinsics = options_.has_intrinsics;
        info_.frame_count = 0;
        info_.listed_count = 0;
        info_.notes = neg_.notes;
        const std::lock_guard<std::mutex> lock(text_mutex_);
        describe_ = neg_.who();
        mode_ = neg_.mode();
        return {};
    }

    core::Result<bool> next(source::Frame& frame) override {
        if (stopped_.load()) {
            return false;
        }
        if (!stream_) {
            return makeError(ErrorCode::kUnavailable,
                             describe() + ": closed after an error; reopen() it first");
        }
        const auto timeout_ns = std::llround(options_.frame_timeout_s * 1e9);
        const std::int64_t deadline = monotonicNs() + timeout_ns;
        std::uint64_t repeats = 0;  // buffers this call dropped as repeats
        for (;;) {
            const std::int64_t left_ns = deadline - monotonicNs();
            if (left_ns <= 0) {
                return timedOut(repeats);
            }
            // Round up: a poll that returns a little early would spin.
            const auto left_ms = std::min<std::int64_t>((left_ns + 999'999) / 1'000'000, INT_MAX);
            std::array<pollfd, 2> fds{};
            fds[0] = {stream_->fd.get(), POLLIN, 0};
            fds[1] = {stop_fd_.get(), POLLIN, 0};
            const int rc = ::poll(fds.data(), fds.size(), static_cast<int>(left_ms));
            if (rc < 0) {
                if (errno == EINTR) {
                    continue;
                }
                return lose("poll failed: " + errnoText(errno));
            }
            if (stopped_.load() || (fds[1].revents & POLLIN) != 0) {
                return false;
            }
            if (rc == 0) {
                continue;  // the deadline check above reports the timeout
            }
            const short ev = fds[0].revents;
            if ((ev & POLLNVAL) != 0) {
                return lose("device lost (the descriptor became invalid)");
            }
            if ((ev & (POLLIN | POLLERR | POLLHUP)) == 0) {
                continue;
            }
            v4l2_buffer buf{};
            buf.type = kCaptureType;
            buf.memory = V4L2_MEMORY_MMAP;
            if (xioctl(stream_->fd.get(), VIDIOC_DQBUF, &buf) != 0) {
                const int err = errno;
                if (err == EAGAIN) {
                    if ((ev & (POLLERR | POLLHUP)) != 0) {
                        // vb2 reports POLLERR when the queue is broken (the
                        // driver's fatal error) or the device unregistered.
                        return lose("device lost (poll reported an error)");
                    }
                    continue;  // a spurious wake-up
                }
                return lose("device lost (VIDIOC_DQBUF: " + errnoText(err) + ")");
            }
            if (buf.index >= stream_->buffers.size()) {
                return lose("the driver returned buffer " + std::to_string(buf.index) + " of " +
                            std::to_string(stream_->buffers.size()));
            }
            // A buffer the driver says is corrupt (e.g. a USB transfer error)
            // or a repeat (drop_repeated_frames) goes back: wait for the next
            // one within the same deadline.
            const bool corrupt = (buf.flags & V4L2_BUF_FLAG_ERROR) != 0;
            if (corrupt || isRepeat(buf)) {
                if (!corrupt) {
                    ++repeats;
                    repeated_.fetch_add(1, std::memory_order_relaxed);
                }
                auto requeued = requeue(buf);
                if (!requeued) {
                    return requeued.error();
                }
                continue;
            }
            return deliver(buf, frame);
        }
    }

    [[nodiscard]] std::uint64_t repeatedFrames() const override {
        return repeated_.load(std::memory_order_relaxed);
    }

    core::Result<bool> reopen() override {
        if (stopped_.load()) {
            return makeError(ErrorCode::kUnavailable, describe() + ": stopped");
        }
        stream_.reset();
        auto started = start(true);
        if (!started) {
            return started.error();
        }
        return true;
    }

    void stop() override {
        stopped_.store(true);
        const std::uint64_t one = 1;
        ssize_t n = 0;
        do {
            n = ::write(stop_fd_.get(), &one, sizeof one);
        } while (n < 0 && errno == EINTR);
    }

private:
    // Closes the device; the error next() returns for it (see camera.h).
    core::Error lose(const std::string& why) {
        const std::string who = describe();
        stream_.reset();
        return makeError(ErrorCode::kUnavailable, who + ": " + why);
    }

    core::Error timedOut(std::uint64_t repeats) {
        // A vanished node explains the silence better than a timeout.
        struct stat st = {};
        if (::stat(neg_.path.c_str(), &st) != 0 && errno == ENOENT) {
            return lose("device lost (the device node is gone)");
        }
        if (repeats > 0) {
            return lose("no new image for " + secondsText(options_.frame_timeout_s) + " s (" +
                        std::to_string(repeats) + " repeats of the last image)");
        }
        return lose("no frame for " + secondsText(options_.frame_timeout_s) + " s");
    }

    // With drop_repeated_frames: whether buf's pixels are the last new
    // buffer's (its signature is kept across reopen(): a camera that came
    // back showing the same frozen image is still not delivering).
    bool isRepeat(const v4l2_buffer& buf) {
        if (!options_.drop_repeated_frames) {
            return false;
        }
        const CaptureStream::Mapping& m = stream_->buffers[buf.index];
        const std::uint64_t signature =
            rawSignature(static_cast<const std::uint8_t*>(m.addr),
                         std::min<std::size_t>(buf.bytesused, m.length));
        if (have_signature_ && signature == last_signature_) {
            return true;
        }
        last_signature_ = signature;
        have_signature_ = true;
        return false;
    }

    core::Status requeue(v4l2_buffer& buf) {
        buf.bytesused = 0;
        if (xioctl(stream_->fd.get(), VIDIOC_QBUF, &buf) != 0) {
            return lose("device lost (VIDIOC_QBUF: " + errnoText(errno) + ")");
        }
        return {};
    }

    core::Result<bool> deliver(v4l2_buffer& buf, source::Frame& frame) {
        std::int64_t t_ns = 0;
        const bool monotonic =
            (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
        if (monotonic && (buf.timestamp.tv_sec != 0 || buf.timestamp.tv_usec != 0)) {
            t_ns = static_cast<std::int64_t>(buf.timestamp.tv_sec) * 1'000'000'000 +
                   static_cast<std::int64_t>(buf.timestamp.tv_usec) * 1000;
        } else {
            // Another clock (or none): the dequeue time is on the clock the
            // rest of the daemon uses, late by the delivery latency.
            t_ns = monotonicNs();
        }
        // Frames must be strictly increasing in time. A timestamp at or before
        // the previous one (a driver glitch, two buffers stamped in the same
        // microsecond) is moved to 1 ns after it: the frame keeps its pixels,
        // the order holds, and the error is no larger than the glitch.
        if (have_last_t_ && t_ns <= last_t_ns_) {
            t_ns = last_t_ns_ + 1;
        }
        const CaptureStream::Mapping& m = stream_->buffers[buf.index];
        RawImage raw;
        raw.format = neg_.format;
        raw.width_px = neg_.width_px;
        raw.height_px = neg_.height_px;
        raw.stride_bytes = neg_.stride_bytes;
        raw.data = static_cast<const std::uint8_t*>(m.addr);
        raw.size_bytes = std::min<std::size_t>(buf.bytesused, m.length);
        auto converted =
            convertRawImage(raw, stream_->buffer_names[buf.index], frame.gray, frame.color);
        // The pixels are copied: the buffer goes back to the driver either way.
        auto requeued = requeue(buf);
        if (!requeued) {
            return requeued.error();
        }
        if (!converted) {
            return converted.error();
        }
        frame.id = next_id_++;
        frame.t_ns = t_ns;
        last_t_ns_ = t_ns;
        have_last_t_ = true;
        if (frame.image_path.native() != neg_.path) {
            frame.image_path = neg_.path;
        }
        frame.T_CtoW_gt.reset();
        frame.depth_path.reset();
        frame.gravity_down_C.reset();
        frame.accel_C.reset();
        return true;
    }

    CameraOptions options_;
    bool by_name_ = false;    // options_.device is a card name, not a path
    base::UniqueFd stop_fd_;  // eventfd: stop() makes it readable
    std::atomic<bool> stopped_{false};
    std::unique_ptr<CaptureStream> stream_;  // null after a loss, until reopen()
    Negotiated neg_;
    source::SequenceInfo info_;
    std::int64_t next_id_ = 0;
    std::int64_t last_t_ns_ = 0;
    bool have_last_t_ = false;
    std::uint64_t last_signature_ = 0;  // drop_repeated_frames: the last new buffer's
    bool have_signature_ = false;
    std::atomic<std::uint64_t> repeated_{0};
    // describe()/mode() may be called from other threads (status) while
    // reopen() changes them.
    mutable std::mutex text_mutex_;
    std::string describe_;
    std::string mode_;
};

// One line per size of a format scaled converts: "YUYV 640x480 @ 30 25 15".
void describeFormats(int fd, CameraDescription& d) {
    std::string others;
    for (const DeviceFormat& f : enumFormats(fd)) {
        if (!formatOfFourcc(f.fourcc)) {
            others += (others.empty() ? "" : ", ") + fourccText(f.fourcc);
            continue;
        }
        const std::string name = formatName(f.fourcc);
        if (f.sizes.kind != FrameSizes::Kind::kDiscrete) {
            d.formats.push_back(name + " " + sizesText(f.sizes));
            continue;
        }
        for (const auto& [w, h] : f.sizes.discrete) {
            const std::string rates = intervalsText(enumIntervals(fd, f.fourcc, w, h));
            d.formats.push_back(name + " " + sizeText(w, h) +
                                (rates.empty() ? std::string() : " @ " + rates));
        }
    }
    if (!others.empty()) {
        d.note = "also offers formats scaled does not convert: " + others;
    }
}

}  // namespace

core::Result<std::unique_ptr<LiveCamera>> openV4l2Camera(const CameraOptions& options) {
    auto ok = checkOptions(options);
    if (!ok) {
        return ok.error();
    }
    base::UniqueFd stop_fd(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!stop_fd.isValid()) {
        return makeError(ErrorCode::kIo, "camera \"" + options.device +
                                             "\": cannot create an eventfd: " + errnoText(errno));
    }
    auto camera = std::make_unique<V4l2Camera>(options, std::move(stop_fd));
    auto started = camera->start(false);
    if (!started) {
        return started.error();
    }
    return std::unique_ptr<LiveCamera>(std::move(camera));
}

std::vector<CameraDescription> listV4l2Cameras() {
    std::vector<CameraDescription> out;
    for (const std::string& path : videoNodes()) {
        CameraDescription d;
        d.backend = "v4l2";
        d.device = path;
        const NodeProbe p = probeNode(path);
        if (p.open_errno != 0) {
            d.note = openNote(p.open_errno);
            out.push_back(std::move(d));
            continue;
        }
        if (p.querycap_errno != 0) {
            d.note = "not a V4L2 device (VIDIOC_QUERYCAP: " + errnoText(p.querycap_errno) + ")";
            out.push_back(std::move(d));
            continue;
        }
        d.name = p.card;
        d.bus = p.bus;
        const NodeKind kind = kindOf(p.caps);
        if (kind == NodeKind::kCaptureMplane) {
            d.note = "multi-planar capture: not supported by the v4l2 source";
            out.push_back(std::move(d));
            continue;
        }
        if (kind != NodeKind::kCapture) {
            continue;  // metadata, output, codec, touch... nodes: not cameras
        }
        describeFormats(p.fd.get(), d);
        out.push_back(std::move(d));
    }
    return out;
}

}  // namespace scaled::drivers::camera
