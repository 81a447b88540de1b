#pragma once

// ObjectEvidence: the scale evidence of physical objects (docs/method.md,
// "Object-level evidence"; ScaleEstimator's model "object").
//
// 1. Tracks. Detections are associated over detection frames into objects:
//    same class, and the box centre near where the object is expected: the
//    projection of its anchor (gated by the anchor's projected uncertainty),
//    or, before it has one, the epipolar segment of its last box centre over
//    the depths of the map. Greedy by that distance. An object keeps its id
//    for the whole epoch, through frames where it is hidden or out of view;
//    the table is bounded (max_objects; when it is full the object unused
//    longest is replaced).
// 2. Anchors. An object's anchor is the point its box-centre rays meet: a
//    weighted least-squares triangulation over its views (a box cut by the
//    image border at a side left out, its centre is not the object's; one
//    cut at its top or bottom gives the plane of its centre column, and at
//    least one whole box is needed), with the
//    3x3 covariance of that fit. It needs min_parallax_deg between views,
//    must lie in front of every view and inside (a margin around) most of
//    its boxes, and is used once its depth uncertainty is below
//    max_anchor_rel_sigma of its distance. Map features are not used: on the
//    real sequences few of them fall on an object, and those that do are as
//    often the wall behind it or the table in front (docs/accuracy.md).
// 3. Per-view extent. Every stored view is measured again with the current
//    anchor: D on the vertical line through the anchor (vertical_extent.h:
//    roll compensation and the truncation rules apply), kappa from the
//    elevations of its top and bottom points, and a per-view error from the
//    box edges (box_edge_sigma_px, at least box_edge_rel_sigma of the box).
//    Views far below the object's best views (partly hidden) or far above
//    them (merged boxes) leave the product (view_band).
// 4. One height per object: object_likelihood.h.
//
// Everything is allocated at create(); update() does not allocate.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/object_likelihood.h>
#include <scaled/core/scale/scale_grid.h>
#include <scaled/core/scale/scale_posterior.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::core {

struct FrameSnapshot;
struct Detection;
struct ObservationRecord;

struct ObjectConfig {
    int max_objects = 32;  // objects tracked at once, in [1, 1024]
    int max_views = 32;    // views kept per object (the oldest is replaced), in [2, 1024]
    // Anchoring: the box centre's noise, a fraction of the box diagonal plus
    // pixels (a priori; the rays' a-posteriori variance factor widens it when
    // they meet worse than that: the centre of a box is not a fixed point of
    // the object, and the map's poses have errors).
    Scalar centre_rel_sigma = Scalar(0.05);
    Scalar centre_sigma_px = 2;
    Scalar min_parallax_deg = 2;  // between the views an anchor is made of
    // An anchor is used once its depth std is below this fraction of its
    // distance. Its uncertainty is part of the object's likelihood (a common
    // relative error of its views), so the gate only keeps out anchors that
    // are barely determined.
    Scalar max_anchor_rel_sigma = Scalar(0.5);
    Scalar anchor_box_margin = Scalar(0.15);  // the anchor projects inside the box grown by this
    // Association: a box joins an object whose predicted centre lies within
    // association_gate half-diagonals of the box (plus 2 sigma of the
    // projected anchor); an object without anchor is searched along the
    // epipolar segment of its last box centre over epipolar_depth_min..max
    // times the median depth of the map in view, and only for
    // max_gap_updates updates after its last view.
    Scalar association_gate = 1;
    Scalar epipolar_depth_min = Scalar(0.25);
    Scalar epipolar_depth_max = 4;
    int max_gap_updates = 30;
    // Per-view error of a box edge: at least this fraction of the box height
    // (ExtentConfig::box_edge_sigma_px is the floor in pixels).
    Scalar box_edge_rel_sigma = Scalar(0.03);
    // Relative error common to all views of one object (a detector that boxes
    // this object consistently too large, the model's own error).
    Scalar object_rel_sigma = Scalar(0.05);
    // Views whose normalised extent D / (1 + kappa w/H) differs from the
    // object's reference (the view_reference_quantile of its views) by more
    // than view_band (or 3 per-view sigmas) are left out.
    Scalar view_band = Scalar(0.2);
    Scalar view_reference_quantile = Scalar(0.8);
    // Relative error common to ALL objects: the map's geometry around the
    // objects against the scale its motion has (the served d converts both).
    // The posterior over d is widened by it (a Gaussian in log d) after the
    // objects are combined. Measured on redkitchen: the tracker's geometry
    // near the objects is 13-26% shorter than its trajectory says
    // (docs/accuracy.md); 0 when the map is trusted.
    Scalar map_rel_sigma = 0;
    bool width_model = true;  // the class's width prior (H + kappa w); off: w = 0
    // One height (and width) for all views of an object (the model). false,
    // for the ablation only: every view draws its own height from the class
    // prior, as the paper's observations do.
    bool one_height = true;
    // A box cut by the image border at its top or bottom only (the near
    // chair whose legs leave the image) still centres the object left to
    // right: its view constrains the anchor to the plane through the camera
    // and the box's centre column. false: such views are left out of the
    // triangulation, as boxes cut at a side always are (the plane of a row
    // says little about depth when the camera moves sideways: with them a
    // television on the wall anchored three times too far, docs/accuracy.md).
    bool cut_box_planes = true;
    ApparentHeightPrior::GridSpec height_grid;
};

