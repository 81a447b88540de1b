#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <scaled/core/slam/quaternion.h>
#include <scaled/core/slam/window_ba.h>

namespace scaled::core::slam {

namespace {

Scalar huberCost(Scalar e, Scalar k) {
    return e < k ? e * e : 2 * k * e - k * k;
}

// to ~= scale R from + t (Umeyama 1991) with fixed-size algebra: no
// allocation (core's alignTrajectories is evaluation code and allocates).
std::optional<Sim3> fitSim3(std::span<const Vec3> from, std::span<const Vec3> to) {
    const auto n = static_cast<Scalar>(from.size());
    if (from.size() < 3 || from.size() != to.size()) {
        return std::nullopt;
    }
    Vec3 mf = Vec3::Zero();
    Vec3 mt = Vec3::Zero();
    for (size_t i = 0; i < from.size(); ++i) {
        mf += from[i];
        mt += to[i];
    }
    mf /= n;
    mt /= n;
    Mat3 cov = Mat3::Zero();
    Scalar var_from = 0;
    for (size_t i = 0; i < from.size(); ++i) {
        cov.noalias() += (to[i] - mt) * (from[i] - mf).transpose();
        var_from += (from[i] - mf).squaredNorm();
    }
    cov /= n;
    var_from /= n;
    if (!(var_from > Scalar(1e-12)) || !cov.allFinite()) {
        return std::nullopt;
    }
    const Eigen::JacobiSVD<Mat3> svd(cov, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Vec3 d = Vec3::Ones();
    if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) {
        d(2) = -1;
    }
    Sim3 out;
    out.R = svd.matrixU() * d.asDiagonal() * svd.matrixV().transpose();
    out.scale = svd.singularValues().dot(d) / var_from;
    out.t = mt - out.scale * out.R * mf;
    if (!(out.scale > 0) || !std::isfinite(out.scale)) {
        return std::nullopt;
    }
    return out;
}

}  // namespace

Status validate(const WindowBaConfig& c) {
    using L = WindowBaLimits;
    const LimitCheck checks[] = {
        {"keyframe_every", static_cast<double>(c.keyframe_every), L::keyframe_every},
        {"window_keyframes", static_cast<double>(c.window_keyframes), L::window_keyframes},
        {"fixed_keyframes", static_cast<double>(c.fixed_keyframes), L::fixed_keyframes},
        {"step_keyframes", static_cast<double>(c.step_keyframes), L::step_keyframes},
        {"max_points", static_cast<double>(c.max_points), L::max_points},
        {"max_observations_per_keyframe", static_cast<double>(c.max_observations_per_keyframe),
         L::max_observations_per_keyframe},
        {"min_views", static_cast<double>(c.min_views), L::min_views},
        {"min_parallax_rad", static_cast<double>(c.min_parallax_rad), L::min_parallax_rad},
        {"huber_px", static_cast<double>(c.huber_px), L::huber_px},
        {"iterations", static_cast<double>(c.iterations), L::iterations},
        {"max_scale_step", static_cast<double>(c.max_scale_step), L::max_scale_step},
        {"defer_frames", static_cast<double>(c.defer_frames), L::defer_frames},
        {"rolling_shutter_s", static_cast<double>(c.rolling_shutter_s), L::rolling_shutter_s},
        {"rolling_shutter_sigma_s", static_cast<double>(c.rolling_shutter_sigma_s),
         L::rolling_shutter_sigma_s},
        {"rolling_shutter_max_s", static_cast<double>(c.rolling_shutter_max_s),
         L::rolling_shutter_max_s},
        {"focal_sigma_rel", static_cast<double>(c.focal_sigma_rel), L::focal_sigma_rel},
        {"focal_max_rel", static_cast<double>(c.focal_max_rel), L::focal_max_rel},
        {"k1_sigma", static_cast<double>(c.k1_sigma), L::k1_sigma},
        {"k1_max_change", static_cast<double>(c.k1_max_change), L::k1_max_change},
    };
    if (const LimitCheck* bad = firstOutside(checks)) {
        return makeError(ErrorCode::kInvalidArgument, std::string("window_ba.") + bad->name +
                                                          " = " + formatLimitValue(bad->value) +
                                                          ": must be " + bad->limits.text());
    }
    if (c.fixed_keyframes > c.window_keyframes - 2) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.fixed_keyframes = " + std::to_string(c.fixed_keyframes) +
                             ": must leave at least 2 of window_keyframes (" +
                             std::to_string(c.window_keyframes) + ") free");
    }
    if (c.rolling_shutter_sigma_s > 0 && c.rolling_shutter_sigma_s < Scalar(1e-4)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.rolling_shutter_sigma_s = " +
                             formatLimitValue(static_cast<double>(c.rolling_shutter_sigma_s)) +
                             ": must be 0 (given) or at least 0.0001 s (estimated)");
    }
    if (c.focal_sigma_rel > 0 && c.focal_sigma_rel < Scalar(1e-4)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.focal_sigma_rel = " +
                             formatLimitValue(static_cast<double>(c.focal_sigma_rel)) +
                             ": must be 0 (given) or at least 0.0001 (estimated)");
    }
    if (c.k1_sigma > 0 && c.k1_sigma < Scalar(1e-4)) {
        return makeError(
            ErrorCode::kInvalidArgument,
            "window_ba.k1_sigma = " + formatLimitValue(static_cast<double>(c.k1_sigma)) +
                ": must be 0 (given) or at least 0.0001 (estimated)");
    }
    if (c.rolling_shutter_sigma_s > 0 && std::abs(c.rolling_shutter_s) > c.rolling_shutter_max_s) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.rolling_shutter_s = " +
                             formatLimitValue(static_cast<double>(c.rolling_shutter_s)) +
                             ": must be within +-rolling_shutter_max_s (" +
                             formatLimitValue(static_cast<double>(c.rolling_shutter_max_s)) +
                             ") when it is estimated");
    }
    if (c.defer_frames >= c.keyframe_every) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.defer_frames = " + std::to_string(c.defer_frames) +
                             ": must be less than keyframe_every (" +
                             std::to_string(c.keyframe_every) + ")");
    }
    if (c.step_keyframes > c.window_keyframes - c.fixed_keyframes) {
        return makeError(ErrorCode::kInvalidArgument,
                         "window_ba.step_keyframes = " + std::to_string(c.step_keyframes) +
                             ": must be at most window_keyframes - fixed_keyframes (" +
                             std::to_string(c.window_keyframes - c.fixed_keyframes) + ")");
    }
    return {};
}

