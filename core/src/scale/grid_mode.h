#pragma once

// The mode of a log-density on the scale grid, shared by the floating
// (gridMode) and the fixed-point (gridModeFixed) posterior. Private to core.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>

#include <scaled/core/scale/scale_grid.h>
#include <scaled/core/types.h>

namespace scaled::core::detail {

// The best bin (the first of equals), refined by the vertex of the parabola
// through it and its two neighbours, at most half a bin either way. Wide is the
// type the three-point differences are formed in: Scalar for Scalar values,
// int64 for Q16 integers (so that they cannot overflow); the vertex offset is
// the one number converted to Scalar.
template <typename Wide, typename Value>
Scalar gridModeOf(const ScaleGrid& grid, std::span<const Value> v) {
    std::size_t j = 0;
    for (std::size_t i = 1; i < v.size(); ++i) {
        if (v[i] > v[j]) {
            j = i;
        }
    }
    Scalar offset = 0;
    if (j > 0 && j + 1 < v.size()) {
        const Wide before = v[j - 1];
        const Wide at = v[j];
        const Wide after = v[j + 1];
        const Wide denom = before - 2 * at + after;
        if (denom < 0) {
            offset = std::clamp(
                Scalar(0.5) * static_cast<Scalar>(before - after) / static_cast<Scalar>(denom),
                Scalar(-0.5), Scalar(0.5));
        }
    }
    return std::exp(grid.logD(j) + offset * grid.delta());
}

}  // namespace scaled::core::detail
