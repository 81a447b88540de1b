#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include <Eigen/Eigenvalues>

#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/object_evidence.h>
#include <scaled/core/scale/scale_estimator.h>

namespace scaled::core {

namespace {

Error invalid(const std::string& field, Scalar value, const std::string& rule) {
    return makeError(ErrorCode::kInvalidArgument, "objects: " + field + " must be " + rule +
                                                      " (got " + std::to_string(value) + ")");
}

Vec2 centreOf(const BoundingBox& b) {
    return {(b.x_min_px + b.x_max_px) / 2, (b.y_min_px + b.y_max_px) / 2};
}

Scalar diagonalOf(const BoundingBox& b) {
    return std::hypot(b.x_max_px - b.x_min_px, b.y_max_px - b.y_min_px);
}

// Distance from q to the segment [a, b].
Scalar segmentDistance(const Vec2& q, const Vec2& a, const Vec2& b) {
    const Vec2 ab = b - a;
    const Scalar len2 = ab.squaredNorm();
    const Scalar t = len2 > 0 ? std::clamp((q - a).dot(ab) / len2, Scalar(0), Scalar(1)) : 0;
    return (q - (a + t * ab)).norm();
}

// Intersection over union of two boxes.
Scalar overlapOf(const BoundingBox& a, const BoundingBox& b) {
    const Scalar ix =
        std::max(Scalar(0), std::min(a.x_max_px, b.x_max_px) - std::max(a.x_min_px, b.x_min_px));
    const Scalar iy =
        std::max(Scalar(0), std::min(a.y_max_px, b.y_max_px) - std::max(a.y_min_px, b.y_min_px));
    const Scalar inter = ix * iy;
    const Scalar uni = (a.x_max_px - a.x_min_px) * (a.y_max_px - a.y_min_px) +
                       (b.x_max_px - b.x_min_px) * (b.y_max_px - b.y_min_px) - inter;
    return uni > 0 ? inter / uni : Scalar(0);
}

// Tangent of the elevation of p seen from c (up positive).
Scalar tanElevation(const Vec3& p, const Vec3& c, const Vec3& up_W) {
    const Vec3 e = p - c;
    const Scalar vertical = e.dot(up_W);
    const Scalar horizontal = (e - vertical * up_W).norm();
    return horizontal > 0 ? vertical / horizontal : Scalar(0);
}

}  // namespace

const char* toString(ObjectState state) {
    switch (state) {
        case ObjectState::kTentative:
            return "tentative";
        case ObjectState::kAnchored:
            return "anchored";
        case ObjectState::kUsed:
            return "used";
    }
    return "unknown";
}

Status validate(const ObjectConfig& c) {
    using L = ObjectLimits;
    const LimitCheck checks[] = {
        {"max_objects", static_cast<double>(c.max_objects), L::max_objects},
        {"max_views", static_cast<double>(c.max_views), L::max_views},
        {"centre_rel_sigma", static_cast<double>(c.centre_rel_sigma), L::centre_rel_sigma},
        {"centre_sigma_px", static_cast<double>(c.centre_sigma_px), L::centre_sigma_px},
        {"min_parallax_deg", static_cast<double>(c.min_parallax_deg), L::min_parallax_deg},
        {"max_anchor_rel_sigma", static_cast<double>(c.max_anchor_rel_sigma),
         L::max_anchor_rel_sigma},
        {"anchor_box_margin", static_cast<double>(c.anchor_box_margin), L::anchor_box_margin},
        {"association_gate", static_cast<double>(c.association_gate), L::association_gate},
        {"epipolar_depth_min", static_cast<double>(c.epipolar_depth_min), L::epipolar_depth_min},
        {"epipolar_depth_max", static_cast<double>(c.epipolar_depth_max), L::epipolar_depth_max},
        {"max_gap_updates", static_cast<double>(c.max_gap_updates), L::max_gap_updates},
        {"box_edge_rel_sigma", static_cast<double>(c.box_edge_rel_sigma), L::box_edge_rel_sigma},
        {"object_rel_sigma", static_cast<double>(c.object_rel_sigma), L::object_rel_sigma},
        {"map_rel_sigma", static_cast<double>(c.map_rel_sigma), L::map_rel_sigma},
        {"view_band", static_cast<double>(c.view_band), L::view_band},
        {"view_reference_quantile", static_cast<double>(c.view_reference_quantile),
         L::view_reference_quantile},
    };
    if (const LimitCheck* bad = firstOutside(checks)) {
        return invalid(bad->name, static_cast<Scalar>(bad->value), bad->limits.text());
    }
    if (!(c.centre_rel_sigma > 0 || c.centre_sigma_px > 0)) {
        return invalid("centre_rel_sigma", c.centre_rel_sigma,
                       "> 0 when centre_sigma_px is 0 (not both 0)");
    }
    if (!(c.epipolar_depth_max > c.epipolar_depth_min)) {
        return invalid("epipolar_depth_min", c.epipolar_depth_min, "below epipolar_depth_max");
    }
    return {};
}

Result<ObjectEvidence> ObjectEvidence::create(
    const ObjectConfig& config, const ExtentConfig& extent, const LikelihoodConfig& likelihood,
    const PriorTable& priors, const PinholeRadialCamera& camera, const ScaleGrid& grid) {
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    ObjectEvidence e(config, extent, likelihood, camera, grid);
    if (auto ok = e.buildPriors(priors); !ok) {
        return ok.error();
    }
    return e;
}

ObjectEvidence::ObjectEvidence(const ObjectConfig& config, const ExtentConfig& extent,
                               const LikelihoodConfig& likelihood,
                               const PinholeRadialCamera& camera, const ScaleGrid& grid)
    : config_(config),
      extent_(extent),
      likelihood_(likelihood),
      camera_(camera),
      grid_(grid),
      tracks_(static_cast<std::size_t>(config.max_objects)),
      views_(static_cast<std::size_t>(config.max_objects) *
             static_cast<std::size_t>(config.max_views)),
      log_l_(static_cast<std::size_t>(config.max_objects) * grid.size(), 0),
      extents_(static_cast<std::size_t>(config.max_views)),
      view_log_l_(config.one_height ? 0 : grid.size(), 0),
      rays_(static_cast<std::size_t>(config.max_views)),
      norm_(static_cast<std::size_t>(config.max_views)),
      norm_sorted_(static_cast<std::size_t>(config.max_views)) {
    candidates_.reserve(static_cast<std::size_t>(kMaxDetections) *
                        static_cast<std::size_t>(config.max_objects));
}

Status ObjectEvidence::buildPriors(const PriorTable& priors) {
    std::vector<ApparentHeightPrior> apparent;
    std::vector<Scalar> ratio;
    std::vector<Scalar> spread;
    for (const HeightPrior& p : priors.priors()) {
        Scalar partial = 0;
        if (likelihood_.partial_visibility) {
            partial =
                p.partialProbability() >= 0 ? p.partialProbability() : likelihood_.partial_weight;
        }
        auto a = ApparentHeightPrior::create(p, partial, config_.height_grid);
        if (!a) {
            return a.error();
        }
        apparent.push_back(std::move(a.value()));
        const Scalar mean = p.mean();
        ratio.push_back(config_.width_model && mean > 0 ? p.widthMean() / mean : Scalar(0));
        spread.push_back(p.relativeSpread());
    }
    apparent_ = std::move(apparent);
    width_ratio_ = std::move(ratio);
    class_spread_ = std::move(spread);
    for (Track& t : tracks_) {
        if (t.active && t.class_index >= static_cast<int>(apparent_.size())) {
            t = Track{};  // its class is gone
        }
        t.dirty = t.active;
    }
    return {};
}

Status ObjectEvidence::setPriors(const PriorTable& priors) {
    return buildPriors(priors);
}

void ObjectEvidence::reset() {
    for (Track& t : tracks_) {
        t = Track{};
    }
    next_id_ = 1;
    updates_ = 0;
}

int ObjectEvidence::activeCount() const {
    int n = 0;
    for (const Track& t : tracks_) {
        n += t.active ? 1 : 0;
    }
    return n;
}

int ObjectEvidence::activeSlot(int k) const {
    for (std::size_t i = 0; i < tracks_.size(); ++i) {
        if (tracks_[i].active && k-- == 0) {
            return static_cast<int>(i);
        }
    }
    return -1;
}

Scalar ObjectEvidence::medianDepth(const FrameSnapshot& frame) {
    const Mat3 R_WtoC = frame.pose.R_CtoW.transpose();
    std::size_t n = 0;
    for (const MapFeature& f : frame.features) {
        if (n == depths_.size()) {
            break;
        }
        const Scalar z = (R_WtoC * (f.p_FinW - frame.pose.p_CinW)).z();
        if (z > 0 && std::isfinite(z)) {
            depths_[n++] = z;
        }
    }
    if (n == 0) {
        return 1;
    }
    auto mid = depths_.begin() + static_cast<std::ptrdiff_t>(n / 2);
    std::nth_element(depths_.begin(), mid, depths_.begin() + static_cast<std::ptrdiff_t>(n));
    return *mid;
}

Scalar ObjectEvidence::associationCost(const Track& t, int slot, const FrameSnapshot& frame,
                                       const BoundingBox& box, Scalar depth_hint) const {
    const Vec2 c = centreOf(box);
    const Scalar half_diag = diagonalOf(box) / 2;
    if (!(half_diag > 0)) {
        return -1;
    }
    const Mat3 R_WtoC = frame.pose.R_CtoW.transpose();
    if (t.has_estimate) {
        // The triangulated point, usable or not yet: the box centre must lie
        // within 3 sigma of its projection, sigma from its covariance (long
        // along the viewing rays while the parallax is small) and the gate.
        const Vec3 p_C = R_WtoC * (t.p_AinW - frame.pose.p_CinW);
        Mat23 J = Mat23::Zero();
        if (const auto px = camera_.project(p_C, &J)) {
            const Mat23 J_W = J * R_WtoC;
            const Scalar g = config_.association_gate * half_diag / 2;
            const Mat2 S = J_W * t.P_AinW * J_W.transpose() + Mat2::Identity() * (g * g);
            const Vec2 r = *px - c;
            const Scalar m2 = r.dot(S.ldlt().solve(r));
            if (std::isfinite(m2) && m2 <= 9) {
                // Objects whose anchor is usable rank first.
                return std::sqrt(m2) / 3 + (t.anchored ? Scalar(0) : Scalar(0.5));
            }
        }
        // A wrong estimate must not lock the object out of its own views: the
        // epipolar search below still applies to a recently seen object.
    }
    if (updates_ - t.last_update > config_.max_gap_updates || t.stored == 0) {
        return -1;
    }
    // The epipolar segment of the last box centre over the depths of the map.
    const View& last = view(slot, (t.head + config_.max_views - 1) % config_.max_views);
    const auto ray_C = camera_.unproject(centreOf(last.box));
    if (!ray_C) {
        return -1;
    }
    const Scalar size_ratio = diagonalOf(box) / std::max(diagonalOf(last.box), Scalar(1));
    if (size_ratio > Scalar(2.5) || size_ratio < Scalar(0.4)) {
        return -1;
    }
    const Vec3 ray_W = last.pose.R_CtoW * ray_C->normalized();
    constexpr int kSamples = 12;
    const Scalar z_lo = config_.epipolar_depth_min * std::min(depth_hint, last.depth_hint);
    const Scalar z_hi = config_.epipolar_depth_max * std::max(depth_hint, last.depth_hint);
    const Scalar step = std::log(z_hi / z_lo) / (kSamples - 1);
    Scalar best = std::numeric_limits<Scalar>::infinity();
    Vec2 prev = Vec2::Zero();
    bool have_prev = false;
    for (int i = 0; i < kSamples; ++i) {
        const Scalar z = z_lo * std::exp(step * static_cast<Scalar>(i));
        const auto px =
            camera_.project(R_WtoC * (last.pose.p_CinW + z * ray_W - frame.pose.p_CinW));
        if (!px) {
            have_prev = false;
            continue;
        }
        best = std::min(best, have_prev ? segmentDistance(c, prev, *px) : (*px - c).norm());
        prev = *px;
        have_prev = true;
    }
    const Scalar epipolar = best / (config_.association_gate * half_diag);
    if (!(epipolar <= 1)) {
        return -1;
    }
    // Objects of one class in a row all lie near each other's epipolar line:
    // the overlap with the last box breaks the tie (views are a fraction of a
    // second apart), and an anchored object that fell back here ranks after
    // those whose anchor agrees.
    return epipolar + (1 - overlapOf(last.box, box)) + (t.has_estimate ? Scalar(1) : Scalar(0.5));
}

int ObjectEvidence::newTrack(int class_index) {
    int slot = -1;
    for (std::size_t i = 0; i < tracks_.size(); ++i) {
        if (!tracks_[i].active) {
            slot = static_cast<int>(i);
            break;
        }
    }
    if (slot < 0) {
        // Full: replace an unused object first, then the one seen longest ago.
        auto worse = [](const Track& a, const Track& b) {
            if (a.used != b.used) {
                return !a.used;
            }
            return a.last_update < b.last_update;
        };
        slot = 0;
        for (std::size_t i = 1; i < tracks_.size(); ++i) {
            if (worse(tracks_[i], tracks_[static_cast<std::size_t>(slot)])) {
                slot = static_cast<int>(i);
            }
        }
    }
    Track& t = tracks_[static_cast<std::size_t>(slot)];
    t = Track{};
    t.active = true;
    t.id = next_id_++;
    t.class_index = class_index;
    return slot;
}

int ObjectEvidence::collectCentreRays(const Track& t, int slot, int& constraints) {
    const auto& k = camera_.intrinsics();
    const Scalar f = (k.fx + k.fy) / 2;
    const Scalar m = extent_.border_margin_px;
    // The views' box-centre rays. A box cut by the image border is not
    // centred on its object along the cut axis: cut at its top or bottom
    // only, it gives the plane of its centre column (cut_box_planes); cut at
    // a side, nothing.
    int n = 0;
    constraints = 0;
    for (int i = 0; i < t.stored; ++i) {
        const View& v = view(slot, i);
        const BoundingBox& b = v.box;
        const bool cut_x = edgeOnImageBorder(camera_, b, BoxEdge::kLeft, m) ||
                           edgeOnImageBorder(camera_, b, BoxEdge::kRight, m);
        const bool cut_y = edgeOnImageBorder(camera_, b, BoxEdge::kTop, m) ||
                           edgeOnImageBorder(camera_, b, BoxEdge::kBottom, m);
        if (cut_x || (cut_y && !config_.cut_box_planes)) {
            continue;
        }
        const Vec2 c = centreOf(b);
        const auto ray_C = camera_.unproject(c);
        if (!ray_C) {
            continue;
        }
        Ray& r = rays_[static_cast<std::size_t>(n)];
        r.plane = cut_y;
        if (r.plane) {
            // The centre column, through two points of the box (a line of
            // the distorted image is nearly one of the undistorted one over
            // a box).
            const Vec2 a(c.x(), b.y_min_px);
            const Vec2 e(c.x(), b.y_max_px);
            const auto ra = camera_.unproject(a);
            const auto re = camera_.unproject(e);
            if (!ra || !re) {
                continue;
            }
            const Vec3 normal_C = ra->cross(*re);
            if (!(normal_C.norm() > 0)) {
                continue;
            }
            r.normal_W = v.pose.R_CtoW * normal_C.normalized();
        }
        r.view = i;
        r.dir_W = v.pose.R_CtoW * ray_C->normalized();
        r.sigma_angle =
            (config_.centre_rel_sigma * diagonalOf(v.box) + config_.centre_sigma_px) / f;
        constraints += r.plane ? 1 : 2;
        ++n;
    }
    return n;
}

bool ObjectEvidence::rayAgreement(int slot, std::span<const Ray> rays, const Vec3& X,
                                  RayAgreement& out) const {
    // In front of every view; how many boxes it projects into (with a
    // margin); the rays' chi-square; the largest angle between two rays.
    int inside = 0;
    Scalar chi2 = 0;
    Scalar min_cos = 1;
    const auto sight = [&](std::size_t k) -> Vec3 {
        return rays[k].plane ? Vec3((X - view(slot, rays[k].view).pose.p_CinW).normalized())
                             : rays[k].dir_W;
    };
    for (std::size_t i = 0; i < rays.size(); ++i) {
        const View& v = view(slot, rays[i].view);
        const Vec3 e = X - v.pose.p_CinW;
        const Scalar along = e.dot(rays[i].dir_W);
        if (!(along > 0)) {
            return false;
        }
        const Scalar s = rays[i].sigma_angle * along;
        if (rays[i].plane) {
            const Scalar off = rays[i].normal_W.dot(e);
            chi2 += off * off / (s * s);
        } else {
            chi2 += (e - along * rays[i].dir_W).squaredNorm() / (s * s);
        }
        const auto px = camera_.project(v.pose.R_CtoW.transpose() * e);
        const Scalar mw = config_.anchor_box_margin * (v.box.x_max_px - v.box.x_min_px);
        const Scalar mh = config_.anchor_box_margin * (v.box.y_max_px - v.box.y_min_px);
        // A cut box holds the anchor left to right only (the object's middle
        // may be outside the image).
        if (px && px->x() >= v.box.x_min_px - mw && px->x() <= v.box.x_max_px + mw &&
            (rays[i].plane || (px->y() >= v.box.y_min_px - mh && px->y() <= v.box.y_max_px + mh))) {
            ++inside;
        }
        // The parallax between the lines of sight (to X from a cut box's
        // view: its centre moves on the object with the cut).
        const Vec3 sight_i = sight(i);
        for (std::size_t j = 0; j < i; ++j) {
            min_cos = std::min(min_cos, sight_i.dot(sight(j)));
        }
    }
    out.inside = inside;
    out.chi2 = chi2;
    out.min_cos = min_cos;
    return true;
}

void ObjectEvidence::triangulate(Track& t, int slot) {
    t.anchored = false;
    t.has_estimate = false;
    // At least two views, one of them a whole box (a ray: the column planes
    // of cut boxes all contain the camera's vertical and leave the anchor's
    // height to noise), and one degree of freedom to spare.
    int constraints = 0;
    const int n = collectCentreRays(t, slot, constraints);
    if (n < 2 || constraints < 4 || constraints == n) {
        return;
    }
    const std::span<const Ray> rays(rays_.data(), static_cast<std::size_t>(n));
    // Weighted least squares: each ray's perpendicular error has std
    // sigma_angle times the depth along it (the map's depth in view first,
    // then the solution's).
    Vec3 X = Vec3::Zero();
    Eigen::SelfAdjointEigenSolver<Mat3> eig;
    for (int iter = 0; iter < 2; ++iter) {
        Mat3 H = Mat3::Zero();
        Vec3 b = Vec3::Zero();
        for (const Ray& r : rays) {
            const View& v = view(slot, r.view);
            const Scalar dist =
                iter == 0 ? v.depth_hint
                          : std::max((X - v.pose.p_CinW).dot(r.dir_W), v.depth_hint / 100);
            const Scalar s = r.sigma_angle * dist;
            const Mat3 A = (r.plane ? Mat3(r.normal_W * r.normal_W.transpose())
                                    : Mat3(Mat3::Identity() - r.dir_W * r.dir_W.transpose())) /
                           (s * s);
            H += A;
            b += A * v.pose.p_CinW;
        }
        eig.compute(H);
        if (eig.info() != Eigen::Success || !(eig.eigenvalues()(0) > 0) ||
            !(eig.eigenvalues()(0) >
              eig.eigenvalues()(2) * std::numeric_limits<Scalar>::epsilon() * 1000)) {
            return;
        }
        X = eig.eigenvectors() *
            (eig.eigenvalues().cwiseInverse().asDiagonal() * (eig.eigenvectors().transpose() * b));
    }
    RayAgreement agreement;
    if (!rayAgreement(slot, rays, X, agreement)) {
        return;
    }
    const Scalar parallax_deg = std::acos(std::clamp(agreement.min_cos, Scalar(-1), Scalar(1))) *
                                180 / std::numbers::pi_v<Scalar>;
    // A-posteriori variance factor: rays that do not meet as well as their
    // assumed noise says (the box centre moving on the object, a pose error
    // of the map) widen the anchor's covariance accordingly.
    const int dof = constraints - 3;
    const Scalar factor =
        dof > 0 ? std::max(Scalar(1), agreement.chi2 / static_cast<Scalar>(dof)) : Scalar(1);
    const Mat3 P = eig.eigenvectors() * eig.eigenvalues().cwiseInverse().asDiagonal() *
                   eig.eigenvectors().transpose() * factor;
    // Its relative depth uncertainty, seen from the latest of those views.
    const Vec3 e = X - view(slot, rays.back().view).pose.p_CinW;
    const Scalar dist = e.norm();
    const Vec3 dir = e / dist;
    const Scalar rel = std::sqrt(std::max(Scalar(0), dir.dot(P * dir))) / dist;
    if (!std::isfinite(rel)) {
        return;
    }
    t.p_AinW = X;
    t.P_AinW = P;
    t.anchor_rel_sigma = rel;
    t.has_estimate = true;
    t.anchored = rel <= config_.max_anchor_rel_sigma && parallax_deg >= config_.min_parallax_deg &&
                 2 * agreement.inside >= n;
}

std::optional<ObjectViewExtent> ObjectEvidence::measureView(const Vec3& p_AinW,
                                                            const CameraPose& pose,
                                                            const Vec3& up_W,
                                                            const BoundingBox& box) const {
    const auto px = camera_.project(pose.R_CtoW.transpose() * (p_AinW - pose.p_CinW));
    if (!px) {
        return std::nullopt;
    }
    const Scalar mw = config_.anchor_box_margin * (box.x_max_px - box.x_min_px);
    const Scalar mh = config_.anchor_box_margin * (box.y_max_px - box.y_min_px);
    if (px->x() < box.x_min_px - mw || px->x() > box.x_max_px + mw || px->y() < box.y_min_px - mh ||
        px->y() > box.y_max_px + mh) {
        return std::nullopt;  // not this object's box, as the anchor sees it
    }
    // The vertical line through the anchor, moved into the box (at the
    // anchor's depth) when the anchor projects into the margin around it.
    VerticalExtent ve;
    ExtentStatus status = computeVerticalExtent(camera_, pose, up_W, p_AinW, box, extent_, &ve);
    if (status == ExtentStatus::kOutsideBox) {
        const Vec2 q(std::clamp(px->x(), box.x_min_px + 1, box.x_max_px - 1),
                     std::clamp(px->y(), box.y_min_px + 1, box.y_max_px - 1));
        const auto ray_C = camera_.unproject(q);
        if (!ray_C) {
            return std::nullopt;
        }
        const Scalar depth = (pose.R_CtoW.transpose() * (p_AinW - pose.p_CinW)).z();
        const Vec3 p = pose.p_CinW + pose.R_CtoW * (*ray_C * depth);
        status = computeVerticalExtent(camera_, pose, up_W, p, box, extent_, &ve);
    }
    if (status != ExtentStatus::kOk) {
        return std::nullopt;
    }
    const Scalar h_px = (ve.pi_t_px - ve.pi_d_px).norm();
    const Scalar edge = std::max(extent_.box_edge_sigma_px, config_.box_edge_rel_sigma * h_px);
    ObjectViewExtent x;
    x.D = ve.D;
    x.kappa = (std::abs(tanElevation(ve.p_t_W, pose.p_CinW, up_W)) +
               std::abs(tanElevation(ve.p_d_W, pose.p_CinW, up_W))) /
              2;
    x.sigma_D = ve.D * std::sqrt(Scalar(2)) * edge / std::max(h_px, Scalar(1));
    return x;
}

std::size_t ObjectEvidence::measureViews(const Track& t, int slot, Scalar width_ratio) {
    std::size_t n = 0;
    for (int i = 0; i < t.stored; ++i) {
        const View& v = view(slot, i);
        if (const auto x = measureView(t.p_AinW, v.pose, v.up_W, v.box)) {
            extents_[n] = *x;
            norm_[n] = x->D / (1 + x->kappa * width_ratio);
            ++n;
        }
    }
    return n;
}

std::size_t ObjectEvidence::keepViewsNearReference(std::size_t n) {
    // Views far from the object's reference extent leave the product.
    std::copy_n(norm_.begin(), n, norm_sorted_.begin());
    const auto q_idx = static_cast<std::ptrdiff_t>(
        std::lround(config_.view_reference_quantile * static_cast<Scalar>(n - 1)));
    std::nth_element(norm_sorted_.begin(), norm_sorted_.begin() + q_idx,
                     norm_sorted_.begin() + static_cast<std::ptrdiff_t>(n));
    const Scalar reference = norm_sorted_[static_cast<std::size_t>(q_idx)];
    for (std::size_t i = 0; i < n; ++i) {
        norm_sorted_[i] = extents_[i].sigma_D / extents_[i].D;
    }
    const auto mid = static_cast<std::ptrdiff_t>(n / 2);
    std::nth_element(norm_sorted_.begin(), norm_sorted_.begin() + mid,
                     norm_sorted_.begin() + static_cast<std::ptrdiff_t>(n));
    const Scalar band =
        std::max(config_.view_band, 3 * norm_sorted_[static_cast<std::size_t>(mid)]);
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n; ++i) {
        if (std::abs(norm_[i] / reference - 1) <= band) {
            extents_[kept++] = extents_[i];
        }
    }
    return kept;
}

