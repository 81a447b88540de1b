#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::CameraIntrinsics;
using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Scalar;
using core::Status;

namespace {

constexpr double kMaxImageSide = 100000;
constexpr double kTumDepthScaleM = 1.0 / 5000.0;  // TUM RGB-D depth PNGs: 5000 units per metre
constexpr double kMillimetre = 1e-3;

// The single data line of a small settings file (camera.txt, gravity.txt).
Result<detail::TextLine> singleDataLine(const std::filesystem::path& file, std::string_view text,
                                        std::string_view expected) {
    const auto lines = detail::dataLines(text);
    if (lines.empty()) {
        return makeError(ErrorCode::kParse, file.string() + ": no data line (expected `" +
                                                std::string(expected) + "`)");
    }
    if (lines.size() > 1) {
        return detail::lineError(
            ErrorCode::kParse, file, lines[1].number,
            "unexpected second data line (expected one line `" + std::string(expected) + "`)",
            lines[1].text);
    }
    return lines.front();
}

}  // namespace

Result<std::vector<TumListEntry>> parseTumImageList(std::string_view text,
                                                    const std::filesystem::path& list_file) {
    std::vector<TumListEntry> out;
    detail::IncreasingTimestamps times;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, list_file, line.number, what, line.text);
        };
        if (fields.size() != 2) {
            return bad("expected 2 fields `timestamp file`, got " + std::to_string(fields.size()));
        }
        auto t = times.next(fields[0], line.number);
        if (!t) {
            return bad(t.error().message);
        }
        out.push_back({*t, std::string(fields[1]), line.number});
    }
    return out;
}

Result<std::vector<TumListEntry>> readTumImageList(const std::filesystem::path& list_file) {
    auto text = detail::readTextFile(list_file);
    if (!text) {
        return text.error();
    }
    return parseTumImageList(*text, list_file);
}

Result<CameraIntrinsics> readTumCameraFile(const std::filesystem::path& camera_file) {
    auto text = detail::readTextFile(camera_file);
    if (!text) {
        return text.error();
    }
    return parseTumCameraFile(*text, camera_file);
}

Result<CameraIntrinsics> parseTumCameraFile(std::string_view text,
                                            const std::filesystem::path& camera_file) {
    constexpr std::string_view kExpected = "width height fx fy cx cy [k1 k2]";
    auto line = singleDataLine(camera_file, text, kExpected);
    if (!line) {
        return line.error();
    }
    const auto bad = [&](const std::string& what) {
        return detail::lineError(ErrorCode::kParse, camera_file, line->number, what, line->text);
    };
    const auto fields = detail::splitFields(line->text);
    if (fields.size() != 6 && fields.size() != 8) {
        return bad("expected 6 or 8 fields `" + std::string(kExpected) + "`, got " +
                   std::to_string(fields.size()));
    }
    static constexpr std::array<std::string_view, 8> kNames = {"width", "height", "fx", "fy",
                                                               "cx",    "cy",     "k1", "k2"};
    std::array<double, 8> v{};
    for (std::size_t i = 0; i < fields.size(); ++i) {
        auto x = detail::parseFiniteNumber(fields[i], kNames[i]);
        if (!x) {
            return bad(x.error().message);
        }
        v[i] = *x;
    }
    for (std::size_t i = 0; i < 2; ++i) {
        if (!(v[i] >= 1 && v[i] <= kMaxImageSide && std::floor(v[i]) == v[i])) {
            return bad(std::string(kNames[i]) + " must be an integer in [1, 100000]: '" +
                       detail::printable(fields[i]) + "'");
        }
    }
    CameraIntrinsics k;
    k.width_px = static_cast<int>(v[0]);
    k.height_px = static_cast<int>(v[1]);
    k.fx = static_cast<Scalar>(v[2]);
    k.fy = static_cast<Scalar>(v[3]);
    k.cx = static_cast<Scalar>(v[4]);
    k.cy = static_cast<Scalar>(v[5]);
    k.k1 = static_cast<Scalar>(v[6]);
    k.k2 = static_cast<Scalar>(v[7]);
    auto camera = core::PinholeRadialCamera::create(k);
    if (!camera) {
        return bad(camera.error().message);
    }
    return k;
}

Result<std::optional<CameraIntrinsics>> readOptionalCameraFile(
    const std::filesystem::path& camera_file) {
    if (!detail::pathExists(camera_file)) {
        return std::optional<CameraIntrinsics>();
    }
    auto k = readTumCameraFile(camera_file);
    if (!k) {
        return k.error();
    }
    return std::optional<CameraIntrinsics>(*k);
}

namespace detail {

Status resolveIntrinsicsFromCameraFile(ReplayIndex& index, const std::filesystem::path& camera_file,
                                       const DatasetOptions& opt) {
    auto from_dataset = readOptionalCameraFile(camera_file);
    if (!from_dataset) {
        return from_dataset.error();
    }
    return resolveIntrinsics(index, *from_dataset, camera_file.string(), opt);
}

}  // namespace detail