// The allowed values of ObjectConfig's parameters (param_limits.h):
// validate() checks them, the daemon's [objects] section offers them.
struct ObjectLimits {
    static constexpr ParamLimits max_objects = closed(1, 1024);
    static constexpr ParamLimits max_views = closed(2, 1024);
    static constexpr ParamLimits centre_rel_sigma = closed(0, 10);  // not both centre terms 0
    static constexpr ParamLimits centre_sigma_px = closed(0, 1000);
    static constexpr ParamLimits min_parallax_deg = closed(0, 90);
    static constexpr ParamLimits max_anchor_rel_sigma = openClosed(0, 10);
    static constexpr ParamLimits anchor_box_margin = closed(0, 10);
    static constexpr ParamLimits association_gate = openClosed(0, 100);
    static constexpr ParamLimits epipolar_depth_min = openClosed(0, 1e6);  // < epipolar_depth_max
    static constexpr ParamLimits epipolar_depth_max = openClosed(0, 1e6);
    static constexpr ParamLimits max_gap_updates = closed(1, 1e6);
    static constexpr ParamLimits box_edge_rel_sigma = closed(0, 1);
    static constexpr ParamLimits object_rel_sigma = closed(0, 10);
    static constexpr ParamLimits map_rel_sigma = closed(0, 1);
    static constexpr ParamLimits view_band = openClosed(0, 10);
    static constexpr ParamLimits view_reference_quantile = closed(0, 1);
};

// Checks ObjectLimits and the parameters' relations; the message names the
// field and its value.
Status validate(const ObjectConfig& config);

enum class ObjectState : std::uint8_t {
    kTentative,  // no usable anchor yet
    kAnchored,   // anchored, no view measurable from it
    kUsed,       // its likelihood is part of the posterior
};
const char* toString(ObjectState state);

struct ObjectSummary {
    int id = 0;            // stable within the epoch, from 1
    int class_index = -1;  // into the PriorTable's priors()
    ObjectState state = ObjectState::kTentative;
    Vec3 p_AinW = Vec3::Zero();   // anchor, SLAM units (valid unless tentative)
    Scalar anchor_rel_sigma = 0;  // depth std / distance of the anchor
    int detections = 0;           // associated so far
    int views = 0;                // kept
    int views_used = 0;           // in its likelihood
    std::int64_t first_frame = 0;
    std::int64_t last_frame = 0;
    Scalar local_estimate = 0;  // mode over d of this object's likelihood alone (0: none)
    // Its apparent height (metres, h of object_likelihood.h) at the posterior's
    // MAP and 95% bounds of d (0 when unused or without a posterior).
    Scalar height_m = 0;
    Interval height_ci95_m;
};

// One detection's fate in an update.
struct ObjectAssignment {
    int object_id = 0;  // 0: not associated (unknown class, skipped, table full)
    bool new_object = false;
};

class ObjectEvidence {
public:
    // At most this many detections are associated per update; more are skipped.
    static constexpr int kMaxDetections = 256;

    // priors: the classes' height (and width) priors; partial weights come
    // from the priors (partialProbability()) or likelihood.partial_weight when
    // likelihood.partial_visibility is on; outliers from likelihood.robust.
    static Result<ObjectEvidence> create(const ObjectConfig& config, const ExtentConfig& extent,
                                         const LikelihoodConfig& likelihood,
                                         const PriorTable& priors,
                                         const PinholeRadialCamera& camera, const ScaleGrid& grid);

    // New priors (SIGHUP): the table stays, the likelihoods are evaluated
    // again at the next update. Allocates.
    Status setPriors(const PriorTable& priors);