Result<WindowBa> WindowBa::create(const PinholeRadialCamera& camera, const WindowBaConfig& config) {
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    return WindowBa(camera, config);
}

WindowBa::WindowBa(const PinholeRadialCamera& camera, const WindowBaConfig& config)
    : camera_given_(camera),
      camera_(camera),
      config_(config),
      capacity_(config.window_keyframes),
      readout_s_(config.rolling_shutter_s),
      estimate_readout_(estimatesReadout(config)),
      k1_(camera.intrinsics().k1),
      estimate_focal_(estimatesFocal(config)),
      estimate_k1_(estimatesK1(config)) {
    const auto cap = static_cast<size_t>(capacity_);
    const auto per_kf = static_cast<size_t>(config.max_observations_per_keyframe);
    const auto max_points = static_cast<size_t>(config.max_points);
    // The most free keyframes: the first optimisation's (all but the first
    // keyframe) or a later one's (the window less the fixed part).
    const int max_free = std::max(
        config.window_keyframes - config.fixed_keyframes,
        std::min(config.fixed_keyframes + config.step_keyframes, config.window_keyframes) - 1);
    const Eigen::Index free_dim = 6 * Eigen::Index{max_free} + globalCount();
    keyframes_.resize(cap);
    saved_keyframes_.resize(cap);
    obs_.resize(cap * per_kf);
    obs_point_.assign(cap * per_kf, -1);
    W_.resize(cap * per_kf);
    W_g_.resize(max_points);
    points_.resize(max_points);
    views_.resize(max_points * cap);
    saved_points_.resize(max_points);
    H_ll_.resize(max_points);
    b_l_.resize(max_points);
    H_ll_inv_.resize(max_points);
    H_pp_ = MatX::Zero(free_dim, free_dim);
    S_ = MatX::Zero(free_dim, free_dim);
    b_p_ = VecX::Zero(free_dim);
    g_ = VecX::Zero(free_dim);
    dx_p_ = VecX::Zero(free_dim);
    sim_from_.reserve(cap);
    sim_to_.reserve(cap);
}

void WindowBa::reset() {
    // The estimated readout time, focal length and distortion are kept: they
    // are the camera's, not the map's.
    head_ = 0;
    count_ = 0;
    frames_ = 0;
    since_opt_ = 0;
    first_optimisation_ = true;
    point_count_ = 0;
    unit_ratio_ = 1;
}

WindowBa::Keyframe& WindowBa::keyframe(int i) {
    return keyframes_[static_cast<size_t>((head_ + i) % capacity_)];
}

const WindowBa::Keyframe& WindowBa::keyframe(int i) const {
    return keyframes_[static_cast<size_t>((head_ + i) % capacity_)];
}

size_t WindowBa::obsIndex(int i, int j) const {
    return static_cast<size_t>((head_ + i) % capacity_) *
               static_cast<size_t>(config_.max_observations_per_keyframe) +
           static_cast<size_t>(j);
}

