// The KITTI odometry layout's text files (drivers/src/dataset_kitti.cpp),
// each reader on the same text: times.txt, poses.txt, calib.txt (P0 and P2).

#include <cstddef>
#include <cstdint>
#include <string_view>

#include <Eigen/Core>
#include <Eigen/LU>

#include <scaled/drivers/dataset/dataset_kitti.h>

#include "fuzz_support.h"

using scaled::fuzz::check;
using scaled::fuzz::isFinite;
using scaled::fuzz::startsWith;

namespace {

template <typename T>
void checkError(const T& result, std::string_view file) {
    if (!result) {
        check(startsWith(result.error().message, file), "an error names the file");
    }
}

}  // namespace

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view text = scaled::fuzz::asText(data, size);

    const auto times = scaled::drivers::dataset::parseKittiTimes(text, "s/times.txt");
    checkError(times, "s/times.txt:");
    if (times) {
        for (std::size_t i = 1; i < times->size(); ++i) {
            check((*times)[i].t_ns > (*times)[i - 1].t_ns, "times increase");
            check((*times)[i].line > (*times)[i - 1].line, "lines increase");
        }
    }

    const auto poses = scaled::drivers::dataset::parseKittiPoses(text, "s/poses.txt");
    checkError(poses, "s/poses.txt:");
    if (poses) {
        for (const auto& pose : *poses) {
            const Eigen::Matrix3d R = pose.R_CtoW.cast<double>();
            const double err =
                (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
            check(err < 1e-9 && R.determinant() > 0, "poses are re-orthonormalised rotations");
            check(pose.p_CinW.allFinite(), "positions are finite");
        }
    }

    for (const std::string_view key : {"P0", "P2"}) {
        const auto P = scaled::drivers::dataset::parseKittiProjection(text, "s/calib.txt", key);
        checkError(P, "s/calib.txt");
        if (P) {
            for (const double x : *P) {
                check(isFinite(x), "projection entries are finite");
            }
        }
    }
    return 0;
}
