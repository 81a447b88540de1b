#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/dnn.hpp>
#include <utility>

#include <scaled/drivers/detector/yolo_decode.h>

namespace scaled::drivers::detector {

using core::Scalar;

namespace {

constexpr std::array<int, 3> kYoloxStrides = {8, 16, 32};
constexpr std::size_t kBoxColumns = 5;  // cx, cy, w, h, objectness

}  // namespace

std::vector<YoloxCell> makeYoloxGrid(int input_size_px) {
    std::vector<YoloxCell> grid;
    for (const int stride : kYoloxStrides) {
        const int n = input_size_px / stride;
        for (int gy = 0; gy < n; ++gy) {
            for (int gx = 0; gx < n; ++gx) {
                grid.push_back({static_cast<double>(gx), static_cast<double>(gy),
                                static_cast<double>(stride)});
            }
        }
    }
    return grid;
}

YoloDecoder::YoloDecoder(std::vector<unsigned char> allowed, std::size_t max_candidates)
    : allowed_(std::move(allowed)) {
    boxes_.reserve(max_candidates);
    shifted_.reserve(max_candidates);
    scores_.reserve(max_candidates);
    class_ids_.reserve(max_candidates);
    keep_.reserve(max_candidates);
}

void YoloDecoder::clear() {
    boxes_.clear();
    scores_.clear();
    class_ids_.clear();
}

int YoloDecoder::bestClass(const float* cls, float& best) const {
    int best_id = -1;
    best = 0;
    for (std::size_t c = 0; c < allowed_.size(); ++c) {
        if (allowed_[c] != 0 && cls[c] > best) {
            best = cls[c];
            best_id = static_cast<int>(c);
        }
    }
    return best_id;
}

void YoloDecoder::add(double x0, double y0, double x1, double y1, float score, int class_id) {
    boxes_.emplace_back(x0, y0, x1 - x0, y1 - y0);
    scores_.push_back(score);
    class_ids_.push_back(class_id);
}

void YoloDecoder::addYolox(const float* rows, std::span<const YoloxCell> grid, double ratio,
                           float score_threshold) {
    const std::size_t cols = kBoxColumns + allowed_.size();
    for (std::size_t i = 0; i < grid.size(); ++i) {
        const float* row = rows + i * cols;
        const float obj = row[4];
        if (!(obj >= score_threshold)) {
            continue;  // score = obj * cls <= obj (and NaN never passes)
        }
        float cls = 0;
        const int id = bestClass(row + kBoxColumns, cls);
        const float score = obj * cls;
        if (id < 0 || !(score >= score_threshold)) {
            continue;
        }
        const YoloxCell& g = grid[i];
        const double cx = (static_cast<double>(row[0]) + g.gx) * g.stride;
        const double cy = (static_cast<double>(row[1]) + g.gy) * g.stride;
        const double w = std::exp(static_cast<double>(row[2])) * g.stride;
        const double h = std::exp(static_cast<double>(row[3])) * g.stride;
        if (!(std::isfinite(cx) && std::isfinite(cy) && std::isfinite(w) && std::isfinite(h))) {
            continue;
        }
        add((cx - w / 2) / ratio, (cy - h / 2) / ratio, (cx + w / 2) / ratio, (cy + h / 2) / ratio,
            score, id);
    }
}

void YoloDecoder::addDarknet(const float* rows, std::size_t row_count, int width_px, int height_px,
                             float score_threshold) {
    const std::size_t cols = kBoxColumns + allowed_.size();
    for (std::size_t i = 0; i < row_count; ++i) {
        const float* row = rows + i * cols;
        if (!(row[4] >= score_threshold)) {
            continue;  // class scores are objectness times class probability
        }
        float score = 0;
        const int id = bestClass(row + kBoxColumns, score);
        if (id < 0 || !(score >= score_threshold)) {
            continue;
        }
        const double cx = static_cast<double>(row[0]) * width_px;
        const double cy = static_cast<double>(row[1]) * height_px;
        const double w = static_cast<double>(row[2]) * width_px;
        const double h = static_cast<double>(row[3]) * height_px;
        if (!(std::isfinite(cx) && std::isfinite(cy) && std::isfinite(w) && std::isfinite(h))) {
            continue;
        }
        add(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2, score, id);
    }
}

void YoloDecoder::finish(std::span<const std::string> names, float score_threshold,
                         float nms_iou_threshold, int max_detections, DetectionResult& out) {
    // Class-aware NMS in one NMSBoxes call: each class's boxes move to their
    // own strip of the plane, far enough apart that boxes of different classes
    // cannot overlap. Not NMSBoxesBatched (OpenCV 4.7+), whose offset ignores
    // negative coordinates (docs/detector.md).
    double extent = 1;
    for (const cv::Rect2d& b : boxes_) {
        extent = std::max({extent, std::abs(b.x), std::abs(b.y), std::abs(b.x + b.width),
                           std::abs(b.y + b.height)});
    }
    const double offset = 2 * extent + 1;
    shifted_.clear();
    for (std::size_t i = 0; i < boxes_.size(); ++i) {
        cv::Rect2d b = boxes_[i];
        b.x += offset * class_ids_[i];
        shifted_.push_back(b);
    }
    keep_.clear();
    cv::dnn::NMSBoxes(shifted_, scores_, score_threshold, nms_iou_threshold, keep_);
    // NMSBoxes returns the kept indices by decreasing score.
    const double x_max = std::max(out.width_px - 1, 0);
    const double y_max = std::max(out.height_px - 1, 0);
    for (const int k : keep_) {
        if (out.detections.size() >= static_cast<std::size_t>(max_detections)) {
            break;
        }
        const auto i = static_cast<std::size_t>(k);
        const cv::Rect2d& b = boxes_[i];
        ObjectDetection d;
        d.box.x_min_px = static_cast<Scalar>(std::clamp(b.x, 0.0, x_max));
        d.box.y_min_px = static_cast<Scalar>(std::clamp(b.y, 0.0, y_max));
        d.box.x_max_px = static_cast<Scalar>(std::clamp(b.x + b.width, 0.0, x_max));
        d.box.y_max_px = static_cast<Scalar>(std::clamp(b.y + b.height, 0.0, y_max));
        if (!(d.box.x_max_px > d.box.x_min_px && d.box.y_max_px > d.box.y_min_px)) {
            continue;  // nothing of it inside the image
        }
        d.class_id = class_ids_[i];
        d.class_name = names[static_cast<std::size_t>(d.class_id)];
        d.score = scores_[i];
        out.detections.push_back(d);
    }
}

}  // namespace scaled::drivers::detector
