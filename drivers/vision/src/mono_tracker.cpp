#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <scaled/core/slam/feature_model.h>
#include <scaled/core/slam/quaternion.h>
#include <scaled/drivers/vision/mono_tracker.h>
#include <scaled/drivers/vision/two_view.h>

namespace scaled::drivers::vision {

using core::Scalar;
using core::Vec2;
using core::Vec3;
namespace slam = core::slam;

// Consecutive stage times of one frame (TrackStats::stage_us): each next() reads
// the clock once and returns the microseconds since the previous read, so the
// stages tile the frame without gaps. No allocation; about 20 ns per read.
class MonoTracker::StageLap {
public:
    double next() {
        const auto now = std::chrono::steady_clock::now();
        const double us = std::chrono::duration<double, std::micro>(now - last_).count();
        last_ = now;
        return us;
    }

private:
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

namespace {

// The element at size / 2 once v is partly sorted in place (the upper median
// for an even count); v must not be empty. Allocation-free.
template <typename T>
T upperMedianInPlace(std::vector<T>& v) {
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
}

// The filter's update report into the frame's stats.
void copyUpdateReport(const slam::UpdateReport& report, TrackStats& stats) {
    stats.predicted = report.predicted;
    stats.matched = report.matched;
    stats.inliers = report.low_innovation_inliers;
    stats.rescued = report.rescued;
    stats.nis_sum = report.nis_sum;
    stats.nis_count = report.nis_count;
}

}  // namespace

core::Status validate(const TrackerConfig& c) {
    if (auto ok = slam::validate(c.slam); !ok) {
        return ok.error();
    }
    if (auto ok = slam::validate(c.window_ba); !ok) {
        return ok.error();
    }
    auto bad = [](const std::string& key, auto v, const std::string& allowed) {
        return core::makeError(
            core::ErrorCode::kInvalidArgument,
            "tracker." + key + " = " + std::to_string(v) + ": must be " + allowed);
    };
    using L = TrackerLimits;
    const auto d = [](auto v) { return static_cast<double>(v); };
    const core::LimitCheck checks[] = {
        {"patch_size", d(c.patch_size), L::patch_size},
        {"patch_source_size", d(c.patch_source_size), L::patch_source_size},
        {"corner_quality", d(c.corners.quality_level), L::corner_quality},
        {"corner_min_distance_px", d(c.corners.min_distance_px), L::corner_min_distance_px},
        {"feature_border_px", d(c.feature_border_px), L::feature_border_px},
        {"free_radius_px", d(c.free_radius_px), L::free_radius_px},
        {"max_new_per_frame", d(c.max_new_per_frame), L::max_new_per_frame},
        {"relocalise_s", d(c.relocalise_s), L::relocalise_s},
        {"relocalise_min_inliers", d(c.relocalise_min_inliers), L::relocalise_min_inliers},
        {"relocalise_reproj_px", d(c.relocalise_reproj_px), L::relocalise_reproj_px},
        {"relocalise_max_brief_distance", d(c.relocalise_max_brief_distance),
         L::relocalise_max_brief_distance},
        {"brief_refresh_frames", d(c.brief_refresh_frames), L::brief_refresh_frames},
        {"relocalise_corners", d(c.relocalise_corners), L::relocalise_corners},
        {"relocalise_search_px", d(c.relocalise_search_px), L::relocalise_search_px},
        {"relocalise_verify_px", d(c.relocalise_verify_px), L::relocalise_verify_px},
        {"relocalise_max_rel_sigma", d(c.relocalise_max_rel_sigma), L::relocalise_max_rel_sigma},
        {"coarse_max_search_pixels", d(c.coarse_max_search_pixels), L::coarse_max_search_pixels},
        {"coarse_min_fraction", d(c.coarse_min_fraction), L::coarse_min_fraction},
        {"near_loss_ratio", d(c.near_loss_ratio), L::near_loss_ratio},
        {"near_loss_frames", d(c.near_loss_frames), L::near_loss_frames},
        {"pyramid_levels", d(c.pyramid_levels), L::pyramid_levels},
        {"coarse_min_ncc", d(c.coarse_min_ncc), L::coarse_min_ncc},
        {"rotation_check_radps", d(c.rotation_check_radps), L::rotation_check_radps},
        {"rotation_check_sigma_radps", d(c.rotation_check_sigma_radps),
         L::rotation_check_sigma_radps},
        {"gyro_noise_density", d(c.gyro_noise_density), L::gyro_noise_density},
        {"gyro_bias_sigma_radps", d(c.gyro_bias_sigma_radps), L::gyro_bias_sigma_radps},
        {"gyro_bias_time_s", d(c.gyro_bias_time_s), L::gyro_bias_time_s},
        {"gyro_max_gap_s", d(c.gyro_max_gap_s), L::gyro_max_gap_s},
        {"start_check_s", d(c.start_check_s), L::start_check_s},
        {"start_check_deg", d(c.start_check_deg), L::start_check_deg},
        {"start_check_flow_px", d(c.start_check_flow_px), L::start_check_flow_px},
        {"start_check_depth_rel_sigma", d(c.start_check_depth_rel_sigma),
         L::start_check_depth_rel_sigma},
        {"min_ncc", d(c.match.min_ncc), L::min_ncc},
        {"max_search_pixels", d(c.match.max_search_pixels), L::max_search_pixels},
    };
    if (const core::LimitCheck* b = core::firstOutside(checks)) {
        return bad(b->name, b->value, b->limits.text());
    }
    if (c.patch_size % 2 == 0) {
        return bad("patch_size", c.patch_size, "odd, in [5, 31]");
    }
    if (c.patch_source_size < 2 * c.patch_size + 1 || c.patch_source_size > 101 ||
        c.patch_source_size % 2 == 0) {
        return bad("patch_source_size", c.patch_source_size, "odd, in [2 patch_size + 1, 101]");
    }
    if (c.max_new_per_frame > c.slam.max_features) {
        return bad("max_new_per_frame", c.max_new_per_frame, "in [1, slam.max_features]");
    }
    if (c.use_gyro && !(c.gyro_noise_density > 0 || c.gyro_bias_sigma_radps > 0)) {
        return bad("gyro_bias_sigma_radps", c.gyro_bias_sigma_radps,
                   "> 0 when gyro_noise_density is 0 (a gyro without noise)");
    }
    return {};
}

core::Result<MonoTracker> MonoTracker::create(const core::PinholeRadialCamera& camera,
                                              const TrackerConfig& config) {
    if (auto ok = validate(config); !ok) {
        return ok.error();
    }
    auto filter = slam::EkfSlam::create(camera, config.slam);
    if (!filter) {
        return filter.error();
    }
    std::optional<slam::WindowBa> ba;
    if (config.window_ba.enabled) {
        auto made = slam::WindowBa::create(camera, config.window_ba);
        if (!made) {
            return made.error();
        }
        ba.emplace(std::move(made.value()));
    }
    return MonoTracker(std::move(filter.value()), std::move(ba), config);
}

MonoTracker::MonoTracker(slam::EkfSlam slam, std::optional<slam::WindowBa> ba,
                         const TrackerConfig& config)
    : slam_(std::move(slam)), ba_(std::move(ba)), config_(config) {
    // The filter's chi-square gate is the one the search ellipse uses.
    config_.match.chi2_gate = static_cast<double>(config_.slam.chi2_gate);
    appearance_.reserve(static_cast<size_t>(config.slam.max_features));
    matches_.reserve(static_cast<size_t>(config.slam.max_measured));
    occupied_.reserve(static_cast<size_t>(config.slam.max_features));
    corners_.reserve(
        static_cast<size_t>(std::max(config.max_new_per_frame * 4, config.relocalise_corners)));
    // Steady-state tracking allocates nothing: every patch buffer a feature
    // can need is made here, and the matcher's scratch sized for the largest
    // search the configuration allows.
    spare_patches_.reserve(static_cast<size_t>(config.slam.max_features));
    for (int i = 0; i < config.slam.max_features; ++i) {
        Patch p;
        p.size = config.patch_size;
        p.source.create(config.patch_source_size, config.patch_source_size, CV_32FC1);
        p.templ.create(config.patch_size, config.patch_size, CV_32FC1);
        spare_patches_.push_back(std::move(p));
    }
    matcher_.reserve(config.patch_size, std::max({config.match.max_search_pixels,
                                                  config.coarse_max_search_pixels, 3}));
    reloc_candidates_.reserve(static_cast<size_t>(config.slam.max_features));
    {
        const auto n = static_cast<size_t>(config.slam.max_features);
        auto& sc = start_check_;
        sc.px_S.reserve(n);
        sc.x_S.reserve(n);
        sc.x_K.reserve(n);
        sc.px_K.reserve(n);
        sc.id_K.reserve(n);
        sc.depth_K.reserve(n);
        sc.scratch.reserve(n);
    }
    corner_briefs_.reserve(static_cast<size_t>(config.relocalise_corners));
    corner_has_brief_.reserve(static_cast<size_t>(config.relocalise_corners));
    reloc_points_W_.reserve(static_cast<size_t>(config.slam.max_features));
    reloc_points_n_.reserve(static_cast<size_t>(config.slam.max_features));
    depth_scratch_.reserve(static_cast<size_t>(config.slam.max_features));
    small_rotation_.create(slam_.camera().width(), slam_.camera().height());
}

void MonoTracker::reset() {
    has_map_ = false;
    if (ba_) {
        resetWindow();
    }
    relocalising_ = false;
    previous_frame_good_ = false;
    clearAppearances();
}

void MonoTracker::clearAppearances() {
    for (auto& a : appearance_) {
        spare_patches_.push_back(std::move(a.patch));
    }
    appearance_.clear();
}

MonoTracker::FeatureAppearance* MonoTracker::appearanceOf(std::uint64_t id) {
    for (auto& a : appearance_) {
        if (a.id == id) {
            return &a;
        }
    }
    return nullptr;
}

void MonoTracker::dropDeletedAppearances() {
    const auto features = slam_.features();
    const auto deleted = [&](const FeatureAppearance& a) {
        return std::none_of(features.begin(), features.end(),
                            [&](const slam::FeatureInfo& f) { return f.id == a.id; });
    };
    for (auto& a : appearance_) {
        if (deleted(a)) {
            spare_patches_.push_back(std::move(a.patch));  // its buffers serve a new feature
        }
    }
    std::erase_if(appearance_, deleted);
}

bool MonoTracker::predictedWarp(const slam::FeatureInfo& f, const FeatureAppearance& a,
                                const Vec2& h_px, const core::CameraPose& cur,
                                core::Mat2& A) const {
    // The patch is taken to lie on the plane through the feature facing the
    // camera that first saw it; map pixel offsets in the current image through
    // that plane into the first image.
    const auto x = slam_.state();
    Vec3 p;
    if (f.kind == slam::FeatureKind::kXyz) {
        p = x.segment<3>(f.offset);
    } else {
        const slam::Vec6 y = x.segment<6>(f.offset);
        if (!(y(5) > Scalar(1e-6))) {
            return false;
        }
        p = slam::inverseDepthToXyz(y);
    }
    const Vec3 n = (p - a.pose_at_init.p_CinW).normalized();
    const auto& cam = slam_.camera();
    auto toInit = [&](const Vec2& u) -> std::optional<Vec2> {
        const auto ray_C = cam.unproject(u);
        if (!ray_C) {
            return std::nullopt;
        }
        const Vec3 ray_W = cur.R_CtoW * *ray_C;
        const Scalar denom = n.dot(ray_W);
        if (std::abs(denom) < Scalar(1e-9)) {
            return std::nullopt;
        }
        const Scalar t = n.dot(p - cur.p_CinW) / denom;
        if (!(t > 0)) {
            return std::nullopt;
        }
        const Vec3 X = cur.p_CinW + t * ray_W;
        return cam.project(a.pose_at_init.R_CtoW.transpose() * (X - a.pose_at_init.p_CinW));
    };
    const auto u0 = toInit(h_px);
    const auto ux = toInit(h_px + Vec2(1, 0));
    const auto uy = toInit(h_px + Vec2(0, 1));
    if (!u0 || !ux || !uy) {
        return false;
    }
    A.col(0) = *ux - *u0;
    A.col(1) = *uy - *u0;
    // A grossly distorted prediction (grazing view) is not worth matching.
    const Scalar det = A.determinant();
    return std::isfinite(det) && det > Scalar(0.1) && det < Scalar(10);
}

int MonoTracker::addFeatures(const cv::Mat& gray, int wanted, bool new_map) {
    if (wanted <= 0) {
        return 0;
    }
    occupied_.clear();
    for (const auto& f : slam_.features()) {
        if (f.in_view) {
            occupied_.push_back(f.px);
        }
    }
    makeFreeMask(gray.size(), occupied_, config_.free_radius_px, mask_);
    CornerConfig cc = config_.corners;
    // A new map takes as many as it needs; later frames add a few at a time.
    cc.max_corners = new_map ? wanted : std::min(wanted, config_.max_new_per_frame);
    cc.min_distance_px = std::max(cc.min_distance_px, config_.free_radius_px);
    detectCorners(gray, mask_, cc, corners_);

    if (slam_.makeRoom(static_cast<int>(corners_.size())) > 0) {
        dropDeletedAppearances();  // their patch buffers serve the new features
    }
    int added = 0;
    for (const Vec2& c : corners_) {
        if (spare_patches_.empty()) {
            spare_patches_.emplace_back();  // not expected: one per feature was made at create()
        }
        const auto border = static_cast<Scalar>(config_.feature_border_px);
        if (c.x() < border || c.y() < border || c.x() > Scalar(gray.cols - 1) - border ||
            c.y() > Scalar(gray.rows - 1) - border) {
            continue;  // born at the border, it would leave the view at once
        }
        Patch& patch = spare_patches_.back();
        if (!extractPatchInto(gray, c, config_.patch_size, config_.patch_source_size, patch)) {
            continue;
        }
        std::uint64_t id = 0;
        const auto depth = new_map && depth_prior_ ? depth_prior_(c) : std::nullopt;
        if (depth && *depth > 0) {
            id = slam_.addFeature(c, 1 / *depth, depth_prior_rel_sigma_ / *depth);
        } else {
            id = slam_.addFeature(c);
        }
        if (id == 0) {
            break;
        }
        FeatureAppearance a;
        a.id = id;
        a.patch = std::move(patch);
        spare_patches_.pop_back();
        a.pose_at_init = slam_.pose();
        a.px_at_init = c;
        a.has_brief = computeBrief(gray, c, a.brief);
        a.brief_frame = slam_.frameIndex();
        appearance_.push_back(std::move(a));
        ++added;
    }
    return added;
}

int MonoTracker::searchLevel(const core::Mat2& S) const {
    // The gate ellipse's area, pi * gate * sqrt(det S), against the budget;
    // each level divides it by 4.
    const double det = static_cast<double>(S.determinant());
    if (!(det > 0) || !std::isfinite(det)) {
        return 0;  // the matcher rejects it with its own checks
    }
    const double area = 3.14159265358979 * config_.match.chi2_gate * std::sqrt(det);
    const double extent =
        2 * std::sqrt(config_.match.chi2_gate * static_cast<double>(std::max(S(0, 0), S(1, 1))));
    const double budget = config_.match.max_search_pixels;
    if (area <= budget && extent + 1 <= budget) {
        return 0;
    }
    const double coarse_budget = config_.coarse_max_search_pixels;
    for (int level = 1; level <= config_.pyramid_levels; ++level) {
        const double shrink = std::ldexp(1.0, level);
        if (area / (shrink * shrink) <= coarse_budget && extent / shrink + 1 <= coarse_budget) {
            return level;
        }
    }
    return -1;
}

const cv::Mat& MonoTracker::pyramidLevel(const cv::Mat& gray, int level) {
    while (pyramid_built_ < level) {
        const cv::Mat& from =
            pyramid_built_ == 0 ? gray : pyramid_[static_cast<size_t>(pyramid_built_ - 1)];
        // pyrDown into the same buffer every frame: no allocation once sized.
        cv::pyrDown(from, pyramid_[static_cast<size_t>(pyramid_built_)]);
        ++pyramid_built_;
    }
    return pyramid_[static_cast<size_t>(level - 1)];
}

std::optional<Match> MonoTracker::matchCoarseToFine(const cv::Mat& gray, int level,
                                                    FeatureAppearance& a, const core::Mat2& A_full,
                                                    const Vec2& h_px, const core::Mat2& S,
                                                    TrackStats& stats) {
    ++stats.coarse_searches;
    const double shrink = std::ldexp(1.0, level);
    const auto s = static_cast<Scalar>(shrink);
    // One template pixel at this level spans `shrink` full-resolution pixels.
    warpTemplate(a.patch, A_full * s);
    MatchConfig coarse = config_.match;
    coarse.min_ncc = config_.coarse_min_ncc;
    coarse.max_search_pixels = config_.coarse_max_search_pixels;
    coarse.subpixel = false;
    // pyrDown's pixel i is centred on full-resolution pixel 2i.
    const auto hit =
        matcher_.match(pyramidLevel(gray, level), a.patch, h_px / s, S / (s * s), coarse);
    warpTemplate(a.patch, A_full);
    if (!hit) {
        return std::nullopt;
    }
    stats.search_evaluations += hit->evaluated;
    // Refine inside a small circle around the coarse hit (about 2 coarse
    // pixels), then keep it only if it lies in the original gate.
    const Vec2 c = hit->px * s;
    const core::Mat2 S_fine = core::Mat2::Identity() * (s * s * Scalar(0.5));
    auto fine = matcher_.match(gray, a.patch, c, S_fine, config_.match);
    if (!fine) {
        return std::nullopt;
    }
    const Vec2 nu = fine->px - h_px;
    if (!(static_cast<double>(nu.dot(S.inverse() * nu)) <= config_.match.chi2_gate)) {
        return std::nullopt;
    }
    ++stats.coarse_matches;
    return fine;
}

bool MonoTracker::knownMapPoint(int slot, slam::MapPoint& mp) const {
    // Only features whose position is known: a fresh inverse-depth feature's
    // point is a guess along its ray.
    if (!slam_.mapPoint(slot, mp)) {
        return false;
    }
    const Scalar dist = (mp.p_FinW - last_good_pose_.p_CinW).norm();
    return std::sqrt(std::max(mp.P_FinW.trace(), Scalar(0))) <
           static_cast<Scalar>(config_.relocalise_max_rel_sigma) * dist;
}

int MonoTracker::knownFeatureCount() const {
    slam::MapPoint mp;
    int known = 0;
    for (int slot = 0; slot < static_cast<int>(slam_.features().size()); ++slot) {
        known += knownMapPoint(slot, mp) ? 1 : 0;
    }
    return known;
}

void MonoTracker::addRelocPoint(const Vec3& p_FinW, const Vec2& px) {
    const auto ray = slam_.camera().unproject(px);
    if (!ray || !((*ray)(2) > 0)) {
        return;
    }
    reloc_points_W_.emplace_back(static_cast<float>(p_FinW.x()), static_cast<float>(p_FinW.y()),
                                 static_cast<float>(p_FinW.z()));
    reloc_points_n_.emplace_back(static_cast<float>((*ray)(0) / (*ray)(2)),
                                 static_cast<float>((*ray)(1) / (*ray)(2)));
}

void MonoTracker::guidedRelocCandidates(const cv::Mat& gray, TrackStats& stats,
                                        const core::CameraPose& from, Scalar radius_px) {
    // Each known feature searched around where the pose `from` puts it (the
    // last well-tracked pose: an outage is usually short and the camera near
    // where it was; or a PnP hypothesis), coarse-to-fine inside radius_px,
    // with its template warped for that pose.
    const auto features = slam_.features();
    const Scalar r = radius_px;
    const core::Mat2 S =
        core::Mat2::Identity() * (r * r / static_cast<Scalar>(config_.match.chi2_gate));
    const int level = searchLevel(S);
    const auto& cam = slam_.camera();
    slam::MapPoint mp;
    for (int slot = 0; slot < static_cast<int>(features.size()) && level >= 0; ++slot) {
        FeatureAppearance* a = appearanceOf(features[static_cast<size_t>(slot)].id);
        if (a == nullptr || !knownMapPoint(slot, mp)) {
            continue;
        }
        const Vec3 p_C = from.R_CtoW.transpose() * (mp.p_FinW - from.p_CinW);
        const auto h = p_C.z() > 0 ? cam.project(p_C) : std::nullopt;
        if (!h || h->x() < 0 || h->y() < 0 || h->x() > Scalar(cam.width() - 1) ||
            h->y() > Scalar(cam.height() - 1)) {
            continue;
        }
        core::Mat2 A = core::Mat2::Identity();
        if (config_.warp_patches &&
            !predictedWarp(features[static_cast<size_t>(slot)], *a, *h, from, A)) {
            A = core::Mat2::Identity();
        }
        std::optional<Match> m;
        if (level == 0) {
            warpTemplate(a->patch, A);
            m = matcher_.match(gray, a->patch, *h, S, config_.match);
        } else {
            m = matchCoarseToFine(gray, level, *a, A, *h, S, stats);
        }
        if (m) {
            addRelocPoint(mp.p_FinW, m->px);
        }
    }
}

void MonoTracker::globalRelocCandidates(const cv::Mat& gray) {
    // The frame's corners and their descriptors against every known
    // feature's descriptor: a feature is a candidate when its nearest corner
    // is within relocalise_max_brief_distance bits, clearly nearer than the
    // second (ratio 0.8) and claimed by no other feature.
    CornerConfig cc = config_.corners;
    cc.max_corners = config_.relocalise_corners;
    cc.min_distance_px = std::max(3, config_.patch_size / 2);
    cc.border_px = std::max(cc.border_px, kBriefRadiusPx + 1);
    detectCorners(gray, cv::Mat(), cc, corners_);
    corner_briefs_.resize(corners_.size());
    corner_has_brief_.resize(corners_.size());
    for (std::size_t i = 0; i < corners_.size(); ++i) {
        corner_has_brief_[i] = computeBrief(gray, corners_[i], corner_briefs_[i]) ? 1 : 0;
    }
    reloc_candidates_.clear();
    const auto features = slam_.features();
    slam::MapPoint mp;
    for (int slot = 0; slot < static_cast<int>(features.size()); ++slot) {
        const FeatureAppearance* a = appearanceOf(features[static_cast<size_t>(slot)].id);
        if (a == nullptr || !a->has_brief || !knownMapPoint(slot, mp)) {
            continue;
        }
        RelocCandidate best;
        int best_d = 257;
        int second_d = 257;
        for (int ci = 0; ci < static_cast<int>(corners_.size()); ++ci) {
            if (corner_has_brief_[static_cast<size_t>(ci)] == 0) {
                continue;
            }
            const int d = briefDistance(a->brief, corner_briefs_[static_cast<size_t>(ci)]);
            if (d < best_d) {
                second_d = best_d;
                best_d = d;
                best = {slot, ci, 1.0 - d / 256.0, corners_[static_cast<size_t>(ci)]};
            } else if (d < second_d) {
                second_d = d;
            }
        }
        if (best_d <= config_.relocalise_max_brief_distance && 5 * best_d < 4 * second_d) {
            reloc_candidates_.push_back(best);
        }
    }
    for (const RelocCandidate& c : reloc_candidates_) {
        const bool shared =
            std::count_if(reloc_candidates_.begin(), reloc_candidates_.end(),
                          [&](const RelocCandidate& o) { return o.corner == c.corner; }) > 1;
        if (!shared && slam_.mapPoint(c.slot, mp)) {
            addRelocPoint(mp.p_FinW, c.px);
        }
    }
}

void MonoTracker::refreshDescriptors(const cv::Mat& gray,
                                     std::span<const slam::FeaturePrediction> preds) {
    const auto features = slam_.features();
    const std::int64_t frame = slam_.frameIndex();
    for (const slam::FeatureMatch& m : matches_) {
        const auto& pr = preds[static_cast<size_t>(m.prediction)];
        if (!features[static_cast<size_t>(pr.slot)].measured) {
            continue;  // rejected by the update
        }
        FeatureAppearance* a = appearanceOf(pr.id);
        if (a == nullptr ||
            (a->has_brief && frame - a->brief_frame < config_.brief_refresh_frames)) {
            continue;
        }
        if (computeBrief(gray, m.z_px, a->brief)) {
            a->has_brief = true;
            a->brief_frame = frame;
        }
    }
}

std::optional<core::CameraPose> MonoTracker::solveRelocPose(TrackStats& stats, int min_inliers) {
    stats.relocalise_candidates = static_cast<int>(reloc_points_W_.size());
    if (stats.relocalise_candidates < min_inliers) {
        return std::nullopt;
    }
    // RANSAC PnP in normalised coordinates (OpenCV's seeded RANSAC:
    // deterministic); the threshold in pixels over the focal length.
    cv::Mat rvec;
    cv::Mat tvec;
    const auto& k = slam_.camera().intrinsics();
    const auto threshold =
        static_cast<float>(config_.relocalise_reproj_px / static_cast<double>(k.fx));
    bool solved = false;
    reloc_inliers_.clear();
    try {
        solved = cv::solvePnPRansac(reloc_points_W_, reloc_points_n_, cv::Mat::eye(3, 3, CV_64F),
                                    cv::Mat(), rvec, tvec, false, 1000, threshold, 0.99,
                                    reloc_inliers_, cv::SOLVEPNP_AP3P);
    } catch (const cv::Exception&) {
        solved = false;  // degenerate points: no pose this frame
    }
    stats.relocalise_inliers = static_cast<int>(reloc_inliers_.size());
    if (!solved || stats.relocalise_inliers < min_inliers) {
        return std::nullopt;
    }
    cv::Mat R_WtoC_cv;
    cv::Rodrigues(rvec, R_WtoC_cv);
    core::Mat3 R_WtoC;
    Vec3 t_WinC;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            R_WtoC(r, c) = static_cast<Scalar>(R_WtoC_cv.at<double>(r, c));
        }
        t_WinC(r) = static_cast<Scalar>(tvec.at<double>(r));
    }
    core::CameraPose T_CtoW;
    T_CtoW.R_CtoW = R_WtoC.transpose();
    T_CtoW.p_CinW = -(T_CtoW.R_CtoW * t_WinC);
    if (!T_CtoW.R_CtoW.allFinite() || !T_CtoW.p_CinW.allFinite()) {
        return std::nullopt;
    }
    return T_CtoW;
}

