#include <cctype>
#include <cstddef>
#include <cstdint>
#include <string>

#include <scaled/drivers/camera/camera.h>

namespace scaled::drivers::camera {

const char* toString(PixelFormat f) {
    switch (f) {
        case PixelFormat::kAuto:
            return "auto";
        case PixelFormat::kYuyv:
            return "YUYV";
        case PixelFormat::kMjpeg:
            return "MJPEG";
        case PixelFormat::kGrey:
            return "GREY";
        case PixelFormat::kNv12:
            return "NV12";
        case PixelFormat::kYuv420:
            return "YUV420";
        case PixelFormat::kRgb888:
            return "RGB888";
        case PixelFormat::kBgr888:
            return "BGR888";
        case PixelFormat::kXrgb8888:
            return "XRGB8888";
        case PixelFormat::kXbgr8888:
            return "XBGR8888";
    }
    return "?";
}

bool parsePixelFormat(const std::string& text, PixelFormat& out) {
    std::string upper;
    upper.reserve(text.size());
    for (const char c : text) {
        upper.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
    }
    for (const PixelFormat f :
         {PixelFormat::kAuto, PixelFormat::kYuyv, PixelFormat::kMjpeg, PixelFormat::kGrey,
          PixelFormat::kNv12, PixelFormat::kYuv420, PixelFormat::kRgb888, PixelFormat::kBgr888,
          PixelFormat::kXrgb8888, PixelFormat::kXbgr8888}) {
        std::string name = toString(f);
        for (char& c : name) {
            c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
        }
        if (upper == name) {
            out = f;
            return true;
        }
    }
    // V4L2's fourcc (what v4l2-ctl --list-formats prints) for the same thing.
    if (upper == "MJPG") {
        out = PixelFormat::kMjpeg;
        return true;
    }
    return false;
}

core::Result<bool> LiveCamera::seek(std::size_t index) {
    return core::makeError(
        core::ErrorCode::kInvalidArgument,
        describe() + ": a live camera cannot seek (to frame " + std::to_string(index) + ")");
}

std::uint64_t rawSignature(const std::uint8_t* data, std::size_t size_bytes) {
    constexpr std::uint64_t kFnvOffset = 14695981039346656037ULL;
    constexpr std::uint64_t kFnvPrime = 1099511628211ULL;
    constexpr std::size_t kStep = 61;
    std::uint64_t h = kFnvOffset;
    for (std::size_t shift = 0; shift < 64; shift += 8) {
        h = (h ^ ((size_bytes >> shift) & 0xffU)) * kFnvPrime;
    }
    if (data == nullptr) {
        return h;
    }
    for (std::size_t i = 0; i < size_bytes; i += kStep) {
        h = (h ^ data[i]) * kFnvPrime;
    }
    return h;
}

}  // namespace scaled::drivers::camera
