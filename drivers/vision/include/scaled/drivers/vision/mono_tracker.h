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
#include <span>
#include <vector>

#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/window_ba.h>
#include <scaled/drivers/vision/brief.h>
#include <scaled/drivers/vision/corner_detector.h>
#include <scaled/drivers/vision/matcher.h>
#include <scaled/drivers/vision/patch.h>
#include <scaled/drivers/vision/small_image_rotation.h>
#include <scaled/drivers/vision/two_view.h>

namespace scaled::drivers::vision {

// Runs the window adjustment's deferred optimisations
// (window_ba.defer_frames > 0) off the tracking thread: start() hands over
// ba.runDue() and returns at once; wait() returns its report once it has
// run. Without one, the tracker runs it on the frame that starts it; either
// way its result is taken defer_frames frames later, so both give the same
// poses to the bit.
class OptimisationRunner {
public:
    OptimisationRunner() = default;
    OptimisationRunner(const OptimisationRunner&) = delete;
    OptimisationRunner& operator=(const OptimisationRunner&) = delete;
    virtual ~OptimisationRunner() = default;
    virtual void start(core::slam::WindowBa& ba) = 0;
    virtual core::slam::WindowBaReport wait() = 0;
};

struct TrackerConfig {
    core::slam::SlamConfig slam;
    // Sliding-window bundle adjustment of the filter's tracks and the map
    // scale correction it gives (core/slam/window_ba.h); on by default.
    core::slam::WindowBaConfig window_ba;
    CornerConfig corners;
    MatchConfig match;
    int patch_size = 11;         // matching template side, pixels (odd)
    int patch_source_size = 61;  // stored appearance the template is warped from
    bool warp_patches = true;    // predict the patch's appearance (plane-induced affine)
    int free_radius_px = 20;     // new corners keep this distance from features in view
    // New features keep this distance from the image border (a feature born
    // at the border leaves the view at once); the patch source may reach
    // beyond the border (replicated pixels).
    int feature_border_px = 20;
    int max_new_per_frame = 10;
    // Coarse-to-fine active search (issue 21): a feature whose gate ellipse
    // holds more than match.max_search_pixels pixels (fast motion, a long
    // frame gap) is searched at the first pyramid level (each level halves
    // the image) where it fits, with the template rendered at that level's
    // sampling, and the best coarse hit is refined at full resolution inside
    // the original gate. 0: no pyramid; such features are not searched.
    int pyramid_levels = 3;
    double coarse_min_ncc = 0.7;          // a coarse hit below this is not refined
    int coarse_max_search_pixels = 8000;  // the pixel budget at a pyramid level
    // The pyramid is used on a frame only when at least this fraction of the
    // searched features' ellipses outgrow the budget (the camera's motion is
    // uncertain, not one feature's depth).
    double coarse_min_fraction = 0.5;
    // A near-loss (docs/slam.md "Near-losses"): a frame searched at full
    // resolution only (the filter was sure of its prediction) on which fewer
    // than near_loss_ratio of its searched features (at least
    // kNearLossMinSearched) were accepted. near_loss_frames of them in a row
    // are a loss (relocalisation, then a new map): the filter is confidently
    // wrong, and each further update pulls the map with it. A frame searched
    // coarse-to-fine is never one (a long frame gap or fast motion accepts a
    // small share as a matter of course: KITTI at 10 Hz). 0: off.
    double near_loss_ratio = 0.25;
    int near_loss_frames = 4;
    static constexpr int kNearLossMinSearched = 10;
    // Relocalisation (issue 21): when the filter is lost, the map is kept and
    // every frame is matched against it (each map feature's template against
    // the image's corners, then a RANSAC PnP pose) for at most relocalise_s
    // seconds; health is kRelocalising meanwhile. A pose with at least
    // relocalise_min_inliers inliers within relocalise_reproj_px puts the
    // camera back into the map (same map, same scale); after the time is up
    // the health is kLost and the caller starts a new map. A map with fewer
    // known features (relocalise_max_rel_sigma) than relocalise_min_inliers
    // cannot give such a pose: it is given up at once. 0: no relocalisation.
    double relocalise_s = 3.0;
    int relocalise_min_inliers = 10;
    double relocalise_reproj_px = 3.0;
    int relocalise_corners = 600;            // corners of a frame the map is matched against
    int relocalise_max_brief_distance = 64;  // of 256 bits: a descriptor match
    int brief_refresh_frames = 5;  // a measured feature's descriptor is renewed this often
    // The guided search: each feature looked for within this radius (pixels)
    // of where the last well-tracked pose puts it, before the whole image.
    double relocalise_search_px = 200;
    // A PnP pose with fewer than relocalise_min_inliers inliers (but more
    // than the minimal sample) is verified: every known feature is searched
    // within this radius (pixels) of where that pose puts it, and the pose
    // solved from those matches must have relocalise_min_inliers. 0: not.
    double relocalise_verify_px = 12;
    // Map features whose position std exceeds this fraction of their distance
    // from the camera are not used (their point is a guess along the ray).
    double relocalise_max_rel_sigma = 0.1;
    // The gyro motion prior (issue 21, core/slam/gyro_prior.h): a frame
    // given IMU samples with a gyroscope that cover its interval is predicted
    // with the gyro's rotation; otherwise (no gyro, a gap, another clock) the
    // constant-velocity model runs. false: never.
    bool use_gyro = true;
    // The rotation check (docs/slam.md "The rotation check"): on a frame
    // predicted without a gyro, the rotation since the previous frame is
    // found from the two frames' small images (small_image_rotation.h). When
    // its rate differs from the motion model's angular velocity by more than
    // rotation_check_radps (a jolt the constant-velocity model cannot follow:
    // 0.6 rad/s is 10 px in a 30 Hz frame at f 525), the frame is predicted
    // with it as a gyro reading of rotation_check_sigma_radps. 0: off.
    double rotation_check_radps = 0.6;
    double rotation_check_sigma_radps = 0.2;
    double gyro_noise_density = 2e-4;     // rad/s/sqrt(Hz), white rate noise
    double gyro_bias_sigma_radps = 0.02;  // what is left of the bias (1 sigma)
    double gyro_max_gap_s = 0.05;         // a longer silence gives no gyro rate
    // The gyro's bias, estimated on line: on every well-tracked frame
    // predicted with the gyro, the gyro's rate (less the estimate) minus the
    // map's own rotation rate over the interval is averaged with this time
    // constant (seconds) into the estimate the next frames subtract. 0: none.
    double gyro_bias_time_s = 10;
    // The start check (docs/slam.md "A map started in motion", "The start
    // check"): for its first start_check_s seconds a new map's attitude is
    // compared with two views' (two_view.h: the essential matrix of the
    // features found in the link's first frame and now, whether the filter
    // took the matches or not), whenever their median image motion reaches
    // start_check_flow_px and their median parallax (the rotation taken out)
    // kStartCheckMinParallaxDeg. Two things are compared: the link's rotation
    // by the filter and by the two views, and the vertical by the filter and
    // by the two views' rotations chained from the map's start. Either off by
    // more than start_check_deg makes the link suspect; it is looked at again
    // once its features have moved kStartCheckConfirm times as far (or at
    // once when at most 2 kStartCheckMinPairs of them are left), and a second
    // disagreement begins the map again at that frame, in the same world
    // frame and unit (not a new map: no new epoch): the camera where the
    // chained two views put it (uncertain by kStartCheckRestartSigmaDeg and
    // kStartCheckRestartSigmaBaseline of the link's baseline), its first
    // features at the two views' depths (relative std
    // start_check_depth_rel_sigma, in the map's unit by the median ratio of
    // the filter's distances to theirs), the gyro bias as it was when the map
    // began. The map begun again is checked as a new one, and is begun again
    // kStartCheckMaxRestarts times at most. A link that agrees starts the
    // next one. A map whose first depths are given (setDepthPrior) is not
    // checked. The filter can take a slide for a turn while its depths are
    // unknown and then keeps a vertical 20-60 degrees off; two views cannot.
    // 0: off.
    double start_check_s = 2;
    double start_check_deg = 3;
    double start_check_flow_px = 15;
    double start_check_depth_rel_sigma = 0.3;
    static constexpr double kStartCheckConfirm = 1.5;
    static constexpr int kStartCheckMinPairs = 12;
    static constexpr int kStartCheckMinInliers = 10;
    static constexpr double kStartCheckMinParallaxDeg = 0.5;
    static constexpr double kStartCheckRestartSigmaDeg = 0.5;
    static constexpr double kStartCheckRestartSigmaBaseline = 0.1;
    static constexpr int kStartCheckMaxRestarts = 3;
};

// The allowed values of the front end's parameters (core/param_limits.h; the
// EKF's are core::slam::SlamLimits): validate() checks them, the daemon's
// [tracker] section offers them.
struct TrackerLimits {
    static constexpr core::ParamLimits patch_size = core::closed(5, 31);  // and odd
    // Odd and at least 2 patch_size + 1.
    static constexpr core::ParamLimits patch_source_size = core::closed(11, 101);
    static constexpr core::ParamLimits corner_quality = core::open(0, 1);
    static constexpr core::ParamLimits corner_min_distance_px = core::closed(1, 200);
    static constexpr core::ParamLimits max_new_per_frame =
        core::closed(1, 1000);  // <= max_features
    static constexpr core::ParamLimits min_ncc = core::open(-1, 1);
    static constexpr core::ParamLimits max_search_pixels = core::closed(1, 1e6);
    static constexpr core::ParamLimits pyramid_levels = core::closed(0, 3);
    static constexpr core::ParamLimits coarse_max_search_pixels = core::closed(1, 1e6);
    static constexpr core::ParamLimits coarse_min_fraction = core::closed(0, 1);
    static constexpr core::ParamLimits near_loss_ratio = core::closed(0, 1);
    static constexpr core::ParamLimits near_loss_frames = core::closed(1, 1000);
    static constexpr core::ParamLimits coarse_min_ncc = core::open(-1, 1);
    static constexpr core::ParamLimits feature_border_px = core::closed(0, 200);
    static constexpr core::ParamLimits free_radius_px = core::closed(1, 200);
    static constexpr core::ParamLimits relocalise_s = core::closed(0, 3600);
    static constexpr core::ParamLimits relocalise_min_inliers = core::closed(4, 1000);
    static constexpr core::ParamLimits relocalise_reproj_px = core::openClosed(0, 100);
    static constexpr core::ParamLimits relocalise_max_brief_distance = core::closed(0, 256);
    static constexpr core::ParamLimits brief_refresh_frames = core::closed(1, 100000);
    static constexpr core::ParamLimits relocalise_corners = core::closed(1, 10000);
    static constexpr core::ParamLimits relocalise_search_px = core::closed(0, 10000);
    static constexpr core::ParamLimits relocalise_verify_px = core::closed(0, 1000);
    static constexpr core::ParamLimits relocalise_max_rel_sigma = core::openClosed(0, 10);
    static constexpr core::ParamLimits rotation_check_radps = core::closed(0, 100);
    static constexpr core::ParamLimits rotation_check_sigma_radps = core::openClosed(0, 100);
    static constexpr core::ParamLimits gyro_noise_density = core::closed(0, 1);  // rad/s/sqrt(Hz)
    static constexpr core::ParamLimits gyro_bias_sigma_radps = core::closed(0, 10);
    static constexpr core::ParamLimits gyro_bias_time_s = core::closed(0, 3600);
    static constexpr core::ParamLimits gyro_max_gap_s = core::openClosed(0, 1);
    static constexpr core::ParamLimits start_check_s = core::closed(0, 60);
    static constexpr core::ParamLimits start_check_deg = core::openClosed(0, 90);
    static constexpr core::ParamLimits start_check_flow_px = core::openClosed(0, 1000);
    static constexpr core::ParamLimits start_check_depth_rel_sigma = core::openClosed(0, 10);
};

// Checks TrackerLimits, core::slam::SlamLimits and the parameters' relations;
// the message names the key and value.
core::Status validate(const TrackerConfig& config);

// Wall time of each stage of MonoTracker::processFrame() on one frame,
// microseconds (std::chrono::steady_clock; core stays clock-free, so the
// tracker times the calls it makes into it). A stage that did not run on the
// frame is 0: a new-map frame has only map, a frame whose prediction failed
// only predict, a frame with no feature to search no match. The stages are
// consecutive and do not overlap; their sum is the frame's time less a few
// hundred nanoseconds (argument checks, the clock reads). Embedded as it is in
// the daemon's frame events and field-log FRAME lines ("stage_us").
struct StageTimes {
    double predict = 0;  // EkfSlam::predict: motion model, covariance propagation
    // EkfSlam::predictMeasurements (projections, innovation covariances S)
    // and, per predicted feature, the active-search setup outside the NCC
    // matcher: finding its appearance, the predicted patch warp
    // (predictedWarp) and warping the template (warpTemplate).
    double search = 0;
    double match = 0;   // Matcher::match calls: NCC search inside the chi-square ellipses
    double update = 0;  // EkfSlam::update: 1-point RANSAC and both EKF updates
    // EkfSlam::manageMap (deletion of bad features, inverse-depth to XYZ
    // conversion), dropping the deleted features' appearances, and new
    // features (free-region mask, corner detection, patch extraction,
    // EkfSlam::addFeature), then the window bundle adjustment (a keyframe,
    // and every window_ba.step_keyframes keyframes an optimisation); on a
    // new-map frame, initialise plus the first features.
    double map = 0;
};

struct TrackStats {
    core::slam::SlamHealth health = core::slam::SlamHealth::kUninitialised;
    bool new_map = false;  // this frame started a new map
    // The start check found the map's start wrong (the map was at most
    // start_check_s old) and began it again at this frame: new features, the
    // camera moved to where two views put it, the same world frame and unit
    // (not a new map).
    bool start_redone = false;
    int predicted = 0;           // features searched
    int matched = 0;             // found by NCC
    int inliers = 0;             // low-innovation inliers of 1-point RANSAC
    int rescued = 0;             // high-innovation inliers rescued
    int added = 0;               // new features initialised
    int features = 0;            // map size after the frame
    int xyz_features = 0;        // of which converted to XYZ (depth converged)
    int visible = 0;             // predicted in view
    int search_evaluations = 0;  // NCC evaluations (front-end cost)
    int coarse_searches = 0;     // features searched coarse-to-fine (pyramid_levels)
    int coarse_matches = 0;      // of which matched at full resolution
    bool relocalised = false;    // this frame put the camera back into the lost map
    bool near_loss = false;      // a near-loss frame (near_loss_ratio)
    // Predicted with the small images' rotation (rotation_check_radps).
    bool rotation_check = false;
    // The window bundle adjustment on this frame (window_ba.enabled): whether
    // it optimised, and the scale it gave the map.
    core::slam::WindowBaReport window_ba;
    // The gyro prior on this frame: kOk when the prediction used it; unset
    // when no IMU samples were given (or use_gyro is off, or no prediction ran).
    std::optional<core::slam::GyroCoverage> gyro;
    int relocalise_candidates = 0;     // map features matched to corners (relocalising frames)
    int relocalise_inliers = 0;        // of which the PnP pose kept
    bool relocalise_verified = false;  // the pose came from verifying a weaker hypothesis
    int relocalise_dropped = 0;        // features added while lost, removed at relocalisation
    // The update's normalised innovations by feature age (UpdateReport).
    std::array<core::Scalar, core::slam::UpdateReport::kAgeBins> nis_sum{};
    std::array<int, core::slam::UpdateReport::kAgeBins> nis_count{};

