#pragma once

// The log-spaced grid of candidate scales d (metres per SLAM unit).

#include <cmath>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::core {

struct GridConfig {
    Scalar d_min = Scalar(0.01);
    Scalar d_max = Scalar(100);
    int bins = 1024;
};

class ScaleGrid {
public:
    static constexpr int kMinBins = 16;
    static constexpr int kMaxBins = 65536;

    static Result<ScaleGrid> create(const GridConfig& config);

    [[nodiscard]] std::size_t size() const { return d_.size(); }
    [[nodiscard]] Scalar d(std::size_t j) const { return d_[j]; }
    [[nodiscard]] Scalar logD(std::size_t j) const {
        return log_d_min_ + delta_ * static_cast<Scalar>(j);
    }
    // Spacing in log d between neighbouring grid points.
    [[nodiscard]] Scalar delta() const { return delta_; }
    [[nodiscard]] Scalar dMin() const { return d_.front(); }
    [[nodiscard]] Scalar dMax() const { return d_.back(); }
    [[nodiscard]] const std::vector<Scalar>& values() const { return d_; }
    // Continuous index of d (may lie outside [0, size-1]).
    [[nodiscard]] Scalar indexOf(Scalar d) const { return (std::log(d) - log_d_min_) / delta_; }

private:
    ScaleGrid() = default;

    Scalar log_d_min_ = 0;
    Scalar delta_ = 0;
    std::vector<Scalar> d_;
};

}  // namespace scaled::core
