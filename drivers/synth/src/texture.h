#pragma once

// Procedural grayscale textures for the synthetic room.

#include <cstdint>
#include <opencv2/core.hpp>

namespace scaled::drivers::synth::detail {

// A cols x rows CV_8UC1 texture at texel_m metres per texel: multi-octave value
// noise (features from 1 cm to 32 cm) under random filled rectangles, rotated
// rectangles, triangles and ellipses of random intensity, sizes from 1.5 cm to
// 40 cm with density ~ 1 / size^2 (many small, few large), plus a per-surface
// brightness offset. Deterministic in the seed; no pattern repeats. richness in
// (0, 1] scales the number of shapes and the noise's contrast: 1 is the rich
// default, 0.1 a mostly plain surface with a few marks.
cv::Mat makeTexture(int cols, int rows, double texel_m, std::uint64_t seed, double richness = 1.0);

}  // namespace scaled::drivers::synth::detail