bool MonoTracker::tryRelocalise(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats) {
    // A pose with relocalise_min_inliers inliers is taken; one with fewer
    // (but more than the minimal sample) is a hypothesis: the features are
    // searched again, within relocalise_verify_px of where it puts them, and
    // the pose solved from those must have relocalise_min_inliers.
    const int min_inliers = config_.relocalise_min_inliers;
    const int min_hypothesis = config_.relocalise_verify_px > 0
                                   ? std::min(kMinHypothesisInliers, min_inliers)
                                   : min_inliers;
    std::optional<core::CameraPose> hypothesis;
    int hypothesis_inliers = 0;
    const auto attempt = [&](auto&& candidates) -> std::optional<core::CameraPose> {
        reloc_points_W_.clear();
        reloc_points_n_.clear();
        candidates();
        auto p = solveRelocPose(stats, min_hypothesis);
        if (p && stats.relocalise_inliers < min_inliers) {
            if (stats.relocalise_inliers > hypothesis_inliers) {
                hypothesis = p;
                hypothesis_inliers = stats.relocalise_inliers;
            }
            return std::nullopt;
        }
        return p;
    };
    auto pose = attempt([&] { globalRelocCandidates(gray); });
    if (!pose) {
        pose = attempt([&] {
            guidedRelocCandidates(gray, stats, last_good_pose_,
                                  static_cast<Scalar>(config_.relocalise_search_px));
        });
    }
    if (!pose && hypothesis) {
        const core::CameraPose from = *hypothesis;
        pose = attempt([&] {
            guidedRelocCandidates(gray, stats, from,
                                  static_cast<Scalar>(config_.relocalise_verify_px));
        });
        stats.relocalise_verified = pose.has_value();
    }
    if (!pose) {
        return false;
    }
    // Uncertainty of the PnP pose: a few pixels at the inliers' median depth.
    depth_scratch_.clear();
    const core::Mat3 R_WtoC = pose->R_CtoW.transpose();
    for (const int i : reloc_inliers_) {
        const auto& P = reloc_points_W_[static_cast<size_t>(i)];
        const Vec3 p_W(static_cast<Scalar>(P.x), static_cast<Scalar>(P.y),
                       static_cast<Scalar>(P.z));
        depth_scratch_.push_back((R_WtoC * (p_W - pose->p_CinW)).z());
    }
    const Scalar depth = std::max(upperMedianInPlace(depth_scratch_), Scalar(1e-3));
    const auto px_angle =
        static_cast<Scalar>(config_.relocalise_reproj_px) / slam_.camera().intrinsics().fx;
    if (!slam_.relocalise(t_ns, *pose, 3 * px_angle * depth, 3 * px_angle)) {
        return false;
    }
    // The features added after the last well-tracked frame were cut from
    // poses the filter was guessing: their rays are not where the map is.
    stats.relocalise_dropped = slam_.removeFeaturesAddedAfter(last_good_frame_);
    dropDeletedAppearances();
    return true;
}

