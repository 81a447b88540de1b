#pragma once

// A binary descriptor of the image around a pixel (BRIEF: Calonder et al.,
// 2010): 256 comparisons of 5x5 box means at fixed pairs of offsets inside a
// 31x31 window. The tracker keeps one per map feature, refreshed where the
// feature is measured, so that a lost camera can find the map again by
// matching the descriptors of a frame's corners (relocalisation). Not
// invariant to rotation about the optical axis or to scale; cheap, and
// computed without allocation.

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>

#include <scaled/core/types.h>

namespace scaled::drivers::vision {

using BriefDescriptor = std::array<std::uint64_t, 4>;

// Distance from the window centre to its border, box included: a descriptor
// needs this many pixels on every side of the (rounded) pixel.
inline constexpr int kBriefRadiusPx = 17;

// The descriptor of the CV_8UC1 image around px (rounded to the nearest
// pixel); false when the window leaves the image or the image is not 8-bit.
bool computeBrief(const cv::Mat& gray, const core::Vec2& px, BriefDescriptor& out);

// Number of differing bits (0..256).
int briefDistance(const BriefDescriptor& a, const BriefDescriptor& b);

}  // namespace scaled::drivers::vision