    StageTimes stage_us;  // this frame's stages, microseconds
    // While relocalising: the attempt (corners, template scan, PnP, and on
    // success the filter's reset); the frame's search and update follow.
    double relocalise_us = 0;
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

    // gray: CV_8UC1 of the camera's size. t_ns strictly increasing. imu: the
    // samples for the gyro prior, when the system has a gyroscope.
    TrackStats processFrame(std::int64_t t_ns, const cv::Mat& gray,
                            const core::slam::ImuWindow* imu = nullptr);

    [[nodiscard]] const core::slam::EkfSlam& filter() const { return slam_; }
    // The camera's pose: the filter's, or with window_ba the newest adjusted
    // keyframe composed with the filter's motion since it.
    [[nodiscard]] core::CameraPose pose() const {
        return ba_ ? servedFromFilter().apply(slam_.pose()) : slam_.pose();
    }
    // The filter's world carried into pose()'s (identity without window_ba):
    // for the filter's points, velocity and gravity in the served frame.
    // While a deferred optimisation runs, the one from before it.
    [[nodiscard]] core::slam::Sim3 servedFromFilter() const {
        if (!ba_) {
            return {};
        }
        return ba_due_ ? ba_served_ : ba_->adjustedFromFilter();
    }
    // Where window_ba.defer_frames > 0 runs its optimisations (nullptr: on the
    // tracking thread). Set before the first frame; it must outlive every
    // frame this tracker processes and wait() for a started optimisation
    // before the tracker is destroyed.
    void setOptimisationRunner(OptimisationRunner* runner) { runner_ = runner; }
    [[nodiscard]] bool hasMap() const { return has_map_; }
    // The gyro bias estimate (gyro_bias_time_s), camera frame, rad/s: kept
    // across maps (it belongs to the device, not the map).
    [[nodiscard]] const core::Vec3& gyroBiasC() const { return gyro_bias_C_; }
    [[nodiscard]] const TrackerConfig& config() const { return config_; }

private:
    struct FeatureAppearance {
        std::uint64_t id = 0;
        Patch patch;
        core::CameraPose pose_at_init;  // camera that cut the patch (SLAM frame)
        core::Vec2 px_at_init = core::Vec2::Zero();
        // Its look where it was last measured (refreshed every few frames),
        // for relocalisation.
        BriefDescriptor brief{};
        bool has_brief = false;
        std::int64_t brief_frame = 0;
    };