Result<core::Vec3> readGravityFile(const std::filesystem::path& gravity_file) {
    auto text = detail::readTextFile(gravity_file);
    if (!text) {
        return text.error();
    }
    return parseGravityFile(*text, gravity_file);
}

Result<core::Vec3> parseGravityFile(std::string_view text,
                                    const std::filesystem::path& gravity_file) {
    auto line = singleDataLine(gravity_file, text, "gx gy gz");
    if (!line) {
        return line.error();
    }
    const auto bad = [&](const std::string& what) {
        return detail::lineError(ErrorCode::kParse, gravity_file, line->number, what, line->text);
    };
    const auto fields = detail::splitFields(line->text);
    if (fields.size() != 3) {
        return bad("expected 3 fields `gx gy gz`, got " + std::to_string(fields.size()));
    }
    static constexpr std::array<std::string_view, 3> kNames = {"gx", "gy", "gz"};
    Eigen::Vector3d g;
    for (Eigen::Index i = 0; i < 3; ++i) {
        auto x = detail::parseFiniteNumber(fields[static_cast<std::size_t>(i)],
                                           kNames[static_cast<std::size_t>(i)]);
        if (!x) {
            return bad(x.error().message);
        }
        g[i] = *x;
    }
    const double norm = g.norm();
    if (!(std::abs(norm - 1) <= detail::kUnitTolerance)) {
        return bad("gravity direction is not a unit vector (norm " + detail::shortNumber(norm) +
                   ")");
    }
    return (g / norm).cast<Scalar>().eval();
}

Result<std::vector<TumAccelSample>> readTumAccelerometer(const std::filesystem::path& accel_file) {
    auto text = detail::readTextFile(accel_file);
    if (!text) {
        return text.error();
    }
    return parseTumAccelerometer(*text, accel_file);
}

Result<std::vector<TumAccelSample>> parseTumAccelerometer(std::string_view text,
                                                          const std::filesystem::path& accel_file) {
    constexpr double kMaxAccel = 1e4;  // m/s^2: about 1000 g, far beyond any handheld sensor
    static constexpr std::array<std::string_view, 3> kNames = {"ax", "ay", "az"};
    std::vector<TumAccelSample> out;
    detail::IncreasingTimestamps times;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, accel_file, line.number, what, line.text);
        };
        if (fields.size() != 4) {
            return bad("expected 4 fields `timestamp ax ay az`, got " +
                       std::to_string(fields.size()));
        }
        auto t = times.next(fields[0], line.number);
        if (!t) {
            return bad(t.error().message);
        }
        TumAccelSample sample;
        sample.t_ns = *t;
        sample.line = line.number;
        for (std::size_t i = 0; i < 3; ++i) {
            auto x = detail::parseFiniteNumber(fields[i + 1], kNames[i]);
            if (!x) {
                return bad(x.error().message);
            }
            if (!(std::abs(*x) <= kMaxAccel)) {
                return bad(std::string(kNames[i]) + " is implausibly large (|a| > 1e4 m/s^2): '" +
                           detail::printable(fields[i + 1]) + "'");
            }
            sample.accel[static_cast<Eigen::Index>(i)] = static_cast<Scalar>(*x);
        }
        out.push_back(sample);
    }
    return out;
}

