#pragma once

// Shared fixtures for the synth tests: the default scene (built once) and cameras.

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/drivers/synth/scene.h>

namespace scaled::drivers::synth::test {

inline core::PinholeRadialCamera makeCamera(int width = 640, int height = 480, Scalar f = 525,
                                            Scalar k1 = 0, Scalar k2 = 0) {
    core::CameraIntrinsics k;
    k.fx = f;
    k.fy = f;
    k.cx = Scalar(width) / 2;
    k.cy = Scalar(height) / 2;
    k.k1 = k1;
    k.k2 = k2;
    k.width_px = width;
    k.height_px = height;
    return core::PinholeRadialCamera::create(k).value();
}

// The default room with its furniture, seed 1 (built once: textures take a while).
inline const Scene& defaultScene() {
    static const Scene scene = Scene::create().value();
    return scene;
}

// The empty default room, seed 1.
inline const Scene& emptyScene() {
    static const Scene scene = [] {
        SceneConfig c;
        c.furniture.clear();
        return Scene::create(c).value();
    }();
    return scene;
}

// A camera at p looking along the world direction of yaw (about z, 0 = +x),
// level apart from pitch (up positive) and roll (radians).
inline core::CameraPose lookAt(const Vec3& p, Scalar yaw, Scalar pitch = 0, Scalar roll = 0) {
    core::Mat3 level;
    level << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    using AA = Eigen::AngleAxis<Scalar>;
    core::CameraPose pose;
    pose.R_CtoW = AA(yaw, Vec3::UnitZ()).toRotationMatrix() * level *
                  AA(pitch, Vec3::UnitX()).toRotationMatrix() *
                  AA(roll, Vec3::UnitZ()).toRotationMatrix();
    pose.p_CinW = p;
    return pose;
}

}  // namespace scaled::drivers::synth::test
