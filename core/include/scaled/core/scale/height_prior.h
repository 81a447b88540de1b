#pragma once

// p_c(H): the prior over the real vertical height of objects of one class,
// as a histogram of heights (metres) with probabilities.

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::core {

class HeightPrior {
public:
    static constexpr int kMaxBins = 512;

    // Explicit histogram. heights_m > 0, probabilities >= 0 with a positive sum;
    // bins of zero probability are dropped, the rest normalised and sorted by height.
    // bin_width_m is the interval each height stands for (0: exact heights).
    static Result<HeightPrior> fromHistogram(std::string class_name,
                                             std::span<const Scalar> heights_m,
                                             std::span<const Scalar> probabilities,
                                             Scalar bin_width_m, bool upright);

    // A normal N(mean, std^2) truncated to [min, max], integrated over `bins`
    // equal-width bins (exact normal CDF mass per bin).
    static Result<HeightPrior> fromNormal(std::string class_name, Scalar mean_m, Scalar std_m,
                                          Scalar min_m, Scalar max_m, int bins, bool upright);

    [[nodiscard]] const std::string& className() const { return class_name_; }
    [[nodiscard]] bool upright() const { return upright_; }
    [[nodiscard]] std::span<const Scalar> heights() const { return heights_m_; }
    [[nodiscard]] std::span<const Scalar> probabilities() const { return probabilities_; }
    [[nodiscard]] std::span<const Scalar> logProbabilities() const { return log_probabilities_; }
    [[nodiscard]] Scalar binWidth() const { return bin_width_m_; }
    [[nodiscard]] std::size_t size() const { return heights_m_.size(); }
    [[nodiscard]] Scalar mean() const;
    [[nodiscard]] Scalar minHeight() const { return heights_m_.front(); }
    [[nodiscard]] Scalar maxHeight() const { return heights_m_.back(); }

    // Beyond the paper (optional, see LikelihoodConfig::partial_weight): the
    // probability that a box of this class shows only part of the object
    // (e.g. a chair behind a table). Negative: the estimator's setting.
    Status setPartialProbability(Scalar probability);
    [[nodiscard]] Scalar partialProbability() const { return partial_probability_; }

    // Beyond the paper (the object model, object_evidence.h): the object's
    // horizontal extent along the line of sight, N(mean, std^2) in metres. A
    // box seen from above or below spans more than the height: about
    // H + w (|tan t| + |tan b|) / 2 on the vertical through the object's
    // centre, t and b the elevations of its top and bottom. std 0 with mean 0:
    // no width model for this class (the default).
    Status setWidth(Scalar mean_m, Scalar std_m);
    [[nodiscard]] Scalar widthMean() const { return width_mean_m_; }
    [[nodiscard]] Scalar widthStd() const { return width_std_m_; }
    [[nodiscard]] bool hasWidth() const { return width_mean_m_ > 0; }
    // Relative spread of the height distribution (std / mean).
    [[nodiscard]] Scalar relativeSpread() const;

private:
    HeightPrior() = default;

    std::string class_name_;
    bool upright_ = false;
    Scalar bin_width_m_ = 0;
    Scalar partial_probability_ = -1;
    Scalar width_mean_m_ = 0;
    Scalar width_std_m_ = 0;
    std::vector<Scalar> heights_m_;
    std::vector<Scalar> probabilities_;
    std::vector<Scalar> log_probabilities_;
};

// The set of class priors in use; looked up by class name.
class PriorTable {
public:
    // Replaces an existing prior of the same class.
    void add(HeightPrior prior);
    [[nodiscard]] const HeightPrior* find(std::string_view class_name) const;
    [[nodiscard]] std::span<const HeightPrior> priors() const { return priors_; }
    [[nodiscard]] bool empty() const { return priors_.empty(); }

private:
    std::vector<HeightPrior> priors_;
};

}  // namespace scaled::core