bool ObjectEvidence::evaluateIntoCache(std::span<const ObjectViewExtent> used,
                                       const ApparentHeightPrior& prior,
                                       const ObjectLikelihoodConfig& lc, int slot) {
    if (config_.one_height) {
        return evaluateObjectLogLikelihood(used, prior, grid_, lc, cache(slot));
    }
    // The ablation: views as independent observations, each with its own
    // height from the class prior.
    std::span<Scalar> sum = cache(slot);
    std::fill(sum.begin(), sum.end(), Scalar(0));
    for (std::size_t i = 0; i < used.size(); ++i) {
        if (!evaluateObjectLogLikelihood(used.subspan(i, 1), prior, grid_, lc, view_log_l_)) {
            return false;
        }
        for (std::size_t j = 0; j < sum.size(); ++j) {
            sum[j] += view_log_l_[j];
        }
    }
    const Scalar top = *std::max_element(sum.begin(), sum.end());
    for (auto& v : sum) {
        v -= top;
    }
    return true;
}

void ObjectEvidence::evaluate(Track& t, int slot) {
    t.dirty = false;
    t.used = false;
    t.views_used = 0;
    t.local_estimate = 0;
    t.s_1 = t.s_d = t.s_k = 0;
    if (!t.anchored || t.class_index < 0 || t.class_index >= static_cast<int>(apparent_.size())) {
        return;
    }
    const ApparentHeightPrior& prior = apparent_[static_cast<std::size_t>(t.class_index)];
    const Scalar ratio = width_ratio_[static_cast<std::size_t>(t.class_index)];
    const std::size_t n = measureViews(t, slot, ratio);
    if (n == 0) {
        return;
    }
    const std::size_t kept = keepViewsNearReference(n);
    if (kept == 0) {
        return;
    }
    ObjectLikelihoodConfig lc;
    lc.width_model = config_.width_model;
    lc.rel_sigma = std::hypot(config_.object_rel_sigma, t.anchor_rel_sigma);
    lc.outlier_weight = likelihood_.robust ? likelihood_.outlier_weight : Scalar(0);
    const std::span<const ObjectViewExtent> used(extents_.data(), kept);
    if (!evaluateIntoCache(used, prior, lc, slot)) {
        return;
    }
    t.used = true;
    t.views_used = static_cast<int>(kept);
    t.local_estimate = gridMode(grid_, cache(slot));
    for (const auto& x : used) {
        const double w = 1 / (static_cast<double>(x.sigma_D) * static_cast<double>(x.sigma_D));
        t.s_1 += w;
        t.s_d += w * static_cast<double>(x.D);
        t.s_k += w * static_cast<double>(x.kappa);
    }
}

