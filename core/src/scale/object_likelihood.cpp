#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <scaled/core/scale/object_likelihood.h>

namespace scaled::core {

namespace {

// Length of the overlap of [a0, a1] and [b0, b1].
double overlap(double a0, double a1, double b0, double b1) {
    return std::max(0.0, std::min(a1, b1) - std::max(a0, b0));
}

double logSumExp2(double a, double b) {
    const double top = std::max(a, b);
    if (!std::isfinite(top)) {
        return top;
    }
    return top + std::log(std::exp(a - top) + std::exp(b - top));
}

}  // namespace

Result<ApparentHeightPrior> ApparentHeightPrior::create(const HeightPrior& prior,
                                                        Scalar partial_weight,
                                                        const GridSpec& grid) {
    if (grid.bins < 16 || grid.bins > 4096 || !(grid.h_min_m > 0) ||
        !(grid.h_max_m > grid.h_min_m) || !std::isfinite(grid.h_max_m)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "apparent height prior: the height grid needs 16..4096 bins and "
                         "0 < h_min_m < h_max_m");
    }
    if (!(partial_weight >= 0 && partial_weight < 1)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "apparent height prior '" + prior.className() +
                             "': partial weight must be in [0, 1) (got " +
                             std::to_string(partial_weight) + ")");
    }
    if (prior.size() == 0) {
        return makeError(ErrorCode::kInvalidArgument,
                         "apparent height prior '" + prior.className() + "': empty prior");
    }
    ApparentHeightPrior p;
    const auto n = static_cast<std::size_t>(grid.bins);
    const double log_min = std::log(static_cast<double>(grid.h_min_m));
    const double step = (std::log(static_cast<double>(grid.h_max_m)) - log_min) /
                        static_cast<double>(grid.bins - 1);
    p.log_h_min_ = static_cast<Scalar>(log_min);
    p.log_step_ = static_cast<Scalar>(step);
    p.width_mean_m_ = prior.widthMean();
    p.width_std_m_ = prior.widthStd();
    p.heights_.resize(n);
    p.log_mass_.resize(n);
    p.bin_var_.resize(n);
    std::vector<double> lo(n);
    std::vector<double> hi(n);
    for (std::size_t m = 0; m < n; ++m) {
        const double c = log_min + step * static_cast<double>(m);
        lo[m] = std::exp(c - step / 2);
        hi[m] = std::exp(c + step / 2);
        p.heights_[m] = static_cast<Scalar>(std::exp(c));
        p.bin_var_[m] = static_cast<Scalar>((hi[m] - lo[m]) * (hi[m] - lo[m]) / 12);
    }
    std::vector<double> mass(n, 0.0);
    const auto heights = prior.heights();
    const auto probs = prior.probabilities();
    const double bw = static_cast<double>(prior.binWidth());
    const double w_full = 1 - static_cast<double>(partial_weight);
    for (std::size_t i = 0; i < heights.size(); ++i) {
        const double h = static_cast<double>(heights[i]);
        const double pi = static_cast<double>(probs[i]);
        if (bw > 0) {
            // A bin of the class histogram stands for a uniform interval.
            for (std::size_t m = 0; m < n; ++m) {
                mass[m] += w_full * pi * overlap(lo[m], hi[m], h - bw / 2, h + bw / 2) / bw;
            }
        } else {
            const double idx = (std::log(h) - log_min) / step;
            const auto m = static_cast<std::size_t>(
                std::clamp(std::lround(idx), 0L, static_cast<long>(n) - 1));
            mass[m] += w_full * pi;
        }
        if (partial_weight > 0) {
            // A visible fraction uniform in (0, 1): density p_i / H on (0, H).
            for (std::size_t m = 0; m < n; ++m) {
                mass[m] +=
                    static_cast<double>(partial_weight) * pi * overlap(lo[m], hi[m], 0, h) / h;
            }
        }
    }
    double total = 0;
    for (const double v : mass) {
        total += v;
    }
    if (!(total > 0)) {
        return makeError(
            ErrorCode::kInvalidArgument,
            "apparent height prior '" + prior.className() + "': no mass inside the height grid");
    }
    for (std::size_t m = 0; m < n; ++m) {
        p.log_mass_[m] = mass[m] > 0 ? static_cast<Scalar>(std::log(mass[m] / total))
                                     : -std::numeric_limits<Scalar>::infinity();
    }
    return p;
}

