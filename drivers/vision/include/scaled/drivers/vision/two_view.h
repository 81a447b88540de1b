#pragma once

// The relative motion of two views from point correspondences alone: the
// essential matrix (five-point RANSAC), the rotation and translation direction
// it gives, and each inlier's depth in the second view. MonoTracker checks a
// new map's first seconds with it (TrackerConfig::start_check_s, docs/slam.md
// "A map started in motion"): the two views need no depth and no motion
// model, so they cannot trade a slide for a turn as the filter can while its
// depths are unknown.

#include <cstdint>
#include <span>

#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::drivers::vision {

struct TwoViewMotion {
    core::Mat3 R_KtoS = core::Mat3::Identity();  // camera K's attitude in camera S's frame
    core::Vec3 t_KinS = core::Vec3::Zero();      // camera K's centre in S, unit length
    int inliers = 0;
    // Median angle between an inlier's two rays once the rotation is taken
    // out: the parallax the translation direction and depths rest on.
    double median_parallax_deg = 0;
};

// x_S, x_K: the same points in views S and K, normalised image coordinates
// (x/z, y/z of the undistorted ray); threshold_px / focal_px is the RANSAC
// threshold on the unit image plane. depth_K (same size as x_K, or empty):
// each point's distance from K along its ray in units of |t|, 0 where it is
// not an inlier or not in front of both views. An error when there are fewer than 8 pairs, the
// sizes differ or no motion is found (OpenCV's exceptions are caught here).
// Allocates (OpenCV): used on a new map's first seconds only.
[[nodiscard]] core::Result<TwoViewMotion> estimateTwoViewMotion(std::span<const core::Vec2> x_S,
                                                                std::span<const core::Vec2> x_K,
                                                                double focal_px,
                                                                double threshold_px,
                                                                std::span<double> depth_K);

}  // namespace scaled::drivers::vision
