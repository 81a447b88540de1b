#pragma once

// Internals shared by the dataset readers (TUM, KITTI, image folder, video)
// and the trajectory files: line-oriented text parsing with FILE:LINE error
// messages, image decoding, and the replay FrameSource the file-based formats
// produce.
// Not installed: include only from drivers/src.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/types.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset::detail {

// Index files larger than this are refused (a full TUM ground truth is a few MB).
constexpr std::uintmax_t kMaxTextBytes = std::uintmax_t{256} << 20U;
// Image files larger than this are refused before decoding.
constexpr std::uintmax_t kMaxImageBytes = std::uintmax_t{512} << 20U;
// |norm - 1| allowed for quaternions and gravity vectors read from files.
constexpr double kUnitTolerance = 1e-3;
// max |R^T R - I| allowed for rotation matrices read from files.
constexpr double kRotationTolerance = 1e-3;

struct TextLine {
    std::size_t number = 0;  // 1-based line number in the file
    std::string_view text;   // without the line end
};

// Whole file as text. Errors (kNotFound, kIo) name the file.
core::Result<std::string> readTextFile(const std::filesystem::path& path);

// The lines of `text` that carry data: blank lines and comment lines (first
// non-blank character '#') are left out; '\r' before '\n' is dropped.
std::vector<TextLine> dataLines(std::string_view text);

// True when some comment line of `text` contains `needle` (ASCII case-insensitive).
bool commentMentions(std::string_view text, std::string_view needle);

// Fields separated by spaces or tabs.
std::vector<std::string_view> splitFields(std::string_view line);

// `text` made printable (control and non-ASCII bytes as \xNN) and shortened.
std::string printable(std::string_view text);

// Shortest text that reads back as `v` ("0.02", not "0.020000").
std::string shortNumber(double v);

// "FILE:LINE: what (text)" — the message format of every parse error.
core::Error lineError(core::ErrorCode code, const std::filesystem::path& file, std::size_t line,
                      std::string_view what, std::string_view text);

// A finite number, whole field consumed (locale-independent). The error
// message says what is wrong with `name`, without a location.
core::Result<double> parseFiniteNumber(std::string_view field, std::string_view name);

bool isRegularFile(const std::filesystem::path& path);
bool pathExists(const std::filesystem::path& path);

// The directory's own name ("redkitchen" for "../shared/data/redkitchen/").
std::string datasetName(const std::filesystem::path& dir);

// frame.gray (CV_8UC1) and frame.color (CV_8UC3 BGR) from a decoded 8-bit
// image of 1, 3 (BGR) or 4 (BGRA) channels. Errors name `source`.
core::Status toGrayAndColor(const cv::Mat& img, const std::string& source, source::Frame& frame);

// "WxH".
std::string sizeText(int width_px, int height_px);

// DatasetOptions::folder_fps: finite and in (0, 1e9] (1 ns frame period).
core::Status validateFps(double fps);

// One frame of a replayed sequence, everything but the pixels.
struct ReplayFrame {
    int64_t t_ns = 0;
    std::filesystem::path image;
    std::string listed_as;       // the image as the index names it, for messages
    std::size_t index_line = 0;  // line of the index file that named the image
    std::optional<core::CameraPose> T_CtoW_gt;
    std::optional<std::filesystem::path> depth_path;
    std::optional<core::Vec3> accel_C;
};

struct ReplayIndex {
    source::SequenceInfo info;
    // rgb.txt or times.txt. For frames with index_line 0 (an image folder
    // without times.txt) a missing image is reported without it.
    std::filesystem::path index_file;
    std::vector<ReplayFrame> frames;
};

// Applies DatasetOptions::drop_missing_tail: frames after the last one whose
// image exists are dropped (a partial download) and a note says so. Fails
// when the index lists no frame or none of its images exists.
core::Status trimMissingTail(ReplayIndex& index, const DatasetOptions& opt);

// Chooses the intrinsics (opt.intrinsics overrides `from_dataset`), takes the
// image size from `image_size` when it is not given (its errors are returned
// unchanged), validates them and fills info.intrinsics / info.has_intrinsics
// (or adds the "no intrinsics" note). `dataset_source` names where
// `from_dataset` came from, for error messages.
core::Status chooseIntrinsics(source::SequenceInfo& info,
                              const std::optional<core::CameraIntrinsics>& from_dataset,
                              std::string_view dataset_source, const DatasetOptions& opt,
                              const std::function<core::Result<cv::Size>()>& image_size);

// chooseIntrinsics() for a replayed index: the image size comes from the
// first existing image.
core::Status resolveIntrinsics(ReplayIndex& index,
                               const std::optional<core::CameraIntrinsics>& from_dataset,
                               std::string_view dataset_source, const DatasetOptions& opt);

// resolveIntrinsics() with the intrinsics of `camera_file` (camera.txt
// format, readOptionalCameraFile) when it exists. Defined in dataset_tum.cpp.
core::Status resolveIntrinsicsFromCameraFile(ReplayIndex& index,
                                             const std::filesystem::path& camera_file,
                                             const DatasetOptions& opt);

// Nanoseconds from seconds; fails on non-finite, negative or huge values.
core::Result<int64_t> toleranceNs(double seconds);

// Index of the element of sorted `times` nearest to `t` if within `tol_ns`.
std::optional<std::size_t> nearestWithin(const std::vector<int64_t>& times, int64_t t,
                                         int64_t tol_ns);

std::unique_ptr<source::FrameSource> makeReplaySource(ReplayIndex index);

// Reads the timestamps of an index file and insists they strictly increase.
class IncreasingTimestamps {
public:
    // The timestamp in `field` (seconds as text), read on `line`. The error says
    // what is wrong, without a location: callers wrap it with lineError.
    core::Result<std::int64_t> next(std::string_view field, std::size_t line);

private:
    std::optional<std::int64_t> last_t_ns_;
    std::size_t last_line_ = 0;
};

}  // namespace scaled::drivers::dataset::detail
