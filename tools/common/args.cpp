#include "args.h"

#include <cmath>
#include <cstdlib>
#include <string>

namespace scaled::tools {

bool parseFrameRange(std::string_view s, std::size_t& first, std::optional<std::size_t>& end) {
    const auto colon = s.find(':');
    if (colon == std::string_view::npos) {
        return false;
    }
    const auto a = s.substr(0, colon);
    const auto b = s.substr(colon + 1);
    first = 0;
    if (!a.empty() && !parseNumber(a, first)) {
        return false;
    }
    if (!b.empty()) {
        std::size_t e = 0;
        if (!parseNumber(b, e) || e <= first) {
            return false;
        }
        end = e;
    }
    return true;
}

bool parseGyroSim(std::string_view s, double& noise_density, double& bias_sigma_radps) {
    const auto colon = s.find(':');
    if (colon == std::string_view::npos) {
        return false;
    }
    double d = 0;
    double b = 0;
    if (!parseNumber(s.substr(0, colon), d) || !parseNumber(s.substr(colon + 1), b)) {
        return false;
    }
    if (!(std::isfinite(d) && std::isfinite(b) && d >= 0 && d <= 1 && b >= 0 && b <= 10)) {
        return false;
    }
    noise_density = d;
    bias_sigma_radps = b;
    return true;
}

bool parseIntrinsics(std::string_view s, core::CameraIntrinsics& k) {
    double v[4];
    for (int i = 0; i < 4; ++i) {
        const auto comma = s.find(',');
        const std::string str(s.substr(0, comma));
        char* end = nullptr;
        v[i] = std::strtod(str.c_str(), &end);
        if (str.empty() || end != str.c_str() + str.size()) {
            return false;
        }
        if (i < 3 && comma == std::string_view::npos) {
            return false;
        }
        s = comma == std::string_view::npos ? std::string_view() : s.substr(comma + 1);
    }
    k.fx = core::Scalar(v[0]);
    k.fy = core::Scalar(v[1]);
    k.cx = core::Scalar(v[2]);
    k.cy = core::Scalar(v[3]);
    return s.empty();
}

std::filesystem::path sharedDir(const std::filesystem::path& fallback) {
    const char* env = std::getenv("SCALED_SHARED_DIR");  // NOLINT(concurrency-mt-unsafe)
    return (env != nullptr && *env != '\0') ? std::filesystem::path(env) : fallback;
}

std::filesystem::path defaultModelPath(const std::filesystem::path& fallback) {
    return sharedDir(fallback) / "models" / "yolox_nano.onnx";
}

}  // namespace scaled::tools
