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

#include <Eigen/LU>
#include <Eigen/SVD>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_kitti.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::CameraIntrinsics;
using core::CameraPose;
using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Scalar;

namespace {

std::string imageName(std::size_t i) {
    std::string digits = std::to_string(i);
    if (digits.size() < 6) {
        digits.insert(0, 6 - digits.size(), '0');
    }
    return "image_0/" + digits + ".png";
}

}  // namespace

Result<std::vector<KittiTime>> readKittiTimes(const std::filesystem::path& times_file) {
    auto text = detail::readTextFile(times_file);
    if (!text) {
        return text.error();
    }
    return parseKittiTimes(*text, times_file);
}

Result<std::vector<KittiTime>> parseKittiTimes(std::string_view text,
                                               const std::filesystem::path& times_file) {
    std::vector<KittiTime> out;
    detail::IncreasingTimestamps times;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, times_file, line.number, what, line.text);
        };
        if (fields.size() != 1) {
            return bad("expected 1 field (time in seconds), got " + std::to_string(fields.size()));
        }
        auto t = times.next(fields[0], line.number);
        if (!t) {
            return bad(t.error().message);
        }
        out.push_back({*t, line.number});
    }
    return out;
}

Result<std::vector<CameraPose>> readKittiPoses(const std::filesystem::path& poses_file) {
    auto text = detail::readTextFile(poses_file);
    if (!text) {
        return text.error();
    }
    return parseKittiPoses(*text, poses_file);
}

Result<std::vector<CameraPose>> parseKittiPoses(std::string_view text,
                                                const std::filesystem::path& poses_file) {
    std::vector<CameraPose> out;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, poses_file, line.number, what, line.text);
        };
        if (fields.size() != 12) {
            return bad("expected 12 fields (3x4 row-major [R | p]), got " +
                       std::to_string(fields.size()));
        }
        Eigen::Matrix<double, 3, 4> P;
        for (std::size_t k = 0; k < 12; ++k) {
            const auto r = static_cast<Eigen::Index>(k / 4);
            const auto c = static_cast<Eigen::Index>(k % 4);
            const std::string name = "P[" + std::to_string(r) + "][" + std::to_string(c) + "]";
            auto x = detail::parseFiniteNumber(fields[k], name);
            if (!x) {
                return bad(x.error().message);
            }
            P(r, c) = *x;
        }
        const Eigen::Matrix3d R = P.leftCols<3>();
        const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
        if (!(err <= detail::kRotationTolerance) || !(R.determinant() > 0)) {
            return bad(
                "rotation is not orthonormal (max |R^T R - I| = " + detail::shortNumber(err) +
                ", det = " + detail::shortNumber(R.determinant()) + ")");
        }
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
        CameraPose pose;
        pose.R_CtoW = (svd.matrixU() * svd.matrixV().transpose()).cast<Scalar>();
        pose.p_CinW = P.col(3).cast<Scalar>();
        out.push_back(pose);
    }
    return out;
}

Result<std::array<double, 12>> readKittiProjection(const std::filesystem::path& calib_file,
                                                   std::string_view key) {
    auto text = detail::readTextFile(calib_file);
    if (!text) {
        return text.error();
    }
    return parseKittiProjection(*text, calib_file, key);
}

Result<std::array<double, 12>> parseKittiProjection(std::string_view text,
                                                    const std::filesystem::path& calib_file,
                                                    std::string_view key) {
    const std::string label = std::string(key) + ":";
    std::optional<std::array<double, 12>> found;
    std::size_t found_line = 0;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        if (fields.empty() || fields[0] != label) {
            continue;  // other matrices (P1..P3, Tr) are not needed
        }
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, calib_file, line.number, what, line.text);
        };
        if (found) {
            return bad("second " + label + " line (first at line " + std::to_string(found_line) +
                       ")");
        }
        if (fields.size() != 13) {
            return bad("expected `" + label + "` and 12 numbers, got " +
                       std::to_string(fields.size() - 1) + " numbers");
        }
        std::array<double, 12> P{};
        for (std::size_t k = 0; k < 12; ++k) {
            auto x = detail::parseFiniteNumber(fields[k + 1],
                                               std::string(key) + "[" + std::to_string(k) + "]");
            if (!x) {
                return bad(x.error().message);
            }
            P[k] = *x;
        }
        found = P;
        found_line = line.number;
    }
    if (!found) {
        return makeError(ErrorCode::kNotFound, calib_file.string() + ": no `" + label + "` line");
    }
    return *found;
}

Result<std::unique_ptr<source::FrameSource>> openKittiDataset(const std::filesystem::path& dir,
                                                              const DatasetOptions& opt) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec) || ec) {
        return makeError(ErrorCode::kNotFound, dir.string() + ": dataset directory not found");
    }
    detail::ReplayIndex index;
    index.info.name = detail::datasetName(dir);
    index.info.dir = dir;
    index.index_file = dir / "times.txt";
    auto times = readKittiTimes(index.index_file);
    if (!times) {
        return times.error();
    }
    index.frames.reserve(times->size());
    for (std::size_t i = 0; i < times->size(); ++i) {
        detail::ReplayFrame f;
        f.t_ns = (*times)[i].t_ns;
        f.listed_as = imageName(i);
        f.image = dir / f.listed_as;
        f.index_line = (*times)[i].line;
        index.frames.push_back(std::move(f));
    }
    if (auto trimmed = detail::trimMissingTail(index, opt); !trimmed) {
        return trimmed.error();
    }

    const std::filesystem::path poses_file = dir / "poses.txt";
    if (detail::pathExists(poses_file)) {
        auto poses = readKittiPoses(poses_file);
        if (!poses) {
            return poses.error();
        }
        for (std::size_t i = 0; i < index.frames.size() && i < poses->size(); ++i) {
            index.frames[i].T_CtoW_gt = (*poses)[i];
        }
        if (poses->size() != times->size()) {
            index.info.notes.push_back(poses_file.string() + " has " +
                                       std::to_string(poses->size()) + " poses for " +
                                       std::to_string(times->size()) + " timestamps");
        }
    } else {
        index.info.notes.push_back(poses_file.string() + " not found: no ground truth");
    }

    std::optional<CameraIntrinsics> from_dataset;
    const std::filesystem::path calib_file = dir / "calib.txt";
    if (detail::pathExists(calib_file)) {
        auto P = readKittiProjection(calib_file, "P0");
        if (!P) {
            return P.error();
        }
        CameraIntrinsics k;
        k.fx = static_cast<Scalar>((*P)[0]);
        k.cx = static_cast<Scalar>((*P)[2]);
        k.fy = static_cast<Scalar>((*P)[5]);
        k.cy = static_cast<Scalar>((*P)[6]);
        from_dataset = k;  // the image size comes from the first image
    }
    if (auto resolved =
            detail::resolveIntrinsics(index, from_dataset, calib_file.string() + ": P0", opt);
        !resolved) {
        return resolved.error();
    }

    if (opt.gravity_from_groundtruth) {
        const auto& first = index.frames.front().T_CtoW_gt;
        if (first) {
            // KITTI's cameras are level: down is the camera's +y axis.
            index.info.gravity_down_W = (first->R_CtoW * core::Vec3::UnitY()).normalized();
        } else {
            index.info.notes.push_back("gravity_from_groundtruth: frame 0 has no pose");
        }
    }
    return detail::makeReplaySource(std::move(index));
}

}  // namespace scaled::drivers::dataset
