// The pipeline's configuration and the field registry both configurations
// share (config_registry.h). The pipeline-only API reads a whole daemon file:
// the daemon's sections ([source] [socket] [log] [pipeline]) are checked like
// every other and then ignored, so `scale-eval --config config/scaled.toml`
// works and a typo there is still an error.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <toml++/toml.h>

#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/detector/thread_priority.h>
#include <scaled/drivers/priors/toml_read.h>

#include "config_registry.h"

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;
using drivers::priors::tomlread::num;
using drivers::priors::tomlread::show;

namespace config_detail {

std::string tomlQuote(const std::string& s) {
    static constexpr char kHex[] = "0123456789ABCDEF";
    std::string out = "\"";
    for (const char c : s) {
        const auto u = static_cast<unsigned char>(c);
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (u < 0x20 || u == 0x7f) {
            // A TOML basic string holds no raw control character (fuzz_daemon_config).
            out += "\\u00";
            out += kHex[u >> 4U];
            out += kHex[u & 0xfU];
        } else {
            out += c;
        }
    }
    return out + "\"";
}

Field boolean(const char* section, const char* key, bool* target) {
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                if (!n.is_boolean()) {
                    return "must be true or false (got " + show(n) + ")";
                }
                *target = n.as_boolean()->get();
                return std::nullopt;
            },
            [=] { return std::string(*target ? "true" : "false"); }};
}

Field path(const char* section, const char* key, std::filesystem::path* target) {
    return {
        section, key,
        [=](const toml::node& n, const std::filesystem::path& base) -> std::optional<std::string> {
            if (!n.is_string()) {
                return "must be a path string (got " + show(n) + ")";
            }
            const std::filesystem::path p(n.as_string()->get());
            *target = p.empty() || p.is_absolute() ? p : (base / p).lexically_normal();
            return std::nullopt;
        },
        [=] { return tomlQuote(target->string()); }};
}

Field text(const char* section, const char* key, std::string* target) {
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                if (!n.is_string()) {
                    return "must be a string (got " + show(n) + ")";
                }
                *target = n.as_string()->get();
                return std::nullopt;
            },
            [=] { return tomlQuote(*target); }};
}

Field stringList(const char* section, const char* key, std::vector<std::string>* target) {
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                const auto* arr = n.as_array();
                if (arr == nullptr) {
                    return "must be an array of strings (got " + show(n) + ")";
                }
                std::vector<std::string> out;
                for (std::size_t i = 0; i < arr->size(); ++i) {
                    const auto* s = arr->get(i)->as_string();
                    if (s == nullptr || s->get().empty()) {
                        return "entry " + std::to_string(i) + " must be a non-empty string (got " +
                               show(*arr->get(i)) + ")";
                    }
                    out.push_back(s->get());
                }
                *target = std::move(out);
                return std::nullopt;
            },
            [=] {
                std::string s = "[";
                for (std::size_t i = 0; i < target->size(); ++i) {
                    s += (i > 0 ? ", " : "") + tomlQuote((*target)[i]);
                }
                return s + "]";
            }};
}

namespace {

std::string join(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) {
        s += (s.empty() ? "" : ", ") + x;
    }
    return s;
}

std::pair<std::string, std::string> splitKey(const std::string& full) {
    const auto dot = full.find('.');
    if (dot == std::string::npos) {
        return {full, ""};
    }
    return {full.substr(0, dot), full.substr(dot + 1)};
}

}  // namespace

