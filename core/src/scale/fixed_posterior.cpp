#include <algorithm>
#include <cmath>
#include <string>

#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/scale_posterior.h>

namespace scaled::core {

namespace {

using fixed::kLogFracBits;

}  // namespace

Result<FixedPosterior> FixedPosterior::create(const PosteriorConfig& config) {
    auto grid = ScaleGrid::create(config.grid);
    if (!grid) {
        return grid.error();
    }
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    if (!(config.log_floor >= kMinLogFloor)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "fixed posterior: log_floor must be in [-16000, 0) (got " +
                             std::to_string(config.log_floor) + ")");
    }
    return FixedPosterior(std::move(grid.value()), config.log_floor, config.drift_sigma_log,
                          config.converged_rel_width);
}

FixedPosterior::FixedPosterior(ScaleGrid grid, Scalar log_floor, Scalar drift_sigma_log,
                               Scalar converged_rel_width)
    : grid_(std::move(grid)),
      floor_(static_cast<LogQ16>(
          std::llround(std::ldexp(static_cast<double>(log_floor), kLogFracBits)))),
      drift_sigma_log_(drift_sigma_log),
      converged_rel_width_(converged_rel_width),
      d_q_(grid_.size(), 0),
      log_p_(grid_.size(), 0),
      work_(grid_.size(), 0),
      cdf_(grid_.size(), 0),
      density_(grid_.size(), 0),
      kernel_log_(2 * kMaxKernelHalfWidth + 1, 0),
      kernel_q30_(2 * kMaxKernelHalfWidth + 1, 0) {
    // d_j in fixed point for the posterior mean, the largest just below 2^31.
    int e = 0;
    std::frexp(static_cast<double>(grid_.dMax()), &e);  // d_max < 2^e
    d_frac_bits_ = 31 - e;
    for (std::size_t j = 0; j < d_q_.size(); ++j) {
        d_q_[j] = std::llround(std::ldexp(static_cast<double>(grid_.d(j)), d_frac_bits_));
    }
}

void FixedPosterior::reset() {
    std::fill(log_p_.begin(), log_p_.end(), 0);
    observations_ = 0;
    density_stale_ = true;
}

void FixedPosterior::normalise() {
    const LogQ16 mx = *std::max_element(log_p_.begin(), log_p_.end());
    for (auto& v : log_p_) {
        // v - mx >= INT32_MIN + ... : both are int32 in [-32768, 0] nats.
        v = fixed::saturateLog(std::max<std::int64_t>(std::int64_t{v} - mx, floor_));
    }
    density_stale_ = true;
}

bool FixedPosterior::addLogLikelihood(std::span<const LogQ16> log_l, Scalar weight) {
    if (log_l.size() != log_p_.size() || !(weight > 0 && weight <= 1)) {
        return false;
    }
    for (const LogQ16 v : log_l) {
        if (v > 0 || v < kFixedLogLikelihoodMin) {
            return false;
        }
    }
    // The weight as a Q16 multiplier (per observation: the one floating step).
    const std::int64_t w = std::max<std::int64_t>(
        1, std::llround(std::ldexp(static_cast<double>(weight), kLogFracBits)));
    for (std::size_t j = 0; j < log_p_.size(); ++j) {
        // log_p >= floor >= -16000 nats and w log_l >= -16384 nats: the sum
        // fits int32; saturate anyway rather than ever wrap.
        const std::int64_t t =
            std::int64_t{log_p_[j]} +
            ((std::int64_t{log_l[j]} * w + (std::int64_t{1} << (kLogFracBits - 1))) >>
             kLogFracBits);
        log_p_[j] = fixed::saturateLog(t);
    }
    normalise();
    ++observations_;
    if (drift_sigma_log_ > 0) {
        diffuse(drift_sigma_log_);
    }
    return true;
}

