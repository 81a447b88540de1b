#pragma once

// EKF MonoSLAM without a known target (Civera, Davison, Montiel: inverse-depth
// features, 2008; 1-point RANSAC, 2010).
//
// One frame:
//   predict(t_ns[, gyro])          constant-velocity motion model, or the
//                                  gyro's rotation (gyro_prior.h)
//   predictMeasurements()          which features should be in view, where, and
//                                  their innovation covariance S (active search)
//   update(matches)                the front end's matches -> 1-point RANSAC,
//                                  low-innovation inlier update, rescue of
//                                  high-innovation inliers, second update
//   manageMap()                    delete unreliable features, convert
//                                  inverse-depth features to XYZ, health check
//   addFeature(px)                 undelayed initialisation of new features
//
// The world frame is the first camera frame and lengths are in SLAM units of
// unknown scale. Every buffer is sized at create(); the per-frame steps do not
// allocate.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/slam/feature_model.h>
#include <scaled/core/slam/gyro_prior.h>
#include <scaled/core/slam/motion_model.h>
#include <scaled/core/slam/slam_types.h>

namespace scaled::core::slam {

struct SlamConfig {
    // Tuned on handheld indoor sequences (7-Scenes redkitchen, docs/accuracy.md)
    // with the unit set by rho0 = 1: sigma_a in SLAM units/s^2.
    MotionNoise motion{Scalar(8), Scalar(1), Scalar(30)};
    Scalar pixel_sigma_px = 1;          // measurement noise of a matched feature
    Scalar init_sigma_v = Scalar(0.1);  // initial velocity std, SLAM units/s
    Scalar init_sigma_w = Scalar(0.1);  // initial angular velocity std, rad/s
    // Undelayed initialisation: inverse depth rho0 +- sigma_rho (1/SLAM unit).
    // The default puts the first features at depth 1: that defines the unit.
    Scalar rho0 = Scalar(1);
    Scalar sigma_rho = Scalar(1);
    Scalar linearity_threshold = Scalar(0.1);  // inverse depth -> XYZ below this

    int max_features = 80;        // map capacity (state size 13 + 6 * max_features)
    int max_measured = 50;        // features searched per frame
    int min_visible = 40;         // add features when fewer are predicted in view
    Scalar image_margin_px = 10;  // a prediction this close to the border is not searched

    // Active search and 1-point RANSAC.
    Scalar chi2_gate = Scalar(9.21);          // 2 dof, 99%: search ellipse and rescue gate
    Scalar ransac_threshold_px = Scalar(2);   // low-innovation inlier threshold
    Scalar ransac_confidence = Scalar(0.99);  // for the adaptive number of hypotheses
    int ransac_min_hypotheses = 1;  // at least this many, whatever the adaptive count says
    int ransac_max_hypotheses = 100;
    std::uint64_t seed = 1;

    // Map management.
    int delete_min_attempts = 10;           // judge a feature after this many searches
    Scalar delete_min_ratio = Scalar(0.5);  // delete below this matches/attempts ratio

