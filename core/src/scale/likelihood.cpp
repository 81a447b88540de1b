#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <scaled/core/scale/likelihood.h>

#include "grid_mode.h"

namespace scaled::core {

bool evaluateLogLikelihood(const VerticalExtent& extent, const HeightPrior& prior,
                           const ScaleGrid& grid, const LikelihoodConfig& config,
                           std::span<Scalar> log_l) {
    const Scalar D = extent.D;
    if (prior.size() == 0 || !(D > 0) || !std::isfinite(D) || log_l.size() != grid.size()) {
        return false;
    }
    const auto heights = prior.heights();
    const auto log_probs = prior.logProbabilities();
    const std::size_t M = heights.size();

    const Scalar var_prior_bin = prior.binWidth() * prior.binWidth() / 12;
    const Scalar res = D * grid.delta();
    const Scalar var_grid_per_d2 = res * res / 12;  // times d^2
    const Scalar min_var = config.min_sigma_m * config.min_sigma_m;

    // Model variance: constant (paper) or proportional to d^2 (propagated).
    Scalar var_const = 0;
    Scalar var_per_d2 = var_grid_per_d2;
    if (config.variance_model == VarianceModel::kPaper) {
        const Scalar s = extent.sigma_D_paper * D;
        var_const = s * s;
    } else {
        var_per_d2 += extent.sigma_D_feature * extent.sigma_D_feature +
                      extent.sigma_D_box * extent.sigma_D_box;
    }
    var_const += var_prior_bin;

    // Partial visibility: suffix sums S_k = sum_{m >= k} p_m / H_m (heights are
    // sorted), so the term at x is S_k for the first k with H_k > x.
    const Scalar partial_weight =
        prior.partialProbability() >= 0 ? prior.partialProbability() : config.partial_weight;
    const bool partial = config.partial_visibility && partial_weight > 0;
    std::array<Scalar, HeightPrior::kMaxBins + 1> suffix{};
    if (partial) {
        for (std::size_t m = M; m-- > 0;) {
            suffix[m] = suffix[m + 1] + std::exp(log_probs[m]) / heights[m];
        }
    }
    const Scalar log_full = partial ? std::log1p(-partial_weight) : 0;
    const Scalar log_partial = partial ? std::log(partial_weight) : 0;
    std::size_t k_partial = 0;

    const Scalar log_sqrt_2pi = Scalar(0.5) * std::log(2 * std::numbers::pi_v<Scalar>);
    const bool robust = config.robust && config.outlier_weight > 0;
    const Scalar log_inlier = robust ? std::log1p(-config.outlier_weight) : 0;
    const Scalar log_outlier =
        robust ? std::log(config.outlier_weight / config.outlier_height_range_m) : 0;

    // Heights are sorted and x = d D grows with j, so the terms within
    // kWindowSigmas standard deviations of x form a window [lo, hi) that only
    // moves forward: O(grid + histogram) per observation. Each term outside it
    // is below exp(-kWindowSigmas^2 / 2) = e^-32 of the peak density, so the
    // sum is exact wherever L matters (within ~e^-20 of its peak); when the
    // window is empty (far tail) the heights bracketing x stand for the sum,
    // which keeps log L finite there.
    constexpr Scalar kWindowSigmas = 8;
    std::size_t lo = 0;
    std::size_t hi = 0;
    for (std::size_t j = 0; j < grid.size(); ++j) {
        const Scalar d = grid.d(j);
        const Scalar x = d * D;
        const Scalar var = std::max(var_const + var_per_d2 * d * d, min_var);
        const Scalar inv_2var = 1 / (2 * var);
        const Scalar log_norm = -log_sqrt_2pi - Scalar(0.5) * std::log(var);
        const Scalar reach = kWindowSigmas * std::sqrt(var);
        while (lo < M && heights[lo] < x - reach) {
            ++lo;
        }
        hi = std::max(hi, lo);
        while (hi < M && heights[hi] <= x + reach) {
            ++hi;
        }
        std::size_t first = lo;
        std::size_t last = hi;  // exclusive
        if (first == last) {
            first = lo > 0 ? lo - 1 : lo;
            last = std::min(M, lo + 1);
        }
        // log-sum-exp over the window: first the largest term, then the sum.
        Scalar best = -std::numeric_limits<Scalar>::infinity();
        for (std::size_t m = first; m < last; ++m) {
            const Scalar r = x - heights[m];
            best = std::max(best, log_probs[m] - r * r * inv_2var);
        }
        Scalar sum = 0;
        for (std::size_t m = first; m < last; ++m) {
            const Scalar r = x - heights[m];
            sum += std::exp(log_probs[m] - r * r * inv_2var - best);
        }
        Scalar value = log_norm + best + std::log(sum);
        if (partial) {
            while (k_partial < M && heights[k_partial] <= x) {
                ++k_partial;
            }
            const Scalar a = log_full + value;
            if (suffix[k_partial] > 0) {
                const Scalar b = log_partial + std::log(suffix[k_partial]);
                const Scalar top = std::max(a, b);
                value = top + std::log(std::exp(a - top) + std::exp(b - top));
            } else {
                value = a;
            }
        }
        if (robust && x <= config.outlier_height_range_m) {
            // log((1-w) L + w/R) for d D in (0, R), computed without leaving the log domain
            // (both terms are densities of the extent; under kPropagated both
            // get the factor d below).
            const Scalar a = log_inlier + value;
            const Scalar top = std::max(a, log_outlier);
            value = top + std::log(std::exp(a - top) + std::exp(log_outlier - top));
        } else if (robust) {
            // An outlier's extent is uniform in (0, R): none is taller.
            value += log_inlier;
        }
        if (config.variance_model == VarianceModel::kPropagated) {
            // Density of the measurement D itself: p(D | d) = d f(d D - H; d sigma_D).
            value += std::log(d);
        }
        log_l[j] = value;
    }
    return true;
}

Scalar gridMode(const ScaleGrid& grid, std::span<const Scalar> v) {
    return detail::gridModeOf<Scalar>(grid, v);
}

}  // namespace scaled::core
