#pragma once

// What scaled-detect prints and draws (a library, so tests can check it).

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/detector/dnn_detector.h>

namespace scaled::tools {

// "a,b , c" -> {"a", "b", "c"} (blanks around names trimmed, empty items kept
// as empty strings so that validate() can name them).
std::vector<std::string> splitList(std::string_view text);

// One line per detection: `class_name score x_min y_min x_max y_max`.
std::string detectionsText(const drivers::detector::DetectionResult& result);

// One JSON object (one line) with class "DETECTIONS": image, size, model,
// family, input size, timing, and the detections.
std::string detectionsJson(const std::filesystem::path& image,
                           const drivers::detector::DetectorInfo& info,
                           const drivers::detector::DetectionResult& result);

// The image with boxes and labels, written to `out` (format from its extension).
core::Status drawDetections(const cv::Mat& image, const drivers::detector::DetectionResult& result,
                            const std::filesystem::path& out);

}  // namespace scaled::tools
