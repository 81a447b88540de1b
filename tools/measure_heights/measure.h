#pragma once

// The geometry of measure-heights: true vertical extents of detected objects
// from an RGB-D sequence with ground-truth poses and a known gravity direction.
//
// Frames of reference. The depth map is back-projected with the pinhole
// intrinsics of the sequence and placed in the ground-truth world frame with
// the ground-truth pose (7-Scenes: the pose of the depth camera, which is
// also the camera whose intrinsics are given). "Height" is the coordinate
// along up_W = -gravity_down_W, in metres, with an arbitrary origin (the floor
// estimate gives it a meaning).
//
// Colour-to-depth registration. In 7-Scenes the colour and depth images come
// from two cameras a few centimetres apart that are not registered, and they
// are not exposed at the same instant (the camera turns up to ~1.5 degrees per
// frame, ~15 px). estimateShift() finds, per frame, the image translation that
// best puts the depth discontinuities on the colour edges (a chamfer match),
// and detection boxes are moved by it before depth is read.

#include <cstdint>
#include <opencv2/core.hpp>
#include <span>
#include <string>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/types.h>

#include "stats.h"

namespace scaled::tools::heights {

// How an object's bottom is found.
enum class BottomRule : std::uint8_t {
    kFloor,   // stands on the floor: height = top - scene floor
    kObject,  // stands on a counter/table: height = top - lowest object pixel
};

// How an object's top is found.
enum class TopRule : std::uint8_t {
    kHighest,  // a high percentile of the segmented pixels' heights
    kPlane,    // the highest well-supported horizontal plane in the box (table tops)
};

struct ClassRule {
    BottomRule bottom = BottomRule::kObject;
    TopRule top = TopRule::kHighest;
    double group_radius_m = 0.3;  // views of one instance: centroids closer than this
};

// The rule of a class (floor-standing furniture vs objects on counters).
ClassRule classRule(const std::string& class_name);

// One frame's depth in the world.
struct DepthView {
    cv::Mat depth;  // CV_32FC1 metres, 0 = none
    core::CameraIntrinsics k;
    core::CameraPose T_CtoW;
    core::Vec3 up_W = core::Vec3::UnitZ();

    // Depth of pixel (u, v) in metres, 0 = none.
    [[nodiscard]] double depthAt(int u, int v) const {
        return static_cast<double>(depth.at<float>(v, u));
    }
    [[nodiscard]] core::Vec3 world(int u, int v, double z) const;
    [[nodiscard]] double height(const core::Vec3& p_W) const { return up_W.dot(p_W); }
    [[nodiscard]] double cameraHeight() const { return height(T_CtoW.p_CinW); }
};

// Valid depth range of the Kinect v1 used here.
inline constexpr double kMinDepthM = 0.4;
inline constexpr double kMaxDepthM = 4.5;

// Appends the heights of every `stride`-th pixel of the view.
void appendHeights(const DepthView& view, int stride, std::vector<float>& heights);

// A horizontal surface seen as a peak of the height histogram.
struct Plane {
    double height_m = 0;  // median of the samples within +-2 cm of the peak
    double mad_m = 0;     // their median absolute deviation (x1.4826)
    double fraction = 0;  // share of all samples within +-2 cm of the peak
};

// Peaks of the histogram (1 cm bins, [1 2 1] smoothing) of `heights` that
// hold at least `min_fraction` of the samples within +-2 cm, lowest first.
std::vector<Plane> findPlanes(std::vector<float> heights, double min_fraction);

// Colour-to-depth translation of one frame: depth pixel (u, v) shows what
// colour pixel (u + dx, v + dy) shows.
struct Shift {
    int dx = 0;
    int dy = 0;
    double score = 0;       // mean truncated distance (px) at the best shift
    double zero_score = 0;  // ... at (0, 0)
    bool ok = false;        // enough edges and a clear improvement over (0, 0)
};

Shift estimateShift(const cv::Mat& color_bgr, const cv::Mat& depth);

// One detection measured in one frame.
struct ViewMeasurement {
    bool ok = false;
    std::string reject;   // why not ok
    int pixels = 0;       // segmented object pixels
    double near_m = 0;    // depth of the object's nearest dominant mode
    double top_m = 0;     // height (world up) of the object's top
    double bottom_m = 0;  // ... of its lowest pixel, or of the plane it stands on (kObject)
    core::Vec3 centroid_W = core::Vec3::Zero();
    cv::Rect depth_box;  // the box in the depth image (after the shift)
    cv::Mat mask;        // CV_8UC1, depth-image size: the segmented pixels
};

// Segments the object of `box` (colour pixels) in the depth view and measures
// its top and bottom heights. `rule` chooses how the top is found.
// `scene_planes` are the horizontal planes of the whole scene (absolute
// heights, lowest first): objects on counters stand on one of them.
ViewMeasurement measureView(const DepthView& view, const core::BoundingBox& box, const Shift& shift,
                            const ClassRule& rule, const std::vector<Plane>& scene_planes,
                            bool keep_mask);

// Robust statistics.
using tools::median;                       // tools/common/stats.h
double mad(const std::vector<double>& v);  // median absolute deviation x 1.4826
double percentile(std::span<const float> values, double q);

// Greedy grouping of views of one class into instances by world centroid
// (horizontal distance, i.e. orthogonal to up): each view joins the instance
// whose running median centroid is nearest within `radius_m`, else starts a
// new one; then every view is reassigned to the nearest final centroid.
// Deterministic for a given order. Returns the instance index per view.
std::vector<int> groupInstances(const std::vector<core::Vec3>& centroids, const core::Vec3& up_W,
                                double radius_m);

}  // namespace scaled::tools::heights