namespace {

// Every prior term within 8 sigma of h*: (h - h*)^2 <= 64 var(h).
constexpr double kWindowSigmas2 = 64;  // 8 sigma

// Sums over the views that do not depend on d.
struct ViewSums {
    double s11 = 0;
    double sk1 = 0;
    double skk = 0;
    double log_s = 0;
};

// The quantities of the evaluation that do not depend on d.
struct ObjectTerms {
    const ApparentHeightPrior& prior;
    double mu_w = 0;
    double sw2 = 0;
    double rho2 = 0;
    double n_views = 0;
    double log_2pi = 0;
    double eps = 0;
    double log_in = 0;
    double log_out = 0;
    double log_range = 0;
    double h_floor = 0;
    // The prior's support: bins with mass.
    std::size_t m_first = 0;
    std::size_t m_last = 0;
    // A log-spaced bin's variance relative to its height squared.
    double bin_var_rel = 0;
    double log_h_min = 0;
    double log_step = 0;
};

// The views' Gaussian in the height h at one d.
struct HeightGaussian {
    double cst = 0;  // log of its integral over h, before the prior
    double h_star = 0;
    double var_h = 0;
};

// Bins [lo, hi) of the prior.
struct BinRange {
    std::size_t lo = 0;
    std::size_t hi = 0;
};

// False when a view is not usable.
bool sumViewsIndependentOfD(std::span<const ObjectViewExtent> views, ViewSums& sums) {
    for (const auto& v : views) {
        const double s2 = static_cast<double>(v.sigma_D) * static_cast<double>(v.sigma_D);
        if (!(v.D > 0) || !std::isfinite(v.D) || !(s2 > 0) || !std::isfinite(s2) ||
            !std::isfinite(v.kappa)) {
            return false;
        }
        sums.s11 += 1 / s2;
        sums.sk1 += static_cast<double>(v.kappa) / s2;
        sums.skk += static_cast<double>(v.kappa) * static_cast<double>(v.kappa) / s2;
        sums.log_s += std::log(s2);
    }
    return true;
}

// False when the prior has no bin with mass.
bool makeObjectTerms(std::span<const ObjectViewExtent> views, const ObjectLikelihoodConfig& config,
                     ObjectTerms& t) {
    const ApparentHeightPrior& prior = t.prior;
    const bool width = config.width_model && prior.widthMean() > 0;
    t.mu_w = width ? static_cast<double>(prior.widthMean()) : 0.0;
    t.sw2 =
        width ? static_cast<double>(prior.widthStd()) * static_cast<double>(prior.widthStd()) : 0.0;
    t.rho2 = static_cast<double>(config.rel_sigma) * static_cast<double>(config.rel_sigma);
    t.n_views = static_cast<double>(views.size());
    t.log_2pi = std::log(2 * std::numbers::pi);
    t.eps = static_cast<double>(config.outlier_weight);
    t.log_in = std::log1p(-t.eps);
    t.log_out = t.eps > 0 ? std::log(t.eps) : 0.0;
    t.log_range = std::log(std::log(static_cast<double>(prior.height(prior.size() - 1)) /
                                    static_cast<double>(prior.height(0))));
    t.h_floor = static_cast<double>(prior.height(0));
    // The prior's support: bins with mass.
    std::size_t m_first = 0;
    while (m_first < prior.size() && !std::isfinite(prior.logMass(m_first))) {
        ++m_first;
    }
    std::size_t m_last = prior.size();
    while (m_last > m_first && !std::isfinite(prior.logMass(m_last - 1))) {
        --m_last;
    }
    if (m_first >= m_last) {
        return false;
    }
    t.m_first = m_first;
    t.m_last = m_last;
    // A log-spaced bin's variance relative to its height squared.
    t.bin_var_rel = static_cast<double>(prior.binVariance(0)) /
                    (static_cast<double>(prior.height(0)) * static_cast<double>(prior.height(0)));
    t.log_h_min = static_cast<double>(prior.logHMin());
    t.log_step = static_cast<double>(prior.logStep());
    return true;
}

// The first bin whose height is at least h (h > 0).
std::size_t indexAbove(const ObjectTerms& t, double h) {
    const double idx = std::ceil((std::log(h) - t.log_h_min) / t.log_step - 1e-9);
    return static_cast<std::size_t>(std::clamp(idx, 0.0, static_cast<double>(t.prior.size())));
}

// log( P(h_m) N(h_m; h*, var_h + h_m^2 rho^2 + bin variance) ), -inf without mass.
double priorTerm(const ObjectTerms& t, std::size_t m, double h_star, double var_h) {
    const double lm = static_cast<double>(t.prior.logMass(m));
    const double h = static_cast<double>(t.prior.height(m));
    const double var = var_h + h * h * t.rho2 + static_cast<double>(t.prior.binVariance(m));
    const double r = h - h_star;
    return lm - 0.5 * r * r / var - 0.5 * (t.log_2pi + std::log(var));
}

HeightGaussian heightGaussianAt(double d, std::span<const ObjectViewExtent> views,
                                const ViewSums& sums, const ObjectTerms& t) {
    const double u = 1 / d;
    double sc1 = 0;
    double skc = 0;
    double scc = 0;
    for (const auto& v : views) {
        const double s2 = static_cast<double>(v.sigma_D) * static_cast<double>(v.sigma_D);
        const double k = static_cast<double>(v.kappa);
        const double c = static_cast<double>(v.D) - u * k * t.mu_w;
        sc1 += c / s2;
        skc += k * c / s2;
        scc += c * c / s2;
    }
    // w integrated out: g = 1 / (skk + d^2 / sigma_w^2) (0 without width uncertainty).
    const double g = t.sw2 > 0 ? 1 / (sums.skk + d * d / t.sw2) : 0.0;
    const double logdet = sums.log_s + (t.sw2 > 0 ? std::log1p(t.sw2 * u * u * sums.skk) : 0.0);
    const double q2 = std::max(u * u * (sums.s11 - sums.sk1 * sums.sk1 * g), 1e-300);
    const double q1 = -2 * u * (sc1 - skc * sums.sk1 * g);
    const double q0 = scc - skc * skc * g;
    HeightGaussian out;
    out.h_star = -q1 / (2 * q2);
    const double rss = std::max(0.0, q0 - q1 * q1 / (4 * q2));
    // log of int exp(-q2 (h - h*)^2 / 2) ... dh, before the prior: the
    // Gaussian in h is sqrt(2 pi / q2) N(h; h*, 1 / q2).
    out.cst =
        -0.5 * rss - 0.5 * logdet - 0.5 * t.n_views * t.log_2pi + 0.5 * (t.log_2pi - std::log(q2));
    out.var_h = 1 / q2;
    return out;
}

BinRange priorWindow(const HeightGaussian& hg, const ObjectTerms& t) {
    const double h_star = hg.h_star;
    const double var_h = hg.var_h;
    const double h_floor = t.h_floor;
    // Prior terms within 8 sigma of h*. The bins are log-spaced, so a
    // bin's variance is var_h + h^2 (rho^2 + c2) with c2 the same for all
    // bins: the window is the solution of (h - h*)^2 <= 64 var(h), an
    // interval found in closed form (all bins above when the relative
    // spread reaches 1/8); the nearest bin with mass when it is empty.
    const double a_rel = 1 - kWindowSigmas2 * (t.rho2 + t.bin_var_rel);
    std::size_t lo = t.m_first;
    std::size_t hi = t.m_last;
    if (a_rel > 0) {
        const double root = std::sqrt(
            std::max(0.0, h_star * h_star * (1 - a_rel) + kWindowSigmas2 * a_rel * var_h));
        const double h_lo = (h_star - root) / a_rel;
        const double h_hi = (h_star + root) / a_rel;
        lo = h_lo > h_floor ? std::max(lo, indexAbove(t, h_lo)) : lo;
        hi = h_hi > h_floor ? std::min(hi, indexAbove(t, h_hi) + 1) : t.m_first;
    } else if (h_star - std::sqrt(kWindowSigmas2 * var_h) > h_floor) {
        lo = std::max(lo, indexAbove(t, h_star - std::sqrt(kWindowSigmas2 * var_h)) -
                              std::min<std::size_t>(indexAbove(t, h_star), 1));
    }
    if (lo >= hi) {
        // Nothing within 8 sigma: the bin with mass nearest to h* keeps log L finite.
        const std::size_t m =
            std::clamp(indexAbove(t, std::max(h_star, h_floor)), t.m_first, t.m_last - 1);
        lo = m;
        hi = m + 1;
    }
    return {lo, hi};
}

// The log-likelihood of the object model at one d: the views' Gaussian times the prior.
double modelLogLikelihood(const HeightGaussian& hg, BinRange bins, const ObjectTerms& t) {
    // One pass: a running log-sum-exp (the sum rescaled when the maximum grows).
    double best = -std::numeric_limits<double>::infinity();
    double sum = 0;
    for (std::size_t m = bins.lo; m < bins.hi; ++m) {
        const double term = priorTerm(t, m, hg.h_star, hg.var_h);
        if (!std::isfinite(term)) {
            continue;  // a bin without mass
        }
        if (term <= best) {
            sum += std::exp(term - best);
        } else {
            sum = sum * std::exp(best - term) + 1;
            best = term;
        }
    }
    return hg.cst + best + std::log(sum);
}

}  // namespace

