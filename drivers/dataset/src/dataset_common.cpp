#include "dataset_common.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>
#include <system_error>
#include <utility>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/image_file.h>
#include <scaled/drivers/dataset/trajectory_io.h>

namespace scaled::drivers::dataset::detail {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

constexpr std::size_t kMaxShownChars = 120;

bool isBlank(char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

char lowerAscii(char c) {
    return (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c;
}

template <typename Fn>
void forEachLine(std::string_view text, Fn&& fn) {
    std::size_t number = 0;
    std::size_t pos = 0;
    while (pos < text.size()) {
        std::size_t end = text.find('\n', pos);
        if (end == std::string_view::npos) {
            end = text.size();
        }
        std::string_view line = text.substr(pos, end - pos);
        if (!line.empty() && line.back() == '\r') {
            line.remove_suffix(1);
        }
        ++number;
        fn(number, line);
        pos = end + 1;
    }
}

std::string_view trimmed(std::string_view s) {
    while (!s.empty() && isBlank(s.front())) {
        s.remove_prefix(1);
    }
    while (!s.empty() && isBlank(s.back())) {
        s.remove_suffix(1);
    }
    return s;
}

class ReplaySource final : public source::FrameSource {
public:
    explicit ReplaySource(ReplayIndex index) : index_(std::move(index)) {}

    [[nodiscard]] const source::SequenceInfo& info() const override { return index_.info; }

    Result<bool> next(source::Frame& frame) override {
        if (cursor_ >= index_.frames.size()) {
            return false;
        }
        const std::size_t i = cursor_++;
        const ReplayFrame& f = index_.frames[i];
        if (!isRegularFile(f.image)) {
            if (f.index_line == 0) {
                return makeError(ErrorCode::kNotFound, f.image.string() + ": image file not found");
            }
            return lineError(ErrorCode::kNotFound, index_.index_file, f.index_line,
                             "image file not found: " + f.image.string(), f.listed_as);
        }
        auto img = drivers::dataset::loadImage(f.image);
        if (!img) {
            return img.error();
        }
        const source::SequenceInfo& info = index_.info;
        if (info.has_intrinsics &&
            (img->cols != info.intrinsics.width_px || img->rows != info.intrinsics.height_px)) {
            return makeError(ErrorCode::kInvalidArgument,
                             f.image.string() + ": image is " + sizeText(img->cols, img->rows) +
                                 " but the intrinsics are for " +
                                 sizeText(info.intrinsics.width_px, info.intrinsics.height_px));
        }
        source::Frame out;
        if (auto split = toGrayAndColor(*img, f.image.string(), out); !split) {
            return split.error();
        }
        out.id = static_cast<int64_t>(i);
        out.t_ns = f.t_ns;
        out.T_CtoW_gt = f.T_CtoW_gt;
        out.depth_path = f.depth_path;
        out.image_path = f.image;
        out.accel_C = f.accel_C;
        if (info.gravity_down_W && f.T_CtoW_gt) {
            out.gravity_down_C =
                (f.T_CtoW_gt->R_CtoW.transpose() * *info.gravity_down_W).normalized().eval();
        }
        frame = std::move(out);
        return true;
    }

    Result<bool> seek(std::size_t index) override {
        if (index > index_.frames.size()) {
            return makeError(ErrorCode::kInvalidArgument,
                             index_.info.name + ": cannot seek to frame " + std::to_string(index) +
                                 ": the sequence has " + std::to_string(index_.frames.size()) +
                                 " frames");
        }
        cursor_ = index;
        return index < index_.frames.size();
    }

private:
    ReplayIndex index_;
    std::size_t cursor_ = 0;
};

}  // namespace

Result<std::string> readTextFile(const std::filesystem::path& path) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kNotFound, path.string() + ": file not found");
    }
    if (!std::filesystem::is_regular_file(status)) {
        return makeError(ErrorCode::kIo, path.string() + ": not a regular file");
    }
    const std::uintmax_t size = std::filesystem::file_size(path, ec);
    if (ec) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot read: " + ec.message());
    }
    if (size > kMaxTextBytes) {
        return makeError(ErrorCode::kIo, path.string() + ": too large for an index file (" +
                                             std::to_string(size) + " bytes)");
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        return makeError(ErrorCode::kIo,
                         path.string() + ": cannot open: " + drivers::base::errnoText(errno));
    }
    std::string text;
    char buf[4096];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
        text.append(buf, static_cast<std::size_t>(in.gcount()));
        if (text.size() > kMaxTextBytes) {
            return makeError(ErrorCode::kIo, path.string() + ": too large for an index file");
        }
    }
    if (in.bad() || !in.eof()) {
        return makeError(ErrorCode::kIo, path.string() + ": read error");
    }
    return text;
}

