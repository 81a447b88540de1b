#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <scaled/core/geometry/lines.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::core {

const char* toString(ExtentStatus status) {
    switch (status) {
        case ExtentStatus::kOk:
            return "ok";
        case ExtentStatus::kBehindCamera:
            return "behind_camera";
        case ExtentStatus::kOutsideBox:
            return "outside_box";
        case ExtentStatus::kTruncatedBox:
            return "truncated_box";
        case ExtentStatus::kVanishingPointInBox:
            return "vanishing_point_in_box";
        case ExtentStatus::kDegenerateDirection:
            return "degenerate_direction";
        case ExtentStatus::kSideExit:
            return "side_exit";
        case ExtentStatus::kNoIntersection:
            return "no_intersection";
        case ExtentStatus::kInconsistent:
            return "inconsistent";
        case ExtentStatus::kTooSmall:
            return "too_small";
        case ExtentStatus::kUnstable:
            return "unstable";
        case ExtentStatus::kRollTooLarge:
            return "roll_too_large";
        case ExtentStatus::kCount:
            break;
    }
    return "unknown";
}

namespace {

bool inside(const BoundingBox& b, const Vec2& px) {
    return px.x() >= b.x_min_px && px.x() <= b.x_max_px && px.y() >= b.y_min_px &&
           px.y() <= b.y_max_px;
}

// The region the image line is intersected with: the detection box itself, or
// (roll compensation) the upright rectangle, rotated by the image roll, whose
// axis-aligned bounding box the detection box is. Local axes: x along the
// rectangle's width, y along the image of "down".
struct Region {
    Vec2 centre = Vec2::Zero();
    Scalar c = 1;  // cos and sin of the roll
    Scalar s = 0;
    Scalar half_w = 0;
    Scalar half_h = 0;

