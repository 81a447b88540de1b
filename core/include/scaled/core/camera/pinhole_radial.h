#pragma once

// Pinhole camera with two-coefficient radial distortion, the model shared by
// the scale estimator and the EKF MonoSLAM.
//
//   normalised undistorted  x_u = (X/Z, Y/Z)
//   distortion              x_d = x_u * (1 + k1 r^2 + k2 r^4),   r^2 = |x_u|^2
//   pixels                  u = fx * x_d.x + cx,   v = fy * x_d.y + cy
//
// Undistortion inverts the polynomial with a bounded Newton iteration and is
// only defined inside the radius where the distortion is monotonic.

#include <optional>

#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::core {

struct CameraIntrinsics {
    Scalar fx = 0;
    Scalar fy = 0;
    Scalar cx = 0;
    Scalar cy = 0;
    Scalar k1 = 0;
    Scalar k2 = 0;
    int width_px = 0;
    int height_px = 0;
};

class PinholeRadialCamera {
public:
    // Validates the intrinsics (positive focal lengths and image size, finite values).
    static Result<PinholeRadialCamera> create(const CameraIntrinsics& intrinsics);

    [[nodiscard]] const CameraIntrinsics& intrinsics() const { return k_; }
    [[nodiscard]] bool hasDistortion() const { return k_.k1 != 0 || k_.k2 != 0; }
    [[nodiscard]] int width() const { return k_.width_px; }
    [[nodiscard]] int height() const { return k_.height_px; }

    // Normalised undistorted -> normalised distorted, with optional 2x2 Jacobian.
    [[nodiscard]] Vec2 distort(const Vec2& x_u, Mat2* J_xd_xu = nullptr) const;

    // Normalised distorted -> normalised undistorted. nullopt outside the
    // monotonic region or if Newton does not converge in its bounded iterations.
    [[nodiscard]] std::optional<Vec2> undistort(const Vec2& x_d, Mat2* J_xu_xd = nullptr) const;

    // Point in the camera frame -> distorted pixel. nullopt when the point is not
    // in front of the camera (Z <= min depth). J is d(pixel)/d(p_C).
    [[nodiscard]] std::optional<Vec2> project(const Vec3& p_C, Mat23* J_px_pC = nullptr) const;

    // Distorted pixel -> viewing ray (x_u, y_u, 1) in the camera frame.
    // J is d(ray)/d(pixel).
    [[nodiscard]] std::optional<Vec3> unproject(const Vec2& px, Mat32* J_ray_px = nullptr) const;

    // Normalised distorted <-> pixel (affine part only).
    [[nodiscard]] Vec2 pixelFromNormalized(const Vec2& x_d) const {
        return {k_.fx * x_d.x() + k_.cx, k_.fy * x_d.y() + k_.cy};
    }
    [[nodiscard]] Vec2 normalizedFromPixel(const Vec2& px) const {
        return {(px.x() - k_.cx) / k_.fx, (px.y() - k_.cy) / k_.fy};
    }

    // Largest undistorted radius where the distortion is still monotonic
    // (infinite when there is no distortion or it is pincushion-only).
    [[nodiscard]] Scalar maxUndistortedRadius() const { return max_r_u_; }

    static constexpr Scalar kMinDepth = Scalar(1e-6);
    static constexpr int kMaxNewtonIterations = 20;

private:
    explicit PinholeRadialCamera(const CameraIntrinsics& k);

    CameraIntrinsics k_;
    Scalar max_r_u_;
};

}  // namespace scaled::core
