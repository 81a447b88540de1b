#include <string>

#include <scaled/core/scale/scale_grid.h>

namespace scaled::core {

Result<ScaleGrid> ScaleGrid::create(const GridConfig& c) {
    if (!(c.d_min > 0) || !std::isfinite(c.d_min) || !std::isfinite(c.d_max) ||
        !(c.d_max > c.d_min)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "scale grid: need 0 < d_min < d_max (got d_min=" +
                             std::to_string(c.d_min) + ", d_max=" + std::to_string(c.d_max) + ")");
    }
    if (c.bins < kMinBins || c.bins > kMaxBins) {
        return makeError(ErrorCode::kInvalidArgument,
                         "scale grid: bins must be in [" + std::to_string(kMinBins) + ", " +
                             std::to_string(kMaxBins) + "] (got " + std::to_string(c.bins) + ")");
    }
    ScaleGrid g;
    g.log_d_min_ = std::log(c.d_min);
    g.delta_ = (std::log(c.d_max) - g.log_d_min_) / static_cast<Scalar>(c.bins - 1);
    g.d_.resize(static_cast<std::size_t>(c.bins));
    for (std::size_t j = 0; j < g.d_.size(); ++j) {
        g.d_[j] = std::exp(g.logD(j));
    }
    return g;
}

}  // namespace scaled::core