namespace {

// [tracker], the EKF's keys (core::slam::SlamConfig; its ranges are core's)
std::vector<Field> ekfFields(core::slam::SlamConfig& s) {
    using L = core::slam::SlamLimits;
    return {
        real("tracker", "sigma_a", &s.motion.sigma_a, L::sigma_a),
        real("tracker", "sigma_a_reference_hz", &s.motion.reference_hz, L::sigma_a_reference_hz),
        real("tracker", "sigma_alpha", &s.motion.sigma_alpha, L::sigma_alpha),
        real("tracker", "pixel_sigma_px", &s.pixel_sigma_px, L::pixel_sigma_px),
        real("tracker", "init_sigma_v", &s.init_sigma_v, L::init_sigma_v),
        real("tracker", "init_sigma_w", &s.init_sigma_w, L::init_sigma_w),
        real("tracker", "rho0", &s.rho0, L::rho0),
        real("tracker", "sigma_rho", &s.sigma_rho, L::sigma_rho),
        real("tracker", "linearity_threshold", &s.linearity_threshold, L::linearity_threshold),
        integer("tracker", "max_features", &s.max_features, L::max_features),
        integer("tracker", "max_measured", &s.max_measured, L::max_measured),
        integer("tracker", "min_visible", &s.min_visible, L::min_visible),
        real("tracker", "image_margin_px", &s.image_margin_px, L::image_margin_px),
        real("tracker", "chi2_gate", &s.chi2_gate, L::chi2_gate),
        real("tracker", "ransac_threshold_px", &s.ransac_threshold_px, L::ransac_threshold_px),
        real("tracker", "ransac_confidence", &s.ransac_confidence, L::ransac_confidence),
        integer("tracker", "ransac_min_hypotheses", &s.ransac_min_hypotheses,
                L::ransac_min_hypotheses),
        integer("tracker", "ransac_max_hypotheses", &s.ransac_max_hypotheses,
                L::ransac_max_hypotheses),
        integer("tracker", "seed", &s.seed, L::seed),
        integer("tracker", "min_inliers", &s.min_inliers, L::min_inliers),
        integer("tracker", "lost_after_frames", &s.lost_after_frames, L::lost_after_frames),
        integer("tracker", "delete_min_attempts", &s.delete_min_attempts, L::delete_min_attempts),
        real("tracker", "delete_min_ratio", &s.delete_min_ratio, L::delete_min_ratio),
        real("tracker", "max_dt_s", &s.max_dt_s, L::max_dt_s),
    };
}

// [tracker], the front end's keys and the window bundle adjustment's
std::vector<Field> frontEndFields(drivers::vision::TrackerConfig& t) {
    using T = drivers::vision::TrackerLimits;  // the vision driver's ranges
    using B = core::slam::WindowBaLimits;      // the window bundle adjustment's, core's
    return {
        integer("tracker", "patch_size", &t.patch_size, T::patch_size),
        integer("tracker", "patch_source_size", &t.patch_source_size, T::patch_source_size),
        boolean("tracker", "warp_patches", &t.warp_patches),
        integer("tracker", "max_new_per_frame", &t.max_new_per_frame, T::max_new_per_frame),
        integer("tracker", "free_radius_px", &t.free_radius_px, T::free_radius_px),
        real("tracker", "corner_quality", &t.corners.quality_level, T::corner_quality),
        integer("tracker", "corner_min_distance_px", &t.corners.min_distance_px,
                T::corner_min_distance_px),
        real("tracker", "min_ncc", &t.match.min_ncc, T::min_ncc),
        integer("tracker", "max_search_pixels", &t.match.max_search_pixels, T::max_search_pixels),
        integer("tracker", "pyramid_levels", &t.pyramid_levels, T::pyramid_levels),
        integer("tracker", "coarse_max_search_pixels", &t.coarse_max_search_pixels,
                T::coarse_max_search_pixels),
        real("tracker", "coarse_min_fraction", &t.coarse_min_fraction, T::coarse_min_fraction),
        real("tracker", "coarse_min_ncc", &t.coarse_min_ncc, T::coarse_min_ncc),
        real("tracker", "near_loss_ratio", &t.near_loss_ratio, T::near_loss_ratio),
        integer("tracker", "near_loss_frames", &t.near_loss_frames, T::near_loss_frames),
        real("tracker", "rotation_check_radps", &t.rotation_check_radps, T::rotation_check_radps),
        real("tracker", "rotation_check_sigma_radps", &t.rotation_check_sigma_radps,
             T::rotation_check_sigma_radps),
        integer("tracker", "feature_border_px", &t.feature_border_px, T::feature_border_px),
        real("tracker", "start_check_s", &t.start_check_s, T::start_check_s),
        real("tracker", "start_check_deg", &t.start_check_deg, T::start_check_deg),
        real("tracker", "start_check_flow_px", &t.start_check_flow_px, T::start_check_flow_px),
        real("tracker", "start_check_depth_rel_sigma", &t.start_check_depth_rel_sigma,
             T::start_check_depth_rel_sigma),
        real("tracker", "relocalise_s", &t.relocalise_s, T::relocalise_s),
        integer("tracker", "relocalise_min_inliers", &t.relocalise_min_inliers,
                T::relocalise_min_inliers),
        real("tracker", "relocalise_reproj_px", &t.relocalise_reproj_px, T::relocalise_reproj_px),
        integer("tracker", "relocalise_corners", &t.relocalise_corners, T::relocalise_corners),
        real("tracker", "relocalise_search_px", &t.relocalise_search_px, T::relocalise_search_px),
        real("tracker", "relocalise_verify_px", &t.relocalise_verify_px, T::relocalise_verify_px),
        integer("tracker", "relocalise_max_brief_distance", &t.relocalise_max_brief_distance,
                T::relocalise_max_brief_distance),
        real("tracker", "relocalise_max_rel_sigma", &t.relocalise_max_rel_sigma,
             T::relocalise_max_rel_sigma),
        integer("tracker", "brief_refresh_frames", &t.brief_refresh_frames,
                T::brief_refresh_frames),
        boolean("tracker", "use_gyro", &t.use_gyro),
        real("tracker", "gyro_noise_density", &t.gyro_noise_density, T::gyro_noise_density),
        real("tracker", "gyro_bias_sigma_radps", &t.gyro_bias_sigma_radps,
             T::gyro_bias_sigma_radps),
        real("tracker", "gyro_max_gap_s", &t.gyro_max_gap_s, T::gyro_max_gap_s),
        real("tracker", "gyro_bias_time_s", &t.gyro_bias_time_s, T::gyro_bias_time_s),
        boolean("tracker", "window_ba", &t.window_ba.enabled),
        integer("tracker", "window_ba_keyframe_every", &t.window_ba.keyframe_every,
                B::keyframe_every),
        integer("tracker", "window_ba_window_keyframes", &t.window_ba.window_keyframes,
                B::window_keyframes),
        integer("tracker", "window_ba_fixed_keyframes", &t.window_ba.fixed_keyframes,
                B::fixed_keyframes),
        integer("tracker", "window_ba_step_keyframes", &t.window_ba.step_keyframes,
                B::step_keyframes),
        integer("tracker", "window_ba_iterations", &t.window_ba.iterations, B::iterations),
        boolean("tracker", "window_ba_scale_feedback", &t.window_ba.scale_feedback),
        real("tracker", "window_ba_max_scale_step", &t.window_ba.max_scale_step, B::max_scale_step),
        integer("tracker", "window_ba_defer_frames", &t.window_ba.defer_frames, B::defer_frames),
        real("tracker", "rolling_shutter_s", &t.window_ba.rolling_shutter_s, B::rolling_shutter_s),
        real("tracker", "rolling_shutter_sigma_s", &t.window_ba.rolling_shutter_sigma_s,
             B::rolling_shutter_sigma_s),
        real("tracker", "rolling_shutter_max_s", &t.window_ba.rolling_shutter_max_s,
             B::rolling_shutter_max_s),
        real("tracker", "focal_sigma_rel", &t.window_ba.focal_sigma_rel, B::focal_sigma_rel),
        real("tracker", "focal_max_rel", &t.window_ba.focal_max_rel, B::focal_max_rel),
        real("tracker", "k1_sigma", &t.window_ba.k1_sigma, B::k1_sigma),
        real("tracker", "k1_max_change", &t.window_ba.k1_max_change, B::k1_max_change),
    };
}

// [tracker]: the EKF's keys, then the front end's
std::vector<Field> trackerFields(drivers::vision::TrackerConfig& t) {
    std::vector<Field> out = ekfFields(t.slam);
    std::vector<Field> front = frontEndFields(t);
    out.insert(out.end(), front.begin(), front.end());
    return out;
}

// [detector] and [detection]
std::vector<Field> detectorFields(PipelineConfig& c) {
    auto& d = c.detector;
    using D = drivers::detector::DetectorLimits;  // the detector driver's
    return {
        choice("detector", "family", &d.family,
               {{"yolox", drivers::detector::ModelFamily::kYolox},
                {"darknet", drivers::detector::ModelFamily::kDarknet}}),
        path("detector", "model", &d.model_path),
        path("detector", "weights", &d.weights_path),
        path("detector", "names", &d.names_path),
        integer("detector", "input_size_px", &d.input_size_px, D::input_size_px),
        real("detector", "score_threshold", &d.score_threshold, D::score_threshold),
        real("detector", "nms_iou_threshold", &d.nms_iou_threshold, D::nms_iou_threshold),
        stringList("detector", "classes", &d.classes),
        integer("detector", "threads", &d.threads, D::threads),
        integer("detector", "nice", &d.nice, D::nice),
        integer("detector", "max_detections", &d.max_detections, D::max_detections),
        integer("detection", "every_frames", &c.detection.every_frames, 1, 100000),
        integer("detection", "phase_frames", &c.detection.phase_frames, 0, 99999),
        real("detection", "min_map_age_s", &c.detection.min_map_age_s, 0, 3600),
        real("detection", "period_s", &c.detection.period_s, 0, 3600),
    };
}

// [estimator]
std::vector<Field> estimatorFields(PipelineConfig& c) {
    auto& e = c.estimator;
    using E = core::EstimatorLimits;  // core's ranges
    using P = core::PosteriorLimits;
    return {
        path("estimator", "priors", &c.priors_path),
        choice(
            "estimator", "model", &e.model,
            {{"paper", core::EstimatorModel::kPaper}, {"object", core::EstimatorModel::kObject}}),
        choice("estimator", "map", &c.estimator_map,
               {{"served", EstimatorMap::kServed}, {"filter", EstimatorMap::kFilter}}),
        choice("estimator", "variance", &e.likelihood.variance_model,
               {{"paper", core::VarianceModel::kPaper},
                {"propagated", core::VarianceModel::kPropagated}}),
        boolean("estimator", "robust", &e.likelihood.robust),
        real("estimator", "outlier_weight", &e.likelihood.outlier_weight, E::outlier_weight),
        real("estimator", "outlier_height_range_m", &e.likelihood.outlier_height_range_m,
             E::outlier_height_range_m),
        boolean("estimator", "partial_visibility", &e.likelihood.partial_visibility),
        real("estimator", "partial_weight", &e.likelihood.partial_weight, E::partial_weight),
        real("estimator", "min_sigma_m", &e.likelihood.min_sigma_m, E::min_sigma_m),
        choice("estimator", "weighting", &e.weighting,
               {{"feature", core::ObservationWeighting::kPerFeature},
                {"box", core::ObservationWeighting::kPerBox}}),
        boolean("estimator", "use_non_upright", &e.use_non_upright),
        real("estimator", "min_detection_score", &e.min_detection_score, E::min_detection_score),
        integer("estimator", "max_features_per_box", &e.max_features_per_box,
                E::max_features_per_box),
        boolean("estimator", "compensate_roll", &e.extent.compensate_roll),
        boolean("estimator", "propagate_variance", &e.extent.propagate_variance),
        real("estimator", "box_edge_sigma_px", &e.extent.box_edge_sigma_px, E::box_edge_sigma_px),
        real("estimator", "border_margin_px", &e.extent.border_margin_px, E::border_margin_px),
        real("estimator", "min_extent_px", &e.extent.min_extent_px, E::min_extent_px),
        real("estimator", "grid_d_min", &e.posterior.grid.d_min, P::grid_d_min),
        real("estimator", "grid_d_max", &e.posterior.grid.d_max, P::grid_d_max),
        integer("estimator", "grid_bins", &e.posterior.grid.bins, P::grid_bins),
        real("estimator", "converged_rel_width", &e.posterior.converged_rel_width,
             P::converged_rel_width),
        real("estimator", "drift_sigma_log", &e.posterior.drift_sigma_log, P::drift_sigma_log),
        real("estimator", "pose_max_rel_width95", &c.pose_max_rel_width95, 0.01, 1000),
        choice("estimator", "posterior_arithmetic", &e.posterior.arithmetic,
               {{"floating", core::PosteriorArithmetic::kFloating},
                {"fixed", core::PosteriorArithmetic::kFixed}}),
    };
}

// [objects]: object-level evidence (core::ObjectConfig)
std::vector<Field> objectFields(core::ObjectConfig& o) {
    using O = core::ObjectLimits;  // core's ranges
    return {
        integer("objects", "max_objects", &o.max_objects, O::max_objects),
        integer("objects", "max_views", &o.max_views, O::max_views),
        real("objects", "centre_rel_sigma", &o.centre_rel_sigma, O::centre_rel_sigma),
        real("objects", "centre_sigma_px", &o.centre_sigma_px, O::centre_sigma_px),
        real("objects", "min_parallax_deg", &o.min_parallax_deg, O::min_parallax_deg),
        real("objects", "max_anchor_rel_sigma", &o.max_anchor_rel_sigma, O::max_anchor_rel_sigma),
        real("objects", "anchor_box_margin", &o.anchor_box_margin, O::anchor_box_margin),
        real("objects", "association_gate", &o.association_gate, O::association_gate),
        real("objects", "epipolar_depth_min", &o.epipolar_depth_min, O::epipolar_depth_min),
        real("objects", "epipolar_depth_max", &o.epipolar_depth_max, O::epipolar_depth_max),
        integer("objects", "max_gap_updates", &o.max_gap_updates, O::max_gap_updates),
        real("objects", "box_edge_rel_sigma", &o.box_edge_rel_sigma, O::box_edge_rel_sigma),
        real("objects", "object_rel_sigma", &o.object_rel_sigma, O::object_rel_sigma),
        real("objects", "map_rel_sigma", &o.map_rel_sigma, O::map_rel_sigma),
        real("objects", "view_band", &o.view_band, O::view_band),
        real("objects", "view_reference_quantile", &o.view_reference_quantile,
             O::view_reference_quantile),
        boolean("objects", "width_model", &o.width_model),
        boolean("objects", "one_height", &o.one_height),
        boolean("objects", "cut_box_planes", &o.cut_box_planes),
    };
}

}  // namespace

