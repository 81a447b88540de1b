#include <string>
#include <system_error>

#include <scaled/drivers/dataset_kitti.h>
#include <scaled/drivers/dataset_tum.h>
#include <scaled/drivers/frame_source.h>

namespace scaled::drivers {

using core::ErrorCode;
using core::makeError;
using core::Result;

Result<std::unique_ptr<FrameSource>> openDataset(const std::filesystem::path& dir,
                                                 const DatasetOptions& opt) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec) || ec) {
        return makeError(ErrorCode::kNotFound, dir.string() + ": dataset directory not found");
    }
    std::optional<DatasetFormat> format = opt.format;
    if (!format) {
        if (std::filesystem::is_regular_file(dir / "rgb.txt", ec)) {
            format = DatasetFormat::kTum;
        } else if (std::filesystem::is_regular_file(dir / "times.txt", ec) &&
                   std::filesystem::is_directory(dir / "image_0", ec)) {
            format = DatasetFormat::kKitti;
        } else {
            return makeError(ErrorCode::kNotFound,
                             dir.string() +
                                 ": not a dataset directory (expected rgb.txt for TUM, or "
                                 "times.txt and image_0/ for KITTI)");
        }
    }
    if (*format == DatasetFormat::kKitti) {
        return openKittiDataset(dir, opt);
    }
    return openTumDataset(dir, opt);
}

}  // namespace scaled::drivers
