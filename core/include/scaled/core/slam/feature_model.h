#pragma once

// Map features and their measurement model.
//
// Inverse depth (Civera, Davison, Montiel 2008): y = (x0, y0, z0, theta, phi, rho)
// is the optical centre the feature was first seen from, the azimuth and
// elevation of the ray in the world frame, and the inverse depth along it:
//   p = x0 + m(theta, phi) / rho,  m = (cos(phi) sin(theta), -sin(phi), cos(phi) cos(theta)).
// Euclidean: y = (x, y, z).
// Measurement: the feature in the camera frame h_C = R(q)^T (rho (x0 - r) + m)
// (resp. R(q)^T (p - r)), projected by the pinhole + radial camera. The
// inverse-depth form stays well defined for points at infinity (rho = 0).

#include <optional>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/slam/slam_types.h>

namespace scaled::core::slam {

// m(theta, phi) and its derivatives.
Vec3 directionFromAngles(Scalar theta, Scalar phi, Vec3* dm_dtheta = nullptr,
                         Vec3* dm_dphi = nullptr);

// Predicted measurement of one feature.
struct FeatureProjection {
    Vec2 h_px = Vec2::Zero();  // predicted distorted pixel
    Vec3 h_C = Vec3::Zero();   // direction (inverse depth) or position (XYZ) in the camera frame
    Mat27 H_pose = Mat27::Zero();     // d h / d (r, q)
    Mat26 H_feature = Mat26::Zero();  // d h / d y (first 3 columns for XYZ)
};

// y holds dimOf(kind) values. nullopt when the point is not in front of the
// camera. Jacobians are filled when want_jacobians.
std::optional<FeatureProjection> projectFeature(const PinholeRadialCamera& cam, const Vec3& r,
                                                const Vec4& q, FeatureKind kind, const Scalar* y,
                                                bool want_jacobians);

// Undelayed initialisation from a distorted pixel seen by the camera at (r, q).
// J_pose (6x7) = dy/d(r,q), J_px (6x2) = dy/dpixel; dy/drho is the unit vector e6.
struct InverseDepthInit {
    Vec6 y = Vec6::Zero();
    Mat67 J_pose = Mat67::Zero();
    Mat62 J_px = Mat62::Zero();
};
std::optional<InverseDepthInit> initInverseDepth(const PinholeRadialCamera& cam, const Vec3& r,
                                                 const Vec4& q, const Vec2& px, Scalar rho0);

// Euclidean point of an inverse-depth feature and J = dp/dy (3x6).
// Requires rho != 0.
Vec3 inverseDepthToXyz(const Vec6& y, Mat36* J = nullptr);

// Linearity index of Civera et al. 2008 (section 5): 4 sigma_d / d1 |cos alpha|
// with sigma_d = sigma_rho / rho^2, d1 the distance from the camera at r to
// the point and alpha the angle between the first ray and the current one.
// Large (not linear enough) when rho <= 0.
Scalar linearityIndex(const Vec6& y, Scalar sigma_rho, const Vec3& r);

}  // namespace scaled::core::slam