void appendFields(std::vector<Field>& out, std::vector<Field> more) {
    for (auto& f : more) {
        out.push_back(std::move(f));
    }
}

// Every key of the pipeline, one table per section.
std::vector<Field> pipelineFields(PipelineConfig& c) {
    std::vector<Field> out = trackerFields(c.tracker);
    appendFields(out, detectorFields(c));
    appendFields(out, estimatorFields(c));
    appendFields(out, objectFields(c.estimator.objects));
    return out;
}

Locator documentLocator(const toml::table& root, std::string_view source) {
    return [&root, source = std::string(source)](const std::vector<std::string>& keys) {
        auto at = [&](const toml::node* n) {
            return n != nullptr && n->source().begin.line > 0
                       ? source + ":" + std::to_string(n->source().begin.line)
                       : source;
        };
        for (const auto& full : keys) {
            const auto [section, key] = splitKey(full);
            const auto* table = root.get_as<toml::table>(section);
            if (table != nullptr && !key.empty()) {
                if (const auto* n = table->get(key)) {
                    return at(n);
                }
            }
        }
        for (const auto& full : keys) {
            if (const auto* n = root.get(splitKey(full).first)) {
                return at(n);
            }
        }
        return source;
    };
}

core::Error checkError(const Locator& where, const std::vector<std::string>& keys,
                       const std::string& what) {
    return makeError(
        ErrorCode::kInvalidArgument,
        where(keys) + ": " + (keys.empty() ? std::string() : keys.front()) + ": " + what);
}

