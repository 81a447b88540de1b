#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <string>

#include <scaled/core/scale/fixed_posterior.h>

#include "grid_mode.h"

namespace scaled::core {

namespace {

using fixed::kLog2FracBits;
using fixed::kLogFracBits;

constexpr double kMinSigmaM = 1e-5;
constexpr double kMaxLengthM = 536870912.0;  // 2^29 m: lengths stay far inside Q32 int64

// Floating -> fixed conversions: per observation or at construction only.
std::int64_t toQ(double v, int frac_bits) {
    return std::llround(std::ldexp(v, frac_bits));
}
std::int64_t toLog2Q24(double v) {
    return toQ(std::log2(v), kLog2FracBits);
}
std::int64_t toLnQ16(double v) {
    return toQ(std::log(v), kLogFracBits);
}

// v > 0 as mantissa * 2^(exponent - 30), mantissa in [2^30, 2^31].
void splitMantissa(double v, std::int64_t* mantissa, int* exponent) {
    int e = 0;
    const double f = std::frexp(v, &e);  // v = f 2^e, f in [0.5, 1)
    *mantissa = std::llround(std::ldexp(f, 31));
    *exponent = e - 1;
}

std::int64_t absValue(std::int64_t v) {
    return v < 0 ? -v : v;
}

// z = r / sigma in Q20 from r (Q32 metres) and 1/sigma = inv_mant 2^(inv_exp - 30):
// z 2^20 = r inv_mant 2^(inv_exp - 42). r is pre-shifted to 32 significant bits
// so the product stays within int64; |z| saturates at 2^11 sigma (z^2 / 2 then
// exceeds 2 million nats, far below any floor).
std::int64_t standardisedQ20(std::int64_t r, std::int64_t inv_mant, int inv_exp) {
    const auto width = static_cast<int>(std::bit_width(static_cast<std::uint64_t>(absValue(r))));
    const int pre = width > 32 ? width - 32 : 0;
    const std::int64_t product = (r >> pre) * inv_mant;
    std::int64_t z = fixed::shiftRound(product, 42 - inv_exp - pre);
    constexpr std::int64_t kZMax = std::int64_t{1} << 31;
    z = std::clamp(z, -kZMax, kZMax);
    return z;
}

}  // namespace

Result<FixedLikelihood> FixedLikelihood::create(const ScaleGrid& grid,
                                                const LikelihoodConfig& config) {
    if (!(static_cast<double>(config.min_sigma_m) >= kMinSigmaM) ||
        !std::isfinite(config.min_sigma_m)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "fixed likelihood: min_sigma_m must be >= 1e-5 m for fixed-point "
                         "arithmetic (got " +
                             std::to_string(config.min_sigma_m) + ")");
    }
    const bool robust = config.robust && config.outlier_weight > 0;
    if (robust && !(config.outlier_weight < 1 && config.outlier_height_range_m > 0 &&
                    static_cast<double>(config.outlier_height_range_m) < kMaxLengthM)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "fixed likelihood: robust mixture needs outlier_weight < 1 and "
                         "0 < outlier_height_range_m < 2^29 m");
    }
    FixedLikelihood f(grid.size());
    f.config_ = config;
    f.robust_ = robust;
    if (robust) {
        const auto w = static_cast<double>(config.outlier_weight);
        f.log_inlier_ = toQ(std::log1p(-w), kLogFracBits);
        f.log_outlier_ =
            toQ(std::log(w / static_cast<double>(config.outlier_height_range_m)), kLogFracBits);
        f.outlier_range_ =
            toQ(static_cast<double>(config.outlier_height_range_m), fixed::kLengthFracBits);
    }
    const auto min_sigma = static_cast<double>(config.min_sigma_m);
    f.log2_min_var_ = toLog2Q24(min_sigma * min_sigma);
    f.grid_delta_ = static_cast<double>(grid.delta());

    const std::size_t n = grid.size();
    for (std::size_t j = 0; j < n; ++j) {
        // The floating likelihood uses d_j = grid.d(j) (a Scalar): so do we.
        const auto d = static_cast<double>(grid.d(j));
        f.log2_d_[j] = toLog2Q24(d);
        f.ln_d_[j] = toLnQ16(d);
        splitMantissa(d, &f.d_mant_[j], &f.d_exp_[j]);
    }
    return f;
}

FixedLikelihood::FixedLikelihood(std::size_t bins)
    : log2_d_(bins, 0),
      ln_d_(bins, 0),
      d_mant_(bins, 0),
      d_exp_(bins, 0),
      values_(bins, 0),
      heights_(kPriorBins, 0),
      log_probs_(kPriorBins, 0),
      log_suffix_(kPriorBins + 1, 0),
      has_suffix_(kPriorBins + 1, 0),
      terms_(kPriorBins, 0) {}

