#include <cstdio>

#include <scaled/core/param_limits.h>
#include <scaled/core/types.h>

namespace scaled::core {

namespace {

std::string number(double v) {
    if (std::isinf(v)) {
        return v > 0 ? "inf" : "-inf";
    }
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.10g", v);
    return buf;
}

}  // namespace

const LimitCheck* firstOutside(std::span<const LimitCheck> checks) {
    for (const LimitCheck& check : checks) {
        // The bounds as the parameter's type holds them: with Scalar = float
        // a value set to a bound (0.99, stored as 0.99f) is at the bound, not
        // past it.
        ParamLimits limits = check.limits;
        limits.lo = static_cast<double>(static_cast<Scalar>(limits.lo));
        limits.hi = static_cast<double>(static_cast<Scalar>(limits.hi));
        if (!limits.contains(check.value)) {
            return &check;
        }
    }
    return nullptr;
}

std::string formatLimitValue(double v) {
    return number(v);
}

std::string ParamLimits::text() const {
    return std::string("in ") + (lo_open ? "(" : "[") + number(lo) + ", " + number(hi) +
           (hi_open ? ")" : "]");
}

}  // namespace scaled::core