void WindowBa::pushKeyframe(const CameraPose& T_CtoW, std::span<const FeatureObservation> obs,
                            const Vec3& v_W, const Vec3& w_C) {
    if (capacity_ < 1) {  // validate() keeps window_keyframes >= 4
        return;
    }
    // Where the served pose has it (the newest keyframe's adjusted pose and
    // the filter's motion since, times the unit ratio), before the ring moves.
    const CameraPose adjusted = adjustedPose(T_CtoW);
    if (count_ == capacity_) {
        head_ = (head_ + 1) % capacity_;
        --count_;
    }
    ++count_;
    Keyframe& kf = keyframe(count_ - 1);
    kf.filter = T_CtoW;
    kf.adjusted = adjusted;
    kf.v_C = T_CtoW.R_CtoW.transpose() * v_W;
    kf.w_C = w_C;
    const int n = std::min(static_cast<int>(obs.size()), config_.max_observations_per_keyframe);
    kf.obs_count = n;
    for (int j = 0; j < n; ++j) {
        obs_[obsIndex(count_ - 1, j)] = obs[static_cast<size_t>(j)];
    }
}

WindowBaReport WindowBa::addFrame(const CameraPose& T_CtoW, std::span<const FeatureObservation> obs,
                                  const Vec3& v_W, const Vec3& w_C) {
    WindowBaReport report;
    if (!config_.enabled) {
        return report;
    }
    const bool is_keyframe = frames_ % config_.keyframe_every == 0;
    ++frames_;
    if (!is_keyframe) {
        return report;
    }
    pushKeyframe(T_CtoW, obs, v_W, w_C);
    ++since_opt_;
    const int wanted = first_optimisation_ ? config_.fixed_keyframes + config_.step_keyframes
                                           : config_.step_keyframes;
    if (since_opt_ < wanted || count_ < config_.fixed_keyframes + 2) {
        report.keyframes = count_;
        return report;
    }
    since_opt_ = 0;
    if (config_.defer_frames > 0) {
        report.keyframes = count_;
        report.due = true;
        return report;
    }
    return optimise();
}

void WindowBa::notifyRescaled(Scalar s, const Vec3& centre_W) {
    for (int i = 0; i < count_; ++i) {
        Keyframe& kf = keyframe(i);
        kf.filter.p_CinW = centre_W + s * (kf.filter.p_CinW - centre_W);
        kf.v_C *= s;
    }
}

WindowBa::RowMotion WindowBa::rowMotion(const Keyframe& kf, const Vec2& z_px) const {
    RowMotion m;
    if (readout_s_ != 0) {
        const Scalar d = readout_s_ * z_px.y() / Scalar(std::max(1, camera_.height() - 1));
        m.E = rotationFromQuat(quatFromRotationVector(-d * kf.w_C));
        m.shift_C = (unit_ratio_ * d) * kf.v_C;
    }
    return m;
}

CameraPose WindowBa::adjustedPose(const CameraPose& filter_T_CtoW) const {
    return adjustedFromFilter().apply(filter_T_CtoW);
}

Sim3 WindowBa::adjustedFromFilter() const {
    if (count_ == 0) {
        return {};
    }
    // The filter's motion since the newest keyframe, its translation times
    // the unit ratio, from that keyframe's adjusted pose: as a map of world
    // points, a point at p_C in the keyframe's filter camera lies at
    // unit_ratio_ p_C in its adjusted camera.
    const Keyframe& last = keyframe(count_ - 1);
    Sim3 out;
    out.scale = unit_ratio_;
    out.R = last.adjusted.R_CtoW * last.filter.R_CtoW.transpose();
    out.t = last.adjusted.p_CinW - out.scale * (out.R * last.filter.p_CinW);
    return out;
}

WindowBaReport WindowBa::optimise() {
    WindowBaReport report;
    report.keyframes = count_;
    // The first optimisation holds only the first keyframe (and leaves the
    // unit where the filter had it); later ones the window's older part.
    const int first_free = first_optimisation_ ? 1 : std::min(config_.fixed_keyframes, count_ - 2);
    report.free_keyframes = count_ - first_free;
    gatherPoints(first_free);
    Scalar c = cost();
    const auto rmsPx = [this](Scalar cost_total) {
        return std::sqrt(std::max(Scalar(0), cost_total - priorCost()) /
                         Scalar(std::max(1, usable_observations_)));
    };
    report.rms_before_px = rmsPx(c);
    Scalar lambda = Scalar(1e-3);
    for (int it = 0; it < config_.iterations; ++it) {
        const Scalar before = c;
        if (iterate(first_free, lambda, c) && before - c < Scalar(1e-6) * before) {
            break;
        }
    }
    report.points = usable_points_;
    report.observations = usable_observations_;
    report.rms_after_px = rmsPx(c);
    report.optimised = true;
    report.rolling_shutter_s = readout_s_;
    report.focal_scale = focal_scale_;
    report.k1 = k1_;
    if (first_optimisation_) {
        first_optimisation_ = false;
        holdFilterGauge();
        return report;
    }
    const Scalar s = scaleOfFreeKeyframes(first_free);
    if (config_.scale_feedback) {
        // The filter's map takes the adjusted unit (the caller rescales it).
        const Scalar hi = 1 + config_.max_scale_step;
        report.scale = std::clamp(s, 1 / hi, hi);
    } else {
        // The filter keeps its unit; the adjusted unit per filter unit scales
        // the filter's motion from the newest keyframe on.
        unit_ratio_ = s;
    }
    return report;
}