// What evaluate() computes once per observation, in fixed point.
struct FixedLikelihood::Observation {
    std::size_t M = 0;  // bins of the prior
    // var = a + b d^2
    bool has_a = false;
    std::int64_t log2_a = 0;  // Q24
    std::int64_t log2_b = 0;  // Q24
    // D = d_mant 2^(d_exp - 30)
    std::int64_t d_mant = 0;
    int d_exp = 0;
    bool partial = false;
    std::int64_t log_full = 0;      // Q16 nats
    std::int64_t log_partial = 0;   // Q16 nats
    std::int64_t log_sqrt_2pi = 0;  // 0.5 ln(2 pi), Q16 nats
};

// Windows over the prior's heights: they only move up as d_j grows.
struct FixedLikelihood::BinCursor {
    std::size_t lo = 0;
    std::size_t hi = 0;
    std::size_t k_partial = 0;
};

bool FixedLikelihood::prepareObservation(const VerticalExtent& extent, const HeightPrior& prior,
                                         Observation& obs) {
    const auto D = static_cast<double>(extent.D);
    const std::size_t M = prior.size();
    if (M == 0 || M > heights_.size() || !(D > 0) || !std::isfinite(D) ||
        !std::isfinite(extent.sigma_D_paper) || !std::isfinite(extent.sigma_D_feature) ||
        !std::isfinite(extent.sigma_D_box)) {
        return false;
    }
    const auto heights = prior.heights();
    const auto log_probs = prior.logProbabilities();
    if (!(static_cast<double>(heights[M - 1]) < kMaxLengthM)) {
        return false;
    }
    obs.M = M;
    for (std::size_t m = 0; m < M; ++m) {
        heights_[m] = toQ(static_cast<double>(heights[m]), fixed::kLengthFracBits);
        log_probs_[m] = toQ(static_cast<double>(log_probs[m]), kLogFracBits);
    }

    // The same variance terms as evaluateLogLikelihood: var = a + b d^2.
    const auto bin_width = static_cast<double>(prior.binWidth());
    const double res = D * grid_delta_;
    double a = bin_width * bin_width / 12;
    double b = res * res / 12;
    if (config_.variance_model == VarianceModel::kPaper) {
        const double s = static_cast<double>(extent.sigma_D_paper) * D;
        a += s * s;
    } else {
        const auto sf = static_cast<double>(extent.sigma_D_feature);
        const auto sb = static_cast<double>(extent.sigma_D_box);
        b += sf * sf + sb * sb;
    }
    obs.has_a = a > 0;
    obs.log2_a = obs.has_a ? toLog2Q24(a) : 0;
    obs.log2_b = toLog2Q24(b);
    splitMantissa(D, &obs.d_mant, &obs.d_exp);

    preparePartialVisibility(prior, obs);
    // -0.5 ln(2 pi), Q16 nats.
    obs.log_sqrt_2pi = toQ(0.5 * std::log(2 * std::numbers::pi), kLogFracBits);
    return true;
}

// The mixture weights and the suffix sums ln sum_{m >= k} p_m / H_m of partial visibility.
void FixedLikelihood::preparePartialVisibility(const HeightPrior& prior, Observation& obs) {
    const std::size_t M = obs.M;
    const auto heights = prior.heights();
    const auto log_probs = prior.logProbabilities();
    const double partial_weight = prior.partialProbability() >= 0
                                      ? static_cast<double>(prior.partialProbability())
                                      : static_cast<double>(config_.partial_weight);
    obs.partial = config_.partial_visibility && partial_weight > 0;
    if (obs.partial) {
        obs.log_full = toQ(std::log1p(-partial_weight), kLogFracBits);
        obs.log_partial = toQ(std::log(partial_weight), kLogFracBits);
        double suffix = 0;
        log_suffix_[M] = 0;
        has_suffix_[M] = 0;
        for (std::size_t m = M; m-- > 0;) {
            suffix += std::exp(static_cast<double>(log_probs[m])) / static_cast<double>(heights[m]);
            has_suffix_[m] = suffix > 0 ? 1 : 0;
            log_suffix_[m] = suffix > 0 ? toLnQ16(suffix) : 0;
        }
    }
}

