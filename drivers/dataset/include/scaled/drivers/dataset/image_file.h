#pragma once

// Image files read from disk, for the dataset readers and the tools. Never
// throw; errors name the file: kNotFound (missing), kIo (not a regular file,
// unreadable, larger than 512 MiB), kParse (empty or cannot be decoded).

#include <filesystem>
#include <opencv2/core.hpp>

#include <scaled/core/result.h>

namespace scaled::drivers::dataset {

// An 8-bit image with 1, 3 (BGR) or 4 (BGRA) channels, as stored.
core::Result<cv::Mat> loadImage(const std::filesystem::path& path);

// Any depth and channel count, unchanged (IMREAD_UNCHANGED): depth maps.
core::Result<cv::Mat> loadImageUnchanged(const std::filesystem::path& path);

}  // namespace scaled::drivers::dataset
