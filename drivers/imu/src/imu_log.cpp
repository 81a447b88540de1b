#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <Eigen/LU>

#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/imu/imu_log.h>

#include "dataset_common.h"

namespace scaled::drivers::imu {

using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

constexpr double kMaxAccelMps2 = 1e4;  // about 1000 g: beyond any sensor we read
constexpr double kMaxGyroRadps = 1e3;  // about 160 turns a second

// Fields separated by commas, each trimmed of spaces and tabs.
std::vector<std::string_view> splitCsv(std::string_view line) {
    std::vector<std::string_view> out;
    std::size_t start = 0;
    while (true) {
        const std::size_t comma = line.find(',', start);
        std::string_view f = line.substr(
            start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
        while (!f.empty() && (f.front() == ' ' || f.front() == '\t')) {
            f.remove_prefix(1);
        }
        while (!f.empty() && (f.back() == ' ' || f.back() == '\t')) {
            f.remove_suffix(1);
        }
        out.push_back(f);
        if (comma == std::string_view::npos) {
            return out;
        }
        start = comma + 1;
    }
}

// A non-negative integer timestamp in nanoseconds, the whole field.
Result<int64_t> parseIntegerNs(std::string_view field) {
    int64_t v = 0;
    const char* end = field.data() + field.size();
    const auto [ptr, ec] = std::from_chars(field.data(), end, v);
    if (ec == std::errc::result_out_of_range) {
        return makeError(ErrorCode::kParse,
                         "timestamp out of range: '" + dataset::detail::printable(field) + "'");
    }
    if (ec != std::errc() || ptr != end || field.empty() || v < 0) {
        return makeError(ErrorCode::kParse, "timestamp is not a non-negative integer [ns]: '" +
                                                dataset::detail::printable(field) + "'");
    }
    return v;
}

// A finite number within +-limit, named `name` in errors.
Result<core::Scalar> parseBounded(std::string_view field, std::string_view name, double limit,
                                  const char* unit) {
    auto x = dataset::detail::parseFiniteNumber(field, name);
    if (!x) {
        return x.error();
    }
    if (!(std::abs(*x) <= limit)) {
        return makeError(ErrorCode::kParse, std::string(name) + " is implausibly large (|" +
                                                std::string(name) + "| > " +
                                                dataset::detail::shortNumber(limit) + " " + unit +
                                                "): '" + dataset::detail::printable(field) + "'");
    }
    return static_cast<core::Scalar>(*x);
}

}  // namespace

core::Mat3 tumKinectImuToCamera() {
    core::Mat3 R = core::Mat3::Identity();
    R(0, 0) = -1;
    R(1, 1) = -1;
    return R;
}

Result<ImuLog> readTumAccelerometer(const std::filesystem::path& path) {
    // drivers::dataset::readTumAccelerometer (dataset_tum.h) parses the file for the
    // frame sources; the same checks and messages here.
    auto rows = drivers::dataset::readTumAccelerometer(path);
    if (!rows) {
        return rows.error();
    }
    ImuLog log;
    log.samples.reserve(rows->size());
    for (const dataset::TumAccelSample& row : *rows) {
        core::ImuSample s;
        s.t_ns = row.t_ns;
        s.accel_mps2 = row.accel;
        log.samples.push_back(s);
    }
    log.R_ItoC = tumKinectImuToCamera();
    log.R_ItoC_source = "TUM Kinect default: down_inC = (ax, ay, -az) / |a| (docs/imu.md)";
    return log;
}

Result<core::Mat3> readEurocSensorRotation(const std::filesystem::path& sensor_yaml) {
    auto text = dataset::detail::readTextFile(sensor_yaml);
    if (!text) {
        return text.error();
    }
    const std::string_view all = *text;
    const auto lineOf = [&](std::size_t pos) {
        return static_cast<std::size_t>(
                   std::count(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(pos), '\n')) +
               1;
    };
    const std::size_t key = all.find("T_BS:");
    if (key == std::string_view::npos) {
        return makeError(ErrorCode::kParse, sensor_yaml.string() + ": no T_BS");
    }
    const std::size_t data = all.find("data:", key);
    const std::size_t open = data == std::string_view::npos ? data : all.find('[', data);
    const std::size_t close = open == std::string_view::npos ? open : all.find(']', open);
    if (close == std::string_view::npos) {
        return dataset::detail::lineError(ErrorCode::kParse, sensor_yaml, lineOf(key),
                                          "T_BS has no `data: [...]`", all.substr(key, 40));
    }
    std::string list(all.substr(open + 1, close - open - 1));
    std::replace(list.begin(), list.end(), '\n', ' ');
    std::replace(list.begin(), list.end(), '\r', ' ');
    const auto fields = splitCsv(list);
    if (fields.size() != 16) {
        return dataset::detail::lineError(
            ErrorCode::kParse, sensor_yaml, lineOf(data),
            "T_BS data: expected 16 numbers, got " + std::to_string(fields.size()),
            all.substr(data, close - data + 1));
    }
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            auto x = dataset::detail::parseFiniteNumber(
                fields[static_cast<std::size_t>(r) * 4 + static_cast<std::size_t>(c)],
                "T_BS element");
            if (!x) {
                return dataset::detail::lineError(ErrorCode::kParse, sensor_yaml, lineOf(data),
                                                  x.error().message,
                                                  all.substr(data, close - data + 1));
            }
            R(r, c) = *x;
        }
    }
    const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (!(err <= dataset::detail::kRotationTolerance) || !(R.determinant() > 0)) {
        return dataset::detail::lineError(
            ErrorCode::kParse, sensor_yaml, lineOf(data),
            "T_BS is not a rotation (max |R^T R - I| = " + dataset::detail::shortNumber(err) +
                ", det = " + dataset::detail::shortNumber(R.determinant()) + ")",
            all.substr(data, close - data + 1));
    }
    return R.cast<core::Scalar>().eval();
}

