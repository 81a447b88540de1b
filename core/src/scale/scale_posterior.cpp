#include <algorithm>
#include <cmath>
#include <string>

#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/scale_posterior.h>

namespace scaled::core {

const char* toString(ScaleState state) {
    switch (state) {
        case ScaleState::kNoData:
            return "no_data";
        case ScaleState::kConverging:
            return "converging";
        case ScaleState::kConverged:
            return "converged";
    }
    return "unknown";
}

Result<ScalePosterior> ScalePosterior::create(const PosteriorConfig& config) {
    auto grid = ScaleGrid::create(config.grid);
    if (!grid) {
        return grid.error();
    }
    if (!(config.converged_rel_width > 0) || !std::isfinite(config.converged_rel_width)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "posterior: converged_rel_width must be > 0 (got " +
                             std::to_string(config.converged_rel_width) + ")");
    }
    if (!(config.log_floor < 0) || !std::isfinite(config.log_floor)) {
        return makeError(ErrorCode::kInvalidArgument, "posterior: log_floor must be < 0");
    }
    if (!(config.drift_sigma_log >= 0) || !std::isfinite(config.drift_sigma_log)) {
        return makeError(ErrorCode::kInvalidArgument, "posterior: drift_sigma_log must be >= 0");
    }
    return ScalePosterior(config, std::move(grid.value()));
}

ScalePosterior::ScalePosterior(const PosteriorConfig& config, ScaleGrid grid)
    : config_(config),
      grid_(std::move(grid)),
      log_p_(grid_.size(), 0),
      work_(grid_.size(), 0),
      work2_(grid_.size(), 0),
      kernel_(2 * kMaxKernelHalfWidth + 1, 0) {}

void ScalePosterior::reset() {
    std::fill(log_p_.begin(), log_p_.end(), Scalar(0));
    observations_ = 0;
}

void ScalePosterior::normalise() {
    const Scalar mx = *std::max_element(log_p_.begin(), log_p_.end());
    for (auto& v : log_p_) {
        v = std::max(v - mx, config_.log_floor);
    }
}

bool ScalePosterior::addLogLikelihood(std::span<const Scalar> log_l, Scalar weight) {
    if (log_l.size() != log_p_.size() || !(weight > 0 && weight <= 1)) {
        return false;
    }
    for (const Scalar v : log_l) {
        if (!std::isfinite(v)) {
            return false;
        }
    }
    for (std::size_t j = 0; j < log_p_.size(); ++j) {
        log_p_[j] += weight * log_l[j];
    }
    normalise();
    ++observations_;
    if (config_.drift_sigma_log > 0) {
        diffuse(config_.drift_sigma_log);
    }
    return true;
}

void ScalePosterior::diffuse(Scalar sigma_log) {
    if (!(sigma_log > 0) || !std::isfinite(sigma_log)) {
        return;
    }
    const Scalar sigma_bins = sigma_log / grid_.delta();
    const int half = std::min(kMaxKernelHalfWidth, static_cast<int>(std::ceil(4 * sigma_bins)));
    if (half < 1) {
        return;
    }
    for (int k = -half; k <= half; ++k) {
        const Scalar x = static_cast<Scalar>(k) / sigma_bins;
        const int slot = k + half;
        kernel_[static_cast<std::size_t>(slot)] = std::exp(Scalar(-0.5) * x * x);
    }
    const auto n = static_cast<int>(log_p_.size());
    for (int j = 0; j < n; ++j) {
        work_[static_cast<std::size_t>(j)] = std::exp(log_p_[static_cast<std::size_t>(j)]);
    }
    for (int j = 0; j < n; ++j) {
        // Truncated at the grid ends and renormalised by the kernel mass inside.
        Scalar acc = 0;
        Scalar wsum = 0;
        const int lo = std::max(0, j - half);
        const int hi = std::min(n - 1, j + half);
        for (int i = lo; i <= hi; ++i) {
            const int slot = i - j + half;
            const Scalar w = kernel_[static_cast<std::size_t>(slot)];
            acc += w * work_[static_cast<std::size_t>(i)];
            wsum += w;
        }
        work2_[static_cast<std::size_t>(j)] = acc / wsum;
    }
    for (std::size_t j = 0; j < log_p_.size(); ++j) {
        // exp(log_floor) may underflow to 0: keep the floor.
        log_p_[j] = work2_[j] > 0 ? std::log(work2_[j]) : config_.log_floor;
    }
    normalise();
}

Scalar ScalePosterior::quantile(std::span<const Scalar> cdf, Scalar q) const {
    // cdf[j] is the mass of bins 0..j; bin j covers log d_j +- delta/2.
    const auto it = std::lower_bound(cdf.begin(), cdf.end(), q);
    const auto j = static_cast<std::size_t>(std::distance(cdf.begin(), it));
    if (j >= cdf.size()) {
        return grid_.dMax();
    }
    const Scalar below = j == 0 ? Scalar(0) : cdf[j - 1];
    const Scalar mass = cdf[j] - below;
    const Scalar frac = mass > 0 ? (q - below) / mass : Scalar(0.5);
    return std::exp(grid_.logD(j) + (frac - Scalar(0.5)) * grid_.delta());
}

ScaleSummary ScalePosterior::summary() const {
    ScaleSummary s;
    s.observations = observations_;
    Scalar total = 0;
    Scalar mean = 0;
    for (std::size_t j = 0; j < log_p_.size(); ++j) {
        const Scalar p = std::exp(log_p_[j]);
        total += p;
        mean += p * grid_.d(j);
        work_[j] = total;
    }
    for (auto& c : work_) {
        c /= total;
    }
    s.mean = mean / total;
    s.map = gridMode(grid_, log_p_);
    s.ci68 = {quantile(work_, Scalar(0.16)), quantile(work_, Scalar(0.84))};
    s.ci95 = {quantile(work_, Scalar(0.025)), quantile(work_, Scalar(0.975))};
    s.rel_width95 = (s.ci95.hi - s.ci95.lo) / s.map;
    if (observations_ == 0) {
        s.state = ScaleState::kNoData;
    } else if (s.rel_width95 < config_.converged_rel_width) {
        s.state = ScaleState::kConverged;
    } else {
        s.state = ScaleState::kConverging;
    }
    return s;
}

}  // namespace scaled::core