    [[nodiscard]] Vec2 toLocal(const Vec2& px) const {
        const Vec2 d = px - centre;
        return {c * d.x() + s * d.y(), -s * d.x() + c * d.y()};
    }
    [[nodiscard]] Vec2 dirToLocal(const Vec2& v) const {
        return {c * v.x() + s * v.y(), -s * v.x() + c * v.y()};
    }
    [[nodiscard]] bool contains(const Vec2& px) const {
        const Vec2 l = toLocal(px);
        return std::abs(l.x()) <= half_w && std::abs(l.y()) <= half_h;
    }
};

Region axisAligned(const BoundingBox& b) {
    Region r;
    r.centre = Vec2((b.x_min_px + b.x_max_px) / 2, (b.y_min_px + b.y_max_px) / 2);
    r.half_w = (b.x_max_px - b.x_min_px) / 2;
    r.half_h = (b.y_max_px - b.y_min_px) / 2;
    return r;
}

struct Exit {
    Scalar t;
    BoxEdge edge;
};

// Which edge a point just outside the region has crossed (the largest violation).
BoxEdge violatedEdge(const Region& r, const Vec2& px) {
    const Vec2 l = r.toLocal(px);
    const std::array<Scalar, 4> v = {-l.x() - r.half_w, l.x() - r.half_w, -l.y() - r.half_h,
                                     l.y() - r.half_h};
    std::size_t best = 0;
    for (std::size_t i = 1; i < v.size(); ++i) {
        if (v[i] > v[best]) {
            best = i;
        }
    }
    return static_cast<BoxEdge>(best);
}

// First exit of x0 + t*dir (t > 0, normalised undistorted coordinates) from the
// region (distorted pixels). Closed form (slabs in the region's frame) without
// distortion; otherwise a bounded march followed by bisection on the distorted
// image of the line.
std::optional<Exit> exitFromRegion(const PinholeRadialCamera& cam, const Vec2& x0, const Vec2& dir,
                                   const Region& region) {
    const auto& k = cam.intrinsics();
    if (!cam.hasDistortion()) {
        const Vec2 p0 = region.toLocal(cam.pixelFromNormalized(x0));
        const Vec2 dp = region.dirToLocal(Vec2(k.fx * dir.x(), k.fy * dir.y()));
        Scalar t_best = std::numeric_limits<Scalar>::infinity();
        BoxEdge edge = BoxEdge::kTop;
        if (dp.x() > 0) {
            t_best = (region.half_w - p0.x()) / dp.x();
            edge = BoxEdge::kRight;
        } else if (dp.x() < 0) {
            t_best = (-region.half_w - p0.x()) / dp.x();
            edge = BoxEdge::kLeft;
        }
        if (dp.y() > 0) {
            const Scalar t_y = (region.half_h - p0.y()) / dp.y();
            if (t_y <= t_best) {
                t_best = t_y;
                edge = BoxEdge::kBottom;
            }
        } else if (dp.y() < 0) {
            const Scalar t_y = (-region.half_h - p0.y()) / dp.y();
            if (t_y <= t_best) {
                t_best = t_y;
                edge = BoxEdge::kTop;
            }
        }
        if (!std::isfinite(t_best) || t_best < 0) {
            return std::nullopt;
        }
        return Exit{t_best, edge};
    }

    constexpr int kMarchSteps = 256;
    constexpr int kBisections = 60;
    const Scalar diag_px = 2 * std::hypot(region.half_w, region.half_h);
    const Scalar step = diag_px / std::min(k.fx, k.fy) / 32;
    const auto pixelAt = [&](Scalar t) -> std::optional<Vec2> {
        const Vec2 x = x0 + t * dir;
        if (x.norm() > cam.maxUndistortedRadius()) {
            return std::nullopt;
        }
        return cam.pixelFromNormalized(cam.distort(x));
    };
    Scalar t_in = 0;
    Scalar t_out = -1;
    for (int i = 1; i <= kMarchSteps; ++i) {
        const Scalar t = step * static_cast<Scalar>(i);
        const auto px = pixelAt(t);
        if (!px) {
            return std::nullopt;  // leaves the valid lens region before leaving the box
        }
        if (!region.contains(*px)) {
            t_out = t;
            break;
        }
        t_in = t;
    }
    if (t_out < 0) {
        return std::nullopt;
    }
    for (int i = 0; i < kBisections; ++i) {
        const Scalar mid = Scalar(0.5) * (t_in + t_out);
        if (mid <= t_in || mid >= t_out) {
            break;
        }
        const auto px = pixelAt(mid);
        if (px && region.contains(*px)) {
            t_in = mid;
        } else {
            t_out = mid;
        }
    }
    const auto px_out = pixelAt(t_out);
    if (!px_out) {
        return std::nullopt;
    }
    return Exit{Scalar(0.5) * (t_in + t_out), violatedEdge(region, *px_out)};
}

// The upright rectangle (width a, height b) rotated by the image roll alpha
// whose bounding box is the detection box:
//   w = a cos|alpha| + b sin|alpha|,  h = a sin|alpha| + b cos|alpha|.
// nullopt when the box cannot be explained that way (solution not positive, or
// roll too large to invert stably).
std::optional<Region> rollCompensated(const BoundingBox& box, Scalar alpha) {
    Region r = axisAligned(box);
    const Scalar ca = std::cos(alpha);
    const Scalar sa = std::abs(std::sin(alpha));
    const Scalar c2 = ca * ca - sa * sa;
    if (c2 < Scalar(0.5)) {  // |alpha| > 30 degrees
        return std::nullopt;
    }
    const Scalar w = 2 * r.half_w;
    const Scalar h = 2 * r.half_h;
    const Scalar a = (w * ca - h * sa) / c2;
    const Scalar b = (h * ca - w * sa) / c2;
    if (!(a > 0 && b > 0)) {
        return std::nullopt;
    }
    r.c = ca;
    r.s = std::sin(alpha);
    r.half_w = a / 2;
    r.half_h = b / 2;
    return r;
}

bool isSide(BoxEdge e) {
    return e == BoxEdge::kLeft || e == BoxEdge::kRight;
}

// Vertical vanishing point inside the box: lambda would pass through it
// before reaching an edge, so the intersections are not top and bottom.
bool vanishingPointInBox(const PinholeRadialCamera& camera, const Vec3& v_C,
                         const BoundingBox& box) {
    if (std::abs(v_C.z()) > std::numeric_limits<Scalar>::epsilon()) {
        const Vec2 vp_u = v_C.head<2>() / v_C.z();
        if (vp_u.norm() <= camera.maxUndistortedRadius() &&
            inside(box, camera.pixelFromNormalized(camera.distort(vp_u)))) {
            return true;
        }
    }
    return false;
}

// The region lambda is intersected with (Region): kOk, or why there is none.
ExtentStatus intersectionRegion(const PinholeRadialCamera& camera, const Vec3& v_C,
                                const BoundingBox& box, const Vec2& pi_i, bool compensate_roll,
                                Region& region) {
    region = axisAligned(box);
    if (compensate_roll) {
        // Image roll at the box centre: the angle of the image of "up" there
        // from the image's -y axis.
        const auto centre_ray = camera.unproject(region.centre);
        if (centre_ray) {
            const Vec3& q = *centre_ray;  // point at unit depth
            const Vec2 up_n = v_C.head<2>() - q.head<2>() * v_C.z();
            const auto& k = camera.intrinsics();
            const Vec2 up_px(k.fx * up_n.x(), k.fy * up_n.y());
            if (up_px.norm() > 0) {
                const Scalar alpha = std::atan2(up_px.x(), -up_px.y());
                if (auto rc = rollCompensated(box, alpha)) {
                    region = *rc;
                } else {
                    return ExtentStatus::kRollTooLarge;
                }
            }
        }
        if (!region.contains(pi_i)) {
            return ExtentStatus::kOutsideBox;
        }
    }
    return ExtentStatus::kOk;
}

// The parameter s of the point p_FinW + s up_W of Lambda closest to the ray
// through x (normalised undistorted); nullopt when it is not in front of the camera.
std::optional<Scalar> closestOnLambda(const CameraPose& pose, const Vec3& p_FinW, const Vec3& up_W,
                                      const Vec2& x) {
    const Vec3 ray_W = pose.R_CtoW * Vec3(x.x(), x.y(), 1);
    const auto st = closestPointParams(p_FinW, up_W, pose.p_CinW, ray_W);
    if (!st || !(st->t > 0)) {
        return std::nullopt;
    }
    return st->s;
}

}  // namespace

