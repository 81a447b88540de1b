#include <optional>
#include <string>
#include <system_error>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_folder.h>
#include <scaled/drivers/dataset/dataset_kitti.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/dataset_video.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::dataset {

using core::ErrorCode;
using core::makeError;
using core::Result;

std::optional<DatasetFormat> parseDatasetFormat(std::string_view text) {
    if (text == "tum") {
        return DatasetFormat::kTum;
    }
    if (text == "kitti") {
        return DatasetFormat::kKitti;
    }
    if (text == "folder") {
        return DatasetFormat::kImageFolder;
    }
    if (text == "video") {
        return DatasetFormat::kVideo;
    }
    return std::nullopt;
}

Result<std::unique_ptr<source::FrameSource>> openDataset(const std::filesystem::path& path,
                                                         const DatasetOptions& opt) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kNotFound,
                         path.string() + ": dataset directory or video file not found");
    }
    const bool is_dir = std::filesystem::is_directory(status);
    std::optional<DatasetFormat> format = opt.format;
    if (!format) {
        if (std::filesystem::is_regular_file(status)) {
            format = DatasetFormat::kVideo;
        } else if (!is_dir) {
            return makeError(ErrorCode::kNotFound,
                             path.string() + ": neither a dataset directory nor a video file");
        } else if (std::filesystem::is_regular_file(path / "rgb.txt", ec)) {
            format = DatasetFormat::kTum;
        } else if (std::filesystem::is_regular_file(path / "times.txt", ec) &&
                   std::filesystem::is_directory(path / "image_0", ec)) {
            format = DatasetFormat::kKitti;
        } else {
            auto images = listImageFiles(path);
            if (!images) {
                return images.error();
            }
            if (images->empty()) {
                return makeError(ErrorCode::kNotFound,
                                 path.string() +
                                     ": not a dataset directory (expected rgb.txt for TUM, "
                                     "times.txt and image_0/ for KITTI, or image files)");
            }
            format = DatasetFormat::kImageFolder;
        }
    }
    switch (*format) {
        case DatasetFormat::kVideo:
            return openVideo(path, opt);
        case DatasetFormat::kImageFolder:
            return openImageFolder(path, opt);
        case DatasetFormat::kKitti:
            return openKittiDataset(path, opt);
        case DatasetFormat::kTum:
            break;
    }
    return openTumDataset(path, opt);
}

}  // namespace scaled::drivers::dataset