bool evaluateObjectLogLikelihood(std::span<const ObjectViewExtent> views,
                                 const ApparentHeightPrior& prior, const ScaleGrid& grid,
                                 const ObjectLikelihoodConfig& config, std::span<Scalar> log_l) {
    if (views.empty() || log_l.size() != grid.size() || prior.size() == 0 ||
        !(config.outlier_weight >= 0 && config.outlier_weight < 1)) {
        return false;
    }
    // Sums over the views that do not depend on d.
    ViewSums sums;
    if (!sumViewsIndependentOfD(views, sums)) {
        return false;
    }
    ObjectTerms t{prior};
    if (!makeObjectTerms(views, config, t)) {
        return false;
    }
    Scalar top = -std::numeric_limits<Scalar>::infinity();
    for (std::size_t j = 0; j < grid.size(); ++j) {
        const double d = static_cast<double>(grid.d(j));
        const HeightGaussian hg = heightGaussianAt(d, views, sums, t);
        const double model = modelLogLikelihood(hg, priorWindow(hg, t), t);
        double value = model;
        if (t.eps > 0) {
            // Unknown height, log-uniform over the height grid: flat in d.
            const double outlier = hg.cst - std::log(std::max(hg.h_star, t.h_floor)) - t.log_range;
            value = logSumExp2(t.log_in + model, t.log_out + outlier);
        }
        log_l[j] = static_cast<Scalar>(value);
        top = std::max(top, log_l[j]);
    }
    if (!std::isfinite(top)) {
        return false;
    }
    // Far below anything the posterior keeps (its floor is -1000 nats), and
    // finite: a sum of many objects' values cannot overflow, even in float.
    constexpr Scalar kLogFloor = Scalar(-1e5);
    for (auto& v : log_l) {
        v = std::isfinite(v) ? std::max(v - top, kLogFloor) : kLogFloor;
    }
    return true;
}

Scalar objectHeightAt(std::span<const ObjectViewExtent> views, Scalar width_mean_m, Scalar d) {
    double num = 0;
    double den = 0;
    for (const auto& v : views) {
        const double s2 = static_cast<double>(v.sigma_D) * static_cast<double>(v.sigma_D);
        if (!(s2 > 0)) {
            continue;
        }
        const double a = static_cast<double>(d) * static_cast<double>(v.D) -
                         static_cast<double>(v.kappa) * static_cast<double>(width_mean_m);
        // Weights 1 / (d sigma)^2, relative: 1 / s2 suffices.
        num += a / s2;
        den += 1 / s2;
    }
    return den > 0 ? static_cast<Scalar>(num / den) : Scalar(0);
}

}  // namespace scaled::core
