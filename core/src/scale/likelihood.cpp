#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include <scaled/core/scale/likelihood.h>

#include "grid_mode.h"

namespace scaled::core {

namespace {

// Heights are sorted and x = d D grows with j, so the terms within
// kWindowSigmas standard deviations of x form a window [lo, hi) that only
// moves forward: O(grid + histogram) per observation. Each term outside it
// is below exp(-kWindowSigmas^2 / 2) = e^-32 of the peak density, so the
// sum is exact wherever L matters (within ~e^-20 of its peak); when the
// window is empty (far tail) the heights bracketing x stand for the sum,
// which keeps log L finite there.
constexpr Scalar kWindowSigmas = 8;

// What the likelihood of one observation needs besides d.
struct ObservationTerms {
    // var(d) = max(var_const + var_per_d2 d^2, min_var)
    Scalar var_const = 0;
    Scalar var_per_d2 = 0;
    Scalar min_var = 0;
    bool partial = false;
    Scalar log_full = 0;
    Scalar log_partial = 0;
    Scalar log_sqrt_2pi = 0;
    bool robust = false;
    Scalar log_inlier = 0;
    Scalar log_outlier = 0;
};

// The prior's heights and log-probabilities, with the windows that move up with x.
struct PriorCursor {
    std::span<const Scalar> heights;
    std::span<const Scalar> log_probs;
    std::size_t lo = 0;
    std::size_t hi = 0;
    std::size_t k_partial = 0;
};

ObservationTerms observationTerms(const VerticalExtent& extent, const HeightPrior& prior,
                                  const ScaleGrid& grid, const LikelihoodConfig& config) {
    const Scalar D = extent.D;
    ObservationTerms t;
    const Scalar var_prior_bin = prior.binWidth() * prior.binWidth() / 12;
    const Scalar res = D * grid.delta();
    const Scalar var_grid_per_d2 = res * res / 12;  // times d^2
    t.min_var = config.min_sigma_m * config.min_sigma_m;

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
    t.var_const = var_const;
    t.var_per_d2 = var_per_d2;

    const Scalar partial_weight =
        prior.partialProbability() >= 0 ? prior.partialProbability() : config.partial_weight;
    t.partial = config.partial_visibility && partial_weight > 0;
    t.log_full = t.partial ? std::log1p(-partial_weight) : 0;
    t.log_partial = t.partial ? std::log(partial_weight) : 0;

    t.log_sqrt_2pi = Scalar(0.5) * std::log(2 * std::numbers::pi_v<Scalar>);
    t.robust = config.robust && config.outlier_weight > 0;
    t.log_inlier = t.robust ? std::log1p(-config.outlier_weight) : 0;
    t.log_outlier = t.robust ? std::log(config.outlier_weight / config.outlier_height_range_m) : 0;
    return t;
}

// log of sum_m P(H_m) N(x; H_m, var(d)) over the window of heights around x = d D.
Scalar fullLogDensity(Scalar d, Scalar x, const ObservationTerms& t, PriorCursor& c) {
    const std::span<const Scalar> heights = c.heights;
    const std::span<const Scalar> log_probs = c.log_probs;
    const std::size_t M = heights.size();
    const Scalar var = std::max(t.var_const + t.var_per_d2 * d * d, t.min_var);
    const Scalar inv_2var = 1 / (2 * var);
    const Scalar log_norm = -t.log_sqrt_2pi - Scalar(0.5) * std::log(var);
    const Scalar reach = kWindowSigmas * std::sqrt(var);
    while (c.lo < M && heights[c.lo] < x - reach) {
        ++c.lo;
    }
    c.hi = std::max(c.hi, c.lo);
    while (c.hi < M && heights[c.hi] <= x + reach) {
        ++c.hi;
    }
    std::size_t first = c.lo;
    std::size_t last = c.hi;  // exclusive
    if (first == last) {
        first = c.lo > 0 ? c.lo - 1 : c.lo;
        last = std::min(M, c.lo + 1);
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
    return log_norm + best + std::log(sum);
}

// The full-visibility value mixed with a partly visible object (suffix: S_k below).
Scalar withPartialVisibility(Scalar value, Scalar x, const ObservationTerms& t,
                             std::span<const Scalar> suffix, PriorCursor& c) {
    const std::size_t M = c.heights.size();
    while (c.k_partial < M && c.heights[c.k_partial] <= x) {
        ++c.k_partial;
    }
    const Scalar a = t.log_full + value;
    if (suffix[c.k_partial] > 0) {
        const Scalar b = t.log_partial + std::log(suffix[c.k_partial]);
        const Scalar top = std::max(a, b);
        return top + std::log(std::exp(a - top) + std::exp(b - top));
    }
    return a;
}

}  // namespace

bool evaluateLogLikelihood(const VerticalExtent& extent, const HeightPrior& prior,
                           const ScaleGrid& grid, const LikelihoodConfig& config,
                           std::span<Scalar> log_l) {
    const Scalar D = extent.D;
    if (prior.size() == 0 || !(D > 0) || !std::isfinite(D) || log_l.size() != grid.size()) {
        return false;
    }
    PriorCursor cursor{prior.heights(), prior.logProbabilities()};
    const auto heights = cursor.heights;
    const auto log_probs = cursor.log_probs;
    const std::size_t M = heights.size();
    const ObservationTerms t = observationTerms(extent, prior, grid, config);

    // Partial visibility: suffix sums S_k = sum_{m >= k} p_m / H_m (heights are
    // sorted), so the term at x is S_k for the first k with H_k > x.
    std::array<Scalar, HeightPrior::kMaxBins + 1> suffix{};
    if (t.partial) {
        for (std::size_t m = M; m-- > 0;) {
            suffix[m] = suffix[m + 1] + std::exp(log_probs[m]) / heights[m];
        }
    }

    for (std::size_t j = 0; j < grid.size(); ++j) {
        const Scalar d = grid.d(j);
        const Scalar x = d * D;
        Scalar value = fullLogDensity(d, x, t, cursor);
        if (t.partial) {
            value = withPartialVisibility(value, x, t, suffix, cursor);
        }
        if (t.robust && x <= config.outlier_height_range_m) {
            // log((1-w) L + w/R) for d D in (0, R), computed without leaving the log domain
            // (both terms are densities of the extent; under kPropagated both
            // get the factor d below).
            const Scalar a = t.log_inlier + value;
            const Scalar top = std::max(a, t.log_outlier);
            value = top + std::log(std::exp(a - top) + std::exp(t.log_outlier - top));
        } else if (t.robust) {
            // An outlier's extent is uniform in (0, R): none is taller.
            value += t.log_inlier;
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
