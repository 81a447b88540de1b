#include "detect_report.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "json.h"

namespace scaled::tools {

using core::ErrorCode;
using core::makeError;
using core::Status;

namespace {

std::string fixed(double v, int decimals) {
    std::array<char, 64> buf{};
    std::snprintf(buf.data(), buf.size(), "%.*f", decimals, v);
    return buf.data();
}

std::string trimmed(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) {
        s.remove_prefix(1);
    }
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) {
        s.remove_suffix(1);
    }
    return std::string(s);
}

// A colour per class, stable across runs.
cv::Scalar classColour(int class_id) {
    static constexpr std::array<std::array<int, 3>, 8> kPalette = {{{56, 56, 255},
                                                                    {151, 157, 255},
                                                                    {31, 112, 255},
                                                                    {29, 178, 255},
                                                                    {49, 210, 207},
                                                                    {10, 249, 72},
                                                                    {23, 204, 146},
                                                                    {187, 212, 0}}};
    const auto& c = kPalette[static_cast<std::size_t>(class_id) % kPalette.size()];
    return {static_cast<double>(c[0]), static_cast<double>(c[1]), static_cast<double>(c[2])};
}

}  // namespace

std::vector<std::string> splitList(std::string_view text) {
    std::vector<std::string> out;
    while (true) {
        const std::size_t comma = text.find(',');
        out.push_back(trimmed(text.substr(0, comma)));
        if (comma == std::string_view::npos) {
            break;
        }
        text.remove_prefix(comma + 1);
    }
    return out;
}

std::string detectionsText(const drivers::detector::DetectionResult& result) {
    std::string s;
    for (const drivers::detector::ObjectDetection& d : result.detections) {
        s += std::string(d.class_name) + ' ' + fixed(static_cast<double>(d.score), 3) + ' ' +
             fixed(d.box.x_min_px, 1) + ' ' + fixed(d.box.y_min_px, 1) + ' ' +
             fixed(d.box.x_max_px, 1) + ' ' + fixed(d.box.y_max_px, 1) + '\n';
    }
    return s;
}

std::string detectionsJson(const std::filesystem::path& image,
                           const drivers::detector::DetectorInfo& info,
                           const drivers::detector::DetectionResult& result) {
    std::string s = "{\"class\":\"DETECTIONS\"";
    s += ",\"image\":" + jsonString(image.string());
    s += ",\"width\":" + std::to_string(result.width_px);
    s += ",\"height\":" + std::to_string(result.height_px);
    s += ",\"model\":" + jsonString(info.model_path.string());
    s += ",\"family\":" + jsonString(drivers::detector::toString(info.family));
    s += ",\"input_size\":" + std::to_string(info.input_size_px);
    s += ",\"timing_ms\":{\"pre\":" + jsonNumber(result.timing.pre_ms, 4) +
         ",\"forward\":" + jsonNumber(result.timing.forward_ms, 4) +
         ",\"post\":" + jsonNumber(result.timing.post_ms, 4) + "}";
    s += ",\"detections\":[";
    for (std::size_t i = 0; i < result.detections.size(); ++i) {
        const drivers::detector::ObjectDetection& d = result.detections[i];
        s += i == 0 ? "{" : ",{";
        s += "\"class_id\":" + std::to_string(d.class_id);
        s += ",\"class_name\":" + jsonString(d.class_name);
        s += ",\"score\":" + jsonNumber(static_cast<double>(d.score), 4);
        s += ",\"box\":[" + jsonNumber(d.box.x_min_px, 6) + "," + jsonNumber(d.box.y_min_px, 6) +
             "," + jsonNumber(d.box.x_max_px, 6) + "," + jsonNumber(d.box.y_max_px, 6) + "]}";
    }
    s += "]}\n";
    return s;
}

Status drawDetections(const cv::Mat& image, const drivers::detector::DetectionResult& result,
                      const std::filesystem::path& out) {
    try {
        cv::Mat canvas;
        if (image.channels() == 1) {
            cv::cvtColor(image, canvas, cv::COLOR_GRAY2BGR);
        } else if (image.channels() == 4) {
            cv::cvtColor(image, canvas, cv::COLOR_BGRA2BGR);
        } else {
            canvas = image.clone();
        }
        for (const drivers::detector::ObjectDetection& d : result.detections) {
            const cv::Scalar colour = classColour(d.class_id);
            const cv::Point p0(static_cast<int>(d.box.x_min_px), static_cast<int>(d.box.y_min_px));
            const cv::Point p1(static_cast<int>(d.box.x_max_px), static_cast<int>(d.box.y_max_px));
            cv::rectangle(canvas, p0, p1, colour, 2);
            const std::string label =
                std::string(d.class_name) + " " + fixed(static_cast<double>(d.score), 2);
            int baseline = 0;
            const cv::Size size =
                cv::getTextSize(label, cv::FONT_HERSHEY_SIMPLEX, 0.5, 1, &baseline);
            const int y = std::max(p0.y, size.height + 2);
            cv::rectangle(canvas, cv::Point(p0.x, y - size.height - 2),
                          cv::Point(p0.x + size.width, y + baseline - 2), colour, cv::FILLED);
            cv::putText(canvas, label, cv::Point(p0.x, y - 2), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                        cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
        }
        if (!cv::imwrite(out.string(), canvas)) {
            return makeError(ErrorCode::kIo, out.string() + ": cannot write the image");
        }
    } catch (const cv::Exception& e) {
        return makeError(ErrorCode::kIo, out.string() + ": cannot write the image (" + e.err + ")");
    }
    return {};
}

}  // namespace scaled::tools