std::int64_t FixedLikelihood::windowLogSumQ16(std::int64_t x, std::int64_t reach,
                                              const fixed::Exp2Split& inv_sigma, std::size_t M,
                                              BinCursor& cursor) {
    constexpr std::int64_t kWindowSigmas = 8;
    std::size_t& lo = cursor.lo;
    std::size_t& hi = cursor.hi;
    // The window of heights within 8 sigma of x (as evaluateLogLikelihood).
    while (lo < M && heights_[lo] < x - reach) {
        ++lo;
    }
    hi = std::max(hi, lo);
    while (hi < M && heights_[hi] <= x + reach) {
        ++hi;
    }
    std::size_t first = lo;
    std::size_t last = hi;
    if (first == last) {
        first = lo > 0 ? lo - 1 : lo;
        last = std::min(M, lo + 1);
    }
    static_assert(kWindowSigmas == 8, "reach above is 2^3 sigma");
    std::int64_t best = std::numeric_limits<std::int64_t>::min();
    for (std::size_t m = first; m < last; ++m) {
        const std::int64_t z =
            standardisedQ20(x - heights_[m], inv_sigma.mantissa, inv_sigma.exponent);
        // z^2 / 2: Q40 -> Q16 nats.
        const std::int64_t term = log_probs_[m] - ((z * z + (std::int64_t{1} << 24)) >> 25);
        terms_[m - first] = term;
        best = std::max(best, term);
    }
    std::int64_t sum = 0;  // Q30, >= 1.0 (the best term)
    for (std::size_t m = first; m < last; ++m) {
        sum += fixed::expNegQ30(best - terms_[m - first]);
    }
    return best + fixed::lnQ16(static_cast<std::uint64_t>(sum), fixed::kProbFracBits);
}

std::int64_t FixedLikelihood::binValueQ16(std::size_t j, const Observation& obs,
                                          BinCursor& cursor) {
    const std::size_t M = obs.M;
    // x = d_j D in Q32 metres: mantissas multiply exactly (< 2^62).
    const std::int64_t x = fixed::shiftRound(d_mant_[j] * obs.d_mant, 28 - d_exp_[j] - obs.d_exp);
    // log2 var = log2(a + b d^2), at least log2(min_sigma^2).
    const std::int64_t log2_bd2 = obs.log2_b + 2 * log2_d_[j];
    std::int64_t log2_var = obs.has_a ? fixed::log2AddExp2Q24(obs.log2_a, log2_bd2) : log2_bd2;
    log2_var = std::max(log2_var, log2_min_var_);
    // log_norm = -0.5 ln(2 pi) - 0.5 ln var.
    constexpr int kHalfLnShift = kLog2FracBits + 32 - kLogFracBits + 1;
    const std::int64_t log_norm =
        -obs.log_sqrt_2pi -
        ((log2_var * fixed::kLn2Q32 + (std::int64_t{1} << (kHalfLnShift - 1))) >> kHalfLnShift);
    // sigma = 2^(log2 var / 2), 1/sigma = 2^(-log2 var / 2), as mantissa/exponent.
    const fixed::Exp2Split sigma = fixed::exp2Split(log2_var / 2);
    const fixed::Exp2Split inv_sigma = fixed::exp2Split(-(log2_var / 2));
    // reach = 8 sigma in Q32 metres = mantissa 2^(exponent - 30 + 32 + 3).
    const std::int64_t reach = fixed::shiftRound(sigma.mantissa, -(sigma.exponent + 5));

    std::int64_t value = log_norm + windowLogSumQ16(x, reach, inv_sigma, M, cursor);

    if (obs.partial) {
        while (cursor.k_partial < M && heights_[cursor.k_partial] <= x) {
            ++cursor.k_partial;
        }
        const std::int64_t full = obs.log_full + value;
        value = has_suffix_[cursor.k_partial] != 0
                    ? fixed::logAddExpQ16(full, obs.log_partial + log_suffix_[cursor.k_partial])
                    : full;
    }
    if (robust_ && x <= outlier_range_) {
        value = fixed::logAddExpQ16(log_inlier_ + value, log_outlier_);
    } else if (robust_) {
        value += log_inlier_;
    }
    if (config_.variance_model == VarianceModel::kPropagated) {
        value += ln_d_[j];
    }
    return value;
}

bool FixedLikelihood::evaluate(const VerticalExtent& extent, const HeightPrior& prior,
                               std::span<LogQ16> log_l) {
    // ---- Per observation: floating point, O(histogram). ----
    Observation obs;
    if (log_l.size() != log2_d_.size() || !prepareObservation(extent, prior, obs)) {
        return false;
    }

    // ---- Per bin: integer only. ----
    BinCursor cursor;
    std::int64_t best_bin = std::numeric_limits<std::int64_t>::min();
    const std::size_t n = log2_d_.size();
    for (std::size_t j = 0; j < n; ++j) {
        const std::int64_t value = binValueQ16(j, obs, cursor);
        values_[j] = value;
        best_bin = std::max(best_bin, value);
    }
    for (std::size_t j = 0; j < n; ++j) {
        const std::int64_t v = values_[j] - best_bin;
        log_l[j] = static_cast<LogQ16>(std::max<std::int64_t>(v, kFixedLogLikelihoodMin));
    }
    return true;
}

Scalar gridModeFixed(const ScaleGrid& grid, std::span<const LogQ16> v) {
    return detail::gridModeOf<std::int64_t>(grid, v);
}

}  // namespace scaled::core
