#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include <Eigen/LU>

#include <scaled/core/slam/feature_model.h>
#include <scaled/vision/mono_tracker.h>

namespace scaled::vision {

using core::Scalar;
using core::Vec2;
using core::Vec3;
namespace slam = core::slam;

namespace {

// Consecutive stage times of one frame (TrackStats::*_us): each next() reads
// the clock once and returns the microseconds since the previous read, so the
// stages tile the frame without gaps. No allocation; about 20 ns per read.
class StageLap {
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

}  // namespace

core::Result<bool> validate(const TrackerConfig& c) {
    if (auto ok = slam::validate(c.slam); !ok) {
        return ok.error();
    }
    auto bad = [](const std::string& key, int v, const char* allowed) {
        return core::makeError(
            core::ErrorCode::kInvalidArgument,
            "tracker." + key + " = " + std::to_string(v) + ": must be " + allowed);
    };
    if (c.patch_size < 5 || c.patch_size > 31 || c.patch_size % 2 == 0) {
        return bad("patch_size", c.patch_size, "odd, in [5, 31]");
    }
    if (c.patch_source_size < 2 * c.patch_size + 1 || c.patch_source_size > 101 ||
        c.patch_source_size % 2 == 0) {
        return bad("patch_source_size", c.patch_source_size, "odd, in [2 patch_size + 1, 101]");
    }
    if (c.free_radius_px < 1 || c.free_radius_px > 200) {
        return bad("free_radius_px", c.free_radius_px, "in [1, 200]");
    }
    if (c.max_new_per_frame < 1 || c.max_new_per_frame > c.slam.max_features) {
        return bad("max_new_per_frame", c.max_new_per_frame, "in [1, slam.max_features]");
    }
    if (!(c.match.min_ncc > -1 && c.match.min_ncc < 1)) {
        return core::makeError(
            core::ErrorCode::kInvalidArgument,
            "tracker.min_ncc = " + std::to_string(c.match.min_ncc) + ": must be in (-1, 1)");
    }
    return true;
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
    return MonoTracker(std::move(filter.value()), config);
}

MonoTracker::MonoTracker(slam::EkfSlam slam, const TrackerConfig& config)
    : slam_(std::move(slam)), config_(config) {
    // The filter's chi-square gate is the one the search ellipse uses.
    config_.match.chi2_gate = static_cast<double>(config_.slam.chi2_gate);
    appearance_.reserve(static_cast<size_t>(config.slam.max_features));
    matches_.reserve(static_cast<size_t>(config.slam.max_measured));
    occupied_.reserve(static_cast<size_t>(config.slam.max_features));
    corners_.reserve(static_cast<size_t>(config.max_new_per_frame) * 4);
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
    matcher_.reserve(config.patch_size, std::max(config.match.max_search_pixels, 3));
}

void MonoTracker::reset() {
    has_map_ = false;
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
                                const Vec2& h_px, core::Mat2& A) const {
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
    const core::CameraPose cur = slam_.pose();
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
        appearance_.push_back(std::move(a));
        ++added;
    }
    return added;
}

TrackStats MonoTracker::processFrame(std::int64_t t_ns, const cv::Mat& gray) {
    TrackStats stats;
    if (gray.empty() || gray.type() != CV_8UC1 || gray.cols != slam_.camera().width() ||
        gray.rows != slam_.camera().height()) {
        stats.health = slam_.health();
        return stats;
    }
    StageLap lap;
    if (!has_map_) {
        slam_.initialise(t_ns, gravity_down_C_);
        clearAppearances();
        has_map_ = true;
        stats.new_map = true;
        stats.added = addFeatures(gray, config_.slam.min_visible + config_.max_new_per_frame, true);
        stats.features = static_cast<int>(slam_.features().size());
        stats.visible = stats.added;
        stats.health = slam_.health();
        stats.map_us = lap.next();
        return stats;
    }
    const slam::SlamHealth predicted = slam_.predict(t_ns);
    stats.predict_us = lap.next();
    if (predicted != slam::SlamHealth::kOk) {
        stats.health = predicted;
        return stats;
    }
    const auto preds = slam_.predictMeasurements();
    matches_.clear();
    for (int i = 0; i < static_cast<int>(preds.size()); ++i) {
        const auto& pr = preds[static_cast<size_t>(i)];
        FeatureAppearance* a = appearanceOf(pr.id);
        if (a == nullptr) {
            continue;
        }
        if (config_.warp_patches) {
            core::Mat2 A;
            const auto& f = slam_.features()[static_cast<size_t>(pr.slot)];
            if (!predictedWarp(f, *a, pr.h_px, A)) {
                continue;
            }
            warpTemplate(a->patch, A);
        }
        stats.search_us += lap.next();
        const auto m = matcher_.match(gray, a->patch, pr.h_px, pr.S, config_.match);
        stats.match_us += lap.next();
        if (m) {
            stats.search_evaluations += m->evaluated;
            matches_.push_back({i, m->px});
        }
    }
    stats.search_us += lap.next();
    const auto report = slam_.update(matches_);
    stats.update_us = lap.next();
    stats.predicted = report.predicted;
    stats.matched = report.matched;
    stats.inliers = report.low_innovation_inliers;
    stats.rescued = report.rescued;
    stats.nis_sum = report.nis_sum;
    stats.nis_count = report.nis_count;
    stats.health = slam_.manageMap();
    dropDeletedAppearances();
    stats.visible = slam_.visibleCount();
    if (stats.health == slam::SlamHealth::kOk && stats.visible < config_.slam.min_visible) {
        stats.added = addFeatures(gray, config_.slam.min_visible - stats.visible, false);
    }
    stats.features = static_cast<int>(slam_.features().size());
    stats.map_us = lap.next();
    return stats;
}

}  // namespace scaled::vision
