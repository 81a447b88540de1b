#pragma once

// The YOLO detectors on OpenCV DNN (CPU), with the pre- and post-processing
// of each model family as the models in ../shared/models were exported:
//
//   kYolox    YOLOX ONNX (e.g. yolox_nano.onnx), any input size that is a
//             multiple of 32. Resize keeping the aspect ratio, paste at the
//             top-left of an S x S canvas filled with 114, BGR, 0..255, no
//             mean/std. Output 1 x N x (5 + C), rows of strides 8, 16, 32,
//             each grid row-major: (px, py, pw, ph, obj, cls[C]) with obj and
//             cls already sigmoided; cx = (px + gx) stride, w = exp(pw) stride;
//             score = obj cls; boxes divided by the resize ratio.
//   kDarknet  Darknet cfg + weights (e.g. Yolo-Fastest): plain resize to S x S
//             (no letterbox), RGB, 1/255. Rows (cx, cy, w, h) as fractions of
//             the image, objectness, class scores already times objectness.
//
// Non-maximum suppression is per class (boxes of different classes never
// suppress each other): boxes are offset by class before one NMSBoxes call
// (yolo_decode.h).
//
// create() loads the model, checks that it outputs one score per class name,
// and runs one warm-up forward pass at the configured size. Every failure is
// an Error naming the file; OpenCV exceptions do not leave this module.
//
// Threads: OpenCV's thread count is a process-wide setting; a non-zero
// `threads` sets it (cv::setNumThreads) at create() and before each forward.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/detector/thread_priority.h>

namespace scaled::drivers::detector {

enum class ModelFamily : std::uint8_t { kYolox, kDarknet };

const char* toString(ModelFamily family);
// "yolox" or "darknet"; kInvalidArgument otherwise.
core::Result<ModelFamily> parseModelFamily(std::string_view text);
// kDarknet for a .cfg file, else kYolox.
ModelFamily familyFromPath(const std::filesystem::path& model_path);

struct DetectorConfig {
    ModelFamily family = ModelFamily::kYolox;
    std::filesystem::path model_path;    // .onnx (kYolox) or .cfg (kDarknet)
    std::filesystem::path weights_path;  // kDarknet; empty: model_path with extension .weights
    std::filesystem::path names_path;    // one class name per line; empty: coco.names next to
                                         // the model
    int input_size_px = 416;             // network input S x S; a multiple of 32 in [64, 1280]
    float score_threshold = 0.3F;        // minimum obj x cls, in (0, 1]
    float nms_iou_threshold = 0.45F;     // boxes of one class overlapping more are merged, (0, 1]
    std::vector<std::string> classes;    // allow-list of class names; empty: every class
    int threads = 0;                     // OpenCV threads; 0 leaves OpenCV's setting alone
    int nice = 10;  // the daemon's detection threads' nice value, in [0, 19] (thread_priority.h)
    int max_detections = 100;  // per image, highest scores first, in [1, 10000]
};

// Checks the ranges (not the files). The message names the field and value.
// The allowed values of DetectorConfig's numbers (core/param_limits.h):
// validate() checks them, the daemon's [detector] section offers them.
struct DetectorLimits {
    static constexpr core::ParamLimits input_size_px = core::closed(64, 1280);  // a multiple of 32
    static constexpr core::ParamLimits score_threshold = core::openClosed(0, 1);
    static constexpr core::ParamLimits nms_iou_threshold = core::openClosed(0, 1);
    static constexpr core::ParamLimits threads = core::closed(0, 256);  // 0: OpenCV's default
    static constexpr core::ParamLimits nice = core::closed(kMinNice, kMaxNice);
    static constexpr core::ParamLimits max_detections = core::closed(1, 10000);
};

core::Status validate(const DetectorConfig& config);

// The names file: one non-empty name per line (a trailing newline and '\r'
// are allowed). Errors name the file and the line.
core::Result<std::vector<std::string>> readClassNames(const std::filesystem::path& names_file);

// What a loaded detector is.
struct DetectorInfo {
    ModelFamily family = ModelFamily::kYolox;
    std::filesystem::path model_path;
    std::filesystem::path weights_path;  // kDarknet only
    std::filesystem::path names_path;
    int input_size_px = 0;
    int class_count = 0;
};

class DnnDetector final : public ObjectDetector {
public:
    static core::Result<std::unique_ptr<DnnDetector>> create(const DetectorConfig& config);

    DnnDetector(const DnnDetector&) = delete;
    DnnDetector& operator=(const DnnDetector&) = delete;
    DnnDetector(DnnDetector&&) = delete;
    DnnDetector& operator=(DnnDetector&&) = delete;
    ~DnnDetector() override;

    core::Status detect(const cv::Mat& image, std::int64_t frame_id, std::int64_t t_ns,
                        DetectionResult& out) override;
    [[nodiscard]] std::span<const std::string> classNames() const override;

    [[nodiscard]] const DetectorInfo& info() const;
    [[nodiscard]] const DetectorConfig& config() const;

private:
    struct Impl;
    explicit DnnDetector(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace scaled::drivers::detector
