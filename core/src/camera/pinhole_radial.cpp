#include <cmath>
#include <limits>
#include <string>

#include <Eigen/LU>

#include <scaled/core/camera/pinhole_radial.h>

namespace scaled::core {

namespace {

bool finite(Scalar v) {
    return std::isfinite(v);
}

// Smallest positive r where d/dr [r (1 + k1 r^2 + k2 r^4)] = 1 + 3 k1 r^2 + 5 k2 r^4 = 0.
Scalar monotonicRadius(Scalar k1, Scalar k2) {
    const Scalar inf = std::numeric_limits<Scalar>::infinity();
    // Solve 5 k2 t^2 + 3 k1 t + 1 = 0 for t = r^2 > 0.
    if (k2 == 0) {
        return k1 < 0 ? std::sqrt(Scalar(-1) / (3 * k1)) : inf;
    }
    const Scalar a = 5 * k2;
    const Scalar b = 3 * k1;
    const Scalar disc = b * b - 4 * a;
    if (disc < 0) {
        return inf;  // never zero: derivative stays positive
    }
    const Scalar sq = std::sqrt(disc);
    Scalar best = inf;
    for (const Scalar t : {(-b - sq) / (2 * a), (-b + sq) / (2 * a)}) {
        if (t > 0 && t < best) {
            best = t;
        }
    }
    return best == inf ? inf : std::sqrt(best);
}

}  // namespace

Result<PinholeRadialCamera> PinholeRadialCamera::create(const CameraIntrinsics& k) {
    for (const Scalar v : {k.fx, k.fy, k.cx, k.cy, k.k1, k.k2}) {
        if (!finite(v)) {
            return makeError(ErrorCode::kInvalidArgument, "camera: intrinsics must be finite");
        }
    }
    if (k.fx <= 0 || k.fy <= 0) {
        return makeError(ErrorCode::kInvalidArgument,
                         "camera: focal lengths fx, fy must be > 0 (got fx=" +
                             std::to_string(k.fx) + ", fy=" + std::to_string(k.fy) + ")");
    }
    if (k.width_px <= 0 || k.height_px <= 0) {
        return makeError(ErrorCode::kInvalidArgument, "camera: image size must be positive (got " +
                                                          std::to_string(k.width_px) + "x" +
                                                          std::to_string(k.height_px) + ")");
    }
    return PinholeRadialCamera(k);
}

PinholeRadialCamera::PinholeRadialCamera(const CameraIntrinsics& k)
    : k_(k), max_r_u_(monotonicRadius(k.k1, k.k2)) {}

Vec2 PinholeRadialCamera::distort(const Vec2& x_u, Mat2* J_xd_xu) const {
    const Scalar r2 = x_u.squaredNorm();
    const Scalar f = 1 + r2 * (k_.k1 + k_.k2 * r2);
    if (J_xd_xu != nullptr) {
        // d(x f)/dx = f I + x (df/dx)^T,  df/dx = (2 k1 + 4 k2 r^2) x
        const Scalar g = 2 * k_.k1 + 4 * k_.k2 * r2;
        *J_xd_xu = f * Mat2::Identity() + g * x_u * x_u.transpose();
    }
    return f * x_u;
}

std::optional<Vec2> PinholeRadialCamera::undistort(const Vec2& x_d, Mat2* J_xu_xd) const {
    if (!hasDistortion()) {
        if (J_xu_xd != nullptr) {
            J_xu_xd->setIdentity();
        }
        return x_d;
    }
    const Scalar tol = std::numeric_limits<Scalar>::epsilon() * 64 * (1 + x_d.norm());
    Vec2 x = x_d;
    Mat2 J;
    bool converged = false;
    for (int it = 0; it < kMaxNewtonIterations; ++it) {
        const Vec2 residual = distort(x, &J) - x_d;
        if (residual.norm() <= tol) {
            converged = true;
            break;
        }
        const Scalar det = J.determinant();
        if (!(std::abs(det) > std::numeric_limits<Scalar>::epsilon())) {
            return std::nullopt;
        }
        x -= J.inverse() * residual;
        if (!x.allFinite()) {
            return std::nullopt;
        }
    }
    if (!converged) {
        // Accept a final iterate that is within tolerance.
        converged = (distort(x, &J) - x_d).norm() <= tol * 16;
    }
    if (!converged || x.norm() > max_r_u_) {
        return std::nullopt;
    }
    if (J_xu_xd != nullptr) {
        (void)distort(x, &J);
        *J_xu_xd = J.inverse();
    }
    return x;
}

std::optional<Vec2> PinholeRadialCamera::project(const Vec3& p_C, Mat23* J_px_pC) const {
    const Scalar z = p_C.z();
    if (!(z > kMinDepth)) {
        return std::nullopt;
    }
    const Vec2 x_u(p_C.x() / z, p_C.y() / z);
    if (x_u.norm() > max_r_u_) {
        return std::nullopt;  // beyond the fold of the distortion polynomial
    }
    Mat2 J_d;
    const Vec2 x_d = distort(x_u, J_px_pC != nullptr ? &J_d : nullptr);
    if (J_px_pC != nullptr) {
        Mat23 J_xu_p;
        J_xu_p << 1 / z, 0, -x_u.x() / z, 0, 1 / z, -x_u.y() / z;
        Mat2 F = Mat2::Zero();
        F(0, 0) = k_.fx;
        F(1, 1) = k_.fy;
        *J_px_pC = F * J_d * J_xu_p;
    }
    return pixelFromNormalized(x_d);
}

std::optional<Vec3> PinholeRadialCamera::unproject(const Vec2& px, Mat32* J_ray_px) const {
    Mat2 J_u;
    const auto x_u = undistort(normalizedFromPixel(px), J_ray_px != nullptr ? &J_u : nullptr);
    if (!x_u) {
        return std::nullopt;
    }
    if (J_ray_px != nullptr) {
        Mat2 Finv = Mat2::Zero();
        Finv(0, 0) = 1 / k_.fx;
        Finv(1, 1) = 1 / k_.fy;
        J_ray_px->setZero();
        J_ray_px->topRows<2>() = J_u * Finv;
    }
    return Vec3(x_u->x(), x_u->y(), 1);
}

}  // namespace scaled::core
