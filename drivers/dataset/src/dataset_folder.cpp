#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_folder.h>
#include <scaled/drivers/dataset/dataset_kitti.h>
#include <scaled/drivers/dataset/dataset_tum.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

constexpr std::array<std::string_view, 8> kImageExtensions = {".png", ".jpg", ".jpeg", ".pgm",
                                                              ".ppm", ".bmp", ".tif",  ".tiff"};

bool isDigit(char c) {
    return c >= '0' && c <= '9';
}

unsigned char lowerAscii(char c) {
    const auto u = static_cast<unsigned char>(c);
    return (u >= 'A' && u <= 'Z') ? static_cast<unsigned char>(u - 'A' + 'a') : u;
}

// <0, 0, >0 like strcmp, in natural order (see naturalLess).
int naturalCompare(std::string_view a, std::string_view b) {
    std::size_t i = 0;
    std::size_t j = 0;
    while (i < a.size() && j < b.size()) {
        if (isDigit(a[i]) && isDigit(b[j])) {
            const std::size_t start_a = i;
            const std::size_t start_b = j;
            while (i < a.size() && isDigit(a[i])) {
                ++i;
            }
            while (j < b.size() && isDigit(b[j])) {
                ++j;
            }
            // Leading zeros do not count (keep one digit of "000").
            std::size_t za = start_a;
            while (za + 1 < i && a[za] == '0') {
                ++za;
            }
            std::size_t zb = start_b;
            while (zb + 1 < j && b[zb] == '0') {
                ++zb;
            }
            const std::size_t len_a = i - za;
            const std::size_t len_b = j - zb;
            if (len_a != len_b) {
                return len_a < len_b ? -1 : 1;
            }
            const int c = a.substr(za, len_a).compare(b.substr(zb, len_b));
            if (c != 0) {
                return c;
            }
            continue;
        }
        const unsigned char ca = lowerAscii(a[i]);
        const unsigned char cb = lowerAscii(b[j]);
        if (ca != cb) {
            return ca < cb ? -1 : 1;
        }
        ++i;
        ++j;
    }
    if (i < a.size()) {
        return 1;
    }
    if (j < b.size()) {
        return -1;
    }
    return 0;
}

}  // namespace

bool isImageFileName(const std::filesystem::path& name) {
    const std::string ext = name.extension().string();
    return std::any_of(kImageExtensions.begin(), kImageExtensions.end(), [&](std::string_view e) {
        return ext.size() == e.size() &&
               std::equal(ext.begin(), ext.end(), e.begin(),
                          [](char x, char y) { return lowerAscii(x) == lowerAscii(y); });
    });
}

bool naturalLess(std::string_view a, std::string_view b) {
    const int c = naturalCompare(a, b);
    return c != 0 ? c < 0 : a < b;
}

Result<std::vector<std::filesystem::path>> listImageFiles(const std::filesystem::path& dir) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec) || ec) {
        return makeError(ErrorCode::kNotFound, dir.string() + ": image folder not found");
    }
    std::vector<std::pair<std::string, std::filesystem::path>> named;
    try {
        std::filesystem::directory_iterator it(dir, ec);
        if (ec) {
            return makeError(ErrorCode::kIo,
                             dir.string() + ": cannot list the folder: " + ec.message());
        }
        for (; it != std::filesystem::directory_iterator(); it.increment(ec)) {
            if (ec) {
                return makeError(ErrorCode::kIo,
                                 dir.string() + ": cannot list the folder: " + ec.message());
            }
            const std::filesystem::path& p = it->path();
            std::string name = p.filename().string();
            if (name.empty() || name.front() == '.' || !isImageFileName(p)) {
                continue;
            }
            std::error_code file_ec;
            if (!std::filesystem::is_regular_file(p, file_ec) || file_ec) {
                continue;  // a directory named x.png, a dangling link
            }
            named.emplace_back(std::move(name), p);
        }
        if (ec) {
            return makeError(ErrorCode::kIo,
                             dir.string() + ": cannot list the folder: " + ec.message());
        }
    } catch (const std::exception& e) {
        return makeError(ErrorCode::kIo,
                         dir.string() + ": cannot list the folder: " + std::string(e.what()));
    }
    std::sort(named.begin(), named.end(),
              [](const auto& x, const auto& y) { return naturalLess(x.first, y.first); });
    std::vector<std::filesystem::path> out;
    out.reserve(named.size());
    for (auto& [name, path] : named) {
        out.push_back(std::move(path));
    }
    return out;
}

Result<std::unique_ptr<source::FrameSource>> openImageFolder(const std::filesystem::path& dir,
                                                             const DatasetOptions& opt) {
    if (auto fps = detail::validateFps(opt.folder_fps); !fps) {
        return fps.error();
    }
    auto images = listImageFiles(dir);
    if (!images) {
        return images.error();
    }
    if (images->empty()) {
        return makeError(ErrorCode::kNotFound,
                         dir.string() +
                             ": no images in the folder (expected .png .jpg .jpeg .pgm .ppm "
                             ".bmp .tif or .tiff files)");
    }

    detail::ReplayIndex index;
    index.info.name = detail::datasetName(dir);
    index.info.dir = dir;
    index.index_file = dir;
    index.frames.reserve(images->size());
    for (std::filesystem::path& p : *images) {
        detail::ReplayFrame f;
        f.listed_as = p.filename().string();
        f.image = std::move(p);
        index.frames.push_back(std::move(f));
    }
    const std::size_t n = index.frames.size();

    const std::filesystem::path times_file = dir / "times.txt";
    if (detail::pathExists(times_file)) {
        auto times = readKittiTimes(times_file);
        if (!times) {
            return times.error();
        }
        if (times->size() < n) {
            return makeError(ErrorCode::kParse,
                             times_file.string() + ": has " + std::to_string(times->size()) +
                                 " times for the " + std::to_string(n) +
                                 " images of the folder (one line per image, in natural order)");
        }
        if (times->size() > n) {
            index.info.notes.push_back(times_file.string() + " has " +
                                       std::to_string(times->size()) + " times for " +
                                       std::to_string(n) + " images: the extra times are unused");
        }
        index.index_file = times_file;
        for (std::size_t i = 0; i < n; ++i) {
            index.frames[i].t_ns = (*times)[i].t_ns;
            index.frames[i].index_line = (*times)[i].line;
        }
    } else {
        const double period_ns = 1e9 / opt.folder_fps;
        constexpr double kMaxNs = 9.0e18;  // below INT64_MAX with margin for rounding
        if (!(static_cast<double>(n - 1) * period_ns <= kMaxNs)) {
            return makeError(ErrorCode::kInvalidArgument,
                             dir.string() + ": " + std::to_string(n) + " frames at " +
                                 detail::shortNumber(opt.folder_fps) +
                                 " Hz overflow the nanosecond timestamps");
        }
        for (std::size_t i = 0; i < n; ++i) {
            index.frames[i].t_ns = std::llround(static_cast<double>(i) * period_ns);
        }
        index.info.notes.push_back(dir.string() + ": no times.txt: frames timed at " +
                                   detail::shortNumber(opt.folder_fps) + " Hz");
    }
    index.info.listed_count = n;
    index.info.frame_count = n;

    if (auto resolved = detail::resolveIntrinsicsFromCameraFile(index, dir / "camera.txt", opt);
        !resolved) {
        return resolved.error();
    }
    return detail::makeReplaySource(std::move(index));
}

}  // namespace scaled::drivers::dataset
