#include <cmath>
#include <limits>

#include <scaled/core/geometry/lines.h>

namespace scaled::core {

std::optional<LineLineParams> closestPointParams(const Vec3& a0, const Vec3& ua, const Vec3& b0,
                                                 const Vec3& ub) {
    // Minimise |a0 + s ua - b0 - t ub|^2: the normal equations
    //   [ua.ua  -ua.ub] [s]   [-ua.w]
    //   [ua.ub  -ub.ub] [t] = [-ub.w],  w = a0 - b0.
    const Vec3 w = a0 - b0;
    const Scalar a = ua.dot(ua);
    const Scalar b = ua.dot(ub);
    const Scalar c = ub.dot(ub);
    const Scalar d = ua.dot(w);
    const Scalar e = ub.dot(w);
    const Scalar denom = a * c - b * b;
    if (!(denom > std::numeric_limits<Scalar>::epsilon() * 16 * a * c)) {
        return std::nullopt;
    }
    return LineLineParams{(b * e - c * d) / denom, (a * e - b * d) / denom};
}

}  // namespace scaled::core
