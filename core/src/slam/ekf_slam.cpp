#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <scaled/core/slam/column_dots.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/quaternion.h>

namespace scaled::core::slam {

namespace {

Error fieldError(const char* field, Scalar value, const std::string& allowed) {
    return makeError(
        ErrorCode::kInvalidArgument,
        std::string("slam.") + field + " = " + std::to_string(value) + ": must be " + allowed);
}

// The first parameter outside its SlamLimits, named.
std::optional<Error> outOfLimits(const SlamConfig& c) {
    using L = SlamLimits;
    const LimitCheck checks[] = {
        {"sigma_a", static_cast<double>(c.motion.sigma_a), L::sigma_a},
        {"sigma_alpha", static_cast<double>(c.motion.sigma_alpha), L::sigma_alpha},
        {"sigma_a_reference_hz", static_cast<double>(c.motion.reference_hz),
         L::sigma_a_reference_hz},
        {"pixel_sigma_px", static_cast<double>(c.pixel_sigma_px), L::pixel_sigma_px},
        {"init_sigma_v", static_cast<double>(c.init_sigma_v), L::init_sigma_v},
        {"init_sigma_w", static_cast<double>(c.init_sigma_w), L::init_sigma_w},
        {"rho0", static_cast<double>(c.rho0), L::rho0},
        {"sigma_rho", static_cast<double>(c.sigma_rho), L::sigma_rho},
        {"linearity_threshold", static_cast<double>(c.linearity_threshold), L::linearity_threshold},
        {"max_features", static_cast<double>(c.max_features), L::max_features},
        {"max_measured", static_cast<double>(c.max_measured), L::max_measured},
        {"min_visible", static_cast<double>(c.min_visible), L::min_visible},
        {"image_margin_px", static_cast<double>(c.image_margin_px), L::image_margin_px},
        {"chi2_gate", static_cast<double>(c.chi2_gate), L::chi2_gate},
        {"ransac_threshold_px", static_cast<double>(c.ransac_threshold_px), L::ransac_threshold_px},
        {"ransac_confidence", static_cast<double>(c.ransac_confidence), L::ransac_confidence},
        {"ransac_min_hypotheses", static_cast<double>(c.ransac_min_hypotheses),
         L::ransac_min_hypotheses},
        {"ransac_max_hypotheses", static_cast<double>(c.ransac_max_hypotheses),
         L::ransac_max_hypotheses},
        {"delete_min_attempts", static_cast<double>(c.delete_min_attempts), L::delete_min_attempts},
        {"delete_min_ratio", static_cast<double>(c.delete_min_ratio), L::delete_min_ratio},
        {"min_inliers", static_cast<double>(c.min_inliers), L::min_inliers},
        {"lost_after_frames", static_cast<double>(c.lost_after_frames), L::lost_after_frames},
        {"max_dt_s", static_cast<double>(c.max_dt_s), L::max_dt_s},
    };
    if (const LimitCheck* bad = firstOutside(checks)) {
        return fieldError(bad->name, static_cast<Scalar>(bad->value), bad->limits.text());
    }
    return std::nullopt;
}

}  // namespace

Status validate(const SlamConfig& c) {
    if (auto bad = outOfLimits(c)) {
        return *bad;
    }
    if (c.max_measured > c.max_features) {
        return fieldError("max_measured", Scalar(c.max_measured), "in [1, max_features]");
    }
    if (c.min_visible > c.max_features) {
        return fieldError("min_visible", Scalar(c.min_visible), "in [0, max_features]");
    }
    if (c.ransac_min_hypotheses > c.ransac_max_hypotheses) {
        return fieldError("ransac_min_hypotheses", Scalar(c.ransac_min_hypotheses),
                          "in [1, ransac_max_hypotheses]");
    }
    return {};
}

const char* toString(SlamHealth health) {
    switch (health) {
        case SlamHealth::kUninitialised:
            return "uninitialised";
        case SlamHealth::kOk:
            return "ok";
        case SlamHealth::kNonFinite:
            return "non-finite state";
        case SlamHealth::kNotPositiveDefinite:
            return "covariance not positive definite";
        case SlamHealth::kLost:
            return "lost";
        case SlamHealth::kBadTimestamp:
            return "bad timestamp";
        case SlamHealth::kRelocalising:
            return "relocalising";
    }
    return "unknown";
}

Result<EkfSlam> EkfSlam::create(const PinholeRadialCamera& camera, const SlamConfig& config) {
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    return EkfSlam(camera, config);
}

EkfSlam::EkfSlam(const PinholeRadialCamera& camera, const SlamConfig& config)
    : camera_(camera),
      config_(config),
      capacity_(kCameraDim + 6 * config.max_features),
      x_(VecX::Zero(capacity_)),
      P_(MatX::Zero(capacity_, capacity_)),
      PHt_(MatX::Zero(capacity_, 2 * Eigen::Index{config.max_measured})),
      S_(MatX::Zero(2 * Eigen::Index{config.max_measured}, 2 * Eigen::Index{config.max_measured})),
      nu_(VecX::Zero(2 * Eigen::Index{config.max_measured})),
      Wt_(MatX::Zero(2 * Eigen::Index{config.max_measured}, capacity_)),
      x_hyp_(VecX::Zero(capacity_)),
      rows_(MatX::Zero(6, capacity_)) {
    features_.reserve(static_cast<size_t>(config.max_features));
    predictions_.reserve(static_cast<size_t>(config.max_measured));
    cand_.reserve(static_cast<size_t>(config.max_measured));
    inliers_.reserve(static_cast<size_t>(config.max_measured));
    best_inliers_.reserve(static_cast<size_t>(config.max_measured));
    accepted_.reserve(static_cast<size_t>(config.max_measured));
    observations_.reserve(static_cast<size_t>(config.max_measured) +
                          static_cast<size_t>(config.max_features));
}

void EkfSlam::initialise(std::int64_t t_ns, const Vec3& gravity_down_C) {
    n_ = kCameraDim;
    x_.setZero();
    P_.setZero();
    x_(kQuat) = 1;
    const Scalar var_v = config_.init_sigma_v * config_.init_sigma_v;
    const Scalar var_w = config_.init_sigma_w * config_.init_sigma_w;
    P_.block<3, 3>(kVel, kVel) = Mat3::Identity() * var_v;
    P_.block<3, 3>(kAngVel, kAngVel) = Mat3::Identity() * var_w;
    features_.clear();
    predictions_.clear();
    cand_.clear();
    observations_.clear();
    up_W_ = -gravity_down_C.normalized();
    t_ns_ = t_ns;
    frame_ = 0;
    bad_frames_ = 0;
    visible_count_ = 0;
    rng_ = config_.seed * 0x9E3779B97F4A7C15ULL + 1;
    health_ = SlamHealth::kOk;
}

std::uint64_t EkfSlam::nextRandom() {
    // xorshift64*: deterministic on every platform.
    rng_ ^= rng_ >> 12;
    rng_ ^= rng_ << 25;
    rng_ ^= rng_ >> 27;
    return rng_ * 0x2545F4914F6CDD1DULL;
}

SlamHealth EkfSlam::predict(std::int64_t t_ns, const GyroRate* gyro) {
    if (health_ == SlamHealth::kUninitialised) {
        return health_;
    }
    const Scalar dt = Scalar(t_ns - t_ns_) * Scalar(1e-9);
    if (!(dt > 0) || dt > config_.max_dt_s) {
        return SlamHealth::kBadTimestamp;
    }
    observations_.clear();
    MotionNoise noise = config_.motion;
    if (gyro != nullptr && gyro->w_C_radps.allFinite() && std::isfinite(gyro->sigma_radps) &&
        gyro->sigma_radps > 0) {
        // The gyro replaces the angular velocity: its mean, its variance, no
        // correlation with the rest; F then carries that variance into the
        // rotation (d q' / d w), and no impulse W is added on top.
        x_.segment<3>(kAngVel) = gyro->w_C_radps;
        P_.block(kAngVel, 0, 3, n_).setZero();
        P_.block(0, kAngVel, n_, 3).setZero();
        P_.block<3, 3>(kAngVel, kAngVel) =
            Mat3::Identity() * (gyro->sigma_radps * gyro->sigma_radps);
        noise.sigma_alpha = 0;
    }
    Mat13 F;
    Mat13 Q;
    const Vec13 xc = x_.head<kCameraDim>();
    x_.head<kCameraDim>() = predictCamera(xc, dt, noise, &F, &Q);
    // P_cc = F P_cc F^T + Q, P_cf = F P_cf.
    // F P_cf column by column (allocation-free), mirrored into P_fc.
    for (int j = kCameraDim; j < n_; ++j) {
        const Vec13 col = P_.block<kCameraDim, 1>(0, j);
        P_.block<kCameraDim, 1>(0, j) = F * col;
        P_.block<1, kCameraDim>(j, 0) = P_.block<kCameraDim, 1>(0, j).transpose();
    }
    const Mat13 Pcc = P_.topLeftCorner<kCameraDim, kCameraDim>();
    P_.topLeftCorner<kCameraDim, kCameraDim>() = F * Pcc * F.transpose() + Q;
    t_ns_ = t_ns;
    ++frame_;
    return health_;
}

bool EkfSlam::projectSlot(const VecX& x, int slot, bool jacobians, FeatureProjection& out) const {
    const FeatureInfo& f = features_[static_cast<size_t>(slot)];
    const Vec3 r = x.segment<3>(kPos);
    const Vec4 q = x.segment<4>(kQuat);
    auto p = projectFeature(camera_, r, q, f.kind, x.data() + f.offset, jacobians);
    if (!p) {
        return false;
    }
    out = *p;
    return true;
}

Mat2 EkfSlam::innovationCovariance(int slot, const FeatureProjection& proj) const {
    const FeatureInfo& f = features_[static_cast<size_t>(slot)];
    const auto Ppp = P_.topLeftCorner<kPoseDim, kPoseDim>();
    Mat2 S = proj.H_pose * Ppp * proj.H_pose.transpose();
    Mat2 cross;
    if (f.kind == FeatureKind::kInverseDepth) {
        const Mat26& Hf = proj.H_feature;
        cross = proj.H_pose * P_.block<kPoseDim, 6>(0, f.offset) * Hf.transpose();
        S += Hf * P_.block<6, 6>(f.offset, f.offset) * Hf.transpose();
    } else {
        const Mat23 Hf = proj.H_feature.leftCols<3>();
        cross = proj.H_pose * P_.block<kPoseDim, 3>(0, f.offset) * Hf.transpose();
        S += Hf * P_.block<3, 3>(f.offset, f.offset) * Hf.transpose();
    }
    S += cross + cross.transpose();
    S.diagonal().array() += config_.pixel_sigma_px * config_.pixel_sigma_px;
    return S;
}

std::span<const FeaturePrediction> EkfSlam::predictMeasurements() {
    predictions_.clear();
    visible_count_ = 0;
    const Scalar margin = config_.image_margin_px;
    const Scalar w = Scalar(camera_.width()) - 1 - margin;
    const Scalar h = Scalar(camera_.height()) - 1 - margin;
    FeatureProjection proj;
    for (int s = 0; s < static_cast<int>(features_.size()); ++s) {
        FeatureInfo& f = features_[static_cast<size_t>(s)];
        f.in_view = false;
        f.measured = false;
        // Jacobians only for features that will be searched.
        const bool searched = static_cast<int>(predictions_.size()) < config_.max_measured;
        if (!projectSlot(x_, s, searched, proj)) {
            continue;
        }
        const Vec2& u = proj.h_px;
        if (u.x() < margin || u.y() < margin || u.x() > w || u.y() > h) {
            continue;
        }
        f.in_view = true;
        f.px = u;
        f.last_seen_frame = frame_;
        ++visible_count_;
        if (searched) {
            FeaturePrediction p;
            p.slot = s;
            p.id = f.id;
            p.h_px = u;
            p.S = innovationCovariance(s, proj);
            predictions_.push_back(p);
        }
    }
    return predictions_;
}

// flatten: choleskyInnovation and downdateCovariance are compiled into this
// function, as they were before they were split out: called, they made the
// update 5-7% slower at 50-100 features (slam_bench TrackerSynthetic).
[[gnu::flatten]] bool EkfSlam::ekfUpdate(int count) {
    if (count <= 0) {
        return true;
    }
    const Eigen::Index m = 2 * Eigen::Index{count};
    auto PHt = PHt_.topLeftCorner(n_, m);
    auto S = S_.topLeftCorner(m, m);
    auto nu = nu_.head(m);
    // P H^T, using the sparsity of H: pose columns and the feature's columns.
    for (Eigen::Index i = 0; i < count; ++i) {
        const Candidate& c = cand_[static_cast<size_t>(inliers_[static_cast<size_t>(i)])];
        const FeatureInfo& f = features_[static_cast<size_t>(c.slot)];
        const int d = dimOf(f.kind);
        PHt.middleCols<2>(2 * i).noalias() =
            P_.topLeftCorner(n_, kPoseDim) * c.proj.H_pose.transpose();
        PHt.middleCols<2>(2 * i).noalias() +=
            P_.block(0, f.offset, n_, d) * c.proj.H_feature.leftCols(d).transpose();
        nu.segment<2>(2 * i) = c.z - c.proj.h_px;
    }
    // S = H P H^T + R.
    for (Eigen::Index i = 0; i < count; ++i) {
        const Candidate& c = cand_[static_cast<size_t>(inliers_[static_cast<size_t>(i)])];
        const FeatureInfo& f = features_[static_cast<size_t>(c.slot)];
        const int d = dimOf(f.kind);
        S.middleRows<2>(2 * i).noalias() = c.proj.H_pose * PHt.topRows<kPoseDim>();
        S.middleRows<2>(2 * i).noalias() +=
            c.proj.H_feature.leftCols(d) * PHt.middleRows(f.offset, d);
    }
    S.diagonal().array() += config_.pixel_sigma_px * config_.pixel_sigma_px;
    // The factorisation, the solves and the covariance downdate are written as
    // plain loops over contiguous columns: Eigen's blocked LLT, triangular
    // solve and rankUpdate malloc() their workspace once m reaches its
    // blocking size (tests/integration/steady_state_alloc_test.cpp counts it).
    if (!choleskyInnovation(m)) {
        return false;
    }
    // Wt = L^-1 (P H^T)^T, column r = L^-1 (row r of P H^T): then K nu = Wt^T L^-1 nu
    // and K S K^T = Wt^T Wt. Forward substitution by columns of L (contiguous).
    auto Wt = Wt_.topLeftCorner(m, n_);
    Wt = PHt.transpose();
    for (Eigen::Index r = 0; r < n_; ++r) {
        auto w = Wt.col(r);
        for (Eigen::Index i = 0; i < m; ++i) {
            w(i) /= S(i, i);
            w.segment(i + 1, m - i - 1) -= w(i) * S.col(i).segment(i + 1, m - i - 1);
        }
    }
    // L^-1 nu, the same way.
    for (Eigen::Index i = 0; i < m; ++i) {
        nu(i) /= S(i, i);
        nu.segment(i + 1, m - i - 1) -= nu(i) * S.col(i).segment(i + 1, m - i - 1);
    }
    for (Eigen::Index r = 0; r < n_; ++r) {
        x_(r) += Wt.col(r).dot(nu);
    }
    downdateCovariance(m);
    symmetrize();
    return true;
}

bool EkfSlam::choleskyInnovation(Eigen::Index m) {
    auto S = S_.topLeftCorner(m, m);
    // In-place Cholesky S = L L^T (lower triangle; S's upper part is not read).
    for (Eigen::Index j = 0; j < m; ++j) {
        Scalar d = S(j, j);
        for (Eigen::Index k = 0; k < j; ++k) {
            d -= S(j, k) * S(j, k);
        }
        if (!(d > 0) || !std::isfinite(d)) {
            return false;
        }
        const Scalar l_jj = std::sqrt(d);
        S(j, j) = l_jj;
        for (Eigen::Index i = j + 1; i < m; ++i) {
            Scalar v = Scalar(0.5) * (S(i, j) + S(j, i));  // symmetrise round-off
            for (Eigen::Index k = 0; k < j; ++k) {
                v -= S(i, k) * S(j, k);
            }
            S(i, j) = v / l_jj;
        }
    }
    return true;
}

void EkfSlam::downdateCovariance(Eigen::Index m) {
    auto Wt = Wt_.topLeftCorner(m, n_);
    // P -= Wt^T Wt on the lower triangle, mirrored by symmetrize(): four
    // columns j at a time, each element the same sum as Wt.col(i).dot(Wt.col(j))
    // (detail::columnDots).
    constexpr std::size_t kCols = 4;
    constexpr auto kColsI = static_cast<Eigen::Index>(kCols);
    Eigen::Index j0 = 0;
    for (; j0 + kColsI <= n_; j0 += kColsI) {
        const Scalar* const cols[kCols] = {Wt.col(j0).data(), Wt.col(j0 + 1).data(),
                                           Wt.col(j0 + 2).data(), Wt.col(j0 + 3).data()};
        for (Eigen::Index i = j0; i < n_; ++i) {
            Scalar dots[kCols];
            detail::columnDots<kCols>(Wt.col(i).data(), cols, m, dots);
            for (Eigen::Index j = j0; j < j0 + kColsI && j <= i; ++j) {
                P_(i, j) -= dots[static_cast<std::size_t>(j - j0)];
            }
        }
    }
    for (; j0 < n_; ++j0) {  // the last n mod 4 columns
        for (Eigen::Index i = j0; i < n_; ++i) {
            P_(i, j0) -= Wt.col(i).dot(Wt.col(j0));
        }
    }
}

void EkfSlam::symmetrize() {
    for (int j = 0; j < n_; ++j) {
        for (int i = 0; i < j; ++i) {
            P_(i, j) = P_(j, i);
        }
    }
}

UpdateReport EkfSlam::update(std::span<const FeatureMatch> matches) {
    UpdateReport report;
    report.predicted = static_cast<int>(predictions_.size());
    const int nc = collectCandidates(matches);
    report.matched = nc;

    ransacLowInnovationInliers(nc, report);
    const bool ok1 = updateLowInnovationInliers(nc, report);
    if (ok1 && !inliers_.empty()) {
        rescueHighInnovationMatches(nc, report);
    }
    normalizeQuaternion();

    recordAcceptedMatches(nc, report);
    const int accepted = report.low_innovation_inliers + report.rescued;
    report.bad_frame = accepted < config_.min_inliers && !features_.empty();
    if (report.bad_frame && report.matched == 0) {
        // A frame where nothing at all matched says more about the frame (a
        // covered lens, a dark scene, total blur) than about the features: it
        // does not count against them, so an outage does not empty the map.
        for (const FeaturePrediction& p : predictions_) {
            --features_[static_cast<size_t>(p.slot)].attempts;
        }
    }
    bad_frames_ = report.bad_frame ? bad_frames_ + 1 : 0;
    return report;
}

int EkfSlam::collectCandidates(std::span<const FeatureMatch> matches) {
    for (const FeaturePrediction& p : predictions_) {
        ++features_[static_cast<size_t>(p.slot)].attempts;
    }
    cand_.clear();
    for (const FeatureMatch& m : matches) {
        if (m.prediction < 0 || m.prediction >= static_cast<int>(predictions_.size()) ||
            !m.z_px.allFinite()) {
            continue;
        }
        Candidate c;
        const FeaturePrediction& pred = predictions_[static_cast<size_t>(m.prediction)];
        c.slot = pred.slot;
        c.S = pred.S;
        c.z = m.z_px;
        if (!projectSlot(x_, c.slot, true, c.proj)) {
            continue;
        }
        c.pred_px = c.proj.h_px;
        cand_.push_back(c);
    }
    return static_cast<int>(cand_.size());
}

void EkfSlam::ransacLowInnovationInliers(int nc, UpdateReport& report) {
    // 1-point RANSAC: each hypothesis is the EKF state update from one match;
    // the matches it predicts within ransac_threshold_px are its support.
    best_inliers_.clear();
    if (nc <= 0) {
        return;
    }
    const Scalar th2 = config_.ransac_threshold_px * config_.ransac_threshold_px;
    int hypotheses = config_.ransac_max_hypotheses;
    Scalar best_sse = 0;
    FeatureProjection proj;
    for (int k = 0; k < hypotheses && k < config_.ransac_max_hypotheses; ++k) {
        const int i = static_cast<int>(nextRandom() % static_cast<std::uint64_t>(nc));
        const Candidate& c = cand_[static_cast<size_t>(i)];
        const FeatureInfo& f = features_[static_cast<size_t>(c.slot)];
        const int d = dimOf(f.kind);
        auto PHt = PHt_.topLeftCorner(n_, 2);
        PHt.noalias() = P_.topLeftCorner(n_, kPoseDim) * c.proj.H_pose.transpose();
        PHt.noalias() += P_.block(0, f.offset, n_, d) * c.proj.H_feature.leftCols(d).transpose();
        const Mat2 S_inv = c.S.inverse();
        const Vec2 nu = c.z - c.proj.h_px;
        x_hyp_.head(n_) = x_.head(n_);
        x_hyp_.head(n_).noalias() += PHt * (S_inv * nu);
        inliers_.clear();
        Scalar sse = 0;
        for (int j = 0; j < nc; ++j) {
            const Candidate& cj = cand_[static_cast<size_t>(j)];
            if (!projectSlot(x_hyp_, cj.slot, false, proj)) {
                continue;
            }
            const Scalar e2 = (cj.z - proj.h_px).squaredNorm();
            if (e2 < th2) {
                inliers_.push_back(j);
                sse += e2;
            }
        }
        ++report.hypotheses;
        // Most support wins; equal support goes to the smaller residual.
        const bool better = inliers_.size() > best_inliers_.size() ||
                            (inliers_.size() == best_inliers_.size() && sse < best_sse);
        if (better) {
            best_inliers_.assign(inliers_.begin(), inliers_.end());
            best_sse = sse;
            const Scalar eps = Scalar(best_inliers_.size()) / Scalar(nc);
            const Scalar need =
                eps >= 1 ? Scalar(1) : std::log(1 - config_.ransac_confidence) / std::log(1 - eps);
            hypotheses = std::max(config_.ransac_min_hypotheses,
                                  static_cast<int>(std::ceil(std::min(need, Scalar(1e6)))));
        }
    }
}

bool EkfSlam::updateLowInnovationInliers(int nc, UpdateReport& report) {
    // Low-innovation inliers: one EKF update with all of them.
    accepted_.assign(static_cast<size_t>(nc), 0);
    inliers_.assign(best_inliers_.begin(), best_inliers_.end());
    const bool ok1 = ekfUpdate(static_cast<int>(inliers_.size()));
    if (ok1) {
        report.low_innovation_inliers = static_cast<int>(inliers_.size());
        for (const int i : inliers_) {
            accepted_[static_cast<size_t>(i)] = 1;
        }
    }
    return ok1;
}

void EkfSlam::rescueHighInnovationMatches(int nc, UpdateReport& report) {
    // Rescue: the other matches, re-predicted after the first update, that
    // now pass the chi-square gate; then a second update with them.
    inliers_.clear();
    for (int j = 0; j < nc; ++j) {
        if (accepted_[static_cast<size_t>(j)] != 0) {
            continue;
        }
        Candidate& c = cand_[static_cast<size_t>(j)];
        if (!projectSlot(x_, c.slot, true, c.proj)) {
            continue;
        }
        const Mat2 S = innovationCovariance(c.slot, c.proj);
        const Vec2 nu = c.z - c.proj.h_px;
        if (nu.dot(S.inverse() * nu) < config_.chi2_gate) {
            inliers_.push_back(j);
        }
    }
    if (ekfUpdate(static_cast<int>(inliers_.size()))) {
        report.rescued = static_cast<int>(inliers_.size());
        for (const int i : inliers_) {
            accepted_[static_cast<size_t>(i)] = 1;
        }
    }
}

void EkfSlam::recordAcceptedMatches(int nc, UpdateReport& report) {
    // Match counts and the consistency (NIS) by feature age of the accepted matches.
    for (int j = 0; j < nc; ++j) {
        if (accepted_[static_cast<size_t>(j)] != 0) {
            const Candidate& c = cand_[static_cast<size_t>(j)];
            FeatureInfo& f = features_[static_cast<size_t>(c.slot)];
            ++f.matches;
            f.measured = true;
            if (observations_.size() < observations_.capacity()) {
                observations_.push_back({f.id, c.z});
            }
            const Vec2 nu = c.z - c.pred_px;
            const int bin = f.attempts < 5 ? 0 : f.attempts < 15 ? 1 : f.attempts < 50 ? 2 : 3;
            report.nis_sum[static_cast<size_t>(bin)] += nu.dot(c.S.inverse() * nu);
            ++report.nis_count[static_cast<size_t>(bin)];
        }
    }
}

void EkfSlam::normalizeQuaternion() {
    Mat4 J;
    const Vec4 q = x_.segment<4>(kQuat);
    x_.segment<4>(kQuat) = quatNormalized(q, &J);
    for (int j = 0; j < n_; ++j) {
        const Vec4 col = P_.block<4, 1>(kQuat, j);
        P_.block<4, 1>(kQuat, j) = J * col;
    }
    for (int i = 0; i < n_; ++i) {
        const Eigen::Matrix<Scalar, 1, 4> row = P_.block<1, 4>(i, kQuat);
        P_.block<1, 4>(i, kQuat) = row * J.transpose();
    }
}

void EkfSlam::removeDims(int offset, int dims) {
    const int n = n_;
    for (int i = offset; i + dims < n; ++i) {
        x_(i) = x_(i + dims);
    }
    for (int j = 0; j < n; ++j) {
        for (int i = offset; i + dims < n; ++i) {
            P_(i, j) = P_(i + dims, j);
        }
    }
    for (int j = offset; j + dims < n; ++j) {
        P_.col(j).head(n - dims) = P_.col(j + dims).head(n - dims);
    }
    n_ = n - dims;
    x_.segment(n_, dims).setZero();
    P_.block(n_, 0, dims, n).setZero();
    P_.block(0, n_, n, dims).setZero();
    for (FeatureInfo& f : features_) {
        if (f.offset > offset) {
            f.offset -= dims;
        }
    }
}

void EkfSlam::removeSlot(int slot) {
    const FeatureInfo f = features_[static_cast<size_t>(slot)];
    features_.erase(features_.begin() + slot);
    removeDims(f.offset, dimOf(f.kind));
}

void EkfSlam::convertToXyz(int slot) {
    FeatureInfo& f = features_[static_cast<size_t>(slot)];
    const int o = f.offset;
    Mat36 J;
    const Vec6 y = x_.segment<6>(o);
    const Vec3 p = inverseDepthToXyz(y, &J);
    auto rows = rows_.topLeftCorner(3, n_);
    rows.noalias() = J * P_.block(o, 0, 6, n_);
    const Mat3 Pff = rows.middleCols<6>(o) * J.transpose();
    P_.block(o, 0, 3, n_) = rows;
    P_.block(0, o, n_, 3) = rows.transpose();
    P_.block<3, 3>(o, o) = Pff;
    x_.segment<3>(o) = p;
    f.kind = FeatureKind::kXyz;
    // The three trailing dimensions of the old parameterisation go.
    removeDims(o + 3, 3);
}

SlamHealth EkfSlam::manageMap() {
    if (health_ == SlamHealth::kUninitialised) {
        return health_;
    }
    for (int s = static_cast<int>(features_.size()) - 1; s >= 0; --s) {
        const FeatureInfo& f = features_[static_cast<size_t>(s)];
        const bool unreliable = f.attempts >= config_.delete_min_attempts &&
                                Scalar(f.matches) < config_.delete_min_ratio * Scalar(f.attempts);
        bool behind = false;
        if (f.kind == FeatureKind::kInverseDepth) {
            const Scalar rho = x_(f.offset + 5);
            const Scalar sd = std::sqrt(std::max(P_(f.offset + 5, f.offset + 5), Scalar(0)));
            behind = rho < -3 * sd;
        }
        if (unreliable || behind) {
            removeSlot(s);
        }
    }
    const Vec3 r = x_.segment<3>(kPos);
    for (int s = 0; s < static_cast<int>(features_.size()); ++s) {
        const FeatureInfo& f = features_[static_cast<size_t>(s)];
        if (f.kind != FeatureKind::kInverseDepth) {
            continue;
        }
        const Scalar var_rho = P_(f.offset + 5, f.offset + 5);
        const Scalar L =
            linearityIndex(x_.segment<6>(f.offset), std::sqrt(std::max(var_rho, Scalar(0))), r);
        if (L < config_.linearity_threshold) {
            convertToXyz(s);
        }
    }
    health_ = checkHealth();
    return health_;
}

SlamHealth assessNumericalHealth(const Eigen::Ref<const VecX>& x, const Eigen::Ref<const MatX>& P) {
    if (!x.allFinite() || !P.allFinite()) {
        return SlamHealth::kNonFinite;
    }
    for (Eigen::Index i = 0; i < P.rows(); ++i) {
        if (!(P(i, i) >= 0)) {
            return SlamHealth::kNotPositiveDefinite;
        }
    }
    if (P.rows() >= kCameraDim) {
        // The camera block must stay positive definite: its Cholesky (with a
        // tiny jitter for the gauge-fixed first frame) must succeed.
        Mat13 Pc = P.topLeftCorner<kCameraDim, kCameraDim>();
        Pc.diagonal().array() += Scalar(1e-9);
        const Eigen::LLT<Mat13> llt(Pc);
        if (llt.info() != Eigen::Success) {
            return SlamHealth::kNotPositiveDefinite;
        }
    }
    return SlamHealth::kOk;
}

void EkfSlam::declareLost() {
    if (health_ != SlamHealth::kUninitialised) {
        health_ = SlamHealth::kLost;
    }
}

SlamHealth EkfSlam::checkHealth() {
    const SlamHealth numerical = assessNumericalHealth(x_.head(n_), P_.topLeftCorner(n_, n_));
    if (numerical != SlamHealth::kOk) {
        return numerical;
    }
    if (bad_frames_ >= config_.lost_after_frames) {
        return SlamHealth::kLost;
    }
    return SlamHealth::kOk;
}

std::uint64_t EkfSlam::addFeature(const Vec2& px) {
    return addInverseDepth(px, config_.rho0, config_.sigma_rho);
}

std::uint64_t EkfSlam::addFeature(const Vec2& px, Scalar rho, Scalar sigma_rho) {
    return addInverseDepth(px, rho, sigma_rho);
}

std::uint64_t EkfSlam::addInverseDepth(const Vec2& px, Scalar rho, Scalar sigma_rho) {
    if (health_ == SlamHealth::kUninitialised ||
        static_cast<int>(features_.size()) >= config_.max_features || n_ + 6 > capacity_ ||
        !px.allFinite() || !std::isfinite(rho) || !(sigma_rho > 0) || !std::isfinite(sigma_rho)) {
        return 0;
    }
    const auto init = initInverseDepth(camera_, x_.segment<3>(kPos), x_.segment<4>(kQuat), px, rho);
    if (!init) {
        return 0;
    }
    const int o = n_;
    const int n = n_;
    auto rows = rows_.topLeftCorner(6, n);
    rows.noalias() = init->J_pose * P_.topLeftCorner(kPoseDim, n);
    P_.block(o, 0, 6, n) = rows;
    P_.block(0, o, n, 6) = rows.transpose();
    const Scalar var_px = config_.pixel_sigma_px * config_.pixel_sigma_px;
    Mat6 Pff = rows.leftCols<kPoseDim>() * init->J_pose.transpose() +
               var_px * init->J_px * init->J_px.transpose();
    Pff(5, 5) += sigma_rho * sigma_rho;
    P_.block<6, 6>(o, o) = Pff;
    x_.segment<6>(o) = init->y;
    n_ = n + 6;
    FeatureInfo f;
    f.id = next_id_++;
    f.kind = FeatureKind::kInverseDepth;
    f.offset = o;
    f.last_seen_frame = frame_;
    f.first_frame = frame_;
    f.in_view = true;
    f.px = px;
    features_.push_back(f);
    if (observations_.size() < observations_.capacity()) {
        observations_.push_back({f.id, px});
    }
    return f.id;
}

int EkfSlam::makeRoom(int n) {
    int removed = 0;
    while (removed<n&& static_cast<int>(features_.size()) + n - removed> config_.max_features) {
        int victim = -1;
        std::int64_t oldest = frame_;
        for (int s = 0; s < static_cast<int>(features_.size()); ++s) {
            const FeatureInfo& f = features_[static_cast<size_t>(s)];
            if (!f.in_view && f.last_seen_frame < oldest) {
                oldest = f.last_seen_frame;
                victim = s;
            }
        }
        if (victim < 0) {
            break;
        }
        removeSlot(victim);
        ++removed;
    }
    return removed;
}

void EkfSlam::rescaleMap(Scalar s, const Vec3& centre_W) {
    if (health_ == SlamHealth::kUninitialised || !(s > 0) || !std::isfinite(s) ||
        !centre_W.allFinite()) {
        return;
    }
    // x' = D x + (1 - s) c on positions, D diagonal: s on positions and
    // velocities, 1 / s on inverse depths, 1 elsewhere; P' = D P D.
    VecX& d = x_hyp_;  // scratch, capacity long
    d.head(n_).setOnes();
    auto scalePosition = [&](int offset) {
        x_.segment<3>(offset) = centre_W + s * (x_.segment<3>(offset) - centre_W);
        d.segment<3>(offset).setConstant(s);
    };
    scalePosition(kPos);
    x_.segment<3>(kVel) *= s;
    d.segment<3>(kVel).setConstant(s);
    for (const FeatureInfo& f : features_) {
        scalePosition(f.offset);
        if (f.kind == FeatureKind::kInverseDepth) {
            x_(f.offset + 5) /= s;
            d(f.offset + 5) = 1 / s;
        }
    }
    const auto dn = d.head(n_);
    P_.topLeftCorner(n_, n_) = dn.asDiagonal() * P_.topLeftCorner(n_, n_) * dn.asDiagonal();
}

bool EkfSlam::relocalise(std::int64_t t_ns, const CameraPose& T_CtoW, Scalar sigma_p,
                         Scalar sigma_theta) {
    if (health_ == SlamHealth::kUninitialised || !T_CtoW.p_CinW.allFinite() ||
        !T_CtoW.R_CtoW.allFinite() || !std::isfinite(sigma_p) || !std::isfinite(sigma_theta)) {
        return false;
    }
    const Vec4 q = quatNormalized(quatFromRotation(T_CtoW.R_CtoW));
    x_.segment<3>(kPos) = T_CtoW.p_CinW;
    x_.segment<4>(kQuat) = q;
    x_.segment<3>(kVel).setZero();
    x_.segment<3>(kAngVel).setZero();
    // The camera forgets its correlations with the map.
    P_.block(0, 0, kCameraDim, n_).setZero();
    P_.block(0, 0, n_, kCameraDim).setZero();
    P_.block<3, 3>(kPos, kPos) = Mat3::Identity() * (sigma_p * sigma_p);
    // q_true = q (x) [1, delta / 2]: d q / d delta = L(q) [0; I] / 2.
    const Eigen::Matrix<Scalar, 4, 3> J = Scalar(0.5) * quatLeftMatrix(q).rightCols<3>();
    P_.block<4, 4>(kQuat, kQuat) = (sigma_theta * sigma_theta) * J * J.transpose();
    P_.block<3, 3>(kVel, kVel) = Mat3::Identity() * (config_.init_sigma_v * config_.init_sigma_v);
    P_.block<3, 3>(kAngVel, kAngVel) =
        Mat3::Identity() * (config_.init_sigma_w * config_.init_sigma_w);
    t_ns_ = t_ns;
    ++frame_;
    bad_frames_ = 0;
    health_ = SlamHealth::kOk;
    return true;
}

bool EkfSlam::restartAt(std::int64_t t_ns, const CameraPose& T_CtoW, Scalar sigma_p,
                        Scalar sigma_theta) {
    if (health_ == SlamHealth::kUninitialised || !T_CtoW.p_CinW.allFinite() ||
        !T_CtoW.R_CtoW.allFinite() || !std::isfinite(sigma_p) || !std::isfinite(sigma_theta)) {
        return false;
    }
    const Vec3 up_W = up_W_;
    const std::int64_t frame = frame_;
    initialise(t_ns, -up_W);
    frame_ = frame;  // relocalise() counts this frame
    return relocalise(t_ns, T_CtoW, sigma_p, sigma_theta);
}

int EkfSlam::removeFeaturesAddedAfter(std::int64_t frame) {
    int removed = 0;
    for (int s = static_cast<int>(features_.size()) - 1; s >= 0; --s) {
        if (features_[static_cast<size_t>(s)].first_frame > frame) {
            removeSlot(s);
            ++removed;
        }
    }
    return removed;
}

CameraPose EkfSlam::pose() const {
    CameraPose p;
    p.R_CtoW = rotationFromQuat(x_.segment<4>(kQuat));
    p.p_CinW = x_.segment<3>(kPos);
    return p;
}

Mat6x6 EkfSlam::poseCovariance() const {
    // delta = 2 vec(q_est^-1 (x) q_true) to first order: d delta / d q = 2 [0 I] L(q^-1).
    const Vec4 q = x_.segment<4>(kQuat);
    Vec4 q_inv(q(0), -q(1), -q(2), -q(3));
    Eigen::Matrix<Scalar, 6, kPoseDim> J = Eigen::Matrix<Scalar, 6, kPoseDim>::Zero();
    J.topLeftCorner<3, 3>().setIdentity();
    J.bottomRightCorner<3, 4>() = 2 * quatLeftMatrix(q_inv).bottomRows<3>();
    return J * P_.topLeftCorner<kPoseDim, kPoseDim>() * J.transpose();
}

bool EkfSlam::mapPoint(int slot, MapPoint& out) const {
    const FeatureInfo& f = features_[static_cast<std::size_t>(slot)];
    out = MapPoint{};
    out.id = f.id;
    out.kind = f.kind;
    out.measured = f.measured;
    if (f.kind == FeatureKind::kXyz) {
        out.p_FinW = x_.segment<3>(f.offset);
        out.P_FinW = P_.block<3, 3>(f.offset, f.offset);
    } else {
        const Vec6 y = x_.segment<6>(f.offset);
        if (!(y(5) > 0)) {
            return false;  // at or beyond infinity: no finite point
        }
        Mat36 J;
        out.p_FinW = inverseDepthToXyz(y, &J);
        out.P_FinW = J * P_.block<6, 6>(f.offset, f.offset) * J.transpose();
    }
    FeatureProjection proj;
    if (projectSlot(x_, slot, false, proj)) {
        out.px = proj.h_px;
        out.in_view = proj.h_px.x() >= 0 && proj.h_px.y() >= 0 &&
                      proj.h_px.x() <= Scalar(camera_.width() - 1) &&
                      proj.h_px.y() <= Scalar(camera_.height() - 1);
    }
    return true;
}

bool EkfSlam::pointInWorld(int slot, Vec3& p_FinW) const {
    const FeatureInfo& f = features_[static_cast<std::size_t>(slot)];
    if (f.kind == FeatureKind::kXyz) {
        p_FinW = x_.segment<3>(f.offset);
        return true;
    }
    const Vec6 y = x_.segment<6>(f.offset);
    if (!(y(5) > 0)) {
        return false;
    }
    p_FinW = inverseDepthToXyz(y, nullptr);
    return true;
}

void EkfSlam::mapPoints(std::vector<MapPoint>& out) const {
    out.clear();
    MapPoint m;
    for (int slot = 0; slot < static_cast<int>(features_.size()); ++slot) {
        if (mapPoint(slot, m)) {
            out.push_back(m);
        }
    }
}

}  // namespace scaled::core::slam