    // Divergence.
    int min_inliers = 3;          // fewer accepted matches in a frame: a bad frame
    int lost_after_frames = 10;   // this many bad frames in a row: lost
    Scalar max_dt_s = Scalar(1);  // a larger frame gap is refused (the caller re-initialises)
};

// The allowed values of SlamConfig's parameters (param_limits.h): validate()
// checks them, the daemon's [tracker] section offers them.
struct SlamLimits {
    static constexpr ParamLimits sigma_a = openClosed(0, 1e4);
    static constexpr ParamLimits sigma_alpha = openClosed(0, 1e4);
    static constexpr ParamLimits sigma_a_reference_hz = closed(0, 1000);
    static constexpr ParamLimits pixel_sigma_px = openClosed(0, 100);
    static constexpr ParamLimits init_sigma_v = closed(0, 1e3);
    static constexpr ParamLimits init_sigma_w = closed(0, 1e3);
    static constexpr ParamLimits rho0 = closed(0, 1e3);
    static constexpr ParamLimits sigma_rho = openClosed(0, 1e3);
    static constexpr ParamLimits linearity_threshold = openClosed(0, 10);
    static constexpr ParamLimits max_features = closed(1, 1000);
    static constexpr ParamLimits max_measured = closed(1, 1000);  // and <= max_features
    static constexpr ParamLimits min_visible = closed(0, 1000);   // and <= max_features
    static constexpr ParamLimits image_margin_px = closed(0, 1000);
    static constexpr ParamLimits chi2_gate = openClosed(0, 1e4);
    static constexpr ParamLimits ransac_threshold_px = openClosed(0, 100);
    static constexpr ParamLimits ransac_confidence = openClosed(0, 0.999999);
    static constexpr ParamLimits ransac_min_hypotheses = closed(1, 10000);  // <= the max
    static constexpr ParamLimits ransac_max_hypotheses = closed(1, 10000);
    static constexpr ParamLimits seed = closed(0, kMaxInt64);
    static constexpr ParamLimits delete_min_attempts = closed(1, 1e6);
    static constexpr ParamLimits delete_min_ratio = closed(0, 1);
    static constexpr ParamLimits min_inliers = closed(1, 1000);
    static constexpr ParamLimits lost_after_frames = closed(1, 100000);
    static constexpr ParamLimits max_dt_s = openClosed(0, 3600);
};

// Checks ranges (SlamLimits) and the parameters' relations; the message
// names the field and value.
Status validate(const SlamConfig& config);

enum class SlamHealth : std::uint8_t {
    kUninitialised,
    kOk,
    kNonFinite,            // NaN or Inf in the state or covariance
    kNotPositiveDefinite,  // covariance lost positive definiteness
    kLost,                 // too few accepted matches for lost_after_frames frames
    kBadTimestamp,         // non-increasing or too large frame interval
    // Not the filter's own: the tracker lost the camera and keeps the map
    // while it tries to find the camera in it again (relocalisation).
    kRelocalising,
};
const char* toString(SlamHealth health);

// Numerical health of a state and covariance: kNonFinite (NaN/Inf anywhere),
// kNotPositiveDefinite (a negative variance, or the 13x13 camera block fails
// Cholesky), else kOk. The filter runs it after every frame.
SlamHealth assessNumericalHealth(const Eigen::Ref<const VecX>& x, const Eigen::Ref<const MatX>& P);

// A feature the filter expects in view, for the front end to search.
struct FeaturePrediction {
    int slot = 0;              // index into the filter's feature list this frame
    std::uint64_t id = 0;      // stable feature id
    Vec2 h_px = Vec2::Zero();  // predicted pixel
    Mat2 S = Mat2::Zero();     // innovation covariance, px^2 (measurement noise included)
};

// The front end's answer for one prediction (index into predictMeasurements()).
struct FeatureMatch {
    int prediction = 0;
    Vec2 z_px = Vec2::Zero();
};

struct UpdateReport {
    int predicted = 0;  // features searched
    int matched = 0;    // matches the front end returned
    int low_innovation_inliers = 0;
    int rescued = 0;
    int hypotheses = 0;
    bool bad_frame = false;
    // Consistency by feature age (issue 19): for the accepted matches, the
    // normalised innovation squared nu^T S^-1 nu at the predicted state (2 on
    // average for a consistent filter, 2 dof), summed per bin of the
    // feature's searches so far: [1, 5), [5, 15), [15, 50), 50 and more.
    static constexpr int kAgeBins = 4;
    std::array<Scalar, kAgeBins> nis_sum{};
    std::array<int, kAgeBins> nis_count{};
};

// A feature seen in this frame: an accepted match or a new feature's pixel
// (for a back end that keeps the tracks, window_ba.h).
struct FeatureObservation {
    std::uint64_t id = 0;
    Vec2 z_px = Vec2::Zero();
};

// What the scale estimator needs about one map point.
struct MapPoint {
    std::uint64_t id = 0;
    FeatureKind kind = FeatureKind::kInverseDepth;
    Vec3 p_FinW = Vec3::Zero();  // SLAM units
    Mat3 P_FinW = Mat3::Zero();  // first-order covariance of p_FinW
    Vec2 px = Vec2::Zero();      // projection by the current (updated) state
    bool in_view = false;        // px inside the image
    bool measured = false;       // accepted as a match this frame
};

struct FeatureInfo {
    std::uint64_t id = 0;
    FeatureKind kind = FeatureKind::kInverseDepth;
    int offset = 0;  // into the state vector
    int attempts = 0;
    int matches = 0;
    std::int64_t last_seen_frame = 0;  // last frame it was predicted in view
    std::int64_t first_frame = 0;      // the frame it was added on
    bool in_view = false;
    bool measured = false;
    Vec2 px = Vec2::Zero();
};

using Mat6x6 = Eigen::Matrix<Scalar, 6, 6>;

class EkfSlam {
public:
    static Result<EkfSlam> create(const PinholeRadialCamera& camera, const SlamConfig& config);

    // Starts a new map at the camera pose of this frame (identity, the world
    // frame). gravity_down_C: unit gravity direction in this camera's frame.
    void initialise(std::int64_t t_ns, const Vec3& gravity_down_C);

