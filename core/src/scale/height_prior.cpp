#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include <scaled/core/scale/height_prior.h>

namespace scaled::core {

namespace {

Error invalid(const std::string& class_name, const std::string& what) {
    return makeError(ErrorCode::kInvalidArgument, "prior '" + class_name + "': " + what);
}

std::string num(Scalar v) {
    std::string s = std::to_string(v);
    s.erase(s.find_last_not_of('0') + 1);
    if (!s.empty() && s.back() == '.') {
        s.pop_back();
    }
    return s;
}

Scalar normalCdf(Scalar x) {
    return Scalar(0.5) * std::erfc(-x / std::sqrt(Scalar(2)));
}

}  // namespace

Result<HeightPrior> HeightPrior::fromHistogram(std::string class_name,
                                               std::span<const Scalar> heights_m,
                                               std::span<const Scalar> probabilities,
                                               Scalar bin_width_m, bool upright) {
    if (heights_m.empty()) {
        return invalid(class_name, "no heights given");
    }
    if (heights_m.size() != probabilities.size()) {
        return invalid(class_name, "heights_m has " + std::to_string(heights_m.size()) +
                                       " entries but probabilities has " +
                                       std::to_string(probabilities.size()));
    }
    if (heights_m.size() > static_cast<std::size_t>(kMaxBins)) {
        return invalid(class_name, "at most " + std::to_string(kMaxBins) + " bins allowed");
    }
    if (!(bin_width_m >= 0) || !std::isfinite(bin_width_m)) {
        return invalid(class_name, "bin_width_m must be >= 0 (got " + num(bin_width_m) + ")");
    }
    Scalar total = 0;
    for (std::size_t i = 0; i < heights_m.size(); ++i) {
        if (!(heights_m[i] > 0) || !std::isfinite(heights_m[i])) {
            return invalid(class_name, "heights_m[" + std::to_string(i) + "] must be > 0 (got " +
                                           num(heights_m[i]) + ")");
        }
        if (!(probabilities[i] >= 0) || !std::isfinite(probabilities[i])) {
            return invalid(class_name, "probabilities[" + std::to_string(i) +
                                           "] must be >= 0 (got " + num(probabilities[i]) + ")");
        }
        total += probabilities[i];
    }
    if (!(total > 0)) {
        return invalid(class_name, "probabilities sum to zero");
    }

    std::vector<std::size_t> order(heights_m.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return heights_m[a] < heights_m[b]; });

    HeightPrior prior;
    prior.class_name_ = std::move(class_name);
    prior.upright_ = upright;
    prior.bin_width_m_ = bin_width_m;
    for (const std::size_t i : order) {
        if (probabilities[i] > 0) {
            prior.heights_m_.push_back(heights_m[i]);
            prior.probabilities_.push_back(probabilities[i] / total);
            prior.log_probabilities_.push_back(std::log(probabilities[i] / total));
        }
    }
    return prior;
}

Result<HeightPrior> HeightPrior::fromNormal(std::string class_name, Scalar mean_m, Scalar std_m,
                                            Scalar min_m, Scalar max_m, int bins, bool upright) {
    for (const Scalar v : {mean_m, std_m, min_m, max_m}) {
        if (!std::isfinite(v)) {
            return invalid(class_name, "mean_m, std_m, min_m and max_m must be finite");
        }
    }
    if (!(std_m > 0)) {
        return invalid(class_name, "std_m must be > 0 (got " + num(std_m) + ")");
    }
    if (!(min_m > 0 && min_m < max_m)) {
        return invalid(class_name, "need 0 < min_m < max_m (got min_m=" + num(min_m) +
                                       ", max_m=" + num(max_m) + ")");
    }
    if (!(mean_m >= min_m && mean_m <= max_m)) {
        return invalid(class_name, "mean_m=" + num(mean_m) + " lies outside [min_m, max_m] = [" +
                                       num(min_m) + ", " + num(max_m) + "]");
    }
    if (bins < 1 || bins > kMaxBins) {
        return invalid(class_name, "bins must be in [1, " + std::to_string(kMaxBins) + "] (got " +
                                       std::to_string(bins) + ")");
    }
    const Scalar width = (max_m - min_m) / static_cast<Scalar>(bins);
    std::vector<Scalar> heights(static_cast<std::size_t>(bins));
    std::vector<Scalar> probs(static_cast<std::size_t>(bins));
    for (int b = 0; b < bins; ++b) {
        const Scalar lo = min_m + width * static_cast<Scalar>(b);
        const Scalar hi = lo + width;
        const auto i = static_cast<std::size_t>(b);
        heights[i] = Scalar(0.5) * (lo + hi);
        probs[i] = normalCdf((hi - mean_m) / std_m) - normalCdf((lo - mean_m) / std_m);
    }
    Scalar total = 0;
    for (const Scalar p : probs) {
        total += p;
    }
    if (!(total > 0)) {
        // The CDF differences underflow when std_m dwarfs the bins (a nearly
        // uniform prior): the density at the bin centres is exact enough there.
        for (std::size_t i = 0; i < probs.size(); ++i) {
            const Scalar z = (heights[i] - mean_m) / std_m;
            probs[i] = std::exp(Scalar(-0.5) * z * z);
        }
    }
    return fromHistogram(std::move(class_name), heights, probs, width, upright);
}

Status HeightPrior::setPartialProbability(Scalar probability) {
    if (!(probability < 1) || !std::isfinite(probability)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "prior '" + class_name_ + "': partial_probability must be < 1 (got " +
                             std::to_string(probability) + ")");
    }
    partial_probability_ = probability < 0 ? Scalar(-1) : probability;
    return {};
}

Status HeightPrior::setWidth(Scalar mean_m, Scalar std_m) {
    if (!(mean_m >= 0) || !std::isfinite(mean_m) || !(std_m >= 0) || !std::isfinite(std_m) ||
        (mean_m == 0 && std_m != 0)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "prior '" + class_name_ + "': width needs mean_m >= 0 and std_m >= 0 " +
                             "(std_m 0 without a mean) (got mean " + std::to_string(mean_m) +
                             ", std " + std::to_string(std_m) + ")");
    }
    width_mean_m_ = mean_m;
    width_std_m_ = std_m;
    return {};
}

Scalar HeightPrior::relativeSpread() const {
    const Scalar m = mean();
    Scalar var = binWidth() * binWidth() / 12;
    for (std::size_t i = 0; i < heights_m_.size(); ++i) {
        var += probabilities_[i] * (heights_m_[i] - m) * (heights_m_[i] - m);
    }
    return m > 0 ? std::sqrt(var) / m : Scalar(0);
}

Scalar HeightPrior::mean() const {
    Scalar m = 0;
    for (std::size_t i = 0; i < heights_m_.size(); ++i) {
        m += heights_m_[i] * probabilities_[i];
    }
    return m;
}

void PriorTable::add(HeightPrior prior) {
    auto it = std::find_if(priors_.begin(), priors_.end(), [&](const HeightPrior& p) {
        return p.className() == prior.className();
    });
    if (it != priors_.end()) {
        *it = std::move(prior);
    } else {
        priors_.push_back(std::move(prior));
    }
}

const HeightPrior* PriorTable::find(std::string_view class_name) const {
    for (const auto& p : priors_) {
        if (p.className() == class_name) {
            return &p;
        }
    }
    return nullptr;
}

}  // namespace scaled::core