void FixedPosterior::diffuse(Scalar sigma_log) {
    if (!(sigma_log > 0) || !std::isfinite(sigma_log)) {
        return;
    }
    // The kernel, once per call (O(kernel), not O(grid)).
    const double sigma_bins = static_cast<double>(sigma_log) / static_cast<double>(grid_.delta());
    const int half = std::min(kMaxKernelHalfWidth, static_cast<int>(std::ceil(4 * sigma_bins)));
    if (half < 1) {
        return;
    }
    // -0.5 (k / sigma_bins)^2 = -k^2 c, c in Q32 nats.
    const std::int64_t c_q32 = std::llround(std::ldexp(0.5 / (sigma_bins * sigma_bins), 32));
    for (int k = -half; k <= half; ++k) {
        const int k_slot = k + half;
        const auto slot = static_cast<std::size_t>(k_slot);
        const std::int64_t k2 = std::int64_t{k} * k;
        kernel_log_[slot] = -((k2 * c_q32 + (std::int64_t{1} << 15)) >> 16);
        kernel_q30_[slot] = fixed::expNegQ30(-kernel_log_[slot]);
    }
    // p'_j = sum_i w_{i-j} p_i / sum_i w_{i-j} over the bins inside the grid,
    // as a log-sum-exp (exact tails, no underflow).
    const auto n = static_cast<int>(log_p_.size());
    for (int j = 0; j < n; ++j) {
        const int lo = std::max(0, j - half);
        const int hi = std::min(n - 1, j + half);
        std::int64_t best = std::numeric_limits<std::int64_t>::min();
        for (int i = lo; i <= hi; ++i) {
            const int i_slot = i - j + half;
            const auto slot = static_cast<std::size_t>(i_slot);
            best = std::max(best, log_p_[static_cast<std::size_t>(i)] + kernel_log_[slot]);
        }
        std::int64_t acc = 0;
        std::int64_t wsum = 0;
        for (int i = lo; i <= hi; ++i) {
            const int i_slot = i - j + half;
            const auto slot = static_cast<std::size_t>(i_slot);
            acc +=
                fixed::expNegQ30(best - (log_p_[static_cast<std::size_t>(i)] + kernel_log_[slot]));
            wsum += kernel_q30_[slot];
        }
        const std::int64_t v = best + fixed::lnQ16(static_cast<std::uint64_t>(acc), 0) -
                               fixed::lnQ16(static_cast<std::uint64_t>(wsum), 0);
        work_[static_cast<std::size_t>(j)] = fixed::saturateLog(std::max<std::int64_t>(v, floor_));
    }
    std::copy(work_.begin(), work_.end(), log_p_.begin());
    normalise();
}

std::span<const Scalar> FixedPosterior::logDensity() const {
    if (density_stale_) {
        // Conversion for reports only (not part of any update).
        for (std::size_t j = 0; j < log_p_.size(); ++j) {
            density_[j] =
                static_cast<Scalar>(std::ldexp(static_cast<double>(log_p_[j]), -kLogFracBits));
        }
        density_stale_ = false;
    }
    return density_;
}

Scalar FixedPosterior::quantile(std::int64_t total, Quantile q) const {
    // First j with cdf_j / total >= num / den, exactly in integers
    // (cdf <= 2^46, den <= 40).
    const std::int64_t target = total * q.num;
    const auto it = std::lower_bound(cdf_.begin(), cdf_.end(), target,
                                     [&](std::int64_t c, std::int64_t t) { return c * q.den < t; });
    const auto j = static_cast<std::size_t>(std::distance(cdf_.begin(), it));
    if (j >= cdf_.size()) {
        return grid_.dMax();
    }
    const std::int64_t below = j == 0 ? 0 : cdf_[j - 1];
    const std::int64_t mass = cdf_[j] - below;
    // Final conversion: the position inside bin j.
    const double frac =
        mass > 0 ? static_cast<double>(target - below * q.den) / static_cast<double>(mass * q.den)
                 : 0.5;
    return static_cast<Scalar>(std::exp(static_cast<double>(grid_.logD(j)) +
                                        (frac - 0.5) * static_cast<double>(grid_.delta())));
}

ScaleSummary FixedPosterior::summary() const {
    ScaleSummary s;
    s.observations = observations_;
    // Probabilities in Q30 (the maximum bin is 1.0), their running sum (the
    // CDF, <= 2^46 for 65536 bins) and sum p_j d_j in two 32-bit halves so the
    // exact integer sum cannot overflow.
    std::int64_t total = 0;
    std::uint64_t mean_hi = 0;
    std::uint64_t mean_lo = 0;
    for (std::size_t j = 0; j < log_p_.size(); ++j) {
        const std::int64_t p = fixed::expNegQ30(-std::int64_t{log_p_[j]});
        total += p;
        cdf_[j] = total;
        const auto pd = static_cast<std::uint64_t>(p) * static_cast<std::uint64_t>(d_q_[j]);
        mean_hi += pd >> 32;
        mean_lo += pd & 0xFFFFFFFFULL;
    }
    const double weighted =
        std::ldexp(static_cast<double>(mean_hi), 32) + static_cast<double>(mean_lo);
    s.mean = static_cast<Scalar>(std::ldexp(weighted / static_cast<double>(total), -d_frac_bits_));
    s.map = gridModeFixed(grid_, log_p_);
    s.ci68 = {quantile(total, {4, 25}), quantile(total, {21, 25})};
    s.ci95 = {quantile(total, {1, 40}), quantile(total, {39, 40})};
    s.rel_width95 = (s.ci95.hi - s.ci95.lo) / s.map;
    if (observations_ == 0) {
        s.state = ScaleState::kNoData;
    } else if (s.rel_width95 < converged_rel_width_) {
        s.state = ScaleState::kConverged;
    } else {
        s.state = ScaleState::kConverging;
    }
    return s;
}

}  // namespace scaled::core