void MonoTracker::updateGyroBias(const slam::GyroRate& rate, const core::Mat3& R_prev_CtoW,
                                 std::int64_t t_prev_ns, std::int64_t t_ns) {
    const Scalar dt = Scalar(t_ns - t_prev_ns) * Scalar(1e-9);
    if (!(dt > 0)) {
        return;
    }
    // The map's rotation rate over the interval, from the updated poses.
    const Vec3 w_map = slam::rotationError(R_prev_CtoW, slam_.pose().R_CtoW) / dt;
    const Vec3 residual = rate.w_C_radps - w_map;  // the bias the estimate still misses
    // An exponential average. (A running mean at first, the n-th residual
    // weighing 1/n, was measured worse: its first noisy estimates bend the
    // young map; docs/slam.md "The gyro prior".)
    const Scalar gain = std::min(Scalar(1), dt / static_cast<Scalar>(config_.gyro_bias_time_s));
    gyro_bias_C_ += gain * residual;
    // A bias beyond this is a broken device or a wrong R_ItoC, not a bias.
    constexpr Scalar kMaxBias = Scalar(0.5);
    if (gyro_bias_C_.norm() > kMaxBias) {
        gyro_bias_C_ *= kMaxBias / gyro_bias_C_.norm();
    }
}

void MonoTracker::startNewMap(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats) {
    slam_.initialise(t_ns, gravity_down_C_);
    stats.new_map = true;
    beginMap(t_ns, gray, stats);
}

