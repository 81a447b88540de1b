#pragma once

// Post-processing of YOLO outputs, separate from the network so that the
// decoding formulas and the class-aware NMS are tested on synthetic tensors
// (dnn_detector.h describes the two families' output layouts).

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <span>
#include <string>
#include <vector>

#include <scaled/drivers/detector/object_detector.h>

namespace scaled::drivers::detector {

// Where one row of a YOLOX output sits: grid cell and stride.
struct YoloxCell {
    double gx = 0;
    double gy = 0;
    double stride = 0;
};

// The rows of a YOLOX output at input size S: strides 8, 16, 32, each grid
// row-major ((S / stride)^2 cells per stride).
std::vector<YoloxCell> makeYoloxGrid(int input_size_px);

class YoloDecoder {
public:
    // `allowed`: one flag per class (non-zero: keep). Scratch buffers are
    // reserved for `max_candidates` boxes per image.
    YoloDecoder(std::vector<unsigned char> allowed, std::size_t max_candidates);

    void clear();

    // YOLOX rows (px, py, pw, ph, obj, cls[C]), C = allowed.size(), one per
    // grid cell. `ratio` is the letterbox resize ratio (network px per image px).
    void addYolox(const float* rows, std::span<const YoloxCell> grid, double ratio,
                  float score_threshold);

    // Darknet rows (cx, cy, w, h fractions of the image, obj, cls[C] already
    // times obj), for an image of width x height pixels.
    void addDarknet(const float* rows, std::size_t row_count, int width_px, int height_px,
                    float score_threshold);

    // Class-aware NMS over everything added, then the kept boxes (by
    // decreasing score, at most max_detections) clipped to the image and
    // appended to out.detections with names from `names`.
    void finish(std::span<const std::string> names, float score_threshold, float nms_iou_threshold,
                int max_detections, DetectionResult& out);

    [[nodiscard]] std::size_t candidateCount() const { return scores_.size(); }

private:
    int bestClass(const float* cls, float& best) const;
    void add(double x0, double y0, double x1, double y1, float score, int class_id);

    std::vector<unsigned char> allowed_;
    std::vector<cv::Rect2d> boxes_;
    std::vector<cv::Rect2d> shifted_;
    std::vector<float> scores_;
    std::vector<int> class_ids_;
    std::vector<int> keep_;
};

}  // namespace scaled::drivers::detector
