#pragma once

// MonoTracker: the EKF MonoSLAM (core/slam) driven by the image front end.
//
// Per frame: predict, search every predicted feature with its patch (warped
// by the predicted change of appearance) inside its chi-square ellipse, hand
// the matches to the filter (1-point RANSAC and updates), manage the map, and
// initialise new features at corners in empty image regions when fewer than
// min_visible are in view. The first frame (and the first after reset())
// starts a new map: world = that camera frame, unit = the initial depth guess.

#include <array>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/vision/corner_detector.h>
#include <scaled/vision/matcher.h>
#include <scaled/vision/patch.h>

namespace scaled::vision {

struct TrackerConfig {
    core::slam::SlamConfig slam;
    CornerConfig corners;
    MatchConfig match;
    int patch_size = 11;         // matching template side, pixels (odd)
    int patch_source_size = 41;  // stored appearance the template is warped from
    bool warp_patches = true;    // predict the patch's appearance (plane-induced affine)
    int free_radius_px = 20;     // new corners keep this distance from features in view
    int max_new_per_frame = 10;
};

core::Result<bool> validate(const TrackerConfig& config);

struct TrackStats {
    core::slam::SlamHealth health = core::slam::SlamHealth::kUninitialised;
    bool new_map = false;        // this frame started a new map
    int predicted = 0;           // features searched
    int matched = 0;             // found by NCC
    int inliers = 0;             // low-innovation inliers of 1-point RANSAC
    int rescued = 0;             // high-innovation inliers rescued
    int added = 0;               // new features initialised
    int features = 0;            // map size after the frame
    int visible = 0;             // predicted in view
    int search_evaluations = 0;  // NCC evaluations (front-end cost)
    // The update's normalised innovations by feature age (UpdateReport).
    std::array<core::Scalar, core::slam::UpdateReport::kAgeBins> nis_sum{};
    std::array<int, core::slam::UpdateReport::kAgeBins> nis_count{};

    // Wall time of each stage of processFrame() on this frame, microseconds
    // (std::chrono::steady_clock; core stays clock-free, so the tracker times
    // the calls it makes into it). A stage that did not run on this frame is
    // 0: a new-map frame has only map_us, a frame whose prediction failed only
    // predict_us, a frame with no feature to search no match_us. The stages
    // are consecutive and do not overlap; their sum is the frame's time less
    // a few hundred nanoseconds (argument checks, the clock reads).
    double predict_us = 0;  // EkfSlam::predict: motion model, covariance propagation
    // EkfSlam::predictMeasurements (projections, innovation covariances S)
    // and, per predicted feature, the active-search setup outside the NCC
    // matcher: finding its appearance, the predicted patch warp
    // (predictedWarp) and warping the template (warpTemplate).
    double search_us = 0;
    double match_us = 0;   // Matcher::match calls: NCC search inside the chi-square ellipses
    double update_us = 0;  // EkfSlam::update: 1-point RANSAC and both EKF updates
    // EkfSlam::manageMap (deletion of bad features, inverse-depth to XYZ
    // conversion), dropping the deleted features' appearances, and new
    // features (free-region mask, corner detection, patch extraction,
    // EkfSlam::addFeature); on a new-map frame, initialise plus the first
    // features.
    double map_us = 0;
};

class MonoTracker {
public:
    static core::Result<MonoTracker> create(const core::PinholeRadialCamera& camera,
                                            const TrackerConfig& config);

    // gravity_down_C: unit gravity direction in the frame of the camera that
    // starts the next map (from the mount, the dataset or the robot).
    void setGravityDownC(const core::Vec3& gravity_down_C) { gravity_down_C_ = gravity_down_C; }
    // The next frame starts a new map.
    void reset();

    // Known depth for the features of a new map (distance along the ray, in
    // the unit the map should have), e.g. from a depth sensor, a known target
    // or, in simulation, the ground truth: it fixes the map's scale, as
    // MonoSLAM's initialisation target did. rel_sigma: relative depth std.
    // Without it (the default) new maps use slam.rho0 / slam.sigma_rho.
    using DepthPrior = std::function<std::optional<core::Scalar>(const core::Vec2& px)>;
    void setDepthPrior(DepthPrior prior, core::Scalar rel_sigma) {
        depth_prior_ = std::move(prior);
        depth_prior_rel_sigma_ = rel_sigma;
    }

    // gray: CV_8UC1 of the camera's size. t_ns strictly increasing.
    TrackStats processFrame(std::int64_t t_ns, const cv::Mat& gray);

    [[nodiscard]] const core::slam::EkfSlam& filter() const { return slam_; }
    [[nodiscard]] bool hasMap() const { return has_map_; }
    [[nodiscard]] const TrackerConfig& config() const { return config_; }

private:
    struct FeatureAppearance {
        std::uint64_t id = 0;
        Patch patch;
        core::CameraPose pose_at_init;  // camera that cut the patch (SLAM frame)
        core::Vec2 px_at_init = core::Vec2::Zero();
    };

    MonoTracker(core::slam::EkfSlam slam, const TrackerConfig& config);
    FeatureAppearance* appearanceOf(std::uint64_t id);
    void dropDeletedAppearances();
    // Forgets every appearance, keeping the patch buffers for new features.
    void clearAppearances();
    bool predictedWarp(const core::slam::FeatureInfo& f, const FeatureAppearance& a,
                       const core::Vec2& h_px, core::Mat2& A) const;
    int addFeatures(const cv::Mat& gray, int wanted, bool new_map);

    core::slam::EkfSlam slam_;
    TrackerConfig config_;
    Matcher matcher_;
    core::Vec3 gravity_down_C_ = core::Vec3(0, 1, 0);
    bool has_map_ = false;
    std::vector<FeatureAppearance> appearance_;
    // Patch buffers not in use, max_features of them allocated at create():
    // deleted features return theirs, new ones take one, so initialising
    // features in steady state does not allocate.
    std::vector<Patch> spare_patches_;
    std::vector<core::slam::FeatureMatch> matches_;
    std::vector<core::Vec2> occupied_;
    std::vector<core::Vec2> corners_;
    cv::Mat mask_;
    DepthPrior depth_prior_;
    core::Scalar depth_prior_rel_sigma_ = 0;
};

}  // namespace scaled::vision