Result<ImuLog> readEurocImu(const std::filesystem::path& path) {
    auto text = dataset::detail::readTextFile(path);
    if (!text) {
        return text.error();
    }
    static constexpr std::array<std::string_view, 6> kNames = {"w_RS_S_x", "w_RS_S_y", "w_RS_S_z",
                                                               "a_RS_S_x", "a_RS_S_y", "a_RS_S_z"};
    ImuLog log;
    int64_t last_t_ns = -1;
    std::size_t last_line = 0;
    for (const dataset::detail::TextLine& line : dataset::detail::dataLines(*text)) {
        const auto bad = [&](const std::string& what) {
            return dataset::detail::lineError(ErrorCode::kParse, path, line.number, what,
                                              line.text);
        };
        const auto fields = splitCsv(line.text);
        if (fields.size() != 7) {
            return bad(
                "expected 7 comma-separated fields `timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z`"
                ", got " +
                std::to_string(fields.size()));
        }
        auto t = parseIntegerNs(fields[0]);
        if (!t) {
            return bad(t.error().message);
        }
        if (*t <= last_t_ns) {
            return bad("timestamp does not increase (previous at line " +
                       std::to_string(last_line) + ")");
        }
        last_t_ns = *t;
        last_line = line.number;
        core::ImuSample s;
        s.t_ns = *t;
        core::Vec3 gyro = core::Vec3::Zero();
        for (std::size_t k = 0; k < 6; ++k) {
            const bool is_gyro = k < 3;
            auto v = parseBounded(fields[k + 1], kNames[k], is_gyro ? kMaxGyroRadps : kMaxAccelMps2,
                                  is_gyro ? "rad/s" : "m/s^2");
            if (!v) {
                return bad(v.error().message);
            }
            (is_gyro ? gyro : s.accel_mps2)[static_cast<Eigen::Index>(k % 3)] = *v;
        }
        s.gyro_radps = gyro;
        log.samples.push_back(s);
    }
    if (log.samples.empty()) {
        return makeError(ErrorCode::kParse, path.string() + ": no samples");
    }

    // EuRoC layout: MAV0/imu0/data.csv, MAV0/imu0/sensor.yaml, MAV0/cam0/sensor.yaml.
    const std::filesystem::path mav = path.parent_path().parent_path();
    const std::filesystem::path cam_yaml = mav / "cam0" / "sensor.yaml";
    const std::filesystem::path imu_yaml = mav / "imu0" / "sensor.yaml";
    if (!dataset::detail::isRegularFile(cam_yaml)) {
        log.R_ItoC_source = "identity (no " + cam_yaml.string() + ")";
        log.R_ItoC_known = false;
        log.notes.push_back(path.string() + ": no " + cam_yaml.string() +
                            ": R_ItoC is the identity; give the camera-IMU rotation");
        return log;
    }
    auto R_CtoB = readEurocSensorRotation(cam_yaml);
    if (!R_CtoB) {
        return R_CtoB.error();
    }
    core::Mat3 R_ItoB = core::Mat3::Identity();
    if (dataset::detail::isRegularFile(imu_yaml)) {
        auto r = readEurocSensorRotation(imu_yaml);
        if (!r) {
            return r.error();
        }
        R_ItoB = *r;
    }
    log.R_ItoC = R_CtoB->transpose() * R_ItoB;
    log.R_ItoC_source = cam_yaml.string() + " T_BS";
    return log;
}

}  // namespace scaled::drivers::imu