void MonoTracker::beginMap(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats) {
    last_good_pose_ = slam_.pose();
    last_good_frame_ = slam_.frameIndex();
    clearAppearances();
    previous_frame_good_ = true;  // the map's origin: a reference for the gyro bias
    near_loss_run_ = 0;
    has_map_ = true;
    stats.added = addFeatures(gray, config_.slam.min_visible + config_.max_new_per_frame, true);
    // A map whose first depths are given has its start fixed already.
    start_check_.active = config_.start_check_s > 0 && !depth_prior_;
    start_check_.map_t0_ns = t_ns;
    if (stats.new_map) {
        start_check_.restarts = 0;
    }
    start_check_.gyro_bias_C = gyro_bias_C_;
    beginStartCheckLink({});
    start_check_.R_chain = start_check_.R_StoW;
    countMap(stats);
    stats.visible = stats.added;
    stats.health = slam_.health();
    if (ba_) {
        resetWindow();
        adjustWindow(stats);
    }
}

void MonoTracker::adjustWindow(TrackStats& stats) {
    if (!ba_) {
        return;
    }
    const bool tracked = slam_.health() == slam::SlamHealth::kOk;
    if (ba_due_) {
        // A deferred optimisation runs: this frame only counts, until the
        // defer_frames-th, which takes its result (and is then a frame of
        // the window like any other: not a keyframe, defer_frames <
        // keyframe_every).
        if (++ba_due_frames_ < config_.window_ba.defer_frames) {
            ba_due_tracked_ += tracked ? 1 : 0;
            return;
        }
        finishDueOptimisation(stats);
    }
    if (!tracked) {
        return;
    }
    const slam::WindowBaReport report = ba_->addFrame(slam_.pose(), slam_.observations(),
                                                      slam_.velocityW(), slam_.angularVelocityC());
    if (report.due) {
        ba_served_ = ba_->adjustedFromFilter();
        ba_due_ = true;
        ba_due_frames_ = 0;
        ba_due_tracked_ = 0;
        if (runner_ != nullptr) {
            runner_->start(*ba_);
        } else {
            ba_inline_report_ = ba_->runDue();
        }
        stats.window_ba = report;
        return;
    }
    if (!stats.window_ba.optimised) {
        stats.window_ba = report;
    }
    applyWindowScale(report);
}

