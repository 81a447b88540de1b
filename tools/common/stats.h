#pragma once

// Summary statistics the tools report: one median and one quantile for
// scale-eval, scale-sim and measure-heights.

#include <algorithm>
#include <cstddef>
#include <vector>

namespace scaled::tools {

// The median (the mean of the two middle values for an even count); 0 for an
// empty vector. T: float or double.
template <typename T>
T median(std::vector<T> v) {
    if (v.empty()) {
        return T(0);
    }
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    if (v.size() % 2 == 1) {
        return *mid;
    }
    const T hi = *mid;
    const T lo = *std::max_element(v.begin(), mid);
    return (lo + hi) / 2;
}

// The q-quantile, q in [0, 1], linear between order statistics (numpy's
// default); 0 for an empty vector.
inline double quantile(std::vector<double> v, double q) {
    if (v.empty()) {
        return 0;
    }
    std::sort(v.begin(), v.end());
    const double pos = q * static_cast<double>(v.size() - 1);
    const auto i = static_cast<std::size_t>(pos);
    const double f = pos - static_cast<double>(i);
    return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

}  // namespace scaled::tools
