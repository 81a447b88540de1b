#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fcntl.h>
#include <limits>
#include <string>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/base/unique_fd.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "dataset_common.h"

namespace scaled::drivers::dataset {

using core::CameraPose;
using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

constexpr uint64_t kInt64MaxMag = static_cast<uint64_t>(std::numeric_limits<int64_t>::max());
constexpr int64_t kMaxExponent = 1000000;  // beyond this, exponents saturate

bool isDigit(char c) {
    return c >= '0' && c <= '9';
}

// mag = mag * 10 + d; false on overflow.
bool pushDigit(uint64_t& mag, unsigned d) {
    constexpr uint64_t kMax = std::numeric_limits<uint64_t>::max();
    if (mag > (kMax - d) / 10) {
        return false;
    }
    mag = mag * 10 + d;
    return true;
}

bool startsWithWord(std::string_view s, std::string_view word) {
    if (s.size() < word.size()) {
        return false;
    }
    for (std::size_t i = 0; i < word.size(); ++i) {
        const char c = s[i];
        const char lower = (c >= 'A' && c <= 'Z') ? static_cast<char>(c - 'A' + 'a') : c;
        if (lower != word[i]) {
            return false;
        }
    }
    return true;
}

// The pieces of a decimal timestamp ([+-]digits[.digits][e[+-]digits]).
struct TimestampParts {
    bool negative = false;
    std::string digits;    // integer and fraction digits, in order
    int64_t frac_len = 0;  // how many of `digits` are the fraction
    int64_t exponent = 0;  // saturated at +-kMaxExponent
};

// The exponent at text[i] when an 'e' or 'E' starts there (i moves past it);
// false when the 'e' has no digits.
bool lexExponent(std::string_view text, std::size_t& i, int64_t& exponent) {
    if (i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
        ++i;
        bool exp_negative = false;
        if (i < text.size() && (text[i] == '+' || text[i] == '-')) {
            exp_negative = text[i] == '-';
            ++i;
        }
        if (i >= text.size() || !isDigit(text[i])) {
            return false;
        }
        while (i < text.size() && isDigit(text[i])) {
            exponent = std::min<int64_t>(exponent * 10 + (text[i++] - '0'), kMaxExponent);
        }
        if (exp_negative) {
            exponent = -exponent;
        }
    }
    return true;
}

// Splits a timestamp into `parts`: nullptr, or why it is not a timestamp.
const char* lexTimestamp(std::string_view text, TimestampParts& parts) {
    std::size_t i = 0;
    if (i < text.size() && (text[i] == '+' || text[i] == '-')) {
        parts.negative = text[i] == '-';
        ++i;
    }
    if (startsWithWord(text.substr(i), "nan") || startsWithWord(text.substr(i), "inf")) {
        return "timestamp is not finite";
    }
    while (i < text.size() && isDigit(text[i])) {
        parts.digits += text[i++];
    }
    if (i < text.size() && text[i] == '.') {
        ++i;
        while (i < text.size() && isDigit(text[i])) {
            parts.digits += text[i++];
            ++parts.frac_len;
        }
    }
    if (parts.digits.empty()) {
        return "timestamp is not a number";
    }
    if (!lexExponent(text, i, parts.exponent)) {
        return "timestamp is not a number";
    }
    if (i != text.size()) {
        return "timestamp is not a number";
    }
    return nullptr;
}

// mag = digits * 10^shift, rounded half up when shift < 0 (digits without
// leading zeros); false on overflow.
bool magnitudeTimesPow10(const std::string& digits, int64_t shift, uint64_t& mag) {
    const auto n_digits = static_cast<int64_t>(digits.size());
    bool overflow = false;
    if (shift >= 0) {
        if (n_digits + shift > 20) {
            overflow = true;
        }
        for (int64_t k = 0; k < n_digits && !overflow; ++k) {
            overflow =
                !pushDigit(mag, static_cast<unsigned>(digits[static_cast<std::size_t>(k)] - '0'));
        }
        for (int64_t k = 0; k < shift && !overflow; ++k) {
            overflow = !pushDigit(mag, 0);
        }
    } else {
        const int64_t keep = n_digits + shift;  // digits left of the ns point
        for (int64_t k = 0; k < keep && !overflow; ++k) {
            overflow =
                !pushDigit(mag, static_cast<unsigned>(digits[static_cast<std::size_t>(k)] - '0'));
        }
        if (!overflow && keep >= 0 && digits[static_cast<std::size_t>(keep)] >= '5') {
            overflow = mag == std::numeric_limits<uint64_t>::max();
            ++mag;
        }
    }
    return !overflow;
}

// t rounded to microseconds, half away from zero (cannot overflow: |t| / 1000).
int64_t roundToUs(int64_t t_ns) {
    const int64_t q = t_ns / 1000;
    const int64_t r = t_ns % 1000;
    if (r >= 500) {
        return q + 1;
    }
    if (r <= -500) {
        return q - 1;
    }
    return q;
}

void appendFixed(std::string& out, double v, int decimals) {
    std::array<char, 64> buf{};
    const auto [ptr, ec] =
        std::to_chars(buf.data(), buf.data() + buf.size(), v, std::chars_format::fixed, decimals);
    if (ec != std::errc()) {
        out += "nan";  // unreachable: callers pass finite values of bounded magnitude
        return;
    }
    out.append(buf.data(), ptr);
}

// Writes all of `data` to `fd`; false with errno set on failure.
bool writeAll(int fd, const std::string& data) {
    std::size_t done = 0;
    while (done < data.size()) {
        const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            return false;
        }
        done += static_cast<std::size_t>(n);
    }
    return true;
}