void ObjectEvidence::associateDetections(const FrameSnapshot& frame,
                                         std::span<const Detection> detections,
                                         std::span<const int> class_index, int n_det,
                                         Scalar depth_hint, std::span<int> track_of) {
    // Candidate pairs, then greedy assignment by cost.
    candidates_.clear();
    for (int di = 0; di < n_det; ++di) {
        const int ci = class_index[static_cast<std::size_t>(di)];
        if (ci < 0) {
            continue;
        }
        for (std::size_t ti = 0; ti < tracks_.size(); ++ti) {
            const Track& t = tracks_[ti];
            if (!t.active || t.class_index != ci) {
                continue;
            }
            const Scalar cost =
                associationCost(t, static_cast<int>(ti), frame,
                                detections[static_cast<std::size_t>(di)].box, depth_hint);
            if (cost >= 0 && candidates_.size() < candidates_.capacity()) {
                candidates_.push_back({cost, di, static_cast<int>(ti)});
            }
        }
    }
    std::sort(candidates_.begin(), candidates_.end(), [](const Candidate& a, const Candidate& b) {
        return a.cost < b.cost ||
               (a.cost == b.cost &&
                (a.detection < b.detection || (a.detection == b.detection && a.track < b.track)));
    });
    for (const Candidate& c : candidates_) {
        if (track_of[static_cast<std::size_t>(c.detection)] >= 0 ||
            tracks_[static_cast<std::size_t>(c.track)].last_update == updates_) {
            continue;
        }
        track_of[static_cast<std::size_t>(c.detection)] = c.track;
        tracks_[static_cast<std::size_t>(c.track)].last_update = updates_;
    }
}

