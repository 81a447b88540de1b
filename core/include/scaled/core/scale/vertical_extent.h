#pragma once

// The paper's observation geometry (Sucar & Hayet 2017, section 4).
//
// For a map feature p_i inside a detection box: the image line lambda through
// its projection pi_i and the vertical vanishing point, the intersections
// pi_t (top) and pi_d (bottom) of lambda with the box boundary, their
// back-projected rays, the points p_t, p_d of the vertical 3-D line Lambda
// through p_i closest to those rays, and D = |p_t - p_d| in SLAM units.

#include <cstdint>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/types.h>

namespace scaled::core {

// Axis-aligned box in distorted pixel coordinates (x right, y down).
struct BoundingBox {
    Scalar x_min_px = 0;
    Scalar y_min_px = 0;
    Scalar x_max_px = 0;
    Scalar y_max_px = 0;
};

// Camera pose: R_CtoW rotates camera-frame vectors into the world frame,
// p_CinW is the camera centre in the world (SLAM units).
struct CameraPose {
    Mat3 R_CtoW = Mat3::Identity();
    Vec3 p_CinW = Vec3::Zero();
};

// A map point with its 3x3 position covariance (SLAM units).
struct MapFeature {
    Vec3 p_FinW = Vec3::Zero();
    Mat3 P_FinW = Mat3::Zero();
};

enum class ExtentStatus : std::uint8_t {
    kOk,
    kBehindCamera,         // feature not in front of the camera
    kOutsideBox,           // projection pi_i not inside the box
    kTruncatedBox,         // the line leaves the box through an edge on the image border
    kVanishingPointInBox,  // camera looks (nearly) straight up or down through the object
    kDegenerateDirection,  // the image of the vertical through pi_i is a point
    kSideExit,             // the line leaves the box through a side edge
    kNoIntersection,       // no exit from the box was found
    kInconsistent,         // p_t not above or p_d not below p_i, or behind the camera
    kTooSmall,             // D or the image extent too small to use
    kUnstable,             // a perturbation for the variance crossed a degeneracy
    kRollTooLarge,         // roll compensation cannot explain the box (see ExtentConfig)
    kCount
};
const char* toString(ExtentStatus status);

enum class BoxEdge : std::uint8_t { kLeft, kRight, kTop, kBottom };

// Whether edge e of box b lies within margin pixels of the image border: the
// object goes on past it, so the edge is not the object's.
[[nodiscard]] bool edgeOnImageBorder(const PinholeRadialCamera& cam, const BoundingBox& b,
                                     BoxEdge e, Scalar margin);

struct ExtentConfig {
    Scalar border_margin_px = 2;     // an exit edge this close to the image border is truncated
    bool reject_side_exit = true;    // a side exit does not measure the object's top or bottom
    Scalar min_extent_px = 4;        // minimum |pi_t - pi_d|
    Scalar box_edge_sigma_px = 2;    // pixel noise of box edges (propagated variance)
    bool propagate_variance = true;  // compute sigma_D_feature and sigma_D_box (numeric Jacobians)
    // Beyond the paper: under camera roll alpha an axis-aligned box around an
    // upright object of image width a and height b is taller than b by about
    // a |sin alpha|. With this on, lambda is intersected with the upright
    // rectangle, rotated by the local image roll, whose bounding box the
    // detection is (the gravity direction gives alpha).
    bool compensate_roll = false;
};

struct VerticalExtent {
    Vec2 pi_i_px = Vec2::Zero();
    Vec2 pi_t_px = Vec2::Zero();
    Vec2 pi_d_px = Vec2::Zero();
    BoxEdge top_edge = BoxEdge::kTop;
    BoxEdge bottom_edge = BoxEdge::kBottom;
    Vec3 p_t_W = Vec3::Zero();
    Vec3 p_d_W = Vec3::Zero();
    Scalar D = 0;                // |p_t - p_d|, SLAM units
    Scalar sigma_D_paper = 0;    // sqrt(2 J P J^T), J = (p_t - p_d)^T / D
    Scalar sigma_D_feature = 0;  // sqrt(g P g^T), g = dD/dp_i (full propagation)
    Scalar sigma_D_box = 0;      // box-edge pixel noise propagated to D
};

struct ExtentResult {
    ExtentStatus status = ExtentStatus::kNoIntersection;
    VerticalExtent extent;
};

// up_W: unit vector of the world "up" direction (opposite to gravity).
ExtentResult measureVerticalExtent(const PinholeRadialCamera& camera, const CameraPose& pose,
                                   const Vec3& up_W, const MapFeature& feature,
                                   const BoundingBox& box, const ExtentConfig& config);

// D only (no variance), used by the numeric Jacobians and by tests.
ExtentStatus computeVerticalExtent(const PinholeRadialCamera& camera, const CameraPose& pose,
                                   const Vec3& up_W, const Vec3& p_FinW, const BoundingBox& box,
                                   const ExtentConfig& config, VerticalExtent* out);

}  // namespace scaled::core
