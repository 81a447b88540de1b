#pragma once

// ObjectDetector: boxes of everyday objects in one image. The interface the
// pipeline calls (and tests replace); dnn_detector.h implements it with
// OpenCV DNN on the CPU.
//
// A detector belongs to one thread at a time: detect() reuses the detector's
// buffers and is not reentrant.

#include <cstdint>
#include <opencv2/core.hpp>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::drivers::detector {

struct ObjectDetection {
    // Pixels of the image given to detect() (x right, y down), clipped to
    // [0, width - 1] x [0, height - 1].
    core::BoundingBox box;
    int class_id = -1;
    std::string_view class_name;  // points into the detector's names; valid while it lives
    float score = 0;              // objectness x class probability, in (0, 1]
};

// Wall-clock cost of one detect(), milliseconds.
struct DetectionTiming {
    double pre_ms = 0;      // colour conversion, resize, letterbox, blob
    double forward_ms = 0;  // the network
    double post_ms = 0;     // decoding, thresholds, class-aware NMS
    [[nodiscard]] double totalMs() const { return pre_ms + forward_ms + post_ms; }
};

// The detections of one frame, tagged with the frame they were computed on
// (detection runs late; the tags pair them with the SLAM snapshot of that frame).
struct DetectionResult {
    std::int64_t frame_id = 0;
    std::int64_t t_ns = 0;
    int width_px = 0;
    int height_px = 0;
    std::vector<ObjectDetection> detections;  // by decreasing score
    DetectionTiming timing;
};

class ObjectDetector {
public:
    ObjectDetector() = default;
    ObjectDetector(const ObjectDetector&) = delete;
    ObjectDetector& operator=(const ObjectDetector&) = delete;
    ObjectDetector(ObjectDetector&&) = delete;
    ObjectDetector& operator=(ObjectDetector&&) = delete;
    virtual ~ObjectDetector() = default;

    // Detects objects in `image` (CV_8UC1 gray, CV_8UC3 BGR or CV_8UC4 BGRA).
    // `out` is overwritten; its vector keeps its capacity between calls.
    // Errors: an empty or unsupported image (kInvalidArgument), or a failure
    // inside the network (kIo); never throws.
    virtual core::Status detect(const cv::Mat& image, std::int64_t frame_id, std::int64_t t_ns,
                                DetectionResult& out) = 0;

    // Class names in model output order.
    [[nodiscard]] virtual std::span<const std::string> classNames() const = 0;
};

// The detections as the scale estimator takes them (class names are views
// into the detector's names). Writes min(out.size(), result size) entries and
// returns how many.
std::size_t toEstimatorDetections(const DetectionResult& result, std::span<core::Detection> out);

}  // namespace scaled::drivers::detector