void ObjectEvidence::addViews(const FrameSnapshot& frame, std::span<const Detection> detections,
                              std::span<const int> class_index, int n_det, Scalar depth_hint,
                              std::span<int> track_of, std::span<ObjectAssignment> assignments,
                              UpdateStats& stats) {
    // New objects for the rest; a view for every associated detection.
    for (int di = 0; di < n_det; ++di) {
        const int ci = class_index[static_cast<std::size_t>(di)];
        if (ci < 0) {
            continue;
        }
        int slot = track_of[static_cast<std::size_t>(di)];
        bool fresh = false;
        if (slot < 0) {
            slot = newTrack(ci);
            fresh = true;
            ++stats.new_objects;
            track_of[static_cast<std::size_t>(di)] = slot;
        }
        Track& t = tracks_[static_cast<std::size_t>(slot)];
        View& v = view(slot, t.head);
        v.pose = frame.pose;
        v.up_W = frame.up_W;
        v.box = detections[static_cast<std::size_t>(di)].box;
        v.frame_id = frame.frame_id;
        v.depth_hint = depth_hint;
        t.head = (t.head + 1) % config_.max_views;
        t.stored = std::min(t.stored + 1, config_.max_views);
        if (t.detections == 0) {
            t.first_frame = frame.frame_id;
        }
        ++t.detections;
        t.last_frame = frame.frame_id;
        t.last_update = updates_;
        t.dirty = true;
        if (static_cast<std::size_t>(di) < assignments.size()) {
            assignments[static_cast<std::size_t>(di)] = {t.id, fresh};
        }
    }
}

