#pragma once

// The allowed values of a numeric parameter, written once, next to the
// parameter's component: core's validate() checks a configuration against
// them and the daemon's configuration registry offers them (the range in
// its error messages and in config/scaled.toml). One table per component:
// SlamLimits (ekf_slam.h), PosteriorLimits (scale_posterior.h),
// EstimatorLimits (scale_estimator.h), ObjectLimits (object_evidence.h).
// Checks between parameters (max_measured <= max_features, ...) stay in
// validate().

#include <cmath>
#include <limits>
#include <span>
#include <string>

namespace scaled::core {

struct ParamLimits {
    double lo = 0;
    double hi = 0;
    bool lo_open = false;  // lo itself is not allowed
    bool hi_open = false;  // hi itself is not allowed

    // Finite and within the bounds.
    [[nodiscard]] bool contains(double v) const {
        return std::isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
    }
    // "in (0, 10000]"; an infinite bound reads "inf".
    [[nodiscard]] std::string text() const;
};

// The usual shapes.
constexpr ParamLimits closed(double lo, double hi) {
    return {lo, hi, false, false};
}
constexpr ParamLimits openClosed(double lo, double hi) {
    return {lo, hi, true, false};
}
constexpr ParamLimits open(double lo, double hi) {
    return {lo, hi, true, true};
}
// One entry of a table-driven check: a parameter's name, value and limits.
struct LimitCheck {
    const char* name;
    double value;
    const ParamLimits& limits;
};

// The first entry whose value is outside its limits (compared at the
// precision of core::Scalar, the type the parameters are held in), or nullptr.
[[nodiscard]] const LimitCheck* firstOutside(std::span<const LimitCheck> checks);

// A value or bound as the messages print it ("5000", "0.99", "inf").
[[nodiscard]] std::string formatLimitValue(double v);

inline constexpr double kUnbounded = std::numeric_limits<double>::infinity();
inline constexpr double kMaxInt64 = 9223372036854775807.0;

}  // namespace scaled::core