void MonoTracker::finishDueOptimisation(TrackStats& stats) {
    const slam::WindowBaReport report = runner_ != nullptr ? runner_->wait() : ba_inline_report_;
    ba_->finishDue(ba_due_tracked_);
    ba_due_ = false;
    stats.window_ba = report;
    applyWindowScale(report);
}

void MonoTracker::resetWindow() {
    if (ba_due_ && runner_ != nullptr) {
        (void)runner_->wait();
    }
    ba_due_ = false;
    ba_->reset();
}

void MonoTracker::applyWindowScale(const slam::WindowBaReport& report) {
    const core::Scalar s = report.scale;
    if (report.optimised && s != 1) {
        const core::Vec3 centre_W = slam_.pose().p_CinW;
        slam_.rescaleMap(s, centre_W);
        ba_->notifyRescaled(s, centre_W);
    }
}

bool MonoTracker::relocaliseFrame(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats,
                                  StageLap& lap) {
    stats.health = slam::SlamHealth::kRelocalising;
    countMap(stats);
    if (static_cast<double>(t_ns - lost_t_ns_) * 1e-9 > config_.relocalise_s) {
        relocalising_ = false;  // given up: the caller starts a new map
        stats.health = slam::SlamHealth::kLost;
        return false;
    }
    const bool back = tryRelocalise(t_ns, gray, stats);
    stats.relocalise_us = lap.next();
    if (!back) {
        return false;
    }
    relocalising_ = false;
    near_loss_run_ = 0;
    stats.relocalised = true;
    return true;
}