int ObjectEvidence::writeRecords(const FrameSnapshot& frame, std::span<const Detection> detections,
                                 int n_det, std::span<const int> track_of,
                                 std::span<ObservationRecord> records, UpdateStats& stats) const {
    // Records: the detections of this update that are views of used objects.
    int written = 0;
    for (int di = 0; di < n_det; ++di) {
        const int slot = track_of[static_cast<std::size_t>(di)];
        if (slot < 0) {
            continue;
        }
        const Track& t = tracks_[static_cast<std::size_t>(slot)];
        if (!t.used) {
            continue;
        }
        ++stats.detections_used;
        if (static_cast<std::size_t>(written) < records.size()) {
            ObservationRecord& r = records[static_cast<std::size_t>(written++)];
            r = ObservationRecord{};
            r.detection_index = di;
            r.object_id = t.id;
            r.local_estimate = t.local_estimate;
            r.weight = 1;
            // The view just added, measured with the current anchor.
            if (const auto x = measureView(t.p_AinW, frame.pose, frame.up_W,
                                           detections[static_cast<std::size_t>(di)].box)) {
                r.D = x->D;
                r.sigma_D_box = x->sigma_D;
                r.kappa = x->kappa;
            }
        }
    }
    return written;
}

ObjectEvidence::UpdateStats ObjectEvidence::update(const FrameSnapshot& frame,
                                                   std::span<const Detection> detections,
                                                   std::span<const int> class_index,
                                                   std::span<ObjectAssignment> assignments,
                                                   std::span<ObservationRecord> records,
                                                   int* records_written) {
    ++updates_;
    UpdateStats stats;
    const Scalar depth_hint = medianDepth(frame);
    const int n_det = static_cast<int>(std::min<std::size_t>(
        {detections.size(), class_index.size(), static_cast<std::size_t>(kMaxDetections)}));
    for (auto& a : assignments) {
        a = ObjectAssignment{};
    }
    std::array<int, kMaxDetections> track_of{};
    track_of.fill(-1);
    associateDetections(frame, detections, class_index, n_det, depth_hint, track_of);
    addViews(frame, detections, class_index, n_det, depth_hint, track_of, assignments, stats);
    for (std::size_t ti = 0; ti < tracks_.size(); ++ti) {
        Track& t = tracks_[ti];
        if (!t.active || !t.dirty) {
            continue;
        }
        triangulate(t, static_cast<int>(ti));
        evaluate(t, static_cast<int>(ti));
    }
    const int written = writeRecords(frame, detections, n_det, track_of, records, stats);
    if (records_written != nullptr) {
        *records_written = written;
    }
    for (const Track& t : tracks_) {
        if (t.active && t.used) {
            ++stats.objects_used;
            stats.views_used += t.views_used;
        }
    }
    return stats;
}

