#pragma once

// Corner detection for feature initialisation. The tracker asks for new
// corners only in image regions that hold no tracked feature yet (see
// makeFreeMask), so both functions take and produce an 8-bit mask.
//
// Pixel convention everywhere in scaled::drivers::vision: x right, y down, pixel centres
// at integer coordinates.

#include <opencv2/core.hpp>
#include <span>
#include <vector>

#include <scaled/core/types.h>

namespace scaled::drivers::vision {

struct CornerConfig {
    int max_corners = 20;         // at most this many corners; <= 0 gives none
    double quality_level = 0.01;  // fraction of the strongest response a corner must exceed
    int min_distance_px = 15;     // minimum distance between two returned corners
    int block_size = 3;           // structure tensor window (pixels)
    bool use_harris = false;      // Harris response instead of Shi-Tomasi min eigenvalue
    int border_px = 12;           // corners keep at least this distance from the image border
};

// Shi-Tomasi (or Harris) corners of a CV_8UC1 image, only where `mask` (CV_8UC1,
// same size, nonzero = allowed; an empty Mat allows everywhere) allows and at least
// border_px from the image border. Integer pixel positions, strongest first.
// The selection follows cv::goodFeaturesToTrack (3x3 local maxima of the response
// above quality_level times the strongest allowed response, then a greedy pick
// keeping min_distance_px apart) but pops candidates from a heap instead of sorting
// them all, which is several times faster on textured images.
// `out` is cleared first; it stays empty for a non-CV_8UC1 image or a mask of the
// wrong type or size. The response is cv::cornerMinEigenVal's (cv::cornerHarris's)
// with aperture 3, computed into per-thread scratch buffers that keep their size:
// after the first call at an image size (and the largest max_corners asked for),
// a call makes no heap allocation, unlike OpenCV's functions.
void detectCorners(const cv::Mat& gray, const cv::Mat& mask, const CornerConfig& cfg,
                   std::vector<core::Vec2>& out);

// Sets `mask` to a CV_8UC1 image of `size` filled with 255 and zeroes a filled disc
// of radius_px (at most 2^20) around each occupied point (rounded to the nearest
// pixel): the pixels within radius_px, as cv::circle(FILLED) draws it. Points that
// are not finite or whose disc misses the image are ignored. A non-positive size
// leaves `mask` empty. Allocates only when `mask` does not have that size yet.
void makeFreeMask(cv::Size size, std::span<const core::Vec2> occupied_px, int radius_px,
                  cv::Mat& mask);

}  // namespace scaled::drivers::vision