void ProblemList::add(core::Error e, std::string key) {
    errors.push_back(std::move(e));
    keys.push_back(std::move(key));
}

bool keyCovers(std::string_view problem_key, std::string_view key) {
    const std::string_view k = problem_key;
    return k == key ||
           (key.size() > k.size() && key.substr(0, k.size()) == k && key[k.size()] == '.');
}

bool ProblemList::about(std::string_view key) const {
    return std::any_of(keys.begin(), keys.end(),
                       [&](const std::string& k) { return keyCovers(k, key); });
}

bool Checker::fail(const std::vector<std::string>& keys, const std::string& what) {
    return fail(checkError(where_, keys, what), keys.empty() ? std::string() : keys.front());
}

bool Checker::fail(core::Error e, std::string key) {
    if (!first_) {
        first_ = e;
    }
    if (all_ == nullptr) {
        return true;
    }
    all_->add(std::move(e), std::move(key));
    return false;
}

bool Checker::failed(const core::Status& nested) {
    if (nested) {
        return false;
    }
    if (!first_) {
        first_ = nested.error();
    }
    return all_ == nullptr;
}

core::Status Checker::result() const {
    if (first_) {
        return *first_;
    }
    return {};
}

Status checkPipeline(const PipelineConfig& c, const Locator& where, ProblemList* all) {
    Checker check(where, all);
    const auto& g = c.estimator.posterior.grid;
    if (!(g.d_max > g.d_min) && check.fail({"estimator.grid_d_max", "estimator.grid_d_min"},
                                           "must be greater than estimator.grid_d_min = " +
                                               num(g.d_min) + " (got " + num(g.d_max) + ")")) {
        return check.result();
    }
    // Below 10 um the fixed-point likelihood's Q32-metre residuals lose precision.
    if (c.estimator.posterior.arithmetic == core::PosteriorArithmetic::kFixed &&
        !(c.estimator.likelihood.min_sigma_m >= core::Scalar(1e-5)) &&
        check.fail({"estimator.min_sigma_m", "estimator.posterior_arithmetic"},
                   "must be >= 1e-05 with estimator.posterior_arithmetic = \"fixed\" (got " +
                       num(c.estimator.likelihood.min_sigma_m) + ")")) {
        return check.result();
    }
    const auto& s = c.tracker.slam;
    if (s.ransac_max_hypotheses < s.ransac_min_hypotheses &&
        check.fail({"tracker.ransac_max_hypotheses", "tracker.ransac_min_hypotheses"},
                   "must be >= tracker.ransac_min_hypotheses = " +
                       std::to_string(s.ransac_min_hypotheses) + " (got " +
                       std::to_string(s.ransac_max_hypotheses) + ")")) {
        return check.result();
    }
    if (c.tracker.patch_size % 2 == 0 &&
        check.fail({"tracker.patch_size"},
                   "must be odd (got " + std::to_string(c.tracker.patch_size) + ")")) {
        return check.result();
    }
    if (auto v = drivers::vision::validate(c.tracker);
        !v && check.fail({"tracker"}, v.error().message)) {
        return check.result();
    }
    if (c.detection.phase_frames >= c.detection.every_frames &&
        check.fail({"detection.phase_frames", "detection.every_frames"},
                   "must be less than detection.every_frames = " +
                       std::to_string(c.detection.every_frames) + " (got " +
                       std::to_string(c.detection.phase_frames) + ")")) {
        return check.result();
    }
    const auto& o = c.estimator.objects;
    if (!(o.epipolar_depth_max > o.epipolar_depth_min) &&
        check.fail({"objects.epipolar_depth_max", "objects.epipolar_depth_min"},
                   "must be greater than objects.epipolar_depth_min = " +
                       num(o.epipolar_depth_min) + " (got " + num(o.epipolar_depth_max) + ")")) {
        return check.result();
    }
    if (!(o.centre_rel_sigma > 0 || o.centre_sigma_px > 0) &&
        check.fail({"objects.centre_rel_sigma", "objects.centre_sigma_px"},
                   "objects.centre_rel_sigma and objects.centre_sigma_px must not both be 0")) {
        return check.result();
    }
    if (auto v = core::validate(o); !v && check.fail({"objects"}, v.error().message)) {
        return check.result();
    }
    return check.result();
}

