#pragma once

// TUM-format trajectories: one pose per line, `t tx ty tz qx qy qz qw`, t in
// seconds, camera-to-world, metres; lines starting with '#' are comments.

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::drivers::dataset {

// Writes `t_ns.size() == poses.size()` poses with t in seconds and 6 decimals.
// Atomic: written to a temporary file next to `path`, synced, then renamed.
// Fails (the message names the file) on mismatched sizes, non-finite poses,
// rotations that are not orthonormal, timestamps that do not increase at
// microsecond resolution, or I/O errors.
core::Status writeTumTrajectory(const std::filesystem::path& path, std::span<const int64_t> t_ns,
                                std::span<const core::CameraPose> poses);

// Reads a TUM trajectory: 8 fields per line, finite numbers, strictly
// increasing timestamps, unit quaternions (|norm - 1| <= 1e-3, normalised).
// Errors read `FILE:LINE: what is wrong (the offending text)`.
core::Result<std::vector<std::pair<int64_t, core::CameraPose>>> readTumTrajectory(
    const std::filesystem::path& path);
// The same on a file's text; `path` names it in error messages.
core::Result<std::vector<std::pair<int64_t, core::CameraPose>>> parseTumTrajectory(
    std::string_view text, const std::filesystem::path& path);

// Decimal seconds ("1341847980.722988", "1.037359e-01", "-2.5") to nanoseconds,
// exactly (digits beyond 1 ns are rounded half away from zero). Fails on
// anything else, including non-finite values and values outside int64 ns.
core::Result<int64_t> parseTimestampNs(std::string_view text);

// Nanoseconds to seconds with 6 decimals (rounded half away from zero).
std::string formatTimestampS(int64_t t_ns);

}  // namespace scaled::drivers::dataset