    // Forgets every object (a new map).
    void reset();

    struct UpdateStats {
        int detections_used = 0;  // associated to an object that is used
        int views_used = 0;       // views in the posterior after this update (all objects)
        int objects_used = 0;
        int new_objects = 0;
    };

    // One frame's detections. class_index[i] is the prior of detections[i]
    // (-1: skip it). assignments (when not empty) receives each detection's
    // object; records (as many as fit) one entry per detection that became a
    // used view of its object.
    UpdateStats update(const FrameSnapshot& frame, std::span<const Detection> detections,
                       std::span<const int> class_index, std::span<ObjectAssignment> assignments,
                       std::span<ObservationRecord> records, int* records_written);

    // Adds the used objects' log-likelihoods to the posterior (after reset()
    // of the posterior by the caller) and sets its observation count to the
    // views used. Returns the number of objects added.
    int addTo(ScalePosterior& posterior) const;

    [[nodiscard]] std::size_t capacity() const { return tracks_.size(); }
    // Active objects, in slot order (ids are not contiguous).
    [[nodiscard]] int activeCount() const;
    // Summary of the k-th active object (k < activeCount()), heights at the
    // given posterior summary.
    [[nodiscard]] ObjectSummary summary(int k, const ScaleSummary& posterior) const;
    // The k-th active object's normalised log-likelihood over the grid (empty unless used).
    [[nodiscard]] std::span<const Scalar> logLikelihood(int k) const;

    // The 95% relative width that the used objects and their classes' spreads
    // allow at best: 1.96-sigma bounds of the log-normal of combined relative
    // std 1 / sqrt(sum_o 1 / s_o^2), s_o the class spread with the object's
    // common error. 0 without used objects.
    [[nodiscard]] Scalar informationLimitRelWidth95() const;

    [[nodiscard]] const ObjectConfig& config() const { return config_; }

    // Bytes held: the table (views and likelihood caches of max_objects), the
    // classes' apparent-height priors and the scratch buffers.
    [[nodiscard]] std::size_t memoryBytes() const;

private:
    struct View {
        CameraPose pose;
        Vec3 up_W = Vec3(0, 0, 1);
        BoundingBox box;
        std::int64_t frame_id = 0;
        Scalar depth_hint = 1;  // median depth of the map in view, SLAM units
    };
    struct Track {
        bool active = false;
        int id = 0;
        int class_index = -1;
        int detections = 0;
        int stored = 0;  // views kept
        int head = 0;    // next view slot (ring)
        int last_update = 0;
        std::int64_t first_frame = 0;
        std::int64_t last_frame = 0;
        bool anchored = false;
        bool has_estimate = false;  // a triangulation exists (anchored or not yet usable)
        Vec3 p_AinW = Vec3::Zero();
        Mat3 P_AinW = Mat3::Zero();
        Scalar anchor_rel_sigma = 0;
        bool used = false;
        bool dirty = false;
        int views_used = 0;
        Scalar local_estimate = 0;
        // Weighted sums of the used views for objectHeightAt-style heights:
        // h(d) = (d * s_d - mu_w * s_k) / s_1.
        double s_1 = 0;
        double s_d = 0;
        double s_k = 0;
    };
    // A view's box-centre ray, for the triangulation; of a box cut at its
    // top or bottom (cut_box_planes), the plane through the camera and the
    // box's centre column (plane: its normal, and dir_W the ray through the
    // cut box's centre, for the in-front and parallax tests).
    struct Ray {
        int view = 0;
        Vec3 dir_W = Vec3::Zero();
        Vec3 normal_W = Vec3::Zero();
        Scalar sigma_angle = 0;  // radians
        bool plane = false;
    };
    struct Candidate {
        Scalar cost = 0;
        int detection = 0;
        int track = 0;
    };

    ObjectEvidence(const ObjectConfig& config, const ExtentConfig& extent,
                   const LikelihoodConfig& likelihood, const PinholeRadialCamera& camera,
                   const ScaleGrid& grid);
    Status buildPriors(const PriorTable& priors);

