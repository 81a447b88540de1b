#pragma once

// A feature's appearance, as in MonoSLAM: a larger square `source` patch cut
// around the feature once, at initialisation, and a small matching template
// re-rendered from it whenever the predicted viewpoint change makes the
// unwarped template a poor predictor of the feature's current look.

#include <opencv2/core.hpp>
#include <optional>

#include <scaled/core/types.h>

namespace scaled::drivers::vision {

// The cv::Mat members follow OpenCV's sharing rules: copying a Patch shares the
// pixels; clone them for an independent copy before warping one of the two.
struct Patch {
    cv::Mat source;  // CV_32FC1, source_size x source_size, raw intensities, feature at centre
    cv::Mat templ;   // CV_32FC1, size x size matching template, feature at centre
    int size = 11;   // template side (odd)
};

// Cuts a patch centred on px (sub-pixel allowed, bilinear) from a CV_8UC1 image;
// `templ` is the central size x size part of `source`. nullopt if the image is
// not CV_8UC1, the sizes are not odd with 1 <= size <= source_size, or the source
// square would leave the image.
std::optional<Patch> extractPatch(const cv::Mat& gray, const core::Vec2& px, int size = 11,
                                  int source_size = 41);

// extractPatch into an existing patch, re-using its buffers: no allocation when
// `patch` already holds a source and template of these sizes (as a recycled
// patch does). false, with `patch` unchanged, where extractPatch gives nullopt.
// The buffers are overwritten: do not pass a patch whose pixels are shared.
bool extractPatchInto(const cv::Mat& gray, const core::Vec2& px, int size, int source_size,
                      Patch& patch);

// Re-renders patch.templ from patch.source under the local affine map A: the
// template offset d (pixels in the current image, from the template centre) shows
// the source at offset A * d from the source centre. A = identity reproduces the
// unwarped template. Bilinear; source samples beyond the source border take the
// nearest border value. No-op for an invalid patch or a non-finite A.
void warpTemplate(Patch& patch, const core::Mat2& A);

}  // namespace scaled::drivers::vision