    // Motion model up to t_ns. kBadTimestamp if t_ns is not after the last frame
    // or the gap exceeds max_dt_s (state unchanged).
    // With a gyro rate over (last frame, t_ns] (gyro_prior.h), the angular
    // velocity is the gyro's (its variance sigma^2, uncorrelated with the rest
    // of the state) and the rotation is propagated without the
    // angular-acceleration impulse; a rate that is not finite or has no
    // positive sigma is ignored (the constant-velocity model runs).
    SlamHealth predict(std::int64_t t_ns, const GyroRate* gyro = nullptr);

    // Features predicted in view (at most max_measured, oldest first).
    std::span<const FeaturePrediction> predictMeasurements();

    // Matches for some of the predictions. Runs 1-point RANSAC and the updates.
    UpdateReport update(std::span<const FeatureMatch> matches);

    // Deletes unreliable features, converts inverse-depth features that became
    // linear, and checks the filter's health.
    SlamHealth manageMap();
    // The front end's verdict that the camera is lost although the last
    // frames had matches (a run of near-losses, MonoTracker): health() is
    // kLost until initialise() or relocalise().
    void declareLost();

    // Undelayed initialisation of a feature at a pixel of the current frame.
    // Returns its id, or 0 if the map is full, the pixel cannot be unprojected
    // or an input is not finite (sigma_rho must be > 0).
    std::uint64_t addFeature(const Vec2& px);
    std::uint64_t addFeature(const Vec2& px, Scalar rho, Scalar sigma_rho);
    // Makes room for n new features by deleting those out of view the longest.
    int makeRoom(int n);

    // Changes the map's unit: every position p becomes c + s (p - c) (camera,
    // Euclidean features, inverse-depth anchors), velocities and inverse
    // depths scale by s and 1/s, and the covariance with them. Every predicted
    // pixel stays the same (the map's scale is not observable): a correction
    // of the map's scale from outside the filter (window_ba.h). s > 0.
    void rescaleMap(Scalar s, const Vec3& centre_W);

    // The features seen in the current frame: the matches the last update()
    // accepted and the features added since (cleared by predict()).
    [[nodiscard]] std::span<const FeatureObservation> observations() const { return observations_; }

    // Puts the camera back into a map it lost (relocalisation): the camera at
    // T_CtoW with independent position and attitude uncertainty (std sigma_p
    // in SLAM units, sigma_theta in radians per axis), velocities zero with
    // the initial uncertainties of a new map, no correlation between the
    // camera and the features (the features keep theirs among themselves);
    // the filter's clock moves to t_ns and the bad-frame count restarts.
    // Nothing happens (false) before initialise() or for a non-finite input.
    bool relocalise(std::int64_t t_ns, const CameraPose& T_CtoW, Scalar sigma_p,
                    Scalar sigma_theta);
    // Empties the map and puts the camera at T_CtoW in the same world frame
    // (its origin, vertical and unit kept), uncertain as relocalise() makes
    // it: a map whose start was found wrong begins again without a new frame
    // (MonoTracker's start check). The frame count goes on. Nothing happens
    // (false) before initialise() or for a non-finite input.
    bool restartAt(std::int64_t t_ns, const CameraPose& T_CtoW, Scalar sigma_p, Scalar sigma_theta);
    // Removes the features added after `frame` (frameIndex()): after a loss,
    // those the filter added while it was no longer tracking, from a pose
    // that was a guess. Returns how many.
    int removeFeaturesAddedAfter(std::int64_t frame);

    [[nodiscard]] SlamHealth health() const { return health_; }
    [[nodiscard]] std::int64_t frameIndex() const { return frame_; }
    [[nodiscard]] std::int64_t timestampNs() const { return t_ns_; }
    [[nodiscard]] CameraPose pose() const;
    [[nodiscard]] Vec3 velocityW() const { return x_.segment<3>(kVel); }
    [[nodiscard]] Vec3 angularVelocityC() const { return x_.segment<3>(kAngVel); }
    // Covariance of (position, rotation error delta) with R_true = R_est Exp(delta).
    [[nodiscard]] Mat6x6 poseCovariance() const;
    [[nodiscard]] Vec3 upW() const { return up_W_; }
    void setGravityDownW(const Vec3& down_W) { up_W_ = -down_W.normalized(); }