Status applyFields(const toml::table& root, std::string_view source,
                   const std::filesystem::path& base_dir, const std::vector<Field>& fields,
                   ProblemList* all) {
    std::vector<std::string> sections;
    for (const auto& f : fields) {
        if (sections.empty() || sections.back() != f.section) {
            sections.push_back(f.section);
        }
    }
    const auto error = [&](const toml::node* n, const std::string& key, const std::string& what) {
        return drivers::priors::tomlread::errorAt(ErrorCode::kInvalidArgument, source, n, key,
                                                  what);
    };
    const Locator nowhere = [](const std::vector<std::string>&) { return std::string(); };
    Checker check(nowhere, all);
    for (const auto& [sk, snode] : root) {
        const std::string section(sk.str());
        const auto* table = snode.as_table();
        bool known = false;
        for (const auto& name : sections) {
            known = known || name == section;
        }
        if (!known) {
            if (check.fail(
                    error(&snode, section, "unknown section (allowed: " + join(sections) + ")"),
                    section)) {
                return check.result();
            }
            continue;
        }
        if (table == nullptr) {
            if (check.fail(error(&snode, section, "must be a table ([" + section + "])"),
                           section)) {
                return check.result();
            }
            continue;
        }
        for (const auto& [k, node] : *table) {
            const std::string key(k.str());
            const Field* field = nullptr;
            std::vector<std::string> allowed;
            for (const auto& f : fields) {
                if (f.section == section) {
                    allowed.push_back(f.key);
                    if (f.key == key) {
                        field = &f;
                    }
                }
            }
            std::string full = section;
            full += '.';
            full += key;
            if (field == nullptr) {
                if (check.fail(
                        error(&node, full,
                              "unknown key (allowed in [" + section + "]: " + join(allowed) + ")"),
                        full)) {
                    return check.result();
                }
                continue;
            }
            if (auto problem = field->set(node, base_dir);
                problem && check.fail(error(&node, full, *problem), full)) {
                return check.result();
            }
        }
    }
    return check.result();
}

