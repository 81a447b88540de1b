#pragma once

// ScaleEstimator: the paper's estimator. For every detection of a class with a
// height prior, every map feature whose projection falls inside the box gives
// an observation D (vertical_extent.h); its likelihood over d (likelihood.h)
// multiplies the grid posterior (scale_posterior.h).
//
// Buffers are sized at construction; update() does not allocate.
// config.posterior.arithmetic = kFixed evaluates each likelihood with
// FixedLikelihood and accumulates it in the fixed-point posterior
// (fixed_posterior.h): no floating point in any per-bin loop.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/object_evidence.h>
#include <scaled/core/scale/scale_posterior.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::core {

struct Detection {
    BoundingBox box;
    std::string_view class_name;  // must outlive the update() call
    Scalar score = 1;
};

// What the estimator needs of the SLAM state at the frame a detection ran on.
struct FrameSnapshot {
    CameraPose pose;
    Vec3 up_W = Vec3(0, 0, 1);  // unit "up" (against gravity) in the world frame
    std::span<const MapFeature> features;
    std::int64_t frame_id = 0;  // the caller's id of the image (object views keep it)
};

// Which evidence the posterior is made of.
enum class EstimatorModel : std::uint8_t {
    // The paper: every map feature inside a box is an observation with its own
    // height drawn from the class prior (ObservationWeighting below).
    kPaper,
    // Objects (object_evidence.h): detections associated into physical
    // objects with 3-D anchors; one unknown height (and width) per object.
    kObject,
};
const char* toString(EstimatorModel model);

enum class ObservationWeighting : std::uint8_t {
    kPerFeature,  // the paper: every feature in a box is an independent factor
    kPerBox,      // each box contributes one factor: features share weight 1/n
};

struct EstimatorConfig {
    EstimatorModel model = EstimatorModel::kPaper;
    ObjectConfig objects;  // model kObject
    PosteriorConfig posterior;
    LikelihoodConfig likelihood;
    ExtentConfig extent;
    ObservationWeighting weighting = ObservationWeighting::kPerFeature;
    bool use_non_upright = false;  // classes with upright = false give no observations
    Scalar min_detection_score = 0;
    int max_features_per_box = 64;  // bound on work per box (first ones in feature order)
};

// One observation: a (detection, feature) pair that passed the geometry
// (model kPaper), or a detection that is a used view of an object (kObject:
// feature_index -1, D and sigma_D_box measured on the object's anchor).
struct ObservationRecord {
    int detection_index = -1;
    int feature_index = -1;
    int object_id = 0;  // kObject: the object's id
    Scalar kappa = 0;   // kObject: (|tan t| + |tan b|) / 2 of the view
    Scalar D = 0;
    Scalar sigma_D_paper = 0;
    Scalar sigma_D_feature = 0;
    Scalar sigma_D_box = 0;
    Scalar local_estimate = 0;  // mode of this observation's likelihood alone
    Scalar weight = 1;
};

struct UpdateStats {
    int detections_used = 0;     // detections with a prior that produced >= 1 observation
    int detections_skipped = 0;  // unknown class, non-upright, low score, or no observation
    int observations = 0;
    std::array<int, static_cast<std::size_t>(ExtentStatus::kCount)> rejected{};
    int records_written = 0;  // into the caller's span (at most its size)
    // kObject: objects and views in the posterior after this update, objects
    // created by it.
    int objects_used = 0;
    int views_used = 0;
    int new_objects = 0;
};

// The allowed values of EstimatorConfig's own parameters and of its
// likelihood and extent parts (param_limits.h): ScaleEstimator::create
// checks them, the daemon's [estimator] section offers them. The posterior's
// are PosteriorLimits, the objects' ObjectLimits.
struct EstimatorLimits {
    static constexpr ParamLimits max_features_per_box = closed(1, 4096);
    static constexpr ParamLimits min_detection_score = closed(0, 1);
    static constexpr ParamLimits outlier_weight = open(0, 1);
    static constexpr ParamLimits outlier_height_range_m = openClosed(0, 1e3);
    static constexpr ParamLimits partial_weight = closed(0, 0.99);
    static constexpr ParamLimits min_sigma_m = openClosed(0, 10);
    static constexpr ParamLimits box_edge_sigma_px = closed(0, 1000);
    static constexpr ParamLimits border_margin_px = closed(0, 1000);
    static constexpr ParamLimits min_extent_px = closed(0, 10000);
};

class ScaleEstimator {
public:
    static Result<ScaleEstimator> create(const EstimatorConfig& config, PriorTable priors,
                                         const PinholeRadialCamera& camera);

    // One frame's detections against that frame's SLAM snapshot. Per-observation
    // records go to `records` (as many as fit).
    UpdateStats update(const FrameSnapshot& frame, std::span<const Detection> detections,
                       std::span<ObservationRecord> records = {});

    // Forget all evidence (e.g. after SLAM re-initialised with a new scale).
    void reset();

    // Replaces the height priors and keeps the posterior (the daemon's SIGHUP
    // reload): later updates use the new priors, earlier evidence stays.
    // Allocates (the table is moved in); not for the per-frame path.
    Status setPriors(PriorTable priors);

    [[nodiscard]] ScaleSummary summary() const { return posterior_.summary(); }
    [[nodiscard]] const ScalePosterior& posterior() const { return posterior_; }
    [[nodiscard]] const PriorTable& priors() const { return priors_; }
    [[nodiscard]] const EstimatorConfig& config() const { return config_; }
    // The object table (model kObject), else nullptr.
    [[nodiscard]] const ObjectEvidence* objects() const { return objects_ ? &*objects_ : nullptr; }
    // The 95% relative width the evidence could reach at best (kObject: the
    // distinct objects used and their classes' spreads); 0 when not known.
    [[nodiscard]] Scalar informationLimitRelWidth95() const {
        return objects_ ? objects_->informationLimitRelWidth95() : Scalar(0);
    }

private:
    ScaleEstimator(const EstimatorConfig& config, PriorTable priors,
                   const PinholeRadialCamera& camera, ScalePosterior posterior,
                   std::optional<FixedLikelihood> fixed_likelihood,
                   std::optional<ObjectEvidence> objects);
    UpdateStats updateObjects(const FrameSnapshot& frame, std::span<const Detection> detections,
                              std::span<ObservationRecord> records);
    // The prior of a detection, or nullptr when it is skipped (unknown class,
    // not upright unless use_non_upright, score below the minimum).
    [[nodiscard]] const HeightPrior* priorFor(const Detection& det) const;
    // One observation's likelihood into the posterior; its local mode (when
    // local_estimate is not null) on success.
    bool addObservation(const VerticalExtent& extent, const HeightPrior& prior, Scalar weight,
                        Scalar* local_estimate);

    EstimatorConfig config_;
    PriorTable priors_;
    PinholeRadialCamera camera_;
    ScalePosterior posterior_;
    std::vector<Scalar> log_l_;
    std::optional<FixedLikelihood> fixed_likelihood_;  // fixed arithmetic only
    std::vector<LogQ16> fixed_log_l_;
    std::vector<VerticalExtent> extents_;
    std::vector<int> extent_features_;
    std::optional<ObjectEvidence> objects_;  // model kObject
    std::vector<int> class_index_;           // kObject scratch: each detection's prior
};

}  // namespace scaled::core