    MonoTracker(core::slam::EkfSlam slam, std::optional<core::slam::WindowBa> ba,
                const TrackerConfig& config);
    // The window bundle adjustment's step after a tracked frame, and the
    // scale correction of the map it gives.
    void adjustWindow(TrackStats& stats);
    // A deferred optimisation's end: its report into stats, the scale it
    // hands the filter (scale_feedback).
    void finishDueOptimisation(TrackStats& stats);
    // A new window (ba_ engaged): a running optimisation is waited for and
    // dropped first.
    void resetWindow();
    void applyWindowScale(const core::slam::WindowBaReport& report);

    // The steps of processFrame(). StageLap (mono_tracker.cpp) times them.
    class StageLap;
    // The first frame of a map: initialise the filter, then the first features.
    void startNewMap(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats);
    // What follows the filter's start: the first features, the relocalisation
    // and start-check bookkeeping, the window.
    void beginMap(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats);
    // A frame while relocalising: true when the camera is back in the map
    // (the frame's search and update follow), false when the frame ends here.
    bool relocaliseFrame(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats, StageLap& lap);
    // The gyro's rate over the frame interval (in `gyro`) when the IMU window
    // covers it; nullptr otherwise (the constant-velocity model runs).
    const core::slam::GyroRate* integrateGyroForFrame(std::int64_t t_ns,
                                                      const core::slam::ImuWindow* imu,
                                                      core::slam::GyroIntegration& gyro,
                                                      TrackStats& stats) const;
    // The rotation check: pushes the frame's small image (every frame, so
    // the previous one is always the last frame's) and, on a frame the
    // filter will predict without a gyro (gyro_given: IMU samples came with
    // it), returns the small images' rate when it differs from the motion
    // model's by more than rotation_check_radps; else nullptr.
    const core::slam::GyroRate* checkRotation(std::int64_t t_ns, const cv::Mat& gray,
                                              bool gyro_given, TrackStats& stats);
    // Median depth (camera z) of the features the last update accepted; 0
    // with fewer than 5.
    core::Scalar medianMeasuredDepth();
    // Enough ellipses outgrow the pixel budget for the pyramid to be used
    // (coarse_min_fraction).
    [[nodiscard]] bool isCoarseFrame(std::span<const core::slam::FeaturePrediction> preds) const;
    // Active search of every predicted feature with its patch: into matches_.
    // Returns whether the frame was searched coarse-to-fine (isCoarseFrame).
    bool searchFeatures(const cv::Mat& gray, std::span<const core::slam::FeaturePrediction> preds,
                        TrackStats& stats, StageLap& lap);
    // Whether the update's share of accepted matches makes this a near-loss
    // frame (near_loss_ratio; never one searched coarse-to-fine); counts
    // near_loss_run_.
    bool countNearLoss(const core::slam::UpdateReport& report, bool coarse_frame);
    // The map's size and how many of its features are XYZ, into stats.
    void countMap(TrackStats& stats) const;
    // After the update: map management, relocalisation on loss, new features.
    void manageMapAfterUpdate(std::int64_t t_ns, const cv::Mat& gray, bool bad_frame,
                              TrackStats& stats);
    // One step of the on-line gyro bias estimate (gyro_bias_time_s) after a
    // good update of a frame predicted with `rate`.
    void updateGyroBias(const core::slam::GyroRate& rate, const core::Mat3& R_prev_CtoW,
                        std::int64_t t_prev_ns, std::int64_t t_ns);
    FeatureAppearance* appearanceOf(std::uint64_t id);
    void dropDeletedAppearances();
    // Forgets every appearance, keeping the patch buffers for new features.
    void clearAppearances();
    // The predicted warp of a's patch at pixel h_px seen from camera pose cur.
    bool predictedWarp(const core::slam::FeatureInfo& f, const FeatureAppearance& a,
                       const core::Vec2& h_px, const core::CameraPose& cur, core::Mat2& A) const;
    int addFeatures(const cv::Mat& gray, int wanted, bool new_map);
    // One relocalisation attempt on this frame: true when the filter has the
    // camera back (slam_.relocalise), its stats in `stats`. First the guided
    // search around the last well-tracked pose, then the whole-image search.
    bool tryRelocalise(std::int64_t t_ns, const cv::Mat& gray, TrackStats& stats);
    // The map point of a feature whose position is known well enough to
    // relocalise against (relocalise_max_rel_sigma).
    bool knownMapPoint(int slot, core::slam::MapPoint& mp) const;
    // How many of the map's features are known well enough (a relocalised
    // pose needs relocalise_min_inliers of them).
    [[nodiscard]] int knownFeatureCount() const;
    void addRelocPoint(const core::Vec3& p_FinW, const core::Vec2& px);
    void guidedRelocCandidates(const cv::Mat& gray, TrackStats& stats, const core::CameraPose& from,
                               core::Scalar radius_px);
    void globalRelocCandidates(const cv::Mat& gray);
    // Renews the descriptors of the features this frame's update accepted.
    void refreshDescriptors(const cv::Mat& gray,
                            std::span<const core::slam::FeaturePrediction> preds);
    // RANSAC PnP over the candidates; the pose when enough inliers agree.
    // A PnP hypothesis to verify needs more inliers than AP3P's minimal sample.
    static constexpr int kMinHypothesisInliers = 5;
    std::optional<core::CameraPose> solveRelocPose(TrackStats& stats, int min_inliers);
    // The pyramid level (1..pyramid_levels) whose gate ellipse fits the pixel
    // budget, 0 when the full-resolution search does, -1 when none does.
    [[nodiscard]] int searchLevel(const core::Mat2& S) const;
    // Level `level` of this frame's pyramid, built on first use.
    const cv::Mat& pyramidLevel(const cv::Mat& gray, int level);
    // Coarse search at `level` with the template rendered at that level's
    // sampling (A_full: the full-resolution warp), then the refinement at full
    // resolution; leaves the full-resolution template in a.patch.
    std::optional<Match> matchCoarseToFine(const cv::Mat& gray, int level, FeatureAppearance& a,
                                           const core::Mat2& A_full, const core::Vec2& h_px,
                                           const core::Mat2& S, TrackStats& stats);