Scalar MonoTracker::medianMeasuredDepth() {
    depth_scratch_.clear();
    const core::CameraPose T = slam_.pose();
    Vec3 p_FinW;
    const auto features = slam_.features();
    for (int slot = 0; slot < static_cast<int>(features.size()); ++slot) {
        if (!features[static_cast<size_t>(slot)].measured || !slam_.pointInWorld(slot, p_FinW)) {
            continue;
        }
        const Scalar z = (T.R_CtoW.transpose() * (p_FinW - T.p_CinW)).z();
        if (z > 0) {
            depth_scratch_.push_back(z);
        }
    }
    constexpr std::size_t kMinDepths = 5;
    return depth_scratch_.size() < kMinDepths ? Scalar(0) : upperMedianInPlace(depth_scratch_);
}

const slam::GyroRate* MonoTracker::checkRotation(std::int64_t t_ns, const cv::Mat& gray,
                                                 bool gyro_given, TrackStats& stats) {
    if (config_.rotation_check_radps <= 0) {
        return nullptr;
    }
    const bool predicting = has_map_ && !relocalising_ && !gyro_given &&
                            slam_.health() == slam::SlamHealth::kOk && t_ns > slam_.timestampNs();
    core::Mat3 R0_CinP = core::Mat3::Identity();
    Vec3 t_CinP_per_depth = Vec3::Zero();
    Vec3 w_model = Vec3::Zero();
    Scalar dt = 0;
    if (predicting) {
        // Start from the motion model's rotation; the scene moved by its
        // velocity at the depth of the features the last frame measured.
        dt = Scalar(t_ns - slam_.timestampNs()) * Scalar(1e-9);
        w_model = slam_.state().segment<3>(slam::kAngVel);
        R0_CinP = slam::rotationFromQuat(slam::quatFromRotationVector(w_model * dt));
        const Scalar depth = medianMeasuredDepth();
        if (depth > 0) {
            t_CinP_per_depth = slam_.pose().R_CtoW.transpose() * slam_.velocityW() * (dt / depth);
        }
    }
    const auto found =
        small_rotation_.push(gray, slam_.camera(), R0_CinP, t_CinP_per_depth, predicting);
    if (!predicting || !found) {
        return nullptr;
    }
    const Eigen::AngleAxis<Scalar> aa(found->R_CinP);
    const Vec3 w_images = aa.axis() * (aa.angle() / dt);
    if (!w_images.allFinite() ||
        (w_images - w_model).norm() <= Scalar(config_.rotation_check_radps)) {
        return nullptr;
    }
    checked_rate_.w_C_radps = w_images;
    checked_rate_.sigma_radps = Scalar(config_.rotation_check_sigma_radps);
    checked_rate_.samples = 0;
    stats.rotation_check = true;
    return &checked_rate_;
}

const slam::GyroRate* MonoTracker::integrateGyroForFrame(std::int64_t t_ns,
                                                         const slam::ImuWindow* imu,
                                                         slam::GyroIntegration& gyro,
                                                         TrackStats& stats) const {
    if (imu == nullptr || !config_.use_gyro) {
        return nullptr;
    }
    slam::GyroModel model;
    model.R_ItoC = imu->R_ItoC;
    model.bias_I_radps = imu->R_ItoC.transpose() * gyro_bias_C_;
    model.noise_density = static_cast<Scalar>(config_.gyro_noise_density);
    model.bias_sigma_radps = static_cast<Scalar>(config_.gyro_bias_sigma_radps);
    model.max_gap_ns = static_cast<std::int64_t>(config_.gyro_max_gap_s * 1e9);
    gyro = slam::integrateGyro(imu->samples, slam_.timestampNs(), t_ns, model);
    stats.gyro = gyro.coverage;
    return gyro.coverage == slam::GyroCoverage::kOk ? &gyro.rate : nullptr;
}

bool MonoTracker::isCoarseFrame(std::span<const slam::FeaturePrediction> preds) const {
    int over_budget = 0;
    for (const auto& pr : preds) {
        over_budget += searchLevel(pr.S) != 0 ? 1 : 0;
    }
    return !preds.empty() && static_cast<double>(over_budget) >=
                                 config_.coarse_min_fraction * static_cast<double>(preds.size());
}

bool MonoTracker::searchFeatures(const cv::Mat& gray,
                                 std::span<const slam::FeaturePrediction> preds, TrackStats& stats,
                                 StageLap& lap) {
    matches_.clear();
    // The pyramid is for a camera whose motion is uncertain (a long frame
    // gap, fast motion): then most ellipses outgrow the budget together. A
    // few large ones on a normal frame are searched as before (not at all):
    // a coarse match there is more often wrong than useful.
    const bool coarse_frame = isCoarseFrame(preds);
    for (int i = 0; i < static_cast<int>(preds.size()); ++i) {
        const auto& pr = preds[static_cast<size_t>(i)];
        FeatureAppearance* a = appearanceOf(pr.id);
        if (a == nullptr) {
            continue;
        }
        const int level = searchLevel(pr.S);
        if (level < 0 || (level > 0 && !coarse_frame)) {
            continue;  // too uncertain to search
        }
        core::Mat2 A = core::Mat2::Identity();
        if (config_.warp_patches) {
            const auto& f = slam_.features()[static_cast<size_t>(pr.slot)];
            if (!predictedWarp(f, *a, pr.h_px, slam_.pose(), A)) {
                continue;
            }
            if (level == 0) {
                warpTemplate(a->patch, A);
            }
        }
        stats.stage_us.search += lap.next();
        const auto m = level == 0 ? matcher_.match(gray, a->patch, pr.h_px, pr.S, config_.match)
                                  : matchCoarseToFine(gray, level, *a, A, pr.h_px, pr.S, stats);
        stats.stage_us.match += lap.next();
        if (m) {
            stats.search_evaluations += m->evaluated;
            matches_.push_back({i, m->px});
        }
    }
    return coarse_frame;
}

bool MonoTracker::countNearLoss(const slam::UpdateReport& report, bool coarse_frame) {
    const int accepted = report.low_innovation_inliers + report.rescued;
    const bool near_loss = config_.near_loss_ratio > 0 && !coarse_frame &&
                           report.predicted >= TrackerConfig::kNearLossMinSearched &&
                           static_cast<double>(accepted) <
                               config_.near_loss_ratio * static_cast<double>(report.predicted);
    near_loss_run_ = near_loss ? near_loss_run_ + 1 : 0;
    return near_loss;
}