int ObjectEvidence::addTo(ScalePosterior& posterior) const {
    int objects = 0;
    int views = 0;
    for (std::size_t ti = 0; ti < tracks_.size(); ++ti) {
        const Track& t = tracks_[ti];
        if (!t.active || !t.used) {
            continue;
        }
        if (posterior.addLogLikelihood(cache(static_cast<int>(ti)))) {
            ++objects;
            views += t.views_used;
        }
    }
    posterior.setObservationCount(views);
    if (objects > 0 && config_.map_rel_sigma > 0) {
        // d_served = d_map (1 + e): log(1 + e) ~ N(0, map_rel_sigma^2).
        posterior.diffuse(std::log1p(config_.map_rel_sigma));
    }
    return objects;
}

ObjectSummary ObjectEvidence::summary(int k, const ScaleSummary& posterior) const {
    ObjectSummary s;
    const int slot = activeSlot(k);
    if (slot < 0) {
        return s;
    }
    const Track& t = tracks_[static_cast<std::size_t>(slot)];
    s.id = t.id;
    s.class_index = t.class_index;
    s.state = t.used ? ObjectState::kUsed
                     : (t.anchored ? ObjectState::kAnchored : ObjectState::kTentative);
    s.p_AinW = t.p_AinW;
    s.anchor_rel_sigma = t.anchor_rel_sigma;
    s.detections = t.detections;
    s.views = t.stored;
    s.views_used = t.views_used;
    s.first_frame = t.first_frame;
    s.last_frame = t.last_frame;
    s.local_estimate = t.local_estimate;
    if (t.used && t.s_1 > 0 && posterior.state != ScaleState::kNoData) {
        const double mu_w =
            config_.width_model
                ? static_cast<double>(
                      apparent_[static_cast<std::size_t>(t.class_index)].widthMean())
                : 0.0;
        const auto at = [&](Scalar d) {
            return static_cast<Scalar>((static_cast<double>(d) * t.s_d - mu_w * t.s_k) / t.s_1);
        };
        s.height_m = at(posterior.map);
        s.height_ci95_m = {at(posterior.ci95.lo), at(posterior.ci95.hi)};
    }
    return s;
}

