#include <cstdio>

#include <scaled/core/param_limits.h>

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
        if (!check.limits.contains(check.value)) {
            return &check;
        }
    }
    return nullptr;
}

std::string ParamLimits::text() const {
    return std::string("in ") + (lo_open ? "(" : "[") + number(lo) + ", " + number(hi) +
           (hi_open ? ")" : "]");
}

}  // namespace scaled::core
