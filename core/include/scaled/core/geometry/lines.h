#pragma once

// Small 3-D line helpers.

#include <optional>

#include <scaled/core/types.h>

namespace scaled::core {

// Closest points between the lines a(s) = a0 + s*ua and b(t) = b0 + t*ub.
// Returns (s, t); nullopt when the lines are (nearly) parallel.
struct LineLineParams {
    Scalar s;
    Scalar t;
};
std::optional<LineLineParams> closestPointParams(const Vec3& a0, const Vec3& ua, const Vec3& b0,
                                                 const Vec3& ub);

}  // namespace scaled::core
