#include <cstdint>
#include <exception>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <system_error>
#include <vector>

#include <scaled/drivers/dataset/image_file.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::ErrorCode;
using core::makeError;
using core::Result;
using detail::kMaxImageBytes;

Result<cv::Mat> loadImageUnchanged(const std::filesystem::path& path) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kNotFound, path.string() + ": image file not found");
    }
    if (!std::filesystem::is_regular_file(status)) {
        return makeError(ErrorCode::kIo, path.string() + ": not a regular file");
    }
    const std::uintmax_t size = std::filesystem::file_size(path, ec);
    if (ec) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot read image: " + ec.message());
    }
    if (size == 0) {
        return makeError(ErrorCode::kParse, path.string() + ": cannot decode image: empty file");
    }
    if (size > kMaxImageBytes) {
        return makeError(ErrorCode::kIo, path.string() + ": image file too large (" +
                                             std::to_string(size) + " bytes)");
    }
    try {
        std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
        std::ifstream in(path, std::ios::binary);
        in.read(reinterpret_cast<char*>(bytes.data()),  // NOLINT(*-reinterpret-cast)
                static_cast<std::streamsize>(bytes.size()));
        if (!in || static_cast<std::uintmax_t>(in.gcount()) != size) {
            return makeError(ErrorCode::kIo, path.string() + ": cannot read image file");
        }
        cv::Mat img = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
        if (img.empty()) {
            return makeError(ErrorCode::kParse,
                             path.string() + ": cannot decode image (corrupt or unknown format)");
        }
        return img;
    } catch (const std::exception& e) {
        return makeError(ErrorCode::kParse,
                         path.string() + ": cannot decode image: " + std::string(e.what()));
    }
}

Result<cv::Mat> loadImage(const std::filesystem::path& path) {
    auto img = loadImageUnchanged(path);
    if (!img) {
        return img;
    }
    if (img->depth() != CV_8U) {
        return makeError(ErrorCode::kParse, path.string() +
                                                ": expected an 8-bit image (got OpenCV depth " +
                                                std::to_string(img->depth()) + ")");
    }
    if (img->channels() != 1 && img->channels() != 3 && img->channels() != 4) {
        return makeError(ErrorCode::kParse, path.string() + ": unsupported image with " +
                                                std::to_string(img->channels()) + " channels");
    }
    return img;
}

}  // namespace scaled::drivers::dataset
