#pragma once

// Small helpers to build cameras, poses and boxes for core tests.

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::test {

using core::Scalar;

// 640x480, principal point at the centre.
inline core::CameraIntrinsics makeIntrinsics(Scalar k1 = 0, Scalar k2 = 0, Scalar f = 500) {
    core::CameraIntrinsics k;
    k.fx = f;
    k.fy = f;
    k.cx = 320;
    k.cy = 240;
    k.k1 = k1;
    k.k2 = k2;
    k.width_px = 640;
    k.height_px = 480;
    return k;
}

inline core::PinholeRadialCamera makeCamera(Scalar k1 = 0, Scalar k2 = 0, Scalar f = 500) {
    return core::PinholeRadialCamera::create(makeIntrinsics(k1, k2, f)).value();
}

// A level camera at p looking along world +y (world z up), then rotated by
// yaw (about world z), pitch (about camera x) and roll (about camera z), radians.
inline core::CameraPose lookAlongY(const core::Vec3& p, Scalar yaw = 0, Scalar pitch = 0,
                                   Scalar roll = 0) {
    core::Mat3 R0;
    R0 << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    using AA = Eigen::AngleAxis<Scalar>;
    core::CameraPose pose;
    pose.R_CtoW = AA(yaw, core::Vec3::UnitZ()).toRotationMatrix() * R0 *
                  AA(pitch, core::Vec3::UnitX()).toRotationMatrix() *
                  AA(roll, core::Vec3::UnitZ()).toRotationMatrix();
    pose.p_CinW = p;
    return pose;
}

inline std::optional<core::Vec2> projectW(const core::PinholeRadialCamera& cam,
                                          const core::CameraPose& pose, const core::Vec3& p_W) {
    return cam.project(pose.R_CtoW.transpose() * (p_W - pose.p_CinW));
}

// Bounding box of the projections of points (all must project), grown by margin_px.
inline core::BoundingBox boxOf(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                               std::initializer_list<core::Vec3> pts, Scalar margin_x_px = 0) {
    core::BoundingBox b{1e9, 1e9, -1e9, -1e9};
    for (const auto& p : pts) {
        const auto px = projectW(cam, pose, p);
        b.x_min_px = std::min(b.x_min_px, px->x());
        b.y_min_px = std::min(b.y_min_px, px->y());
        b.x_max_px = std::max(b.x_max_px, px->x());
        b.y_max_px = std::max(b.y_max_px, px->y());
    }
    b.x_min_px -= margin_x_px;
    b.x_max_px += margin_x_px;
    return b;
}

}  // namespace scaled::test