bool edgeOnImageBorder(const PinholeRadialCamera& cam, const BoundingBox& b, BoxEdge e,
                       Scalar margin) {
    const auto w = static_cast<Scalar>(cam.width() - 1);
    const auto h = static_cast<Scalar>(cam.height() - 1);
    switch (e) {
        case BoxEdge::kLeft:
            return b.x_min_px <= margin;
        case BoxEdge::kRight:
            return b.x_max_px >= w - margin;
        case BoxEdge::kTop:
            return b.y_min_px <= margin;
        case BoxEdge::kBottom:
            return b.y_max_px >= h - margin;
    }
    return true;
}

ExtentStatus computeVerticalExtent(const PinholeRadialCamera& camera, const CameraPose& pose,
                                   const Vec3& up_W, const Vec3& p_FinW, const BoundingBox& box,
                                   const ExtentConfig& config, VerticalExtent* out) {
    const Mat3 R_WtoC = pose.R_CtoW.transpose();
    const Vec3 p_FinC = R_WtoC * (p_FinW - pose.p_CinW);
    const auto pi_i = camera.project(p_FinC);
    if (!pi_i) {
        return ExtentStatus::kBehindCamera;
    }
    if (!inside(box, *pi_i)) {
        return ExtentStatus::kOutsideBox;
    }

    // Image of the vertical line Lambda through p_i, in normalised undistorted
    // coordinates: x(s) = (p + s v).xy / (p + s v).z. Its tangent at s = 0 points
    // from pi_i towards (or away from) the vertical vanishing point v.xy / v.z.
    const Vec3 v_C = R_WtoC * up_W;
    const Scalar z = p_FinC.z();
    const Vec2 x0(p_FinC.x() / z, p_FinC.y() / z);
    Vec2 dir = (v_C.head<2>() - x0 * v_C.z()) / z;
    const Scalar dir_norm = dir.norm();
    if (!(dir_norm > std::sqrt(std::numeric_limits<Scalar>::epsilon()))) {
        return ExtentStatus::kDegenerateDirection;
    }
    dir /= dir_norm;  // +dir is the image of "up" (s > 0)

    if (vanishingPointInBox(camera, v_C, box)) {
        return ExtentStatus::kVanishingPointInBox;
    }

    Region region;
    if (const ExtentStatus st =
            intersectionRegion(camera, v_C, box, *pi_i, config.compensate_roll, region);
        st != ExtentStatus::kOk) {
        return st;
    }
    const auto top = exitFromRegion(camera, x0, dir, region);
    const auto bottom = exitFromRegion(camera, x0, -dir, region);
    if (!top || !bottom) {
        return ExtentStatus::kNoIntersection;
    }
    if (edgeOnImageBorder(camera, box, top->edge, config.border_margin_px) ||
        edgeOnImageBorder(camera, box, bottom->edge, config.border_margin_px)) {
        return ExtentStatus::kTruncatedBox;
    }
    if (config.reject_side_exit && (isSide(top->edge) || isSide(bottom->edge))) {
        return ExtentStatus::kSideExit;
    }

    // Back-project pi_t and pi_d and take the points of Lambda closest to the rays.
    const Vec2 x_t = x0 + top->t * dir;
    const Vec2 x_d = x0 - bottom->t * dir;
    const auto s_t = closestOnLambda(pose, p_FinW, up_W, x_t);
    const auto s_d = closestOnLambda(pose, p_FinW, up_W, x_d);
    if (!s_t || !s_d || !(*s_t > 0) || !(*s_d < 0)) {
        return ExtentStatus::kInconsistent;
    }

    VerticalExtent e;
    e.pi_i_px = *pi_i;
    e.pi_t_px = camera.pixelFromNormalized(camera.distort(x_t));
    e.pi_d_px = camera.pixelFromNormalized(camera.distort(x_d));
    e.top_edge = top->edge;
    e.bottom_edge = bottom->edge;
    e.p_t_W = p_FinW + *s_t * up_W;
    e.p_d_W = p_FinW + *s_d * up_W;
    e.D = (e.p_t_W - e.p_d_W).norm();
    const Scalar scale = std::max(Scalar(1), p_FinC.norm());
    if ((e.pi_t_px - e.pi_d_px).norm() < config.min_extent_px ||
        !(e.D > std::numeric_limits<Scalar>::epsilon() * 1024 * scale) || !std::isfinite(e.D)) {
        return ExtentStatus::kTooSmall;
    }
    *out = e;
    return ExtentStatus::kOk;
}