std::optional<std::string> checkPose(const CameraPose& pose) {
    const Eigen::Matrix3d R = pose.R_CtoW.cast<double>();
    const Eigen::Vector3d p = pose.p_CinW.cast<double>();
    if (!R.allFinite() || !p.allFinite()) {
        return std::string("pose is not finite");
    }
    const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (err > detail::kRotationTolerance || R.determinant() <= 0) {
        return "R_CtoW is not a rotation (max |R^T R - I| = " + detail::shortNumber(err) +
               ", det = " + detail::shortNumber(R.determinant()) + ")";
    }
    return std::nullopt;
}

}  // namespace

Result<int64_t> parseTimestampNs(std::string_view text) {
    const auto fail = [&](const char* what) {
        return makeError(ErrorCode::kParse,
                         std::string(what) + ": '" + detail::printable(text) + "'");
    };
    TimestampParts parts;
    if (const char* why = lexTimestamp(text, parts); why != nullptr) {
        return fail(why);
    }
    std::string& digits = parts.digits;
    const std::size_t first = digits.find_first_not_of('0');
    if (first == std::string::npos) {
        return int64_t{0};
    }
    digits.erase(0, first);
    // value in ns = digits * 10^shift
    const int64_t shift = parts.exponent - parts.frac_len + 9;
    uint64_t mag = 0;
    const bool overflow = !magnitudeTimesPow10(digits, shift, mag);
    const uint64_t limit = parts.negative ? kInt64MaxMag + 1 : kInt64MaxMag;
    if (overflow || mag > limit) {
        return fail("timestamp out of range (beyond +-292 years in ns)");
    }
    if (!parts.negative) {
        return static_cast<int64_t>(mag);
    }
    if (mag == kInt64MaxMag + 1) {
        return std::numeric_limits<int64_t>::min();
    }
    return -static_cast<int64_t>(mag);
}

std::string formatTimestampS(int64_t t_ns) {
    const int64_t us = roundToUs(t_ns);
    const uint64_t mag = us < 0 ? 0 - static_cast<uint64_t>(us) : static_cast<uint64_t>(us);
    std::string frac = std::to_string(mag % 1000000);
    std::string out = us < 0 ? "-" : "";
    out += std::to_string(mag / 1000000);
    out += '.';
    out.append(6 - frac.size(), '0');
    out += frac;
    return out;
}