std::vector<TextLine> dataLines(std::string_view text) {
    std::vector<TextLine> out;
    forEachLine(text, [&](std::size_t number, std::string_view line) {
        const std::string_view t = trimmed(line);
        if (!t.empty() && t.front() != '#') {
            out.push_back({number, line});
        }
    });
    return out;
}

bool commentMentions(std::string_view text, std::string_view needle) {
    bool found = false;
    forEachLine(text, [&](std::size_t /*number*/, std::string_view line) {
        const std::string_view t = trimmed(line);
        if (found || t.empty() || t.front() != '#' || needle.size() > t.size()) {
            return;
        }
        for (std::size_t i = 0; i + needle.size() <= t.size() && !found; ++i) {
            std::size_t k = 0;
            while (k < needle.size() && lowerAscii(t[i + k]) == lowerAscii(needle[k])) {
                ++k;
            }
            found = k == needle.size();
        }
    });
    return found;
}

std::vector<std::string_view> splitFields(std::string_view line) {
    std::vector<std::string_view> out;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && isBlank(line[i])) {
            ++i;
        }
        const std::size_t start = i;
        while (i < line.size() && !isBlank(line[i])) {
            ++i;
        }
        if (i > start) {
            out.push_back(line.substr(start, i - start));
        }
    }
    return out;
}

std::string printable(std::string_view text) {
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out;
    for (const char c : text) {
        if (out.size() >= kMaxShownChars) {
            out += "...";
            break;
        }
        const auto u = static_cast<unsigned char>(c);
        if (u >= 0x20 && u < 0x7f) {
            out += c;
        } else {
            out += "\\x";
            out += kHex[u >> 4U];
            out += kHex[u & 0xfU];
        }
    }
    return out;
}

std::string shortNumber(double v) {
    std::array<char, 64> buf{};
    const auto [ptr, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v);
    return ec == std::errc() ? std::string(buf.data(), ptr) : std::to_string(v);
}

core::Error lineError(ErrorCode code, const std::filesystem::path& file, std::size_t line,
                      std::string_view what, std::string_view text) {
    std::string msg = file.string();
    msg += ':';
    msg += std::to_string(line);
    msg += ": ";
    msg += what;
    msg += " (";
    msg += printable(trimmed(text));
    msg += ')';
    return makeError(code, std::move(msg));
}

Result<double> parseFiniteNumber(std::string_view field, std::string_view name) {
    std::string_view s = field;
    if (s.size() > 1 && s.front() == '+' && s[1] != '-' && s[1] != '+') {
        s.remove_prefix(1);
    }
    double v = 0;
    const char* const end = s.data() + s.size();
    const auto [ptr, ec] = std::from_chars(s.data(), end, v);
    if (ec == std::errc::result_out_of_range) {
        return makeError(ErrorCode::kParse,
                         std::string(name) + " is out of range: '" + printable(field) + "'");
    }
    if (ec != std::errc() || ptr != end) {
        return makeError(ErrorCode::kParse,
                         std::string(name) + " is not a number: '" + printable(field) + "'");
    }
    if (!std::isfinite(v)) {
        return makeError(ErrorCode::kParse,
                         std::string(name) + " is not finite: '" + printable(field) + "'");
    }
    return v;
}

