#pragma once

// Opening a recorded sequence: a TUM RGB-D or 7-Scenes directory, KITTI
// odometry, an image folder or a video file, as a source::FrameSource.

#include <filesystem>
#include <memory>
#include <optional>
#include <string_view>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

enum class DatasetFormat { kTum, kKitti, kImageFolder, kVideo };

// "tum", "kitti", "folder" or "video" (the tools' --format); nullopt for
// anything else.
[[nodiscard]] std::optional<DatasetFormat> parseDatasetFormat(std::string_view text);

struct DatasetOptions {
    // Detected when empty. A regular file -> video. A directory: rgb.txt -> TUM;
    // times.txt and image_0/ -> KITTI; else image files in it -> image folder.
    std::optional<DatasetFormat> format;
    // TUM: ground truth, depth and accelerometer samples are associated to an
    // image by nearest timestamp when they are at most this far apart (else the
    // frame has none).
    double max_assoc_dt_s = 0.02;
    // Overrides the dataset's intrinsics. width_px/height_px of 0 are taken
    // from the first image.
    std::optional<core::CameraIntrinsics> intrinsics;
    // TUM: gravity comes from gravity.txt only (nothing is derived from the
    // ground truth). KITTI: when set, gravity = +y axis of the first camera
    // (KITTI's cameras are mounted level), in the ground-truth world frame.
    bool gravity_from_groundtruth = false;
    // Overrides depth_scale_m. Default for TUM: 0.001 when a comment of depth.txt
    // mentions millimetres (7-Scenes conversions), else 1/5000 (TUM RGB-D).
    std::optional<double> depth_scale_m;
    // Drop the frames after the last image that exists (partial downloads).
    // When false, every listed frame is kept and next() reports the missing ones.
    bool drop_missing_tail = true;
    // Frame rate (Hz) of an image folder without times.txt (frame i at i / fps),
    // and of a video whose container gives no frame rate. Finite, in (0, 1e9].
    double folder_fps = 30.0;
};

// `path` is a dataset directory, an image folder or a video file (see the top
// of this file). Errors name the path.
core::Result<std::unique_ptr<source::FrameSource>> openDataset(const std::filesystem::path& path,
                                                               const DatasetOptions& opt = {});

}  // namespace scaled::drivers::dataset