void MonoTracker::manageMapAfterUpdate(std::int64_t t_ns, const cv::Mat& gray, bool bad_frame,
                                       TrackStats& stats) {
    stats.health = slam_.manageMap();
    if (stats.health == slam::SlamHealth::kOk && near_loss_run_ >= config_.near_loss_frames) {
        slam_.declareLost();  // a run of near-losses: lost, as after lost_after_frames
        stats.health = slam::SlamHealth::kLost;
    }
    previous_frame_good_ = !bad_frame && stats.health == slam::SlamHealth::kOk;
    if (stats.health == slam::SlamHealth::kLost && config_.relocalise_s > 0 &&
        knownFeatureCount() >= config_.relocalise_min_inliers) {
        // Keep the map and look for the camera in it from the next frame on.
        // (With fewer known features than a pose needs inliers, none can be
        // found however long it looks: KITTI's far features, seen by a camera
        // driving away from them. Then the caller starts a new map at once.)
        relocalising_ = true;
        lost_t_ns_ = t_ns;
        stats.health = slam::SlamHealth::kRelocalising;
    }
    dropDeletedAppearances();
    stats.visible = slam_.visibleCount();
    if (stats.health == slam::SlamHealth::kOk && stats.visible < config_.slam.min_visible) {
        stats.added = addFeatures(gray, config_.slam.min_visible - stats.visible, false);
    }
    countMap(stats);
}

void MonoTracker::countMap(TrackStats& stats) const {
    const auto features = slam_.features();
    stats.features = static_cast<int>(features.size());
    stats.xyz_features = static_cast<int>(std::ranges::count_if(
        features, [](const slam::FeatureInfo& f) { return f.kind == slam::FeatureKind::kXyz; }));
}

TrackStats MonoTracker::processFrame(std::int64_t t_ns, const cv::Mat& gray,
                                     const slam::ImuWindow* imu) {
    TrackStats stats;
    if (gray.empty() || gray.type() != CV_8UC1 || gray.cols != slam_.camera().width() ||
        gray.rows != slam_.camera().height()) {
        stats.health = slam_.health();
        return stats;
    }
    StageLap lap;
    const slam::GyroRate* checked =
        checkRotation(t_ns, gray, imu != nullptr && config_.use_gyro, stats);
    if (!has_map_) {
        startNewMap(t_ns, gray, stats);
        stats.stage_us.map = lap.next();
        return stats;
    }
    pyramid_built_ = 0;
    const slam::GyroRate* rate = nullptr;
    slam::GyroIntegration gyro;
    const bool bias_reference = previous_frame_good_;
    const core::Mat3 R_prev_CtoW = slam_.pose().R_CtoW;
    const std::int64_t t_prev_ns = slam_.timestampNs();
    previous_frame_good_ = false;
    if (relocalising_) {
        if (!relocaliseFrame(t_ns, gray, stats, lap)) {
            return stats;
        }
    } else {
        rate = integrateGyroForFrame(t_ns, imu, gyro, stats);
        if (rate == nullptr) {
            // The small images' rotation, when it says the model is off (never
            // beside IMU samples: checkRotation is told of them).
            rate = checked;
        }
        const slam::SlamHealth predicted = slam_.predict(t_ns, rate);
        stats.stage_us.predict = lap.next();
        if (predicted != slam::SlamHealth::kOk) {
            stats.health = predicted;
            stats.gyro.reset();  // nothing was predicted, with the gyro or without
            stats.rotation_check = false;
            return stats;
        }
    }
    const auto preds = slam_.predictMeasurements();
    const bool coarse_frame = searchFeatures(gray, preds, stats, lap);
    stats.stage_us.search += lap.next();
    const auto report = slam_.update(matches_);
    if (!report.bad_frame) {
        last_good_pose_ = slam_.pose();  // where relocalisation's guided search looks
        last_good_frame_ = slam_.frameIndex();
        if (config_.relocalise_s > 0) {
            refreshDescriptors(gray, preds);
        }
        if (rate != nullptr && !stats.rotation_check && bias_reference &&
            config_.gyro_bias_time_s > 0) {
            updateGyroBias(*rate, R_prev_CtoW, t_prev_ns, t_ns);
        }
    }
    stats.stage_us.update = lap.next();
    copyUpdateReport(report, stats);
    stats.near_loss = countNearLoss(report, coarse_frame);
    manageMapAfterUpdate(t_ns, gray, report.bad_frame, stats);
    if (start_check_.active && stats.health == slam::SlamHealth::kOk &&
        checkStart(t_ns, gray, preds, stats)) {
        stats.stage_us.map = lap.next();
        return stats;
    }
    adjustWindow(stats);
    stats.stage_us.map = lap.next();
    return stats;
}

void MonoTracker::beginStartCheckLink(std::span<const slam::FeaturePrediction> preds) {
    StartCheck& c = start_check_;
    c.suspect = false;
    c.next_flow_px = 0;
    c.R_StoW = slam_.pose().R_CtoW;
    c.p_SinW = slam_.pose().p_CinW;
    c.px_S.clear();
    // Every feature found in this frame, whether the filter took it or not
    // (a filter that has turned wrong rejects the matches that say so), and
    // those just added. (A map's first frame has no predictions.)
    for (const slam::FeatureMatch& m : preds.empty()
                                           ? std::span<const slam::FeatureMatch>{}
                                           : std::span<const slam::FeatureMatch>(matches_)) {
        c.px_S.emplace_back(preds[static_cast<std::size_t>(m.prediction)].id, m.z_px);
    }
    for (const auto& o : slam_.observations()) {
        if (std::ranges::find_if(c.px_S, [&](const auto& p) { return p.first == o.id; }) ==
            c.px_S.end()) {
            c.px_S.emplace_back(o.id, o.z_px);
        }
    }
}

double MonoTracker::collectStartPairs(std::span<const slam::FeaturePrediction> preds) {
    StartCheck& c = start_check_;
    c.x_S.clear();
    c.x_K.clear();
    c.px_K.clear();
    c.id_K.clear();
    c.scratch.clear();
    const auto& cam = slam_.camera();
    for (const slam::FeatureMatch& m : matches_) {
        const std::uint64_t id = preds[static_cast<std::size_t>(m.prediction)].id;
        const auto it = std::find_if(c.px_S.begin(), c.px_S.end(),
                                     [&](const auto& p) { return p.first == id; });
        if (it == c.px_S.end()) {
            continue;
        }
        const auto ray_S = cam.unproject(it->second);
        const auto ray_K = cam.unproject(m.z_px);
        if (!ray_S || !ray_K || !(ray_S->z() > 0) || !(ray_K->z() > 0)) {
            continue;
        }
        c.x_S.emplace_back(ray_S->head<2>() / ray_S->z());
        c.x_K.emplace_back(ray_K->head<2>() / ray_K->z());
        c.px_K.push_back(m.z_px);
        c.id_K.push_back(id);
        c.scratch.push_back(static_cast<double>((m.z_px - it->second).norm()));
    }
    if (c.x_S.size() < static_cast<std::size_t>(TrackerConfig::kStartCheckMinPairs)) {
        return -1;
    }
    return upperMedianInPlace(c.scratch);
}