namespace {

// The frames of rgb.txt, in index.frames.
core::Status readTumFrames(const std::filesystem::path& dir, detail::ReplayIndex& index) {
    index.index_file = dir / "rgb.txt";
    auto rgb = readTumImageList(index.index_file);
    if (!rgb) {
        return rgb.error();
    }
    index.frames.reserve(rgb->size());
    for (TumListEntry& e : *rgb) {
        detail::ReplayFrame f;
        f.t_ns = e.t_ns;
        f.image = dir / e.file;
        f.listed_as = std::move(e.file);
        f.index_line = e.line;
        index.frames.push_back(std::move(f));
    }
    return {};
}

// Each frame's ground-truth pose from groundtruth.txt (nearest within tol_ns),
// or a note that there is none.
core::Status attachTumGroundTruth(const std::filesystem::path& dir, int64_t tol_ns,
                                  const DatasetOptions& opt, detail::ReplayIndex& index) {
    const std::filesystem::path gt_file = dir / "groundtruth.txt";
    if (!detail::pathExists(gt_file)) {
        index.info.notes.push_back(gt_file.string() + " not found: no ground truth");
        return {};
    }
    auto gt = readTumTrajectory(gt_file);
    if (!gt) {
        return gt.error();
    }
    std::vector<int64_t> times;
    times.reserve(gt->size());
    for (const auto& [t, pose] : *gt) {
        times.push_back(t);
    }
    std::size_t without = 0;
    for (detail::ReplayFrame& f : index.frames) {
        if (auto k = detail::nearestWithin(times, f.t_ns, tol_ns)) {
            f.T_CtoW_gt = (*gt)[*k].second;
        } else {
            ++without;
        }
    }
    if (without > 0) {
        index.info.notes.push_back(gt_file.string() + ": " + std::to_string(without) + " of " +
                                   std::to_string(index.frames.size()) +
                                   " frames have no pose within " +
                                   detail::shortNumber(opt.max_assoc_dt_s) + " s");
    }
    return {};
}

// Each frame's depth image from depth.txt (nearest within tol_ns, when the
// file exists), and the depth scale.
core::Status attachTumDepth(const std::filesystem::path& dir, int64_t tol_ns,
                            const DatasetOptions& opt, detail::ReplayIndex& index) {
    const std::filesystem::path depth_file = dir / "depth.txt";
    if (!detail::pathExists(depth_file)) {
        return {};
    }
    auto text = detail::readTextFile(depth_file);
    if (!text) {
        return text.error();
    }
    auto depth = parseTumImageList(*text, depth_file);
    if (!depth) {
        return depth.error();
    }
    std::vector<int64_t> times;
    times.reserve(depth->size());
    for (const TumListEntry& e : *depth) {
        times.push_back(e.t_ns);
    }
    for (detail::ReplayFrame& f : index.frames) {
        if (auto k = detail::nearestWithin(times, f.t_ns, tol_ns)) {
            std::filesystem::path p = dir / (*depth)[*k].file;
            if (detail::isRegularFile(p)) {
                f.depth_path = std::move(p);
            }
        }
    }
    index.info.depth_scale_m = opt.depth_scale_m.value_or(
        detail::commentMentions(*text, "millimet") ? kMillimetre : kTumDepthScaleM);
    return {};
}

// The gravity direction of gravity.txt, when the file exists.
core::Status attachTumGravity(const std::filesystem::path& dir, detail::ReplayIndex& index) {
    const std::filesystem::path gravity_file = dir / "gravity.txt";
    if (detail::pathExists(gravity_file)) {
        auto g = readGravityFile(gravity_file);
        if (!g) {
            return g.error();
        }
        index.info.gravity_down_W = *g;
    }
    return {};
}

// Each frame's accelerometer sample from accelerometer.txt (nearest within
// tol_ns, when the file exists).
core::Status attachTumAccelerometer(const std::filesystem::path& dir, int64_t tol_ns,
                                    const DatasetOptions& opt, detail::ReplayIndex& index) {
    const std::filesystem::path accel_file = dir / "accelerometer.txt";
    if (!detail::pathExists(accel_file)) {
        return {};
    }
    auto samples = readTumAccelerometer(accel_file);
    if (!samples) {
        return samples.error();
    }
    std::vector<int64_t> times;
    times.reserve(samples->size());
    for (const TumAccelSample& a : *samples) {
        times.push_back(a.t_ns);
    }
    std::size_t without = 0;
    for (detail::ReplayFrame& f : index.frames) {
        if (auto k = detail::nearestWithin(times, f.t_ns, tol_ns)) {
            f.accel_C = (*samples)[*k].accel;
        } else {
            ++without;
        }
    }
    if (without > 0) {
        index.info.notes.push_back(accel_file.string() + ": " + std::to_string(without) + " of " +
                                   std::to_string(index.frames.size()) +
                                   " frames have no sample within " +
                                   detail::shortNumber(opt.max_assoc_dt_s) + " s");
    }
    return {};
}

}  // namespace

Result<std::unique_ptr<source::FrameSource>> openTumDataset(const std::filesystem::path& dir,
                                                            const DatasetOptions& opt) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec) || ec) {
        return makeError(ErrorCode::kNotFound, dir.string() + ": dataset directory not found");
    }
    auto tol_ns = detail::toleranceNs(opt.max_assoc_dt_s);
    if (!tol_ns) {
        return tol_ns.error();
    }
    if (opt.depth_scale_m && !(std::isfinite(*opt.depth_scale_m) && *opt.depth_scale_m > 0)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "DatasetOptions.depth_scale_m must be finite and > 0 (got " +
                             detail::shortNumber(*opt.depth_scale_m) + ")");
    }

    detail::ReplayIndex index;
    index.info.name = detail::datasetName(dir);
    index.info.dir = dir;
    if (auto ok = readTumFrames(dir, index); !ok) {
        return ok.error();
    }
    if (auto trimmed = detail::trimMissingTail(index, opt); !trimmed) {
        return trimmed.error();
    }
    if (auto ok = attachTumGroundTruth(dir, *tol_ns, opt, index); !ok) {
        return ok.error();
    }
    if (auto ok = attachTumDepth(dir, *tol_ns, opt, index); !ok) {
        return ok.error();
    }
    if (auto resolved = detail::resolveIntrinsicsFromCameraFile(index, dir / "camera.txt", opt);
        !resolved) {
        return resolved.error();
    }
    if (auto ok = attachTumGravity(dir, index); !ok) {
        return ok.error();
    }
    if (auto ok = attachTumAccelerometer(dir, *tol_ns, opt, index); !ok) {
        return ok.error();
    }
    return detail::makeReplaySource(std::move(index));
}

}  // namespace scaled::drivers::dataset