ExtentResult measureVerticalExtent(const PinholeRadialCamera& camera, const CameraPose& pose,
                                   const Vec3& up_W, const MapFeature& feature,
                                   const BoundingBox& box, const ExtentConfig& config) {
    ExtentResult r;
    r.status = computeVerticalExtent(camera, pose, up_W, feature.p_FinW, box, config, &r.extent);
    if (r.status != ExtentStatus::kOk) {
        return r;
    }
    VerticalExtent& e = r.extent;
    const Scalar cov_scale = feature.P_FinW.trace();
    if (!std::isfinite(cov_scale) || cov_scale < 0) {
        r.status = ExtentStatus::kUnstable;
        return r;
    }

    // Paper: sigma_D^2 = 2 J P J^T with J = (p_t - p_d)^T / D.
    const RowVec3 J = (e.p_t_W - e.p_d_W).transpose() / e.D;
    e.sigma_D_paper = std::sqrt(std::max(Scalar(0), 2 * (J * feature.P_FinW * J.transpose())(0)));

    if (!config.propagate_variance) {
        return r;
    }
    // Full propagation by central differences (D is a composition of projection,
    // box intersection and line-line closest points; a numeric Jacobian is exact
    // enough and keeps one source of truth for the geometry).
    //
    // The step is the usual cbrt(eps) times the quantity's scale, capped at
    // kMaxRelativeStep of the feature's distance and kMaxPixelStep pixels: in a
    // float build cbrt(eps) is 5e-3, which would move a box edge by ~2 px (as
    // much as the edge noise itself) and the feature by ~2.5 px in the image,
    // often across an edge of the box, so that perturbed evaluations fail
    // (kUnstable) where the double build's tiny steps do not. In a double build
    // the caps are never reached (cbrt(eps) = 6e-6).
    constexpr Scalar kMaxRelativeStep = Scalar(2e-4);
    constexpr Scalar kMaxPixelStep = Scalar(0.1);
    const Scalar eps_cbrt = std::cbrt(std::numeric_limits<Scalar>::epsilon());
    const auto evalD = [&](const Vec3& p, const BoundingBox& b, Scalar* D) {
        VerticalExtent tmp;
        if (computeVerticalExtent(camera, pose, up_W, p, b, config, &tmp) != ExtentStatus::kOk) {
            return false;
        }
        *D = tmp.D;
        return true;
    };
    const Scalar h_p = std::min(eps_cbrt, kMaxRelativeStep) *
                       std::max(Scalar(1), (feature.p_FinW - pose.p_CinW).norm());
    RowVec3 g;
    for (int i = 0; i < 3; ++i) {
        Vec3 p_plus = feature.p_FinW;
        Vec3 p_minus = feature.p_FinW;
        p_plus(i) += h_p;
        p_minus(i) -= h_p;
        Scalar d_plus = 0;
        Scalar d_minus = 0;
        if (!evalD(p_plus, box, &d_plus) || !evalD(p_minus, box, &d_minus)) {
            r.status = ExtentStatus::kUnstable;
            return r;
        }
        g(i) = (d_plus - d_minus) / (2 * h_p);
    }
    e.sigma_D_feature = std::sqrt(std::max(Scalar(0), (g * feature.P_FinW * g.transpose())(0)));

    Scalar var_box = 0;
    const Scalar h_px = std::min(eps_cbrt * std::max(Scalar(1), box.x_max_px), kMaxPixelStep);
    using Edge = Scalar BoundingBox::*;
    for (Edge edge : {&BoundingBox::x_min_px, &BoundingBox::y_min_px, &BoundingBox::x_max_px,
                      &BoundingBox::y_max_px}) {
        BoundingBox b_plus = box;
        BoundingBox b_minus = box;
        b_plus.*edge += h_px;
        b_minus.*edge -= h_px;
        Scalar d_plus = 0;
        Scalar d_minus = 0;
        if (!evalD(feature.p_FinW, b_plus, &d_plus) || !evalD(feature.p_FinW, b_minus, &d_minus)) {
            r.status = ExtentStatus::kUnstable;
            return r;
        }
        const Scalar dD = (d_plus - d_minus) / (2 * h_px);
        var_box += dD * dD;
    }
    e.sigma_D_box = config.box_edge_sigma_px * std::sqrt(var_box);
    return r;
}

}  // namespace scaled::core