    [[nodiscard]] std::span<const FeatureInfo> features() const { return features_; }
    [[nodiscard]] int stateDim() const { return n_; }
    [[nodiscard]] int visibleCount() const { return visible_count_; }
    // Map points for the scale estimator, written into out (cleared first;
    // reserve max_features to keep it allocation-free). Inverse-depth features
    // with rho <= 0 (at or beyond infinity) are left out.
    void mapPoints(std::vector<MapPoint>& out) const;
    // The map point of features()[slot]; false (out holds only id, kind and
    // measured) for an inverse-depth feature with rho <= 0.
    bool mapPoint(int slot, MapPoint& out) const;
    // Only the position of features()[slot] (mapPoint's p_FinW, without its
    // covariance and projection); false for an inverse-depth feature with
    // rho <= 0.
    bool pointInWorld(int slot, Vec3& p_FinW) const;

    [[nodiscard]] const SlamConfig& config() const { return config_; }
    [[nodiscard]] const PinholeRadialCamera& camera() const { return camera_; }
    // The full state and covariance (active part), for tests and logs.
    [[nodiscard]] Eigen::Ref<const VecX> state() const { return x_.head(n_); }
    [[nodiscard]] Eigen::Ref<const MatX> covariance() const { return P_.topLeftCorner(n_, n_); }

private:
    EkfSlam(const PinholeRadialCamera& camera, const SlamConfig& config);

    struct Candidate {
        int slot = 0;
        Vec2 z = Vec2::Zero();
        Mat2 S = Mat2::Zero();        // innovation covariance of the prediction
        Vec2 pred_px = Vec2::Zero();  // the prediction, before this frame's update
        FeatureProjection proj;
    };

    std::uint64_t addInverseDepth(const Vec2& px, Scalar rho, Scalar sigma_rho);
    bool projectSlot(const VecX& x, int slot, bool jacobians, FeatureProjection& out) const;
    Mat2 innovationCovariance(int slot, const FeatureProjection& proj) const;
    // update()'s steps, in order. Candidates: the usable matches, into cand_.
    int collectCandidates(std::span<const FeatureMatch> matches);
    // 1-point RANSAC over cand_[0..nc): the largest support into best_inliers_.
    void ransacLowInnovationInliers(int nc, UpdateReport& report);
    // One EKF update with best_inliers_; false if it failed.
    bool updateLowInnovationInliers(int nc, UpdateReport& report);
    // A second EKF update with the other matches that now pass the chi-square gate.
    void rescueHighInnovationMatches(int nc, UpdateReport& report);
    // Per-feature match counts and the report's NIS by feature age.
    void recordAcceptedMatches(int nc, UpdateReport& report);
    // EKF update with the candidates in cand_[0..count); false if S is not PD.
    bool ekfUpdate(int count);
    // ekfUpdate()'s steps on the workspace's first m = 2 count rows: S = L L^T
    // in place (false if S is not PD); P -= K S K^T on the lower triangle.
    // (The products and the gain stay in ekfUpdate(): moving them changes
    // GCC's inlining and so its fused multiply-adds on aarch64.)
    bool choleskyInnovation(Eigen::Index m);
    void downdateCovariance(Eigen::Index m);
    void removeDims(int offset, int dims);
    void removeSlot(int slot);
    void convertToXyz(int slot);
    void normalizeQuaternion();
    void symmetrize();
    SlamHealth checkHealth();
    std::uint64_t nextRandom();

    PinholeRadialCamera camera_;
    SlamConfig config_;
    int capacity_ = 0;  // maximum state dimension
    int n_ = 0;         // active state dimension
    VecX x_;
    MatX P_;
    std::vector<FeatureInfo> features_;
    std::vector<FeaturePrediction> predictions_;
    std::vector<Candidate> cand_;  // matched candidates of this frame
    std::vector<int> inliers_;     // indices into cand_
    std::vector<int> best_inliers_;
    std::vector<unsigned char> accepted_;           // per candidate
    std::vector<FeatureObservation> observations_;  // this frame's, max_measured + max_features
    // Scratch for updates, sized at create().
    MatX PHt_;  // capacity x 2 max_measured
    MatX S_;    // 2 max_measured square
    VecX nu_;   // 2 max_measured
    MatX Wt_;   // 2 max_measured x capacity: L^-1 (P H^T)^T
    VecX x_hyp_;
    MatX rows_;  // 6 x capacity
    Vec3 up_W_ = Vec3(0, -1, 0);
    std::int64_t t_ns_ = 0;
    std::int64_t frame_ = 0;
    std::uint64_t next_id_ = 1;
    std::uint64_t rng_ = 1;
    int bad_frames_ = 0;
    int visible_count_ = 0;
    SlamHealth health_ = SlamHealth::kUninitialised;
};

}  // namespace scaled::core::slam
