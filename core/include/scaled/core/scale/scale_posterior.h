#pragma once

// The grid posterior over the global scale d, accumulated in the log domain.
// The prior over d is uniform in log d (scale-invariant). All buffers are
// allocated at construction: updates do not allocate. Not thread-safe, not even
// for const calls: summary() uses the object's scratch buffer.

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/scale_grid.h>

namespace scaled::core {

enum class ScaleState : std::uint8_t { kNoData, kConverging, kConverged };
const char* toString(ScaleState state);

struct Interval {
    Scalar lo = 0;
    Scalar hi = 0;
};

struct ScaleSummary {
    Scalar map = 0;   // mode (parabola-refined in log d)
    Scalar mean = 0;  // posterior mean of d
    Interval ci68;    // equal-tailed credible intervals
    Interval ci95;
    Scalar rel_width95 = 0;  // (ci95.hi - ci95.lo) / map
    int observations = 0;
    ScaleState state = ScaleState::kNoData;
};

// How the posterior (and ScaleEstimator's likelihood) is computed: in Scalar
// floating point, or in integer fixed point (fixed_posterior.h: Q16 nats and
// table exp/log, no floating point in any per-bin loop; for boards without a
// fast FPU). See docs/numerics.md for the agreement between the two.
enum class PosteriorArithmetic : std::uint8_t { kFloating, kFixed };
const char* toString(PosteriorArithmetic arithmetic);

struct PosteriorConfig {
    GridConfig grid;
    PosteriorArithmetic arithmetic = PosteriorArithmetic::kFloating;
    // Converged when the 95% interval is narrower than this fraction of the MAP.
    Scalar converged_rel_width = Scalar(0.10);
    // Floor of the normalised log posterior (max = 0). Keeps every bin finite so
    // the posterior can never underflow, whatever the evidence. Fixed
    // arithmetic needs it in [-16000, 0).
    Scalar log_floor = -1000;
    // Diffusion of log d per update (scale drift). 0 = off.
    Scalar drift_sigma_log = 0;
};

// The allowed values of PosteriorConfig's parameters (param_limits.h):
// validate() and ScaleGrid::create check them, the daemon's [estimator]
// section offers them.
struct PosteriorLimits {
    static constexpr ParamLimits grid_d_min = openClosed(0, kUnbounded);  // finite, < d_max
    static constexpr ParamLimits grid_d_max = openClosed(0, kUnbounded);
    static constexpr ParamLimits grid_bins = closed(ScaleGrid::kMinBins, ScaleGrid::kMaxBins);
    static constexpr ParamLimits converged_rel_width = openClosed(0, 10);
    static constexpr ParamLimits drift_sigma_log = closed(0, 1);
};

// Checks the posterior's own fields (the grid is checked by ScaleGrid::create);
// the message names the field and value.
Status validate(const PosteriorConfig& config);

// With config.arithmetic = kFixed every call is forwarded to a FixedPosterior
// (fixed_posterior.h); the interface is the same for both.
class ScalePosterior {
public:
    static constexpr int kMaxKernelHalfWidth = 256;

    static Result<ScalePosterior> create(const PosteriorConfig& config);

    void reset();

    // Adds one observation's log-likelihood (size grid().size()), tempered by
    // weight in (0, 1]. Non-finite entries are rejected as a whole: returns
    // false and changes nothing. Fixed arithmetic: the values are converted to
    // Q16 nats first (floating point per bin: ScaleEstimator does not use this
    // path, it evaluates the likelihood in fixed point).
    bool addLogLikelihood(std::span<const Scalar> log_l, Scalar weight = 1);

    // Adds a fixed-point log-likelihood (FixedLikelihood's output: Q16 nats in
    // [kFixedLogLikelihoodMin, 0]). Floating arithmetic: converted to Scalar.
    bool addFixedLogLikelihood(std::span<const LogQ16> log_l, Scalar weight = 1);

    // Convolves the posterior with a Gaussian of std sigma_log in log d.
    void diffuse(Scalar sigma_log);

    // Sets the number of observations the summary reports (the object model
    // adds one likelihood per object but counts its views).
    void setObservationCount(int observations);

    [[nodiscard]] ScaleSummary summary() const;
    [[nodiscard]] const ScaleGrid& grid() const { return grid_; }
    [[nodiscard]] const PosteriorConfig& config() const { return config_; }
    [[nodiscard]] PosteriorArithmetic arithmetic() const { return config_.arithmetic; }
    // Normalised log density (maximum 0) on the grid, in Scalar nats (fixed
    // arithmetic: converted into a buffer sized at create, valid until the
    // next non-const call).
    [[nodiscard]] std::span<const Scalar> logDensity() const {
        return fixed_ ? fixed_->logDensity() : std::span<const Scalar>(log_p_);
    }
    // The fixed-point posterior (nullptr under floating arithmetic).
    [[nodiscard]] const FixedPosterior* fixedPosterior() const {
        return fixed_ ? &*fixed_ : nullptr;
    }
    [[nodiscard]] int observations() const {
        return fixed_ ? fixed_->observations() : observations_;
    }

private:
    ScalePosterior(const PosteriorConfig& config, ScaleGrid grid,
                   std::optional<FixedPosterior> fixed);
    void normalise();
    [[nodiscard]] Scalar quantile(std::span<const Scalar> cdf, Scalar q) const;

    PosteriorConfig config_;
    ScaleGrid grid_;
    std::vector<Scalar> log_p_;
    mutable std::vector<Scalar> work_;  // probabilities / cdf scratch
    std::vector<Scalar> work2_;
    std::vector<Scalar> kernel_;
    int observations_ = 0;
    std::optional<FixedPosterior> fixed_;
    std::vector<LogQ16> fixed_in_;  // addLogLikelihood's conversion (fixed only)
};

}  // namespace scaled::core
