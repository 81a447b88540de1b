#pragma once

// TUM RGB-D style datasets (also the 7-Scenes conversions in ../shared/data):
//
//   rgb.txt          `t rgb/x.png` per line, strictly increasing t (seconds)
//   depth.txt        optional, same format; associated by nearest timestamp
//   groundtruth.txt  optional, `t tx ty tz qx qy qz qw` (camera-to-world, metres),
//                    associated by nearest timestamp within max_assoc_dt_s
//   camera.txt       optional, one line `width height fx fy cx cy [k1 k2]`
//   gravity.txt      optional, one line `gx gy gz`: unit down vector, GT world frame
//
// File names in rgb.txt/depth.txt are relative to the dataset directory and may
// not contain spaces. See frame_source.h for the error format and for what
// happens when images are missing.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/frame_source.h>

namespace scaled::drivers {

core::Result<std::unique_ptr<FrameSource>> openTumDataset(const std::filesystem::path& dir,
                                                          const DatasetOptions& opt = {});

struct TumListEntry {
    int64_t t_ns = 0;
    std::string file;      // as written in the list, relative to the dataset directory
    std::size_t line = 0;  // 1-based line in the list file
};

// rgb.txt / depth.txt: two fields per line, strictly increasing timestamps.
core::Result<std::vector<TumListEntry>> readTumImageList(const std::filesystem::path& list_file);

// camera.txt: `width height fx fy cx cy` or `... k1 k2`; validated.
core::Result<core::CameraIntrinsics> readTumCameraFile(const std::filesystem::path& camera_file);

// gravity.txt: one unit vector (|norm - 1| <= 1e-3), returned normalised.
core::Result<core::Vec3> readGravityFile(const std::filesystem::path& gravity_file);

}  // namespace scaled::drivers