bool MonoTracker::checkStart(std::int64_t t_ns, const cv::Mat& gray,
                             std::span<const slam::FeaturePrediction> preds, TrackStats& stats) {
    StartCheck& c = start_check_;
    if (static_cast<double>(t_ns - c.map_t0_ns) * 1e-9 > config_.start_check_s) {
        c.active = false;
        return false;
    }
    // The link's features seen now: their pixels then and now.
    const double flow_px = collectStartPairs(preds);
    // A suspect link is looked at again once its features have moved
    // farther, or at once when too few of them are left to wait for that.
    const bool last_chance =
        c.suspect &&
        c.x_S.size() <= 2 * static_cast<std::size_t>(TrackerConfig::kStartCheckMinPairs);
    if (flow_px < config_.start_check_flow_px || (!last_chance && flow_px < c.next_flow_px)) {
        return false;
    }
    c.depth_K.assign(c.x_K.size(), 0.0);
    const double focal = static_cast<double>(slam_.camera().intrinsics().fx);
    const auto two = estimateTwoViewMotion(c.x_S, c.x_K, focal, 1.0, c.depth_K);
    if (!two || two->inliers < TrackerConfig::kStartCheckMinInliers ||
        two->median_parallax_deg < TrackerConfig::kStartCheckMinParallaxDeg) {
        return false;  // too few pairs, or a turn with too little slide for two views
    }
    // The link's rotation by the two views and by the filter; the vertical
    // by the filter and by the two views' rotations chained from the start.
    const core::Mat3 R_KtoS_filter = c.R_StoW.transpose() * slam_.pose().R_CtoW;
    const Eigen::AngleAxis<Scalar> diff(two->R_KtoS.transpose() * R_KtoS_filter);
    const double diff_deg = std::abs(static_cast<double>(diff.angle())) * 180.0 / std::numbers::pi;
    const core::Mat3 R_KtoW_two = c.R_chain * two->R_KtoS;
    const core::Vec3 down_W = -slam_.upW();
    const core::Vec3 down_filter = slam_.pose().R_CtoW.transpose() * down_W;
    const core::Vec3 down_two = R_KtoW_two.transpose() * down_W;
    const double tilt_deg =
        std::acos(std::clamp(static_cast<double>(down_filter.dot(down_two)), -1.0, 1.0)) * 180.0 /
        std::numbers::pi;
    if (diff_deg <= config_.start_check_deg && tilt_deg <= config_.start_check_deg) {
        // Agreed: the next link starts here, the attitude carried across this one.
        c.R_chain = R_KtoW_two;
        beginStartCheckLink(preds);
        return false;
    }
    if (!c.suspect) {
        // Once may be the two views' error: look again over a longer baseline.
        c.suspect = true;
        c.next_flow_px = flow_px * TrackerConfig::kStartCheckConfirm;
        return false;
    }
    // The filter has turned away from both: start again here.
    return restartFromTwoViews(t_ns, gray, *two, R_KtoW_two, stats);
}

double MonoTracker::startCheckUnit() {
    // The map's unit per unit of the two views' baseline: the filter's
    // distance to each of the pairs' features over the two views' depth,
    // their median.
    StartCheck& c = start_check_;
    c.scratch.clear();
    const core::Vec3 p_KinW = slam_.pose().p_CinW;
    const auto features = slam_.features();
    for (std::size_t i = 0; i < c.id_K.size(); ++i) {
        if (!(c.depth_K[i] > 0)) {
            continue;
        }
        const auto it = std::ranges::find_if(
            features, [&](const slam::FeatureInfo& f) { return f.id == c.id_K[i]; });
        slam::MapPoint point;
        if (it == features.end() ||
            !slam_.mapPoint(static_cast<int>(it - features.begin()), point)) {
            continue;
        }
        const double distance = static_cast<double>((point.p_FinW - p_KinW).norm());
        if (std::isfinite(distance) && distance > 0) {
            c.scratch.push_back(distance / c.depth_K[i]);
        }
    }
    if (c.scratch.size() < static_cast<std::size_t>(TrackerConfig::kStartCheckMinInliers) / 2) {
        return 0;
    }
    return upperMedianInPlace(c.scratch);
}

bool MonoTracker::restartFromTwoViews(std::int64_t t_ns, const cv::Mat& gray,
                                      const TwoViewMotion& two, const core::Mat3& R_KtoW,
                                      TrackStats& stats) {
    StartCheck& c = start_check_;
    const double unit = startCheckUnit();
    if (!(unit > 0) || !std::isfinite(unit)) {
        return false;
    }
    // This frame's pose by the two views: the attitude chained from the
    // map's start (R_KtoW), the position from the link's first frame (the
    // map's origin, or a link the filter agreed on) along the two views'
    // translation, turned by the filter's attitude there (within
    // start_check_deg of the chain's) and scaled to the map's unit. The world
    // frame, its vertical and its unit go on.
    core::CameraPose T_KtoW;
    T_KtoW.R_CtoW = R_KtoW;
    T_KtoW.p_CinW = c.p_SinW + static_cast<Scalar>(unit) * (c.R_StoW * two.t_KinS);
    const auto sigma_theta =
        static_cast<Scalar>(TrackerConfig::kStartCheckRestartSigmaDeg * std::numbers::pi / 180.0);
    const auto sigma_p = static_cast<Scalar>(TrackerConfig::kStartCheckRestartSigmaBaseline * unit);
    if (!slam_.restartAt(t_ns, T_KtoW, sigma_p, sigma_theta)) {
        return false;
    }
    DepthPrior saved_prior = std::move(depth_prior_);
    const core::Scalar saved_sigma = depth_prior_rel_sigma_;
    // A new corner takes the depth of the two views' point within 5 px of it
    // (in the map's unit); the others start at rho0.
    depth_prior_ = [this, unit](const core::Vec2& px) -> std::optional<core::Scalar> {
        const StartCheck& sc = start_check_;
        double best = 25.0;
        std::optional<core::Scalar> depth;
        for (std::size_t i = 0; i < sc.px_K.size(); ++i) {
            const double d2 = static_cast<double>((sc.px_K[i] - px).squaredNorm());
            if (sc.depth_K[i] > 0 && d2 < best) {
                best = d2;
                depth = static_cast<core::Scalar>(sc.depth_K[i] * unit);
            }
        }
        return depth;
    };
    depth_prior_rel_sigma_ = static_cast<core::Scalar>(config_.start_check_depth_rel_sigma);
    // The bias learned from the map given up is not trusted.
    gyro_bias_C_ = c.gyro_bias_C;
    beginMap(t_ns, gray, stats);
    stats.start_redone = true;
    // The begun-again map is checked as a new one, kStartCheckMaxRestarts
    // times at most.
    start_check_.active = ++start_check_.restarts < TrackerConfig::kStartCheckMaxRestarts;
    start_check_.map_t0_ns = t_ns;
    depth_prior_ = std::move(saved_prior);
    depth_prior_rel_sigma_ = saved_sigma;
    return true;
}

}  // namespace scaled::drivers::vision
