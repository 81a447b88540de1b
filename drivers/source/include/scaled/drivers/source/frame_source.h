#pragma once

// Frames from a camera or a recorded sequence. FrameSource is the interface the
// tracker reads from; openDataset() replays a recording from disk. It takes a
// directory or a file and detects the format (DatasetOptions::format forces one):
//
//   TUM RGB-D layout  (directory with rgb.txt) rgb.txt (`t rgb/x.png`), optional
//                     depth.txt, groundtruth.txt (`t tx ty tz qx qy qz qw`,
//                     camera-to-world, metres), camera.txt (`width height fx fy cx cy
//                     [k1 k2]`), gravity.txt (unit down vector in the ground-truth
//                     world frame), accelerometer.txt (`t ax ay az`); dataset_tum.h.
//   KITTI odometry    (directory with times.txt and image_0/) image_0/NNNNNN.png,
//                     times.txt (one time in seconds per line), optional poses.txt
//                     (3x4 row-major camera-to-world per line) and calib.txt
//                     (`P0: 12 numbers`); dataset_kitti.h.
//   Image folder      (any other directory holding images) the images in natural
//                     order, times from times.txt or DatasetOptions::folder_fps,
//                     optional camera.txt; dataset_folder.h.
//   Video file        (a regular file) anything cv::VideoCapture decodes, optional
//                     camera.txt next to it; dataset_video.h.
//
// All index files are parsed once, in openDataset(); images are read by next().
// Every parse error is a core::Error whose message reads `FILE:LINE: what is
// wrong (the offending text)`; nothing throws.
//
// Partial downloads: when the images listed at the end of an index do not
// exist (e.g. the TUM rgb.txt of a whole sequence next to its first 16 images),
// openDataset() keeps the frames up to the last image that exists and adds a
// note to SequenceInfo::notes (DatasetOptions::drop_missing_tail). A missing
// image before that point is an error of next(), naming the index file and line.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/types.h>

namespace scaled::drivers::source {

struct Frame {
    int64_t id = 0;    // 0-based index in the sequence
    int64_t t_ns = 0;  // timestamp in nanoseconds, strictly increasing along the sequence
    cv::Mat gray;      // CV_8UC1
    cv::Mat color;     // CV_8UC3 BGR; for grayscale datasets (KITTI image_0) the gray image
                       // expanded to three channels
    std::optional<core::CameraPose> T_CtoW_gt;        // ground-truth pose, metres
    std::optional<std::filesystem::path> depth_path;  // associated depth image, if it exists
    std::filesystem::path image_path;  // where the pixels came from (logs); the video file
    // Unit gravity direction (pointing down) in this frame's camera frame:
    // R_CtoW^T * SequenceInfo::gravity_down_W, set when both the sequence's
    // gravity and this frame's ground-truth pose are known. It is derived from
    // nothing else: the accelerometer (accel_C) never sets it, because the
    // orientation of the TUM accelerometer axes relative to the colour camera
    // is not documented (see dataset_tum.h). So there is no conflict to
    // resolve: ground truth + gravity.txt is the one source.
    std::optional<core::Vec3> gravity_down_C;
    // Raw accelerometer reading (m/s^2) nearest in time to the frame (within
    // DatasetOptions::max_assoc_dt_s), as written in the dataset (TUM
    // accelerometer.txt), axes and sign unchanged. Not rotated into the camera
    // frame and not a gravity estimate: see dataset_tum.h for what is known
    // about its frame.
    std::optional<core::Vec3> accel_C;
};

struct SequenceInfo {
    std::string name;           // the dataset directory's name (a video: the file's name)
    std::filesystem::path dir;  // dataset directory (a video: its directory; empty when live)
    core::CameraIntrinsics intrinsics{};       // valid only when has_intrinsics
    bool has_intrinsics = false;               // false: the caller must supply intrinsics
    std::optional<core::Vec3> gravity_down_W;  // unit, in the ground-truth world frame
    double depth_scale_m = 0;        // metres per depth-image unit; 0 when there is no depth
    std::size_t frame_count = 0;     // frames next() will return from the start (a video: at
                                     // most; the container's count may be an estimate)
    std::size_t listed_count = 0;    // frames the index lists (>= frame_count)
    std::vector<std::string> notes;  // things a user should know (dropped frames, missing GT)
};

class FrameSource {
public:
    FrameSource() = default;
    FrameSource(const FrameSource&) = delete;
    FrameSource& operator=(const FrameSource&) = delete;
    FrameSource(FrameSource&&) = delete;
    FrameSource& operator=(FrameSource&&) = delete;
    virtual ~FrameSource() = default;

    [[nodiscard]] virtual const SequenceInfo& info() const = 0;

    // Reads the frame at the cursor into `frame` and advances the cursor.
    // true: a frame was read; false: end of the sequence (frame untouched).
    // An unreadable frame is an Error (the message names the image and, for a
    // missing image, the index file and line that listed it); the cursor moves
    // past it, so the caller may log it and go on.
    virtual core::Result<bool> next(Frame& frame) = 0;

    // Moves the cursor to frame `index` (for --frames A:B). index == frame_count
    // is the end (returns false); beyond that is a kInvalidArgument error.
    virtual core::Result<bool> seek(std::size_t index) = 0;
};

}  // namespace scaled::drivers::source
