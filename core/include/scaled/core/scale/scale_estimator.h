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
#include <scaled/core/result.h>
#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/likelihood.h>
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
};

enum class ObservationWeighting : std::uint8_t {
    kPerFeature,  // the paper: every feature in a box is an independent factor
    kPerBox,      // each box contributes one factor: features share weight 1/n
};

struct EstimatorConfig {
    PosteriorConfig posterior;
    LikelihoodConfig likelihood;
    ExtentConfig extent;
    ObservationWeighting weighting = ObservationWeighting::kPerFeature;
    bool use_non_upright = false;  // classes with upright = false give no observations
    Scalar min_detection_score = 0;
    int max_features_per_box = 64;  // bound on work per box (first ones in feature order)
};

// One observation: a (detection, feature) pair that passed the geometry.
struct ObservationRecord {
    int detection_index = -1;
    int feature_index = -1;
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
    void reset() { posterior_.reset(); }

    // Replaces the height priors and keeps the posterior (the daemon's SIGHUP
    // reload): later updates use the new priors, earlier evidence stays.
    // Allocates (the table is moved in); not for the per-frame path.
    void setPriors(PriorTable priors) { priors_ = std::move(priors); }

    [[nodiscard]] ScaleSummary summary() const { return posterior_.summary(); }
    [[nodiscard]] const ScalePosterior& posterior() const { return posterior_; }
    [[nodiscard]] const PriorTable& priors() const { return priors_; }
    [[nodiscard]] const EstimatorConfig& config() const { return config_; }

private:
    ScaleEstimator(const EstimatorConfig& config, PriorTable priors,
                   const PinholeRadialCamera& camera, ScalePosterior posterior,
                   std::optional<FixedLikelihood> fixed_likelihood);
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
};

}  // namespace scaled::core
