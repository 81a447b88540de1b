#pragma once

// TUM RGB-D style datasets (also the 7-Scenes conversions in ../shared/data):
//
//   rgb.txt          `t rgb/x.png` per line, strictly increasing t (seconds)
//   depth.txt        optional, same format; associated by nearest timestamp
//   groundtruth.txt  optional, `t tx ty tz qx qy qz qw` (camera-to-world, metres),
//                    associated by nearest timestamp within max_assoc_dt_s
//   camera.txt       optional, one line `width height fx fy cx cy [k1 k2]`
//   gravity.txt      optional, one line `gx gy gz`: unit down vector, GT world frame
//   accelerometer.txt optional, `t ax ay az` per line (m/s^2), strictly increasing
//                    t; the sample nearest to a frame within max_assoc_dt_s
//                    becomes Frame::accel_C
//
// Gravity per frame: Frame::gravity_down_C = R_CtoW^T * gravity_down_W when
// gravity.txt and the frame's ground-truth pose are both known.
//
// Accelerometer convention: not documented by the benchmark, since MEASURED.
// A TUM RGB-D accelerometer.txt holds `timestamp ax ay az`, accelerations in
// m/s^2 from the Kinect's built-in accelerometer. Compared with the ground
// truth on a TUM fr1 sequence, gravity (down) in the colour camera's optical
// frame is (ax, ay, -az) / |a|. drivers/imu/imu_log.h reads the file as IMU
// samples with that mapping (tumKinectImuToCamera) and core/geometry/gravity.h
// turns a still window into a direction (docs/imu.md). Here the readings are
// still exposed raw in Frame::accel_C and are NOT turned into a gravity
// direction: gravity_down_C comes from ground truth only.
//
// File names in rgb.txt/depth.txt are relative to the dataset directory and may
// not contain spaces. See frame_source.h for the error format and for what
// happens when images are missing.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

core::Result<std::unique_ptr<source::FrameSource>> openTumDataset(const std::filesystem::path& dir,
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

// readTumCameraFile() when the file exists, nullopt when it does not (the
// intrinsics then come from the options or the caller).
core::Result<std::optional<core::CameraIntrinsics>> readOptionalCameraFile(
    const std::filesystem::path& camera_file);

// gravity.txt: one unit vector (|norm - 1| <= 1e-3), returned normalised.
core::Result<core::Vec3> readGravityFile(const std::filesystem::path& gravity_file);

struct TumAccelSample {
    int64_t t_ns = 0;
    core::Vec3 accel = core::Vec3::Zero();  // m/s^2, as written (see the top of this file)
    std::size_t line = 0;                   // 1-based line in the file
};

// accelerometer.txt: `timestamp ax ay az` per line, strictly increasing
// timestamps, finite values of at most 1e4 m/s^2.
core::Result<std::vector<TumAccelSample>> readTumAccelerometer(
    const std::filesystem::path& accel_file);

// The readers above on a file's text (they read the file and call these);
// `file` names it in error messages. The fuzz targets (tests/fuzz) call these.
core::Result<std::vector<TumListEntry>> parseTumImageList(std::string_view text,
                                                          const std::filesystem::path& file);
core::Result<core::CameraIntrinsics> parseTumCameraFile(std::string_view text,
                                                        const std::filesystem::path& file);
core::Result<core::Vec3> parseGravityFile(std::string_view text, const std::filesystem::path& file);
core::Result<std::vector<TumAccelSample>> parseTumAccelerometer(std::string_view text,
                                                                const std::filesystem::path& file);

}  // namespace scaled::drivers::dataset