void WindowBa::holdFilterGauge() {
    // The first window's adjustment in the filter's frame and unit: the Sim(3)
    // from the adjusted keyframes to the filter's, applied to them.
    sim_from_.clear();
    sim_to_.clear();
    for (int i = 0; i < count_; ++i) {
        sim_from_.push_back(keyframe(i).adjusted.p_CinW);
        sim_to_.push_back(keyframe(i).filter.p_CinW);
    }
    const auto a = fitSim3(sim_from_, sim_to_);
    if (!a) {
        return;
    }
    for (int i = 0; i < count_; ++i) {
        Keyframe& kf = keyframe(i);
        kf.adjusted.p_CinW = a->scale * a->R * kf.adjusted.p_CinW + a->t;
        kf.adjusted.R_CtoW = a->R * kf.adjusted.R_CtoW;
    }
}

Scalar WindowBa::scaleOfFreeKeyframes(int first_free) {
    // Umeyama over the free keyframes and the newest fixed one: adjusted ~=
    // s R filter + t. s > 1: the filter's recent unit is too small.
    std::vector<Vec3>& from = sim_from_;
    std::vector<Vec3>& to = sim_to_;
    from.clear();
    to.clear();
    for (int i = first_free - 1; i < count_; ++i) {
        from.push_back(keyframe(i).filter.p_CinW);
        to.push_back(keyframe(i).adjusted.p_CinW);
    }
    const auto a = fitSim3(from, to);
    return a ? a->scale : Scalar(1);
}

int WindowBa::findOrAddPoint(std::uint64_t id) {
    for (int k = 0; k < point_count_; ++k) {
        if (points_[static_cast<size_t>(k)].id == id) {
            return k;
        }
    }
    if (point_count_ == config_.max_points) {
        return -1;
    }
    Point& pt = points_[static_cast<size_t>(point_count_)];
    pt = Point{};
    pt.id = id;
    return point_count_++;
}

void WindowBa::gatherPoints(int first_free) {
    point_count_ = 0;
    for (int i = 0; i < count_; ++i) {
        const Keyframe& kf = keyframe(i);
        for (int j = 0; j < kf.obs_count; ++j) {
            const FeatureObservation& o = obs_[obsIndex(i, j)];
            const int k = findOrAddPoint(o.id);
            obs_point_[obsIndex(i, j)] = k;
            if (k < 0) {
                continue;
            }
            Point& pt = points_[static_cast<size_t>(k)];
            if (pt.views == 0) {
                pt.first_kf = i;
            }
            pt.last_kf = i;
            views_[static_cast<size_t>(k) * static_cast<size_t>(capacity_) +
                   static_cast<size_t>(pt.views)] = {i, j};
            ++pt.views;
        }
    }
    usable_points_ = 0;
    for (int k = 0; k < point_count_; ++k) {
        Point& pt = points_[static_cast<size_t>(k)];
        pt.usable = pt.views >= config_.min_views && pt.last_kf >= first_free && triangulate(pt);
        usable_points_ += pt.usable ? 1 : 0;
    }
    usable_observations_ = 0;
    for (int i = 0; i < count_; ++i) {
        for (int j = 0; j < keyframe(i).obs_count; ++j) {
            const int k = obs_point_[obsIndex(i, j)];
            usable_observations_ += k >= 0 && points_[static_cast<size_t>(k)].usable ? 1 : 0;
        }
    }
}

