#pragma once

// The grid posterior over the global scale d, accumulated in the log domain.
// The prior over d is uniform in log d (scale-invariant). All buffers are
// allocated at construction: updates do not allocate. Not thread-safe, not even
// for const calls: summary() uses the object's scratch buffer.

#include <cstdint>
#include <span>
#include <vector>

#include <scaled/core/result.h>
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

struct PosteriorConfig {
    GridConfig grid;
    // Converged when the 95% interval is narrower than this fraction of the MAP.
    Scalar converged_rel_width = Scalar(0.10);
    // Floor of the normalised log posterior (max = 0). Keeps every bin finite so
    // the posterior can never underflow, whatever the evidence.
    Scalar log_floor = -1000;
    // Diffusion of log d per update (scale drift). 0 = off.
    Scalar drift_sigma_log = 0;
};

class ScalePosterior {
public:
    static constexpr int kMaxKernelHalfWidth = 256;

    static Result<ScalePosterior> create(const PosteriorConfig& config);

    void reset();

    // Adds one observation's log-likelihood (size grid().size()), tempered by
    // weight in (0, 1]. Non-finite entries are rejected as a whole: returns
    // false and changes nothing.
    bool addLogLikelihood(std::span<const Scalar> log_l, Scalar weight = 1);

    // Convolves the posterior with a Gaussian of std sigma_log in log d.
    void diffuse(Scalar sigma_log);

    [[nodiscard]] ScaleSummary summary() const;
    [[nodiscard]] const ScaleGrid& grid() const { return grid_; }
    [[nodiscard]] const PosteriorConfig& config() const { return config_; }
    // Normalised log density (maximum 0) on the grid.
    [[nodiscard]] std::span<const Scalar> logDensity() const { return log_p_; }
    [[nodiscard]] int observations() const { return observations_; }

private:
    ScalePosterior(const PosteriorConfig& config, ScaleGrid grid);
    void normalise();
    [[nodiscard]] Scalar quantile(std::span<const Scalar> cdf, Scalar q) const;

    PosteriorConfig config_;
    ScaleGrid grid_;
    std::vector<Scalar> log_p_;
    mutable std::vector<Scalar> work_;  // probabilities / cdf scratch
    std::vector<Scalar> work2_;
    std::vector<Scalar> kernel_;
    int observations_ = 0;
};

}  // namespace scaled::core