    core::slam::EkfSlam slam_;
    std::optional<core::slam::WindowBa> ba_;  // when window_ba.enabled
    OptimisationRunner* runner_ = nullptr;
    bool ba_due_ = false;         // a deferred optimisation runs (ba_ is the runner's)
    int ba_due_frames_ = 0;       // frames since it started
    int ba_due_tracked_ = 0;      // of them, tracked ones (the window's frame count)
    core::slam::Sim3 ba_served_;  // servedFromFilter() while it runs
    core::slam::WindowBaReport ba_inline_report_;  // its report, run without a runner
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
    std::array<cv::Mat, 4> pyramid_;  // levels 1.. of the current frame (buffers reused)
    int pyramid_built_ = 0;           // levels of pyramid_ valid for the current frame
    bool relocalising_ = false;
    std::int64_t lost_t_ns_ = 0;  // when the filter was lost
    // Relocalisation scratch (reserved at create()).
    std::vector<cv::Point3f> reloc_points_W_;
    std::vector<cv::Point2f> reloc_points_n_;  // normalised image coordinates
    std::vector<core::Scalar> depth_scratch_;
    SmallImageRotation small_rotation_;  // the rotation check's images
    core::slam::GyroRate checked_rate_;  // its rate on a frame where it fired
    struct RelocCandidate {
        int slot = -1;
        int corner = -1;
        double ncc = -2;
        core::Vec2 px = core::Vec2::Zero();
    };
    std::vector<RelocCandidate> reloc_candidates_;
    std::vector<int> reloc_inliers_;
    std::vector<BriefDescriptor> corner_briefs_;  // of corners_, while relocalising
    std::vector<unsigned char> corner_has_brief_;
    core::CameraPose last_good_pose_;   // the last frame that was not a bad frame
    std::int64_t last_good_frame_ = 0;  // its frameIndex()
    core::Vec3 gyro_bias_C_ = core::Vec3::Zero();
    // The previous frame's updated pose was good (same map, not a bad frame):
    // the reference the gyro bias is measured against.
    bool previous_frame_good_ = false;
    // Near-loss frames in a row (near_loss_ratio) in this map since it was
    // started or relocalised.
    int near_loss_run_ = 0;
    DepthPrior depth_prior_;
    core::Scalar depth_prior_rel_sigma_ = 0;
    // The start check (start_check_s): the current link's first frame (its
    // features' pixels, the filter's attitude, the vertical), and whether the
    // last check disagreed. Buffers reserved at create().
    struct StartCheck {
        bool active = false;
        bool suspect = false;
        int restarts = 0;
        std::int64_t map_t0_ns = 0;
        double next_flow_px = 0;
        core::Mat3 R_StoW = core::Mat3::Identity();  // the filter's attitude at the link's start
        core::Vec3 p_SinW = core::Vec3::Zero();      // and its position
        // The attitude at the link's start by the two views' rotations of the
        // links before, chained from the map's (re)start.
        core::Mat3 R_chain = core::Mat3::Identity();
        core::Vec3 gyro_bias_C = core::Vec3::Zero();  // the gyro bias when the map began
        std::vector<std::pair<std::uint64_t, core::Vec2>> px_S;
        std::vector<core::Vec2> x_S;  // pairs of the check, normalised
        std::vector<core::Vec2> x_K;
        std::vector<core::Vec2> px_K;
        std::vector<std::uint64_t> id_K;
        std::vector<double> depth_K;
        std::vector<double> scratch;
    };
    StartCheck start_check_;
    void beginStartCheckLink(std::span<const core::slam::FeaturePrediction> preds);
    // After a tracked frame: true when it restarted the map.
    bool checkStart(std::int64_t t_ns, const cv::Mat& gray,
                    std::span<const core::slam::FeaturePrediction> preds, TrackStats& stats);
    // The link's features seen in this frame into x_S, x_K, px_K: their
    // median motion in pixels, or -1 with fewer than kStartCheckMinPairs.
    double collectStartPairs(std::span<const core::slam::FeaturePrediction> preds);
    // The map's unit per unit of the two views' baseline (from the pairs'
    // depths in both), or 0 with too few.
    double startCheckUnit();
    // The map begun again at this frame, in the same world frame and unit:
    // the camera where the two views put it from the link's first frame, the
    // first features at depth_K's depths. false (nothing done) with too few
    // depths.
    bool restartFromTwoViews(std::int64_t t_ns, const cv::Mat& gray, const TwoViewMotion& two,
                             const core::Mat3& R_KtoW, TrackStats& stats);
};

}  // namespace scaled::drivers::vision
