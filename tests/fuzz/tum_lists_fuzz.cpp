// The TUM RGB-D layout's text files (drivers/src/dataset_tum.cpp,
// trajectory_io.cpp), each reader on the same text: rgb.txt/depth.txt,
// groundtruth.txt, gravity.txt, accelerometer.txt. What a reader accepts
// keeps its documented invariants; what it refuses is an error naming the file.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string_view>

#include <Eigen/Core>

#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "fuzz_support.h"

using scaled::fuzz::check;
using scaled::fuzz::startsWith;

namespace {

// Rotations the readers return are orthonormal (they normalise what they read).
bool isRotation(const Eigen::Matrix3d& R) {
    const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    return err < 1e-9 && R.determinant() > 0;
}

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

    const auto list = scaled::drivers::dataset::parseTumImageList(text, "d/rgb.txt");
    checkError(list, "d/rgb.txt:");
    if (list) {
        for (std::size_t i = 0; i < list->size(); ++i) {
            const auto& e = (*list)[i];
            check(!e.file.empty() && e.file.find_first_of(" \t\n") == std::string::npos,
                  "a listed file is one field");
            check(i == 0 || (e.t_ns > (*list)[i - 1].t_ns && e.line > (*list)[i - 1].line),
                  "timestamps and lines increase");
        }
    }

    const auto gt = scaled::drivers::dataset::parseTumTrajectory(text, "d/groundtruth.txt");
    checkError(gt, "d/groundtruth.txt:");
    if (gt) {
        for (std::size_t i = 0; i < gt->size(); ++i) {
            const auto& [t, pose] = (*gt)[i];
            check(i == 0 || t > (*gt)[i - 1].first, "trajectory timestamps increase");
            check(isRotation(pose.R_CtoW.cast<double>()), "trajectory rotations are rotations");
            check(pose.p_CinW.allFinite(), "trajectory positions are finite");
        }
    }

    const auto g = scaled::drivers::dataset::parseGravityFile(text, "d/gravity.txt");
    checkError(g, "d/gravity.txt");
    if (g) {
        check(std::abs(g->cast<double>().norm() - 1) < 1e-9, "gravity is a unit vector");
    }

    const auto accel = scaled::drivers::dataset::parseTumAccelerometer(text, "d/accelerometer.txt");
    checkError(accel, "d/accelerometer.txt:");
    if (accel) {
        for (std::size_t i = 0; i < accel->size(); ++i) {
            const auto& a = (*accel)[i];
            check(i == 0 || a.t_ns > (*accel)[i - 1].t_ns, "accelerometer timestamps increase");
            check(a.accel.allFinite() && a.accel.cwiseAbs().maxCoeff() <= 1e4,
                  "accelerations are finite and at most 1e4 m/s^2");
        }
    }
    return 0;
}
