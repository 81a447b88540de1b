#pragma once

// The scale posterior and the observation likelihood in fixed point: integer
// log-probabilities (Q16 nats, fixed_point.h) and table-based exp / log /
// log-sum-exp, for boards without a fast FPU. Selected by
// PosteriorConfig::arithmetic = PosteriorArithmetic::kFixed (ScalePosterior and
// ScaleEstimator then use these classes; they can also be used directly).
//
// Where floating point remains (docs/numerics.md, "Fixed-point posterior"):
//   - at construction: the per-grid tables (d_j, log d_j) and the config's
//     constants are converted once;
//   - per observation, before the per-bin loop: D, the sigma terms, the prior's
//     heights and log-probabilities, the partial-visibility suffix sums and the
//     observation weight are converted to fixed point (O(histogram), not
//     O(grid));
//   - per summary: the final conversion of MAP, mean and interval bounds to
//     Scalar (a handful of exp() calls), and logDensity()'s conversion of the
//     integer density to Scalar for reports.
// Every per-bin loop (likelihood, accumulation, normalisation, diffusion,
// CDF, quantile search) is integer-only. No allocation after create(), no
// exceptions, all loops bounded by the grid and histogram sizes.

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/fixed_point.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/scale_grid.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::core {

struct PosteriorConfig;
struct ScaleSummary;

using fixed::LogQ16;

// The fixed likelihood is normalised to a maximum of 0 and saturated at this
// value (-16384 nats). Exact for the posterior whenever weight * 16384 nats
// exceeds twice |log_floor| (weight >= 1/8 at the default floor of -1000
// nats): a bin further below the likelihood's maximum ends at the posterior's
// floor either way. With smaller weights such bins are still >= weight * 16384
// nats below the peak, i.e. invisible in every summary.
inline constexpr LogQ16 kFixedLogLikelihoodMin = -(16384 << fixed::kLogFracBits);

// evaluateLogLikelihood (likelihood.h) in integer arithmetic. Same model and
// options; the output is shifted so that its maximum is 0 (a constant per
// observation: it does not change the posterior) and saturated at
// kFixedLogLikelihoodMin.
class FixedLikelihood {
public:
    // Inputs the fixed formats cannot represent faithfully are rejected here:
    // min_sigma_m < 1e-5 m (z = r / sigma would lose precision in Q32 metres),
    // outlier_height_range_m >= 2^29 m.
    static Result<FixedLikelihood> create(const ScaleGrid& grid, const LikelihoodConfig& config);

    // Writes the normalised log-likelihood (size grid size). Returns false and
    // writes nothing where evaluateLogLikelihood would not give a finite
    // likelihood: empty prior, D not positive or not finite, non-finite sigmas,
    // heights beyond 2^29 m.
    bool evaluate(const VerticalExtent& extent, const HeightPrior& prior, std::span<LogQ16> log_l);

    [[nodiscard]] std::size_t size() const { return log2_d_.size(); }

private:
    static constexpr auto kPriorBins = static_cast<std::size_t>(HeightPrior::kMaxBins);
    struct Observation;  // evaluate()'s per-observation terms (fixed_likelihood.cpp)
    struct BinCursor;    // evaluate()'s windows over the prior, moving up with d
    explicit FixedLikelihood(std::size_t bins);
    // Per observation, floating point: false where evaluate() returns false.
    bool prepareObservation(const VerticalExtent& extent, const HeightPrior& prior,
                            Observation& obs);
    void preparePartialVisibility(const HeightPrior& prior, Observation& obs);
    // Per bin, integer only: the unnormalised log L at d_j, Q16 nats.
    std::int64_t binValueQ16(std::size_t j, const Observation& obs, BinCursor& cursor);
    // ln sum_m P(h_m) exp(-z_m^2 / 2) over the heights within 8 sigma of x, Q16 nats.
    std::int64_t windowLogSumQ16(std::int64_t x, std::int64_t reach,
                                 const fixed::Exp2Split& inv_sigma, std::size_t M,
                                 BinCursor& cursor);

    LikelihoodConfig config_;
    bool robust_ = false;
    std::int64_t log_inlier_ = 0;     // Q16 nats
    std::int64_t log_outlier_ = 0;    // Q16 nats
    std::int64_t outlier_range_ = 0;  // Q32 metres
    std::int64_t log2_min_var_ = 0;   // Q24
    double grid_delta_ = 0;

    // Per-grid tables (built at create).
    std::vector<std::int64_t> log2_d_;  // log2 d_j, Q24
    std::vector<std::int64_t> ln_d_;    // ln d_j, Q16 nats
    std::vector<std::int64_t> d_mant_;  // d_j = d_mant * 2^(d_exp - 30)
    std::vector<int> d_exp_;
    std::vector<std::int64_t> values_;  // unnormalised log L, Q16 nats

    // Per-observation prior in fixed point (sized HeightPrior::kMaxBins).
    std::vector<std::int64_t> heights_;     // Q32 metres
    std::vector<std::int64_t> log_probs_;   // Q16 nats
    std::vector<std::int64_t> log_suffix_;  // ln sum_{m >= k} p_m / H_m, Q16 nats
    std::vector<std::uint8_t> has_suffix_;
    std::vector<std::int64_t> terms_;  // window terms of one bin
};

// The mode of a fixed log-likelihood or log density on the grid, refined by a
// parabola in log d (as gridMode). The integer part is exact; only the final
// offset and exp() are floating.
Scalar gridModeFixed(const ScaleGrid& grid, std::span<const LogQ16> log_values);

class FixedPosterior {
public:
    static constexpr int kMaxKernelHalfWidth = 256;
    // The floor must leave room for a saturated likelihood in int32.
    static constexpr Scalar kMinLogFloor = -16000;

    static Result<FixedPosterior> create(const PosteriorConfig& config);

    void reset();
    void setObservationCount(int observations) { observations_ = observations; }

    // Adds weight * log_l (weight in (0, 1], applied as a Q16 multiplier).
    // Values must be <= 0 and >= kFixedLogLikelihoodMin (FixedLikelihood's
    // output); returns false and changes nothing otherwise.
    bool addLogLikelihood(std::span<const LogQ16> log_l, Scalar weight = 1);

    // Convolves the posterior with a Gaussian of std sigma_log in log d,
    // truncated at the grid ends and renormalised (as ScalePosterior::diffuse),
    // as a log-sum-exp over the kernel so the tails stay exact down to the floor.
    void diffuse(Scalar sigma_log);

    [[nodiscard]] ScaleSummary summary() const;
    [[nodiscard]] const ScaleGrid& grid() const { return grid_; }
    // Normalised log density (maximum 0), Q16 nats.
    [[nodiscard]] std::span<const LogQ16> logDensityFixed() const { return log_p_; }
    // The same in Scalar nats, converted into a buffer sized at create (no
    // allocation); valid until the next non-const call.
    [[nodiscard]] std::span<const Scalar> logDensity() const;
    [[nodiscard]] int observations() const { return observations_; }

private:
    FixedPosterior(ScaleGrid grid, Scalar log_floor, Scalar drift_sigma_log,
                   Scalar converged_rel_width);
    void normalise();
    struct Quantile {
        std::int64_t num;
        std::int64_t den;
    };
    [[nodiscard]] Scalar quantile(std::int64_t total, Quantile q) const;

    ScaleGrid grid_;
    LogQ16 floor_ = 0;
    Scalar drift_sigma_log_ = 0;
    Scalar converged_rel_width_ = 0;
    int d_frac_bits_ = 0;  // d_q_ = d_j * 2^d_frac_bits_
    std::vector<std::int64_t> d_q_;
    std::vector<LogQ16> log_p_;
    std::vector<LogQ16> work_;
    mutable std::vector<std::int64_t> cdf_;
    mutable std::vector<Scalar> density_;
    mutable bool density_stale_ = true;
    std::vector<std::int64_t> kernel_log_;  // Q16 nats
    std::vector<std::int64_t> kernel_q30_;
    int observations_ = 0;
};

}  // namespace scaled::core
