#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <system_error>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <scaled/core/geometry/gravity.h>

namespace scaled::core {

namespace {

// `v` with `decimals` digits after the point ("9.807").
std::string fixed(double v, int decimals = 3) {
    std::array<char, 64> buf{};
    const auto [ptr, ec] =
        std::to_chars(buf.data(), buf.data() + buf.size(), v, std::chars_format::fixed, decimals);
    if (ec != std::errc()) {
        return "nan";
    }
    return {buf.data(), ptr};
}

std::string seconds(int64_t t_ns) {
    return fixed(static_cast<double>(t_ns) * 1e-9);
}

bool finite(const Vec3& v) {
    return v.allFinite();
}

Status checkOptions(const GravityOptions& o) {
    const auto bad = [](const std::string& what) {
        return makeError(ErrorCode::kInvalidArgument, "gravity: " + what);
    };
    if (o.window_ns <= 0) {
        return bad("window_ns = " + std::to_string(o.window_ns) + ": must be > 0");
    }
    if (o.min_samples == 0) {
        return bad("min_samples = 0: must be >= 1");
    }
    const std::array<std::pair<const char*, Scalar>, 4> positive = {{
        {"gravity_mps2", o.gravity_mps2},
        {"magnitude_tolerance_mps2", o.magnitude_tolerance_mps2},
        {"max_spread_mps2", o.max_spread_mps2},
        {"max_rate_radps", o.max_rate_radps},
    }};
    for (const auto& [name, value] : positive) {
        if (!(std::isfinite(value) && value > 0)) {
            return bad(std::string(name) + " = " + fixed(static_cast<double>(value)) +
                       ": must be finite and > 0");
        }
    }
    return {};
}

// R_ItoC a rotation, the samples in time order, at least one.
Status checkInputs(std::span<const ImuSample> samples, const Mat3& R_ItoC) {
    const RotationDefect defect = rotationDefect(R_ItoC);
    if (!R_ItoC.allFinite() || !isRotation(defect)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "gravity: R_ItoC is not a rotation (max |R^T R - I| = " +
                             fixed(defect.orthogonality, 6) +
                             ", det = " + fixed(defect.determinant, 6) + ")");
    }
    for (std::size_t k = 1; k < samples.size(); ++k) {
        if (samples[k].t_ns < samples[k - 1].t_ns) {
            return makeError(ErrorCode::kInvalidArgument,
                             "gravity: samples out of time order: sample " + std::to_string(k) +
                                 " at " + std::to_string(samples[k].t_ns) + " ns after " +
                                 std::to_string(samples[k - 1].t_ns) + " ns");
        }
    }
    if (samples.empty()) {
        return makeError(ErrorCode::kDegenerate, "gravity: no accelerometer samples");
    }
    return {};
}

// The samples in the window [t_begin_ns, t_end_ns] that the options select.
std::span<const ImuSample> windowOf(std::span<const ImuSample> samples,
                                    const GravityOptions& options, int64_t& t_begin_ns,
                                    int64_t& t_end_ns) {
    // The window [t_begin, t_end]; the saturating arithmetic keeps extreme
    // timestamps from overflowing.
    constexpr int64_t kMin = std::numeric_limits<int64_t>::min();
    constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
    int64_t t_begin = 0;
    int64_t t_end = 0;
    if (options.at_t_ns) {
        t_end = *options.at_t_ns;
        t_begin = t_end < kMin + options.window_ns ? kMin : t_end - options.window_ns;
    } else {
        t_begin = samples.front().t_ns;
        t_end = t_begin > kMax - options.window_ns ? kMax : t_begin + options.window_ns;
    }
    const auto first = std::lower_bound(samples.begin(), samples.end(), t_begin,
                                        [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
    const auto last = std::upper_bound(first, samples.end(), t_end,
                                       [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
    t_begin_ns = t_begin;
    t_end_ns = t_end;
    return {first, last};
}

// The window's mean, magnitude, spread and mean rate (window not empty).
Result<GravityEstimate> windowStatistics(std::span<const ImuSample> window) {
    Vec3 sum = Vec3::Zero();
    Scalar rate_sum = 0;
    std::size_t rate_count = 0;
    for (const ImuSample& s : window) {
        if (!finite(s.accel_mps2) || (s.gyro_radps && !finite(*s.gyro_radps))) {
            return makeError(ErrorCode::kInvalidArgument,
                             "gravity: sample at " + std::to_string(s.t_ns) + " ns is not finite");
        }
        sum += s.accel_mps2;
        if (s.gyro_radps) {
            rate_sum += s.gyro_radps->norm();
            ++rate_count;
        }
    }
    const auto n = static_cast<Scalar>(window.size());
    GravityEstimate est;
    est.samples = window.size();
    est.t_first_ns = window.front().t_ns;
    est.t_last_ns = window.back().t_ns;
    est.mean_accel_mps2 = sum / n;
    est.magnitude_mps2 = est.mean_accel_mps2.norm();
    Scalar sq = 0;
    for (const ImuSample& s : window) {
        sq += (s.accel_mps2 - est.mean_accel_mps2).squaredNorm();
    }
    est.spread_mps2 = std::sqrt(sq / n);
    if (rate_count > 0) {
        est.mean_rate_radps = rate_sum / static_cast<Scalar>(rate_count);
    }
    return est;
}

// Why the window does not look static ("" when it does), reasons joined by "; ".
std::string reasonsNotStatic(const GravityEstimate& est, const GravityOptions& options) {
    std::vector<std::string> reasons;
    const Scalar off = std::abs(est.magnitude_mps2 - options.gravity_mps2);
    if (!(off <= options.magnitude_tolerance_mps2)) {
        reasons.push_back("mean specific force " + fixed(static_cast<double>(est.magnitude_mps2)) +
                          " m/s^2, expected " + fixed(static_cast<double>(options.gravity_mps2)) +
                          " +- " + fixed(static_cast<double>(options.magnitude_tolerance_mps2)) +
                          " (accelerating, falling, or not in m/s^2)");
    }
    if (!(est.spread_mps2 <= options.max_spread_mps2)) {
        reasons.push_back("accelerometer spread " + fixed(static_cast<double>(est.spread_mps2)) +
                          " m/s^2 rms > " + fixed(static_cast<double>(options.max_spread_mps2)) +
                          " (moving or vibrating)");
    }
    if (est.mean_rate_radps && !(*est.mean_rate_radps <= options.max_rate_radps)) {
        reasons.push_back("mean angular rate " + fixed(static_cast<double>(*est.mean_rate_radps)) +
                          " rad/s > " + fixed(static_cast<double>(options.max_rate_radps)) +
                          " (rotating)");
    }
    std::string joined;
    for (std::size_t k = 0; k < reasons.size(); ++k) {
        joined += (k > 0 ? "; " : "") + reasons[k];
    }
    return joined;
}

}  // namespace

Scalar angleBetween(const Vec3& a, const Vec3& b) {
    const Scalar na = a.norm();
    const Scalar nb = b.norm();
    if (!(na > 0) || !(nb > 0)) {
        return 0;
    }
    // atan2 of |a x b| and a . b: accurate at small angles, unlike acos.
    return std::atan2(a.cross(b).norm(), a.dot(b));
}

RotationDefect rotationDefect(const Mat3& R_in) {
    const Eigen::Matrix3d& R = R_in.cast<double>();
    RotationDefect d;
    d.orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    d.determinant = R.determinant();
    return d;
}

bool isRotation(const RotationDefect& d) {
    return d.orthogonality <= kRotationTolerance && d.determinant > 0;
}

Result<GravityEstimate> estimateGravityDown(std::span<const ImuSample> samples, const Mat3& R_ItoC,
                                            const GravityOptions& options) {
    if (auto ok = checkOptions(options); !ok) {
        return ok.error();
    }
    if (auto ok = checkInputs(samples, R_ItoC); !ok) {
        return ok.error();
    }
    int64_t t_begin = 0;
    int64_t t_end = 0;
    const std::span<const ImuSample> window = windowOf(samples, options, t_begin, t_end);
    const std::string where = "[" + seconds(t_begin) + ", " + seconds(t_end) + "] s";
    if (window.size() < options.min_samples) {
        return makeError(ErrorCode::kDegenerate, "gravity: " + std::to_string(window.size()) +
                                                     " accelerometer samples in " + where +
                                                     ", need at least " +
                                                     std::to_string(options.min_samples));
    }

    auto stats = windowStatistics(window);
    if (!stats) {
        return stats.error();
    }
    GravityEstimate est = *stats;
    const std::string reasons = reasonsNotStatic(est, options);
    if (!reasons.empty()) {
        return makeError(ErrorCode::kDegenerate, "gravity: not static in " + where + " (" +
                                                     std::to_string(est.samples) +
                                                     " samples): " + reasons);
    }
    const auto n = static_cast<Scalar>(window.size());
    // |f_mean| is within the tolerance of gravity, so not zero.
    est.down_inI = -est.mean_accel_mps2 / est.magnitude_mps2;
    est.down_inC = (R_ItoC * est.down_inI).normalized();
    est.sigma_rad = est.spread_mps2 / (est.magnitude_mps2 * std::sqrt(n));
    return est;
}

}  // namespace scaled::core