std::span<const Scalar> ObjectEvidence::logLikelihood(int k) const {
    const int slot = activeSlot(k);
    if (slot < 0 || !tracks_[static_cast<std::size_t>(slot)].used) {
        return {};
    }
    return cache(slot);
}

std::size_t ObjectEvidence::memoryBytes() const {
    std::size_t bytes = sizeof(*this) + tracks_.capacity() * sizeof(Track) +
                        views_.capacity() * sizeof(View) + log_l_.capacity() * sizeof(Scalar) +
                        extents_.capacity() * sizeof(ObjectViewExtent) +
                        rays_.capacity() * sizeof(Ray) +
                        (view_log_l_.capacity() + norm_.capacity() + norm_sorted_.capacity() +
                         width_ratio_.capacity() + class_spread_.capacity()) *
                            sizeof(Scalar) +
                        candidates_.capacity() * sizeof(Candidate) + grid_.size() * sizeof(Scalar);
    for (const ApparentHeightPrior& a : apparent_) {
        bytes += sizeof(a) + 3 * a.size() * sizeof(Scalar);
    }
    return bytes;
}

Scalar ObjectEvidence::informationLimitRelWidth95() const {
    double info = 0;
    for (const Track& t : tracks_) {
        if (!t.active || !t.used) {
            continue;
        }
        const double s =
            std::hypot(static_cast<double>(class_spread_[static_cast<std::size_t>(t.class_index)]),
                       static_cast<double>(config_.object_rel_sigma));
        if (s > 0) {
            info += 1 / (s * s);
        }
    }
    if (!(info > 0)) {
        return 0;
    }
    const double sigma = 1 / std::sqrt(info);
    return static_cast<Scalar>(std::exp(1.96 * sigma) - std::exp(-1.96 * sigma));
}

}  // namespace scaled::core