    [[nodiscard]] View& view(int track, int k) {
        return views_[static_cast<std::size_t>(track) *
                          static_cast<std::size_t>(config_.max_views) +
                      static_cast<std::size_t>(k)];
    }
    [[nodiscard]] const View& view(int track, int k) const {
        return views_[static_cast<std::size_t>(track) *
                          static_cast<std::size_t>(config_.max_views) +
                      static_cast<std::size_t>(k)];
    }
    [[nodiscard]] std::span<Scalar> cache(int track) {
        return {log_l_.data() + static_cast<std::size_t>(track) * grid_.size(), grid_.size()};
    }
    [[nodiscard]] std::span<const Scalar> cache(int track) const {
        return {log_l_.data() + static_cast<std::size_t>(track) * grid_.size(), grid_.size()};
    }
    [[nodiscard]] int activeSlot(int k) const;
    [[nodiscard]] Scalar medianDepth(const FrameSnapshot& frame);
    // Association distance of a box to a track (in gate units), or a negative
    // value when the track cannot take it.
    [[nodiscard]] Scalar associationCost(const Track& t, int slot, const FrameSnapshot& frame,
                                         const BoundingBox& box, Scalar depth_hint) const;
    int newTrack(int class_index);
    // update()'s steps: detections to tracks (greedy by cost) into track_of
    // (-1: none); new tracks and a view for every detection; the records.
    void associateDetections(const FrameSnapshot& frame, std::span<const Detection> detections,
                             std::span<const int> class_index, int n_det, Scalar depth_hint,
                             std::span<int> track_of);
    void addViews(const FrameSnapshot& frame, std::span<const Detection> detections,
                  std::span<const int> class_index, int n_det, Scalar depth_hint,
                  std::span<int> track_of, std::span<ObjectAssignment> assignments,
                  UpdateStats& stats);
    int writeRecords(const FrameSnapshot& frame, std::span<const Detection> detections, int n_det,
                     std::span<const int> track_of, std::span<ObservationRecord> records,
                     UpdateStats& stats) const;
    // How a triangulated anchor agrees with its rays (triangulate()).
    struct RayAgreement {
        int inside = 0;      // boxes it projects into, with the margin
        Scalar chi2 = 0;     // the rays' chi-square
        Scalar min_cos = 1;  // cosine of the largest angle between two rays
    };
    // The usable views' box-centre rays (and column planes) into rays_;
    // returns how many, and the constraints they give (2 per ray, 1 per
    // plane).
    int collectCentreRays(const Track& t, int slot, int& constraints);
    // False when X is not in front of every ray's view.
    bool rayAgreement(int slot, std::span<const Ray> rays, const Vec3& X, RayAgreement& out) const;
    void triangulate(Track& t, int slot);
    // One view measured on the vertical through the anchor: nullopt when the
    // anchor does not project into (a margin around) the box or the geometry
    // gives no extent.
    [[nodiscard]] std::optional<ObjectViewExtent> measureView(const Vec3& p_AinW,
                                                              const CameraPose& pose,
                                                              const Vec3& up_W,
                                                              const BoundingBox& box) const;
    // evaluate()'s steps: the views measured with the anchor into extents_ and
    // norm_ (returns how many); those near the reference extent kept in
    // front of extents_ (returns how many); their log-likelihood into the
    // track's cache (false when it cannot be evaluated).
    std::size_t measureViews(const Track& t, int slot, Scalar width_ratio);
    std::size_t keepViewsNearReference(std::size_t n);
    bool evaluateIntoCache(std::span<const ObjectViewExtent> used, const ApparentHeightPrior& prior,
                           const ObjectLikelihoodConfig& lc, int slot);
    void evaluate(Track& t, int slot);

    ObjectConfig config_;
    ExtentConfig extent_;
    LikelihoodConfig likelihood_;
    PinholeRadialCamera camera_;
    ScaleGrid grid_;
    std::vector<ApparentHeightPrior> apparent_;  // one per class of the PriorTable
    std::vector<Scalar> width_ratio_;            // mu_w / mean height per class
    std::vector<Scalar> class_spread_;           // relative std of the class height
    std::vector<Track> tracks_;
    std::vector<View> views_;
    std::vector<Scalar> log_l_;
    std::vector<ObjectViewExtent> extents_;  // scratch, max_views
    std::vector<Scalar> view_log_l_;         // scratch, grid (one_height = false)
    std::vector<Ray> rays_;                  // scratch, max_views
    std::vector<Scalar> norm_;               // scratch, max_views
    std::vector<Scalar> norm_sorted_;        // scratch, max_views
    std::vector<Candidate> candidates_;      // scratch, kMaxDetections * max_objects
    std::array<Scalar, 512> depths_{};       // scratch for the median depth
    int next_id_ = 1;
    int updates_ = 0;
};

}  // namespace scaled::core
