#pragma once

// Command-line value parsers and defaults the tools share.

#include <charconv>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string_view>
#include <system_error>

#include <scaled/core/camera/pinhole_radial.h>

namespace scaled::tools {

// The whole of `s` as a number of type T (no sign, space or suffix slack).
template <typename T>
bool parseNumber(std::string_view s, T& out) {
    const auto* end = s.data() + s.size();
    const auto r = std::from_chars(s.data(), end, out);
    return r.ec == std::errc() && r.ptr == end;
}

// --frames A:B: A (default 0) inclusive, B exclusive and > A (default: open).
bool parseFrameRange(std::string_view s, std::size_t& first, std::optional<std::size_t>& end);

// --gyro-sim D:B: the simulated gyro's noise density (rad/s/sqrt(Hz)) and bias
// sigma (rad/s): D in [0, 1], B in [0, 10] (the simulated gyro's ranges).
bool parseGyroSim(std::string_view s, double& noise_density, double& bias_sigma_radps);

// --intrinsics fx,fy,cx,cy (sets those four fields only).
bool parseIntrinsics(std::string_view s, core::CameraIntrinsics& k);

// $SCALED_SHARED_DIR, else `fallback` (../shared next to the working directory
// unless a tool knows better).
std::filesystem::path sharedDir(const std::filesystem::path& fallback = "../shared");

// The default detector model: <shared>/models/yolox_nano.onnx.
std::filesystem::path defaultModelPath(const std::filesystem::path& fallback = "../shared");

}  // namespace scaled::tools
