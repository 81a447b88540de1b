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

const char* toString(PosteriorArithmetic arithmetic) {
    switch (arithmetic) {
        case PosteriorArithmetic::kFloating:
            return "floating";
        case PosteriorArithmetic::kFixed:
            return "fixed";
    }
    return "unknown";
}

Status validate(const PosteriorConfig& config) {
    if (!PosteriorLimits::converged_rel_width.contains(config.converged_rel_width)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "posterior: converged_rel_width must be " +
                             PosteriorLimits::converged_rel_width.text() + " (got " +
                             std::to_string(config.converged_rel_width) + ")");
    }
    if (!(config.log_floor < 0) || !std::isfinite(config.log_floor)) {
        return makeError(ErrorCode::kInvalidArgument, "posterior: log_floor must be < 0");
    }
    if (!PosteriorLimits::drift_sigma_log.contains(config.drift_sigma_log)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "posterior: drift_sigma_log must be " +
                             PosteriorLimits::drift_sigma_log.text() + " (got " +
                             std::to_string(config.drift_sigma_log) + ")");
    }
    return {};
}

Result<ScalePosterior> ScalePosterior::create(const PosteriorConfig& config) {
    auto grid = ScaleGrid::create(config.grid);
    if (!grid) {
        return grid.error();
    }
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    std::optional<FixedPosterior> fixed;
    if (config.arithmetic == PosteriorArithmetic::kFixed) {
        auto f = FixedPosterior::create(config);
        if (!f) {
            return f.error();
        }
        fixed.emplace(std::move(f.value()));
    } else if (config.arithmetic != PosteriorArithmetic::kFloating) {
        return makeError(ErrorCode::kInvalidArgument, "posterior: unknown arithmetic");
    }
    return ScalePosterior(config, std::move(grid.value()), std::move(fixed));
}

ScalePosterior::ScalePosterior(const PosteriorConfig& config, ScaleGrid grid,
                               std::optional<FixedPosterior> fixed)
    : config_(config),
      grid_(std::move(grid)),
      // Under fixed arithmetic the floating buffers are unused; fixed_in_ holds
      // addLogLikelihood's conversion.
      log_p_(fixed ? 0 : grid_.size(), 0),
      work_(fixed ? 0 : grid_.size(), 0),
      work2_(fixed ? 0 : grid_.size(), 0),
      kernel_(fixed ? 0 : 2 * kMaxKernelHalfWidth + 1, 0),
      fixed_(std::move(fixed)),
      fixed_in_(fixed_ ? grid_.size() : 0, 0) {}

void ScalePosterior::reset() {
    if (fixed_) {
        fixed_->reset();
        return;
    }
    std::fill(log_p_.begin(), log_p_.end(), Scalar(0));
    observations_ = 0;
}

void ScalePosterior::normalise() {
    const Scalar mx = *std::max_element(log_p_.begin(), log_p_.end());
    for (auto& v : log_p_) {
        v = std::max(v - mx, config_.log_floor);
    }
}

void ScalePosterior::setObservationCount(int observations) {
    if (fixed_) {
        fixed_->setObservationCount(observations);
        return;
    }
    observations_ = observations;
}

bool ScalePosterior::addLogLikelihood(std::span<const Scalar> log_l, Scalar weight) {
    if (log_l.size() != grid_.size() || !(weight > 0 && weight <= 1)) {
        return false;
    }
    for (const Scalar v : log_l) {
        if (!std::isfinite(v)) {
            return false;
        }
    }
    if (fixed_) {
        // Conversion at the boundary: shift to a maximum of 0, Q16, saturate.
        const Scalar mx = *std::max_element(log_l.begin(), log_l.end());
        for (std::size_t j = 0; j < log_l.size(); ++j) {
            const double q = std::ldexp(static_cast<double>(log_l[j] - mx), fixed::kLogFracBits);
            fixed_in_[j] = static_cast<LogQ16>(
                std::llround(std::max(q, static_cast<double>(kFixedLogLikelihoodMin))));
        }
        return fixed_->addLogLikelihood(fixed_in_, weight);
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

bool ScalePosterior::addFixedLogLikelihood(std::span<const LogQ16> log_l, Scalar weight) {
    if (fixed_) {
        return fixed_->addLogLikelihood(log_l, weight);
    }
    if (log_l.size() != grid_.size()) {
        return false;
    }
    for (std::size_t j = 0; j < log_l.size(); ++j) {
        work_[j] =
            static_cast<Scalar>(std::ldexp(static_cast<double>(log_l[j]), -fixed::kLogFracBits));
    }
    // work_ is scratch: addLogLikelihood reads it all before diffuse() reuses it.
    return addLogLikelihood(work_, weight);
}

void ScalePosterior::diffuse(Scalar sigma_log) {
    if (fixed_) {
        fixed_->diffuse(sigma_log);
        return;
    }
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
    if (fixed_) {
        return fixed_->summary();
    }
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