Status writeTumTrajectory(const std::filesystem::path& path, std::span<const int64_t> t_ns,
                          std::span<const CameraPose> poses) {
    const std::string name = path.string();
    if (t_ns.size() != poses.size()) {
        return makeError(ErrorCode::kInvalidArgument, name + ": " + std::to_string(t_ns.size()) +
                                                          " timestamps but " +
                                                          std::to_string(poses.size()) + " poses");
    }
    if (!path.has_filename()) {
        return makeError(ErrorCode::kInvalidArgument, name + ": not a file name");
    }
    std::string text = "# t tx ty tz qx qy qz qw (camera-to-world, metres, t in seconds)\n";
    for (std::size_t i = 0; i < poses.size(); ++i) {
        if (auto problem = checkPose(poses[i])) {
            return makeError(ErrorCode::kInvalidArgument,
                             name + ": pose " + std::to_string(i) + ": " + *problem);
        }
        if (i > 0 && roundToUs(t_ns[i]) <= roundToUs(t_ns[i - 1])) {
            return makeError(ErrorCode::kInvalidArgument,
                             name + ": pose " + std::to_string(i) + ": timestamp " +
                                 std::to_string(t_ns[i]) +
                                 " ns does not increase at microsecond resolution (previous " +
                                 std::to_string(t_ns[i - 1]) + " ns)");
        }
        Eigen::Quaterniond q(poses[i].R_CtoW.cast<double>());
        q.normalize();
        if (q.w() < 0) {
            q.coeffs() = -q.coeffs();
        }
        const Eigen::Vector3d p = poses[i].p_CinW.cast<double>();
        text += formatTimestampS(t_ns[i]);
        for (const double v : {p.x(), p.y(), p.z()}) {
            text += ' ';
            appendFixed(text, v, 9);
        }
        for (const double v : {q.x(), q.y(), q.z(), q.w()}) {
            text += ' ';
            appendFixed(text, v, 9);
        }
        text += '\n';
    }

    const std::string tmp = name + ".tmp." + std::to_string(::getpid());
    base::UniqueFd fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
    if (!fd.isValid()) {
        return makeError(ErrorCode::kIo,
                         name + ": cannot create " + tmp + ": " + base::errnoText(errno));
    }
    const bool written = writeAll(fd.get(), text) && ::fsync(fd.get()) == 0;
    const int write_errno = written ? 0 : errno;
    const int close_errno = fd.close();
    if (!written || close_errno != 0) {
        ::unlink(tmp.c_str());
        return makeError(ErrorCode::kIo, name + ": cannot write " + tmp + ": " +
                                             base::errnoText(written ? close_errno : write_errno));
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) {
        ::unlink(tmp.c_str());
        return makeError(ErrorCode::kIo, name + ": cannot rename " + tmp + ": " + ec.message());
    }
    return {};
}

Result<std::vector<std::pair<int64_t, CameraPose>>> readTumTrajectory(
    const std::filesystem::path& path) {
    auto text = detail::readTextFile(path);
    if (!text) {
        return text.error();
    }
    return parseTumTrajectory(*text, path);
}

Result<std::vector<std::pair<int64_t, CameraPose>>> parseTumTrajectory(
    std::string_view text, const std::filesystem::path& path) {
    std::vector<std::pair<int64_t, CameraPose>> out;
    detail::IncreasingTimestamps times;
    for (const detail::TextLine& line : detail::dataLines(text)) {
        const auto fields = detail::splitFields(line.text);
        const auto bad = [&](const std::string& what) {
            return detail::lineError(ErrorCode::kParse, path, line.number, what, line.text);
        };
        if (fields.size() != 8) {
            return bad("expected 8 fields `t tx ty tz qx qy qz qw`, got " +
                       std::to_string(fields.size()));
        }
        auto t = times.next(fields[0], line.number);
        if (!t) {
            return bad(t.error().message);
        }
        static constexpr std::array<std::string_view, 7> kNames = {"tx", "ty", "tz", "qx",
                                                                   "qy", "qz", "qw"};
        std::array<double, 7> v{};
        for (std::size_t k = 0; k < v.size(); ++k) {
            auto x = detail::parseFiniteNumber(fields[k + 1], kNames[k]);
            if (!x) {
                return bad(x.error().message);
            }
            v[k] = *x;
        }
        Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
        const double norm = q.norm();
        if (!(std::abs(norm - 1) <= detail::kUnitTolerance)) {
            return bad("quaternion is not unit (norm " + detail::shortNumber(norm) + ")");
        }
        q.normalize();
        CameraPose pose;
        pose.R_CtoW = q.toRotationMatrix().cast<core::Scalar>();
        pose.p_CinW = Eigen::Vector3d(v[0], v[1], v[2]).cast<core::Scalar>();
        out.emplace_back(*t, pose);
    }
    return out;
}

}  // namespace scaled::drivers::dataset