Status applyAssignments(const std::vector<std::string>& assignments,
                        const std::vector<Field>& fields,
                        std::vector<std::pair<std::string, std::string>>& set_by,
                        ProblemList* all) {
    using drivers::priors::tomlread::parse;
    const Locator nowhere = [](const std::vector<std::string>&) { return std::string(); };
    Checker check(nowhere, all);
    std::error_code ec;
    const auto cwd = std::filesystem::current_path(ec);
    for (const auto& a : assignments) {
        const auto eq = a.find('=');
        const auto dot = a.find('.');
        const std::string source = "--set " + a;
        if (eq == std::string::npos || dot == std::string::npos || dot > eq) {
            if (check.fail(
                    makeError(ErrorCode::kInvalidArgument,
                              source + ": expected section.key=value (e.g. estimator.robust=true)"),
                    a)) {
                return check.result();
            }
            continue;
        }
        const std::string section = a.substr(0, dot);
        const std::string key = a.substr(dot + 1, eq - dot - 1);
        std::string full = section;
        full += '.';
        full += key;
        std::string value = a.substr(eq + 1);
        // A bare word that is not a TOML value is taken as a string.
        if (!parse("v = " + value, source)) {
            value = tomlQuote(value);
        }
        std::string text = "[" + section;
        text += "]\n";
        text += key;
        text += " = ";
        text += value;
        text += '\n';
        auto root = parse(text, source);
        if (!root) {
            if (check.fail(
                    makeError(ErrorCode::kInvalidArgument,
                              source + ": not a valid assignment (" + root.error().message + ")"),
                    full)) {
                return check.result();
            }
            continue;
        }
        if (auto ok = applyFields(*root, source, cwd, fields); !ok) {
            // The line number of the synthetic text means nothing to the user.
            std::string msg = ok.error().message;
            const std::string prefix = source + ":2: ";
            if (msg.rfind(prefix, 0) == 0) {
                std::string shorter = source;
                shorter += ": ";
                shorter += msg.substr(prefix.size());
                msg = std::move(shorter);
            }
            if (check.fail(makeError(ok.error().code, msg), full)) {
                return check.result();
            }
            continue;
        }
        set_by.emplace_back(std::move(full), source);
    }
    return check.result();
}