bool WindowBa::triangulate(Point& pt) {
    // Least squares over the rays of every view: sum (I - r r^T)(X - p) = 0.
    Eigen::Matrix<Scalar, 4, 4> A = Eigen::Matrix<Scalar, 4, 4>::Zero();
    Vec3 first_ray = Vec3::Zero();
    Vec3 last_ray = Vec3::Zero();
    for (const View& v : viewsOf(pt)) {
        const Keyframe& kf = keyframe(v.kf);
        const auto ray_C = camera_.unproject(obs_[obsIndex(v.kf, v.j)].z_px);
        if (!ray_C) {
            return false;
        }
        const RowMotion m = rowMotion(kf, obs_[obsIndex(v.kf, v.j)].z_px);
        const Vec3 ray = (kf.adjusted.R_CtoW * (m.E.transpose() * *ray_C)).normalized();
        const Vec3 origin = kf.adjusted.p_CinW + kf.adjusted.R_CtoW * m.shift_C;
        if (v.kf == pt.first_kf) {
            first_ray = ray;
        }
        last_ray = ray;
        const Mat3 M = Mat3::Identity() - ray * ray.transpose();
        Eigen::Matrix<Scalar, 3, 4> Ai;
        Ai.leftCols<3>() = M;
        Ai.col(3) = -M * origin;
        A.noalias() += Ai.transpose() * Ai;
    }
    const Scalar parallax = std::acos(std::clamp(first_ray.dot(last_ray), Scalar(-1), Scalar(1)));
    if (!(parallax >= config_.min_parallax_rad)) {
        return false;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<Scalar, 4, 4>> es(A);
    const Eigen::Matrix<Scalar, 4, 1> h = es.eigenvectors().col(0);
    if (!(std::abs(h(3)) > Scalar(1e-9))) {
        return false;
    }
    pt.p_W = h.head<3>() / h(3);
    for (const int i : {pt.first_kf, pt.last_kf}) {
        const Keyframe& kf = keyframe(i);
        if (!((kf.adjusted.R_CtoW.transpose() * (pt.p_W - kf.adjusted.p_CinW)).z() > 0)) {
            return false;
        }
    }
    return pt.p_W.allFinite();
}

Scalar WindowBa::cost() const {
    Scalar c = 0;
    for (int i = 0; i < count_; ++i) {
        const Keyframe& kf = keyframe(i);
        for (int j = 0; j < kf.obs_count; ++j) {
            const int k = obs_point_[obsIndex(i, j)];
            if (k < 0 || !points_[static_cast<size_t>(k)].usable) {
                continue;
            }
            const Vec2& z = obs_[obsIndex(i, j)].z_px;
            const RowMotion m = rowMotion(kf, z);
            const Vec3 p_C = m.E * (kf.adjusted.R_CtoW.transpose() *
                                        (points_[static_cast<size_t>(k)].p_W - kf.adjusted.p_CinW) -
                                    m.shift_C);
            const auto px = camera_.project(p_C);
            if (!px) {
                c += 100 * config_.huber_px * config_.huber_px;
                continue;
            }
            c += huberCost((*px - z).norm(), config_.huber_px);
        }
    }
    return c + priorCost();
}

Scalar WindowBa::priorCost() const {
    Scalar c = 0;
    if (estimate_readout_) {
        const Scalar e = (readout_s_ - config_.rolling_shutter_s) / config_.rolling_shutter_sigma_s;
        c += e * e;
    }
    if (estimate_focal_) {
        const Scalar e = (focal_scale_ - 1) / config_.focal_sigma_rel;
        c += e * e;
    }
    if (estimate_k1_) {
        const Scalar e = (k1_ - camera_given_.intrinsics().k1) / config_.k1_sigma;
        c += e * e;
    }
    return c;
}

bool WindowBa::setCameraEstimate(Scalar focal_scale, Scalar k1) {
    CameraIntrinsics k = camera_given_.intrinsics();
    k.fx *= focal_scale;
    k.fy *= focal_scale;
    k.k1 = k1;
    auto c = PinholeRadialCamera::create(k);  // focal_max_rel keeps the factor > 0
    if (!c) {
        return false;
    }
    camera_ = *c;
    focal_scale_ = focal_scale;
    k1_ = k1;
    return true;
}

void WindowBa::globalRows(int first_free, Eigen::Index (&rows)[kGlobals],
                          bool (&active)[kGlobals]) const {
    active[0] = estimate_focal_;
    active[1] = estimate_k1_;
    active[2] = estimate_readout_;
    Eigen::Index r = 6 * Eigen::Index{count_ - first_free};
    for (int a = 0; a < kGlobals; ++a) {
        rows[a] = r;
        r += active[a] ? 1 : 0;
    }
}

void WindowBa::accumulateView(int i, int j, int first_free) {
    const Keyframe& kf = keyframe(i);
    const int k = obs_point_[obsIndex(i, j)];
    const auto pk = static_cast<size_t>(k);
    const Vec2& z = obs_[obsIndex(i, j)].z_px;
    const RowMotion m = rowMotion(kf, z);
    // p_C in the keyframe's camera; the row's camera sees E (p_C - shift_C).
    const Vec3 p_C = kf.adjusted.R_CtoW.transpose() * (points_[pk].p_W - kf.adjusted.p_CinW);
    Mat23 J_px;
    const Vec3 p_row = m.E * (p_C - m.shift_C);
    const auto px = camera_.project(p_row, &J_px);
    if (!px) {
        return;
    }
    // d pixel / d readout time: the row's camera moves on by d = t y / (H - 1)
    // seconds, p_row by -(w x p_row) - E (unit v) per second.
    // d pixel / d focal factor s (fx = s fx0): (pixel - centre) / s;
    // d pixel / d k1: f x_u r_u^2 (x_d = x_u (1 + k1 r_u^2 + k2 r_u^4)).
    Eigen::Matrix<Scalar, 2, kGlobals> J_g = Eigen::Matrix<Scalar, 2, kGlobals>::Zero();
    const CameraIntrinsics& ki = camera_.intrinsics();
    if (estimate_focal_) {
        J_g.col(0) = (*px - Vec2(ki.cx, ki.cy)) / focal_scale_;
    }
    if (estimate_k1_) {
        const Vec2 x_u = p_row.head<2>() / p_row.z();
        J_g.col(1) = Vec2(ki.fx * x_u.x(), ki.fy * x_u.y()) * x_u.squaredNorm();
    }
    if (estimate_readout_) {
        J_g.col(2) = J_px * (-kf.w_C.cross(p_row) - m.E * (unit_ratio_ * kf.v_C)) *
                     (z.y() / Scalar(std::max(1, camera_.height() - 1)));
    }
    J_px = J_px * m.E;  // d pixel / d p_C
    const Vec2 r = *px - z;
    const Scalar e = r.norm();
    const Scalar w = e < config_.huber_px ? Scalar(1) : config_.huber_px / e;
    const Mat23 J_X = J_px * kf.adjusted.R_CtoW.transpose();
    H_ll_[pk].noalias() += w * J_X.transpose() * J_X;
    b_l_[pk].noalias() -= w * J_X.transpose() * r;
    Eigen::Index rows[kGlobals];
    bool active[kGlobals];
    globalRows(first_free, rows, active);
    for (int a = 0; a < kGlobals; ++a) {
        if (!active[a]) {
            continue;
        }
        for (int b = 0; b <= a; ++b) {  // the lower triangle
            if (active[b]) {
                H_pp_(rows[a], rows[b]) += w * J_g.col(a).dot(J_g.col(b));
            }
        }
        b_p_(rows[a]) -= w * J_g.col(a).dot(r);
        W_g_[pk].col(a).noalias() += w * J_X.transpose() * J_g.col(a);
    }
    if (i < first_free) {
        return;
    }
    Eigen::Matrix<Scalar, 2, 6> J_c;
    J_c.leftCols<3>() = -J_X;               // d / d p_CinW
    J_c.rightCols<3>() = J_px * skew(p_C);  // d / d theta, R_CtoW <- R_CtoW Exp(theta)
    const Eigen::Index c6 = 6 * Eigen::Index{i - first_free};
    H_pp_.block<6, 6>(c6, c6).noalias() += w * J_c.transpose() * J_c;
    b_p_.segment<6>(c6).noalias() -= w * J_c.transpose() * r;
    W_[obsIndex(i, j)].noalias() = w * J_c.transpose() * J_X;
    for (int a = 0; a < kGlobals; ++a) {
        if (active[a]) {
            // The lower triangle: the global's row, the pose's columns.
            H_pp_.block<1, 6>(rows[a], c6).noalias() += w * J_g.col(a).transpose() * J_c;
        }
    }
}

Eigen::Index WindowBa::denseDim(int first_free) const {
    return 6 * Eigen::Index{count_ - first_free} + globalCount();
}

void WindowBa::accumulate(int first_free) {
    const Eigen::Index n_free = denseDim(first_free);
    H_pp_.topLeftCorner(n_free, n_free).setZero();
    b_p_.head(n_free).setZero();
    for (int k = 0; k < point_count_; ++k) {
        H_ll_[static_cast<size_t>(k)].setZero();
        b_l_[static_cast<size_t>(k)].setZero();
        W_g_[static_cast<size_t>(k)].setZero();
    }
    Eigen::Index rows[kGlobals];
    bool active[kGlobals];
    globalRows(first_free, rows, active);
    if (estimate_focal_) {
        // Its prior: at the camera's given focal length.
        const Scalar inv_var = 1 / (config_.focal_sigma_rel * config_.focal_sigma_rel);
        H_pp_(rows[0], rows[0]) = inv_var;
        b_p_(rows[0]) = -inv_var * (focal_scale_ - 1);
    }
    if (estimate_k1_) {
        // Its prior: at the camera's given k1.
        const Scalar inv_var = 1 / (config_.k1_sigma * config_.k1_sigma);
        H_pp_(rows[1], rows[1]) = inv_var;
        b_p_(rows[1]) = -inv_var * (k1_ - camera_given_.intrinsics().k1);
    }
    if (estimate_readout_) {
        // Its prior: at the given readout time.
        const Scalar inv_var =
            1 / (config_.rolling_shutter_sigma_s * config_.rolling_shutter_sigma_s);
        H_pp_(n_free - 1, n_free - 1) = inv_var;
        b_p_(n_free - 1) = -inv_var * (readout_s_ - config_.rolling_shutter_s);
    }
    for (int i = 0; i < count_; ++i) {
        for (int j = 0; j < keyframe(i).obs_count; ++j) {
            const int k = obs_point_[obsIndex(i, j)];
            W_[obsIndex(i, j)].setZero();
            if (k >= 0 && points_[static_cast<size_t>(k)].usable) {
                accumulateView(i, j, first_free);
            }
        }
    }
}

void WindowBa::schurComplement(int first_free, Scalar lambda) {
    // S = H_pp - sum_points W H_ll^-1 W^T, g = b_p - sum W H_ll^-1 b_l, on
    // the free poses' part of the buffers.
    const Eigen::Index n_free = denseDim(first_free);
    Eigen::Index rows[kGlobals];
    bool active[kGlobals];
    globalRows(first_free, rows, active);
    S_.topLeftCorner(n_free, n_free) = H_pp_.topLeftCorner(n_free, n_free);
    g_.head(n_free) = b_p_.head(n_free);
    for (Eigen::Index d = 0; d < n_free; ++d) {
        S_(d, d) = S_(d, d) * (1 + lambda) + Scalar(1e-9);
    }
    for (int k = 0; k < point_count_; ++k) {
        const auto pk = static_cast<size_t>(k);
        if (!points_[pk].usable) {
            continue;
        }
        Mat3 H = H_ll_[pk];
        H.diagonal() *= 1 + lambda;
        H.diagonal().array() += Scalar(1e-9);
        H_ll_inv_[pk] = H.inverse();
        const auto views = viewsOf(points_[pk]);
        for (int a = 0; a < kGlobals; ++a) {
            if (!active[a]) {
                continue;
            }
            const Vec3 V_g = H_ll_inv_[pk] * W_g_[pk].col(a);  // H_ll^-1 symmetric
            g_(rows[a]) -= V_g.dot(b_l_[pk]);
            for (int b = 0; b <= a; ++b) {
                if (active[b]) {
                    S_(rows[a], rows[b]) -= V_g.dot(W_g_[pk].col(b));
                }
            }
            for (const View& b : views) {
                if (b.kf >= first_free) {
                    const Eigen::Index cb = 6 * Eigen::Index{b.kf - first_free};
                    S_.block<1, 6>(rows[a], cb).noalias() -=
                        V_g.transpose() * W_[obsIndex(b.kf, b.j)].transpose();
                }
            }
        }
        for (const View& a : views) {
            if (a.kf < first_free) {
                continue;
            }
            const Eigen::Matrix<Scalar, 6, 3> V = W_[obsIndex(a.kf, a.j)] * H_ll_inv_[pk];
            const Eigen::Index ca = 6 * Eigen::Index{a.kf - first_free};
            g_.segment<6>(ca).noalias() -= V * b_l_[pk];
            // The lower triangle only (the Cholesky reads no more): views
            // are in keyframe order, so b up to a.
            for (const View& b : views) {
                if (b.kf > a.kf) {
                    break;
                }
                if (b.kf >= first_free) {
                    const Eigen::Index cb = 6 * Eigen::Index{b.kf - first_free};
                    S_.block<6, 6>(ca, cb).noalias() -= V * W_[obsIndex(b.kf, b.j)].transpose();
                }
            }
        }
    }
}

std::span<const WindowBa::View> WindowBa::viewsOf(const Point& pt) const {
    const auto k = static_cast<size_t>(&pt - points_.data());
    return {views_.data() + k * static_cast<size_t>(capacity_), static_cast<size_t>(pt.views)};
}

bool WindowBa::step(int first_free) {
    // iterate() has kept the readout time's step within its bounds; the
    // focal factor's and k1's are clamped here, and the points take the
    // clamped steps (the poses keep theirs: the cost decides).
    Eigen::Index rows[kGlobals];
    bool active[kGlobals];
    globalRows(first_free, rows, active);
    Eigen::Matrix<Scalar, kGlobals, 1> dg = Eigen::Matrix<Scalar, kGlobals, 1>::Zero();
    for (int a = 0; a < kGlobals; ++a) {
        dg(a) = active[a] ? dx_p_(rows[a]) : Scalar(0);
    }
    readout_s_ += dg(2);
    if (estimate_focal_ || estimate_k1_) {
        const Scalar hi = 1 + config_.focal_max_rel;
        const Scalar k1_given = camera_given_.intrinsics().k1;
        const Scalar s = std::clamp(focal_scale_ + dg(0), 1 / hi, hi);
        const Scalar k1 = std::clamp(k1_ + dg(1), k1_given - config_.k1_max_change,
                                     k1_given + config_.k1_max_change);
        dg(0) = s - focal_scale_;
        dg(1) = k1 - k1_;
        if (!std::isfinite(s) || !std::isfinite(k1) || !setCameraEstimate(s, k1)) {
            return false;  // no camera for that step: iterate() restores the state
        }
    }
    for (int i = first_free; i < count_; ++i) {
        Keyframe& kf = keyframe(i);
        const Eigen::Index c6 = 6 * Eigen::Index{i - first_free};
        kf.adjusted.p_CinW += dx_p_.segment<3>(c6);
        kf.adjusted.R_CtoW =
            kf.adjusted.R_CtoW * rotationFromQuat(quatFromRotationVector(dx_p_.segment<3>(c6 + 3)));
    }
    for (int k = 0; k < point_count_; ++k) {
        const auto pk = static_cast<size_t>(k);
        Point& pt = points_[pk];
        if (!pt.usable) {
            continue;
        }
        Vec3 rhs = b_l_[pk];
        for (int a = 0; a < kGlobals; ++a) {
            if (active[a]) {
                rhs -= W_g_[pk].col(a) * dg(a);
            }
        }
        for (const View& a : viewsOf(pt)) {
            if (a.kf >= first_free) {
                rhs.noalias() -= W_[obsIndex(a.kf, a.j)].transpose() *
                                 dx_p_.segment<6>(6 * Eigen::Index{a.kf - first_free});
            }
        }
        pt.p_W += H_ll_inv_[pk] * rhs;
    }
    return true;
}

bool WindowBa::iterate(int first_free, Scalar& lambda, Scalar& c) {
    accumulate(first_free);
    schurComplement(first_free, lambda);
    // Cholesky in place on the free part (no allocation); not positive
    // definite: more damping.
    const Eigen::Index n_free = denseDim(first_free);
    Eigen::Ref<MatX> S = S_.topLeftCorner(n_free, n_free);
    const Eigen::LLT<Eigen::Ref<MatX>> llt(S);
    if (llt.info() != Eigen::Success) {
        lambda *= 5;
        return false;
    }
    auto dx = dx_p_.head(n_free);
    dx = g_.head(n_free);
    llt.solveInPlace(dx);
    if (estimate_readout_) {
        // A readout time stepping past +-rolling_shutter_max_s is held at the
        // bound (negative: the last row is read first), and
        // the poses take their step for that: with S = L L^T, L = [L_p 0;
        // l^T l_t], the poses' part of S dx = g at a fixed dt is
        // L_p L_p^T dx_p = g_p - L_p l dt.
        const Eigen::Index t = n_free - 1;
        const Scalar held = std::clamp(readout_s_ + dx(t), -config_.rolling_shutter_max_s,
                                       config_.rolling_shutter_max_s);
        if (held != readout_s_ + dx(t)) {
            const Scalar dt = held - readout_s_;
            auto dx_p = dx.head(t);
            const auto L_p = S.topLeftCorner(t, t).triangularView<Eigen::Lower>();
            dx_p = g_.head(t);
            L_p.solveInPlace(dx_p);
            dx_p.noalias() -= S.row(t).head(t).transpose() * dt;
            L_p.transpose().solveInPlace(dx_p);
            dx(t) = dt;
        }
    }
    for (int i = 0; i < count_; ++i) {
        saved_keyframes_[static_cast<size_t>(i)] = keyframe(i);
    }
    std::copy_n(points_.begin(), point_count_, saved_points_.begin());
    saved_readout_s_ = readout_s_;
    saved_focal_scale_ = focal_scale_;
    saved_k1_ = k1_;
    const bool stepped = step(first_free);
    const Scalar c_new = stepped ? cost() : c;
    if (stepped && std::isfinite(c_new) && c_new < c) {
        c = c_new;
        lambda = std::max(Scalar(1e-7), lambda / 3);
        return true;
    }
    for (int i = 0; i < count_; ++i) {
        keyframe(i) = saved_keyframes_[static_cast<size_t>(i)];
    }
    std::copy_n(saved_points_.begin(), point_count_, points_.begin());
    readout_s_ = saved_readout_s_;
    if (estimate_focal_ || estimate_k1_) {
        (void)setCameraEstimate(saved_focal_scale_, saved_k1_);
    }
    lambda *= 5;
    return false;
}

}  // namespace scaled::core::slam