bool isRegularFile(const std::filesystem::path& path) {
    std::error_code ec;
    return std::filesystem::is_regular_file(path, ec) && !ec;
}

bool pathExists(const std::filesystem::path& path) {
    std::error_code ec;
    return std::filesystem::exists(path, ec) && !ec;
}

std::string datasetName(const std::filesystem::path& dir) {
    std::filesystem::path p = dir.lexically_normal();
    if (!p.has_filename()) {
        p = p.parent_path();
    }
    std::string name = p.filename().string();
    return name.empty() || name == "." || name == ".." ? dir.string() : name;
}

std::string sizeText(int width_px, int height_px) {
    return std::to_string(width_px) + "x" + std::to_string(height_px);
}

Status toGrayAndColor(const cv::Mat& img, const std::string& source, source::Frame& frame) {
    if (img.empty() || img.depth() != CV_8U) {
        return makeError(ErrorCode::kParse, source + ": expected a non-empty 8-bit image");
    }
    try {
        switch (img.channels()) {
            case 1:
                frame.gray = img;
                cv::cvtColor(img, frame.color, cv::COLOR_GRAY2BGR);
                break;
            case 3:
                frame.color = img;
                cv::cvtColor(img, frame.gray, cv::COLOR_BGR2GRAY);
                break;
            case 4:
                cv::cvtColor(img, frame.color, cv::COLOR_BGRA2BGR);
                cv::cvtColor(img, frame.gray, cv::COLOR_BGRA2GRAY);
                break;
            default:
                return makeError(ErrorCode::kParse, source + ": unsupported image with " +
                                                        std::to_string(img.channels()) +
                                                        " channels");
        }
    } catch (const std::exception& e) {
        return makeError(ErrorCode::kIo,
                         source + ": cannot convert image: " + std::string(e.what()));
    }
    return {};
}

Status validateFps(double fps) {
    constexpr double kMaxFps = 1e9;  // a frame period of at least 1 ns
    if (!(std::isfinite(fps) && fps > 0 && fps <= kMaxFps)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "DatasetOptions.folder_fps must be finite and in (0, 1e9] Hz (got " +
                             shortNumber(fps) + ")");
    }
    return {};
}

Status trimMissingTail(ReplayIndex& index, const DatasetOptions& opt) {
    const std::size_t listed = index.frames.size();
    index.info.listed_count = listed;
    if (listed == 0) {
        return makeError(ErrorCode::kNotFound, index.index_file.string() + ": lists no frames");
    }
    std::size_t last = listed;  // index of the last existing image, listed = none
    for (std::size_t i = listed; i-- > 0;) {
        if (isRegularFile(index.frames[i].image)) {
            last = i;
            break;
        }
    }
    if (last == listed) {
        const ReplayFrame& first = index.frames.front();
        return lineError(ErrorCode::kNotFound, index.index_file, first.index_line,
                         "none of the " + std::to_string(listed) +
                             " listed images exists; the first is " + first.image.string(),
                         first.listed_as);
    }
    if (opt.drop_missing_tail && last + 1 < listed) {
        index.frames.resize(last + 1);
        index.info.notes.push_back(index.index_file.string() + " lists " + std::to_string(listed) +
                                   " frames but only the first " + std::to_string(last + 1) +
                                   " images exist (partial download?): replaying those");
    }
    index.info.frame_count = index.frames.size();
    return {};
}