Locator assignmentLocator(std::vector<std::pair<std::string, std::string>> set_by,
                          std::string fallback) {
    return [set_by = std::move(set_by),
            fallback = std::move(fallback)](const std::vector<std::string>& keys) {
        for (const auto& key : keys) {
            // The last assignment of a key is the one that counts.
            for (auto it = set_by.rbegin(); it != set_by.rend(); ++it) {
                if (it->first == key) {
                    return it->second;
                }
            }
        }
        return fallback;
    };
}

std::vector<std::string> fieldKeys(const std::vector<Field>& fields) {
    std::vector<std::string> keys;
    keys.reserve(fields.size());
    for (const auto& f : fields) {
        keys.push_back(f.section + "." + f.key);
    }
    return keys;
}

std::string fieldsToToml(const std::vector<Field>& fields) {
    std::string out;
    std::string section;
    for (const auto& f : fields) {
        if (f.section != section) {
            section = f.section;
            out += (out.empty() ? "[" : "\n[") + section + "]\n";
        }
        out += f.key + " = " + f.value() + "\n";
    }
    return out;
}

Result<std::string> readConfigFile(const std::filesystem::path& path) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) {
        return makeError(
            ErrorCode::kIo,
            path.string() + ": cannot read configuration: " +
                (std::filesystem::exists(path, ec) ? "not a regular file" : "no such file"));
    }
    std::ifstream in(path, std::ios::binary);
    const auto size = std::filesystem::file_size(path, ec);
    std::string text(ec ? 0 : size, '\0');
    if (!in || ec || !in.read(text.data(), static_cast<std::streamsize>(text.size()))) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot read configuration");
    }
    return text;
}

}  // namespace config_detail

