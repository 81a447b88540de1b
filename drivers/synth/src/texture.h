#pragma once

// Procedural grayscale textures for the synthetic room.

#include <cstdint>
#include <opencv2/core.hpp>

namespace scaled::drivers::synth::detail {

// A cols x rows CV_8UC1 texture at texel_m metres per texel: multi-octave value
// noise (features from 1 cm to 32 cm) under random filled rectangles, rotated
// rectangles, triangles and ellipses of random intensity, sizes from 1.5 cm to
// 40 cm with density ~ 1 / size^2 (many small, few large), plus a per-surface
// brightness offset. Deterministic in the seed; no pattern repeats.
cv::Mat makeTexture(int cols, int rows, double texel_m, std::uint64_t seed);

}  // namespace scaled::drivers::synth::detail
