#include <cmath>
#include <exception>
#include <string>

#include <scaled/drivers/dataset/depth_image.h>
#include <scaled/drivers/dataset/image_file.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::ErrorCode;
using core::makeError;
using core::Result;

Result<cv::Mat> loadDepthMetres(const source::Frame& frame, const source::SequenceInfo& info) {
    const std::string which =
        "frame " + std::to_string(frame.id) +
        (frame.image_path.empty() ? std::string() : " (" + frame.image_path.string() + ")");
    if (!frame.depth_path) {
        return makeError(ErrorCode::kNotFound, which + ": no depth image for this frame");
    }
    const std::filesystem::path& path = *frame.depth_path;
    if (!(std::isfinite(info.depth_scale_m) && info.depth_scale_m > 0)) {
        return makeError(ErrorCode::kNotFound,
                         path.string() + ": the sequence has no depth scale (depth_scale_m " +
                             detail::shortNumber(info.depth_scale_m) + ")");
    }
    auto raw = loadImageUnchanged(path);
    if (!raw) {
        return raw.error();
    }
    if (raw->type() != CV_16UC1) {
        return makeError(ErrorCode::kParse,
                         path.string() + ": expected a 16-bit single-channel depth image (got " +
                             std::to_string(raw->channels()) + " channel(s) of OpenCV depth " +
                             std::to_string(raw->depth()) + ")");
    }
    try {
        cv::Mat metres;
        raw->convertTo(metres, CV_32F, info.depth_scale_m);
        return metres;
    } catch (const std::exception& e) {
        return makeError(ErrorCode::kIo,
                         path.string() + ": cannot convert the depth image: " + e.what());
    }
}

}  // namespace scaled::drivers::dataset