namespace {

// The pipeline-only API applies a daemon configuration around `config` (the
// daemon's sections checked against its defaults) and keeps the pipeline.
template <typename Apply>
Status viaDaemon(PipelineConfig& config, Apply&& apply) {
    DaemonConfig work = defaultDaemonConfig();
    work.pipeline = config;
    auto ok = std::forward<Apply>(apply)(work);
    if (ok) {
        config = std::move(work.pipeline);
    }
    return ok;
}

}  // namespace

PipelineConfig defaultPipelineConfig() {
    PipelineConfig c;
    c.detection.every_frames = 10;
    c.estimator.likelihood.variance_model = core::VarianceModel::kPropagated;
    c.estimator.weighting = core::ObservationWeighting::kPerFeature;
    c.estimator.likelihood.robust = true;
    c.estimator.likelihood.outlier_weight = core::Scalar(0.05);
    c.estimator.likelihood.partial_visibility = true;
    c.estimator.extent.compensate_roll = true;
    // Object-level evidence (docs/accuracy.md, issue 18): calibrated on every
    // run where the paper model's intervals held the truth in 75% of updates.
    c.estimator.model = core::EstimatorModel::kObject;
    // The width term is right where the map is (scale-eval --truth-geometry)
    // but, on the tracker's map, whose geometry around the objects is ~15%
    // shorter than its motion says, it makes the estimate 20-30% high; off,
    // the two errors largely cancel on the measured runs. Revisit when the
    // map's scale holds (issue 19).
    c.estimator.objects.width_model = false;
    // That same geometry error, common to all objects, is in the interval:
    // 13-26% on the measured runs. Lower it as the map's scale holds.
    c.estimator.objects.map_rel_sigma = core::Scalar(0.1);
    // The window adjustment's optimisation taken one frame after the frame
    // that starts it, so the daemon runs it beside the tracking (docs/slam.md,
    // "The optimisation off the frame"): the same figures as 0 over the 26 runs
    // and the detector's ten phases.
    c.tracker.window_ba.defer_frames = 1;
    // The camera's readout time estimated by the window (docs/slam.md, "The
    // readout time estimated in the window"): a prior at a global shutter, 30
    // ms wide. On kitchen renders with a 30 ms shutter it finds 15-28 ms and
    // 20 runs of 30 meet issue 19's bounds (14 without); on global-shutter
    // renders within 3.1 ms of 0 (19 runs of 20, as without), on KITTI 0 to
    // -6.6 ms; negative: rows read upwards (redkitchen backwards: -23 ms).
    c.tracker.window_ba.rolling_shutter_sigma_s = core::Scalar(0.03);
    return c;
}

Status applyPipelineToml(std::string_view toml_text, std::string_view source_name,
                         const std::filesystem::path& base_dir, PipelineConfig& config) {
    return viaDaemon(config, [&](DaemonConfig& d) {
        return applyDaemonToml(toml_text, source_name, base_dir, d);
    });
}

Status applyPipelineFile(const std::filesystem::path& path, PipelineConfig& config) {
    return viaDaemon(config, [&](DaemonConfig& d) { return applyDaemonFile(path, d); });
}

Status applyPipelineOverrides(const std::vector<std::string>& assignments, PipelineConfig& config) {
    return viaDaemon(config, [&](DaemonConfig& d) { return applyDaemonOverrides(assignments, d); });
}

bool wideForPoses(const PipelineConfig& config, double scale, double ci95_lo, double ci95_hi) {
    return !(scale > 0) || !std::isfinite(scale) ||
           !(ci95_hi - ci95_lo <= config.pose_max_rel_width95 * scale);
}

std::vector<std::string> pipelineConfigKeys() {
    PipelineConfig c;
    return config_detail::fieldKeys(config_detail::pipelineFields(c));
}

std::string toToml(const PipelineConfig& config) {
    PipelineConfig copy = config;
    return config_detail::fieldsToToml(config_detail::pipelineFields(copy));
}

}  // namespace scaled::daemon
