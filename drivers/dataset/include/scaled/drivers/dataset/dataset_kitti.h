#pragma once

// KITTI odometry sequences (left grayscale camera):
//
//   image_0/NNNNNN.png  frame N (6 digits, zero-padded)
//   times.txt           one time in seconds per line (frame N = N-th data line)
//   poses.txt           optional, 12 numbers per line: 3x4 row-major [R | p]
//                       camera-to-world, metres (line N = frame N)
//   calib.txt           optional, `P0: 12 numbers` (3x4 projection of camera 0):
//                       fx = P[0], cx = P[2], fy = P[5], cy = P[6]; the image
//                       size comes from the first image
//
// Color frames are the grayscale image expanded to three channels. See
// frame_source.h for the error format and for what happens when images are missing.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

core::Result<std::unique_ptr<source::FrameSource>> openKittiDataset(
    const std::filesystem::path& dir, const DatasetOptions& opt = {});

struct KittiTime {
    int64_t t_ns = 0;
    std::size_t line = 0;  // 1-based line in times.txt
};

// times.txt: one timestamp per line, strictly increasing.
core::Result<std::vector<KittiTime>> readKittiTimes(const std::filesystem::path& times_file);

// poses.txt: rotations must be orthonormal within 1e-3 (they are re-orthonormalised).
core::Result<std::vector<core::CameraPose>> readKittiPoses(const std::filesystem::path& poses_file);

// The 12 numbers of the line `KEY: ...` of calib.txt (kNotFound when absent).
core::Result<std::array<double, 12>> readKittiProjection(const std::filesystem::path& calib_file,
                                                         std::string_view key = "P0");

// The readers above on a file's text (they read the file and call these);
// `file` names it in error messages. The fuzz targets (tests/fuzz) call these.
core::Result<std::vector<KittiTime>> parseKittiTimes(std::string_view text,
                                                     const std::filesystem::path& file);
core::Result<std::vector<core::CameraPose>> parseKittiPoses(std::string_view text,
                                                            const std::filesystem::path& file);
core::Result<std::array<double, 12>> parseKittiProjection(std::string_view text,
                                                          const std::filesystem::path& file,
                                                          std::string_view key = "P0");

}  // namespace scaled::drivers::dataset