Status chooseIntrinsics(source::SequenceInfo& info,
                        const std::optional<core::CameraIntrinsics>& from_dataset,
                        std::string_view dataset_source, const DatasetOptions& opt,
                        const std::function<Result<cv::Size>()>& image_size) {
    std::optional<core::CameraIntrinsics> k = opt.intrinsics ? opt.intrinsics : from_dataset;
    const std::string source =
        opt.intrinsics ? std::string("DatasetOptions.intrinsics") : std::string(dataset_source);
    if (!k) {
        info.has_intrinsics = false;
        info.notes.push_back("no intrinsics in the dataset: the caller must supply them");
        return {};
    }
    if (k->width_px == 0 || k->height_px == 0) {
        auto size = image_size();
        if (!size) {
            return size.error();
        }
        k->width_px = size->width;
        k->height_px = size->height;
    }
    auto camera = core::PinholeRadialCamera::create(*k);
    if (!camera) {
        return makeError(ErrorCode::kInvalidArgument, source + ": " + camera.error().message);
    }
    info.intrinsics = *k;
    info.has_intrinsics = true;
    return {};
}

Status resolveIntrinsics(ReplayIndex& index,
                         const std::optional<core::CameraIntrinsics>& from_dataset,
                         std::string_view dataset_source, const DatasetOptions& opt) {
    return chooseIntrinsics(
        index.info, from_dataset, dataset_source, opt, [&]() -> Result<cv::Size> {
            const auto first =
                std::find_if(index.frames.begin(), index.frames.end(),
                             [](const ReplayFrame& f) { return isRegularFile(f.image); });
            if (first == index.frames.end()) {
                const std::string source = opt.intrinsics ? std::string("DatasetOptions.intrinsics")
                                                          : std::string(dataset_source);
                return makeError(ErrorCode::kNotFound,
                                 source + ": no image to take the image size from");
            }
            auto img = drivers::dataset::loadImage(first->image);
            if (!img) {
                return img.error();
            }
            return img->size();
        });
}

Result<int64_t> toleranceNs(double seconds) {
    constexpr double kMaxSeconds = 1e6;
    if (!(seconds >= 0 && seconds <= kMaxSeconds)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "DatasetOptions.max_assoc_dt_s must be in [0, 1e6] s (got " +
                             shortNumber(seconds) + ")");
    }
    return static_cast<int64_t>(std::llround(seconds * 1e9));
}

std::optional<std::size_t> nearestWithin(const std::vector<int64_t>& times, int64_t t,
                                         int64_t tol_ns) {
    // |a - b| without overflow: the difference of two int64 fits in uint64.
    const auto dist = [](int64_t a, int64_t b) {
        return a >= b ? static_cast<uint64_t>(a) - static_cast<uint64_t>(b)
                      : static_cast<uint64_t>(b) - static_cast<uint64_t>(a);
    };
    const auto it = std::lower_bound(times.begin(), times.end(), t);
    std::optional<std::size_t> best;
    uint64_t best_d = std::numeric_limits<uint64_t>::max();
    if (it != times.end()) {
        best = static_cast<std::size_t>(it - times.begin());
        best_d = dist(*it, t);
    }
    if (it != times.begin() && dist(*(it - 1), t) < best_d) {
        best = static_cast<std::size_t>(it - times.begin()) - 1;
        best_d = dist(*(it - 1), t);
    }
    if (!best || tol_ns < 0 || best_d > static_cast<uint64_t>(tol_ns)) {
        return std::nullopt;
    }
    return best;
}

std::unique_ptr<source::FrameSource> makeReplaySource(ReplayIndex index) {
    return std::make_unique<ReplaySource>(std::move(index));
}

core::Result<std::int64_t> IncreasingTimestamps::next(std::string_view field, std::size_t line) {
    auto t = parseTimestampNs(field);
    if (!t) {
        return t.error();
    }
    if (last_t_ns_ && *t <= *last_t_ns_) {
        return core::makeError(
            core::ErrorCode::kParse,
            "timestamp does not increase (previous at line " + std::to_string(last_line_) + ")");
    }
    last_t_ns_ = *t;
    last_line_ = line;
    return *t;
}

}  // namespace scaled::drivers::dataset::detail
