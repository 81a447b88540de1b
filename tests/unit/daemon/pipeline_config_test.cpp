// The pipeline configuration: every key checked, errors that name the file,
// line, key and value; overrides; relative paths; a round trip through toToml.

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include <scaled/daemon/pipeline_config.h>

#include "temp_dir.h"

namespace scaled::daemon {
namespace {

std::string applyError(const std::string& text, PipelineConfig& c) {
    auto r = applyPipelineToml(text, "test.toml", "/base", c);
    EXPECT_FALSE(r.ok()) << "accepted: " << text;
    return r.ok() ? std::string() : r.error().message;
}

TEST(PipelineConfig, DefaultsAreTheChosenOnes) {
    const PipelineConfig c = defaultPipelineConfig();
    EXPECT_EQ(c.detection.every_frames, 10);
    EXPECT_EQ(c.detection.phase_frames, 0);
    EXPECT_EQ(c.estimator.likelihood.variance_model, core::VarianceModel::kPropagated);
    EXPECT_EQ(c.estimator.weighting, core::ObservationWeighting::kPerFeature);
    EXPECT_TRUE(c.estimator.likelihood.robust);
    EXPECT_TRUE(c.estimator.likelihood.partial_visibility);
    EXPECT_TRUE(c.estimator.extent.compensate_roll);
    EXPECT_EQ(c.estimator.posterior.arithmetic, core::PosteriorArithmetic::kFloating);
    // The object model, with ObjectConfig's settings but the width term off
    // (chosen in docs/accuracy.md).
    EXPECT_EQ(c.estimator.model, core::EstimatorModel::kObject);
    const core::ObjectConfig o;
    EXPECT_EQ(c.estimator.objects.max_objects, o.max_objects);
    EXPECT_EQ(c.estimator.objects.max_views, o.max_views);
    EXPECT_EQ(c.estimator.objects.max_gap_updates, o.max_gap_updates);
    EXPECT_EQ(c.estimator.objects.epipolar_depth_min, o.epipolar_depth_min);
    EXPECT_EQ(c.estimator.objects.epipolar_depth_max, o.epipolar_depth_max);
    EXPECT_EQ(c.estimator.objects.view_band, o.view_band);
    EXPECT_FALSE(c.estimator.objects.width_model);
    EXPECT_TRUE(c.estimator.objects.one_height);
    EXPECT_EQ(c.estimator.objects.map_rel_sigma, core::Scalar(0.1));
}

TEST(PipelineConfig, ReadsTheObjectModelKeys) {
    PipelineConfig c = defaultPipelineConfig();
    // Values a float build holds exactly, all different from the defaults.
    const std::string text = R"([estimator]
model = "object"
[objects]
max_objects = 8
max_views = 16
centre_rel_sigma = 0.25
centre_sigma_px = 0
min_parallax_deg = 4.5
max_anchor_rel_sigma = 0.5
anchor_box_margin = 0
association_gate = 1.5
epipolar_depth_min = 0.5
epipolar_depth_max = 8
max_gap_updates = 12
box_edge_rel_sigma = 0.0625
object_rel_sigma = 0.125
view_band = 0.375
view_reference_quantile = 0.5
width_model = false
)";
    auto r = applyPipelineToml(text, "test.toml", "/base", c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const auto& o = c.estimator.objects;
    EXPECT_EQ(c.estimator.model, core::EstimatorModel::kObject);
    EXPECT_EQ(o.max_objects, 8);
    EXPECT_EQ(o.max_views, 16);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.centre_rel_sigma), 0.25);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.centre_sigma_px), 0.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.min_parallax_deg), 4.5);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.max_anchor_rel_sigma), 0.5);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.anchor_box_margin), 0.0);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.association_gate), 1.5);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.epipolar_depth_min), 0.5);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.epipolar_depth_max), 8.0);
    EXPECT_EQ(o.max_gap_updates, 12);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.box_edge_rel_sigma), 0.0625);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.object_rel_sigma), 0.125);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.view_band), 0.375);
    EXPECT_DOUBLE_EQ(static_cast<double>(o.view_reference_quantile), 0.5);
    EXPECT_FALSE(o.width_model);
    // Untouched keys keep their values.
    EXPECT_TRUE(c.estimator.likelihood.robust);

    // toToml writes them back, and reading that gives the same configuration.
    const std::string dumped = toToml(c);
    EXPECT_NE(dumped.find("[objects]\nmax_objects = 8\n"), std::string::npos) << dumped;
    EXPECT_NE(dumped.find("model = \"object\"\n"), std::string::npos) << dumped;
    PipelineConfig back = defaultPipelineConfig();
    ASSERT_TRUE(applyPipelineToml(dumped, "dump", "/", back).ok());
    EXPECT_EQ(toToml(back), dumped);

    // Overrides reach them too.
    ASSERT_TRUE(applyPipelineOverrides({"estimator.model=paper", "objects.width_model=true",
                                        "objects.max_views=2", "objects.view_band=10"},
                                       c)
                    .ok());
    EXPECT_EQ(c.estimator.model, core::EstimatorModel::kPaper);
    EXPECT_TRUE(c.estimator.objects.width_model);
    EXPECT_EQ(c.estimator.objects.max_views, 2);
    EXPECT_DOUBLE_EQ(static_cast<double>(c.estimator.objects.view_band), 10.0);
}

TEST(PipelineConfig, ObjectModelKeysAreRangeChecked) {
    struct Case {
        const char* line;     // at line 3 of the file, in [objects]
        const char* message;  // after "test.toml:3: objects.KEY: "
    };
    const Case cases[] = {
        {"max_objects = 0", "must be an integer in [1, 1024] (got 0)"},
        {"max_objects = 1025", "must be an integer in [1, 1024] (got 1025)"},
        {"max_objects = 2.5", "must be an integer in [1, 1024] (got 2.5)"},
        {"max_views = 1", "must be an integer in [2, 1024] (got 1)"},
        {"max_views = 1025", "must be an integer in [2, 1024] (got 1025)"},
        {"centre_rel_sigma = -0.5", "must be a number in [0, 10] (got -0.5)"},
        {"centre_rel_sigma = 11", "must be a number in [0, 10] (got 11)"},
        {"centre_sigma_px = -1", "must be a number in [0, 1000] (got -1)"},
        {"centre_sigma_px = 1001", "must be a number in [0, 1000] (got 1001)"},
        {"min_parallax_deg = -1", "must be a number in [0, 90] (got -1)"},
        {"min_parallax_deg = 91", "must be a number in [0, 90] (got 91)"},
        {"max_anchor_rel_sigma = 0", "must be a number in (0, 10] (got 0)"},
        {"max_anchor_rel_sigma = 10.5", "must be a number in (0, 10] (got 10.5)"},
        {"anchor_box_margin = -0.5", "must be a number in [0, 10] (got -0.5)"},
        {"anchor_box_margin = 11", "must be a number in [0, 10] (got 11)"},
        {"association_gate = 0", "must be a number in (0, 100] (got 0)"},
        {"association_gate = 101", "must be a number in (0, 100] (got 101)"},
        {"epipolar_depth_min = 0", "must be a number in (0, 1e+06] (got 0)"},
        {"epipolar_depth_min = nan", "must be a number in (0, 1e+06] (got nan)"},
        {"epipolar_depth_max = -4", "must be a number in (0, 1e+06] (got -4)"},
        {"epipolar_depth_max = 1000001", "must be a number in (0, 1e+06] (got 1000001)"},
        {"max_gap_updates = 0", "must be an integer in [1, 1000000] (got 0)"},
        {"max_gap_updates = 1000001", "must be an integer in [1, 1000000] (got 1000001)"},
        {"box_edge_rel_sigma = -0.5", "must be a number in [0, 1] (got -0.5)"},
        {"box_edge_rel_sigma = 1.5", "must be a number in [0, 1] (got 1.5)"},
        {"object_rel_sigma = -0.5", "must be a number in [0, 10] (got -0.5)"},
        {"object_rel_sigma = 11", "must be a number in [0, 10] (got 11)"},
        {"view_band = 0", "must be a number in (0, 10] (got 0)"},
        {"view_band = 11", "must be a number in (0, 10] (got 11)"},
        {"view_reference_quantile = -0.5", "must be a number in [0, 1] (got -0.5)"},
        {"view_reference_quantile = 1.5", "must be a number in [0, 1] (got 1.5)"},
        {"width_model = 1", "must be true or false (got 1)"},
        {"width_model = \"yes\"", "must be true or false (got \"yes\")"},
    };
    for (const Case& k : cases) {
        SCOPED_TRACE(k.line);
        PipelineConfig c = defaultPipelineConfig();
        const std::string line = k.line;
        const std::string key = line.substr(0, line.find(" = "));
        EXPECT_EQ(applyError("[objects]\n\n" + line + "\n", c),
                  "test.toml:3: objects." + key + ": " + k.message);
        // Nothing applied.
        EXPECT_EQ(toToml(c), toToml(defaultPipelineConfig()));
    }

    PipelineConfig c = defaultPipelineConfig();
    EXPECT_EQ(applyError("[estimator]\nmodel = \"objects\"\n", c),
              "test.toml:2: estimator.model: must be one of \"paper\", \"object\" (got "
              "\"objects\")");
    EXPECT_EQ(applyError("[objects]\nmax_object = 8\n", c),
              "test.toml:2: objects.max_object: unknown key (allowed in [objects]: max_objects, "
              "max_views, centre_rel_sigma, centre_sigma_px, min_parallax_deg, "
              "max_anchor_rel_sigma, anchor_box_margin, association_gate, epipolar_depth_min, "
              "epipolar_depth_max, max_gap_updates, box_edge_rel_sigma, object_rel_sigma, "
              "map_rel_sigma, "
              "view_band, view_reference_quantile, width_model, one_height, cut_box_planes)");
    EXPECT_EQ(applyError("objects = 1\n", c), "test.toml:1: objects: must be a table ([objects])");
    auto bad = applyPipelineOverrides({"objects.max_views=0"}, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message,
              "--set objects.max_views=0: objects.max_views: must be an integer in [2, 1024] (got "
              "0)");
}

// The configuration's bound is the tracker's own (EkfSlam::create refuses more
// than 10000 hypotheses): a value the file accepts must not fail later, at
// start-up, with a less precise message.
TEST(PipelineConfig, RansacHypothesesStayWithinWhatTheTrackerAccepts) {
    PipelineConfig c = defaultPipelineConfig();
    auto bad = applyPipelineOverrides({"tracker.ransac_max_hypotheses=20000"}, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message,
              "--set tracker.ransac_max_hypotheses=20000: tracker.ransac_max_hypotheses: must be "
              "an integer in [1, 10000] (got 20000)");
    ASSERT_TRUE(
        applyPipelineOverrides(
            {"tracker.ransac_max_hypotheses=10000", "tracker.ransac_min_hypotheses=10000"}, c)
            .ok());
    EXPECT_TRUE(core::slam::validate(c.tracker.slam).ok());
}

// The ranges of the core components' keys are core's tables (SlamLimits,
// PosteriorLimits, EstimatorLimits, ObjectLimits): at a closed bound the key
// is accepted, just past a bound it is refused, by the registry and by core's
// own check of the same parameter.
TEST(PipelineConfig, CoreKeysTakeTheirRangesFromCore) {
    struct Key {
        const char* name = nullptr;  // section.key
        core::ParamLimits limits;
        bool integer = false;
        const char* with = nullptr;  // another override an in-range value needs
    };
    using S = core::slam::SlamLimits;
    using P = core::PosteriorLimits;
    using E = core::EstimatorLimits;
    using O = core::ObjectLimits;
    const Key keys[] = {
        {"tracker.sigma_a", S::sigma_a, false},
        {"tracker.pixel_sigma_px", S::pixel_sigma_px, false},
        {"tracker.init_sigma_v", S::init_sigma_v, false},
        {"tracker.rho0", S::rho0, false},
        {"tracker.linearity_threshold", S::linearity_threshold, false},
        {"tracker.chi2_gate", S::chi2_gate, false},
        {"tracker.ransac_confidence", S::ransac_confidence, false},
        {"tracker.ransac_max_hypotheses", S::ransac_max_hypotheses, true},
        {"tracker.min_inliers", S::min_inliers, true},
        {"tracker.lost_after_frames", S::lost_after_frames, true},
        {"tracker.max_dt_s", S::max_dt_s, false},
        {"estimator.converged_rel_width", P::converged_rel_width, false},
        {"estimator.drift_sigma_log", P::drift_sigma_log, false},
        {"estimator.max_features_per_box", E::max_features_per_box, true},
        {"estimator.outlier_weight", E::outlier_weight, false},
        {"estimator.partial_weight", E::partial_weight, false},
        {"estimator.min_sigma_m", E::min_sigma_m, false},
        {"estimator.min_extent_px", E::min_extent_px, false},
        {"objects.max_objects", O::max_objects, true},
        {"objects.max_views", O::max_views, true},
        {"objects.association_gate", O::association_gate, false},
        {"objects.view_band", O::view_band, false},
        {"objects.max_gap_updates", O::max_gap_updates, true},
        {"tracker.rolling_shutter_s", core::slam::WindowBaLimits::rolling_shutter_s, false,
         "tracker.rolling_shutter_max_s=1"},
        {"tracker.rolling_shutter_sigma_s", core::slam::WindowBaLimits::rolling_shutter_sigma_s,
         false},
        {"tracker.rolling_shutter_max_s", core::slam::WindowBaLimits::rolling_shutter_max_s, false},
        {"tracker.focal_sigma_rel", core::slam::WindowBaLimits::focal_sigma_rel, false},
        {"tracker.focal_max_rel", core::slam::WindowBaLimits::focal_max_rel, false},
        {"tracker.k1_sigma", core::slam::WindowBaLimits::k1_sigma, false},
        {"tracker.k1_max_change", core::slam::WindowBaLimits::k1_max_change, false},
    };
    const auto text = [](double v, bool integer) {
        std::ostringstream out;
        if (integer) {
            out << static_cast<long long>(v);
        } else {
            out << std::setprecision(17) << v;
        }
        return out.str();
    };
    for (const Key& k : keys) {
        SCOPED_TRACE(k.name);
        const double step = k.integer ? 1 : std::max(1e-6, std::abs(k.limits.hi) * 1e-6);
        const double above = k.limits.hi_open ? k.limits.hi : k.limits.hi + step;
        const double below = k.limits.lo_open ? k.limits.lo : k.limits.lo - step;
        for (const double bad : {above, below}) {
            PipelineConfig c = defaultPipelineConfig();
            EXPECT_FALSE(
                applyPipelineOverrides({std::string(k.name) + "=" + text(bad, k.integer)}, c).ok())
                << "accepted " << bad;
            EXPECT_FALSE(k.limits.contains(bad)) << bad;
        }
        for (const double good : {k.limits.lo, k.limits.hi}) {
            if ((good == k.limits.lo && k.limits.lo_open) ||
                (good == k.limits.hi && k.limits.hi_open)) {
                continue;
            }
            PipelineConfig c = defaultPipelineConfig();
            std::vector<std::string> set{std::string(k.name) + "=" + text(good, k.integer)};
            if (k.with != nullptr) {
                set.emplace_back(k.with);
            }
            const auto r = applyPipelineOverrides(set, c);
            EXPECT_TRUE(r.ok()) << good << ": " << (r.ok() ? "" : r.error().message);
        }
    }
    // An estimated readout time's prior beyond the estimate's bound is refused.
    PipelineConfig c = defaultPipelineConfig();
    const auto r = applyPipelineOverrides({"tracker.rolling_shutter_s=0.06"}, c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("+-rolling_shutter_max_s (0.05)"), std::string::npos)
        << r.error().message;
    // Core refuses what the registry refuses: a value past a bound set
    // directly in the configuration.
    c = defaultPipelineConfig();
    c.tracker.slam.chi2_gate = static_cast<core::Scalar>(2e4);
    EXPECT_FALSE(core::slam::validate(c.tracker.slam).ok());
    c = defaultPipelineConfig();
    c.estimator.objects.view_band = 0;
    EXPECT_FALSE(core::validate(c.estimator.objects).ok());
    c = defaultPipelineConfig();
    c.estimator.posterior.drift_sigma_log = 2;
    EXPECT_FALSE(core::validate(c.estimator.posterior).ok());
}

TEST(PipelineConfig, EpipolarDepthMaxMustExceedMin) {
    PipelineConfig c = defaultPipelineConfig();
    // Equal is rejected, at the line of epipolar_depth_max.
    EXPECT_EQ(applyError("[objects]\nepipolar_depth_min = 2\nepipolar_depth_max = 2\n", c),
              "test.toml:3: objects.epipolar_depth_max: must be greater than "
              "objects.epipolar_depth_min = 2 (got 2)");
    EXPECT_EQ(applyError("[objects]\nepipolar_depth_max = 0.5\nepipolar_depth_min = 3\n", c),
              "test.toml:2: objects.epipolar_depth_max: must be greater than "
              "objects.epipolar_depth_min = 3 (got 0.5)");
    // Only the minimum in the file, above the default maximum (4): the
    // message points at the line that is there.
    EXPECT_EQ(applyError("[objects]\n\nepipolar_depth_min = 5\n", c),
              "test.toml:3: objects.epipolar_depth_max: must be greater than "
              "objects.epipolar_depth_min = 5 (got 4)");
    EXPECT_EQ(toToml(c), toToml(defaultPipelineConfig()));
    // A maximum just above the minimum is fine.
    ASSERT_TRUE(applyPipelineToml("[objects]\nepipolar_depth_min = 2\nepipolar_depth_max = 2.5\n",
                                  "test.toml", "/base", c)
                    .ok());
    // Overrides are checked after all of them, named by the --set that made them.
    PipelineConfig d = defaultPipelineConfig();
    auto r = applyPipelineOverrides({"objects.epipolar_depth_max=0.125"}, d);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message,
              "--set objects.epipolar_depth_max=0.125: objects.epipolar_depth_max: must be "
              "greater than objects.epipolar_depth_min = 0.25 (got 0.125)");
    EXPECT_TRUE(applyPipelineOverrides(
                    {"objects.epipolar_depth_max=0.125", "objects.epipolar_depth_min=0.0625"}, d)
                    .ok());
}

TEST(PipelineConfig, CentreSigmasMustNotBothBeZero) {
    PipelineConfig c = defaultPipelineConfig();
    EXPECT_EQ(applyError("[objects]\ncentre_rel_sigma = 0\ncentre_sigma_px = 0\n", c),
              "test.toml:2: objects.centre_rel_sigma: objects.centre_rel_sigma and "
              "objects.centre_sigma_px must not both be 0");
    // Either alone may be 0.
    for (const char* text :
         {"[objects]\ncentre_rel_sigma = 0\n", "[objects]\ncentre_sigma_px = 0\n"}) {
        PipelineConfig d = defaultPipelineConfig();
        EXPECT_TRUE(applyPipelineToml(text, "test.toml", "/base", d).ok()) << text;
    }
}

TEST(PipelineConfig, PosteriorArithmeticIsCheckedLikeEveryKey) {
    PipelineConfig c = defaultPipelineConfig();
    auto r = applyPipelineToml("[estimator]\nposterior_arithmetic = \"fixed\"\n", "test.toml",
                               "/base", c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(c.estimator.posterior.arithmetic, core::PosteriorArithmetic::kFixed);
    ASSERT_TRUE(applyPipelineOverrides({"estimator.posterior_arithmetic=floating"}, c).ok());
    EXPECT_EQ(c.estimator.posterior.arithmetic, core::PosteriorArithmetic::kFloating);
    EXPECT_EQ(applyError("[estimator]\n\nposterior_arithmetic = \"integer\"\n", c),
              "test.toml:3: estimator.posterior_arithmetic: must be one of \"floating\", "
              "\"fixed\" (got \"integer\")");
    EXPECT_EQ(applyError("[estimator]\nposterior_arithmetic = 1\n", c),
              "test.toml:2: estimator.posterior_arithmetic: must be one of \"floating\", "
              "\"fixed\" (got 1)");
    // The fixed formats need min_sigma_m >= 10 um.
    EXPECT_EQ(applyError("[estimator]\nposterior_arithmetic = \"fixed\"\nmin_sigma_m = 1e-6\n", c),
              "test.toml:3: estimator.min_sigma_m: must be >= 1e-05 with "
              "estimator.posterior_arithmetic = \"fixed\" (got 1e-06)");
    // Its own range is core's (core::EstimatorLimits): 0 is no sigma.
    EXPECT_EQ(applyError("[estimator]\nmin_sigma_m = 0\n", c),
              "test.toml:2: estimator.min_sigma_m: must be a number in (0, 10] (got 0)");
}

TEST(PipelineConfig, AppliesKeysAndKeepsTheRest) {
    PipelineConfig c = defaultPipelineConfig();
    const std::string text = R"([detection]
every_frames = 5
period_s = 2.5
[estimator]
variance = "paper"
robust = false
outlier_weight = 0.1
priors = "priors/x.toml"
[detector]
family = "darknet"
model = "/m/yolo.cfg"
classes = ["cup", "chair"]
input_size_px = 320
[tracker]
sigma_a = 4
seed = 7
)";
    auto r = applyPipelineToml(text, "test.toml", "/etc/scaled", c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(c.detection.every_frames, 5);
    EXPECT_DOUBLE_EQ(c.detection.period_s, 2.5);
    EXPECT_EQ(c.estimator.likelihood.variance_model, core::VarianceModel::kPaper);
    EXPECT_FALSE(c.estimator.likelihood.robust);
    EXPECT_DOUBLE_EQ(static_cast<double>(c.estimator.likelihood.outlier_weight), 0.1);
    EXPECT_EQ(c.priors_path, std::filesystem::path("/etc/scaled/priors/x.toml"));
    EXPECT_EQ(c.detector.family, drivers::detector::ModelFamily::kDarknet);
    EXPECT_EQ(c.detector.model_path, std::filesystem::path("/m/yolo.cfg"));
    ASSERT_EQ(c.detector.classes.size(), 2U);
    EXPECT_EQ(c.detector.classes[1], "chair");
    EXPECT_EQ(c.detector.input_size_px, 320);
    EXPECT_DOUBLE_EQ(static_cast<double>(c.tracker.slam.motion.sigma_a), 4.0);
    EXPECT_EQ(c.tracker.slam.seed, 7U);
    // Untouched keys keep their values.
    EXPECT_TRUE(c.estimator.extent.compensate_roll);
}

TEST(PipelineConfig, ErrorsNameFileLineKeyAndValue) {
    PipelineConfig c = defaultPipelineConfig();
    EXPECT_EQ(applyError("[estimator]\nrobust = true\nrobustt = 1\n", c),
              "test.toml:3: estimator.robustt: unknown key (allowed in [estimator]: priors, "
              "model, map, variance, robust, outlier_weight, outlier_height_range_m, "
              "partial_visibility, "
              "partial_weight, min_sigma_m, weighting, use_non_upright, min_detection_score, "
              "max_features_per_box, compensate_roll, propagate_variance, box_edge_sigma_px, "
              "border_margin_px, min_extent_px, grid_d_min, grid_d_max, grid_bins, "
              "converged_rel_width, drift_sigma_log, pose_max_rel_width95, posterior_arithmetic)");
    EXPECT_EQ(applyError("\n[estimatr]\n", c),
              "test.toml:2: estimatr: unknown section (allowed: source, tracker, detector, "
              "detection, estimator, objects, camera, gpio, imu, pipeline, socket, log)");
    EXPECT_EQ(applyError("[detection]\nevery_frames = 0\n", c),
              "test.toml:2: detection.every_frames: must be an integer in [1, 100000] (got 0)");
    EXPECT_EQ(applyError("[detection]\nevery_frames = 2.5\n", c),
              "test.toml:2: detection.every_frames: must be an integer in [1, 100000] (got 2.5)");
    EXPECT_EQ(applyError("[detection]\nevery_frames = 5\nphase_frames = 5\n", c),
              "test.toml:3: detection.phase_frames: must be less than detection.every_frames = 5 "
              "(got 5)");
    EXPECT_EQ(applyError("[estimator]\nvariance = \"exact\"\n", c),
              "test.toml:2: estimator.variance: must be one of \"paper\", \"propagated\" (got "
              "\"exact\")");
    EXPECT_EQ(applyError("[estimator]\nrobust = 1\n", c),
              "test.toml:2: estimator.robust: must be true or false (got 1)");
    EXPECT_EQ(applyError("[estimator]\noutlier_weight = 0\n", c),
              "test.toml:2: estimator.outlier_weight: must be a number in (0, 1) (got 0)");
    EXPECT_EQ(applyError("[tracker]\nsigma_a = nan\n", c),
              "test.toml:2: tracker.sigma_a: must be a number in (0, 10000] (got nan)");
    EXPECT_EQ(applyError("[detector]\nclasses = [\"cup\", 3]\n", c),
              "test.toml:2: detector.classes: entry 1 must be a non-empty string (got 3)");
    EXPECT_EQ(applyError("detection = 3\n", c),
              "test.toml:1: detection: must be a table ([detection])");
    EXPECT_EQ(applyError("[estimator]\ngrid_d_min = 5\ngrid_d_max = 2\n", c),
              "test.toml:3: estimator.grid_d_max: must be greater than estimator.grid_d_min = 5 "
              "(got 2)");
    EXPECT_EQ(applyError("[detection]\nperiod_s = -0.5\n", c),
              "test.toml:2: detection.period_s: must be a number in [0, 3600] (got -0.5)");
    // The daemon's sections are checked too (and then ignored).
    EXPECT_EQ(applyError("[log]\nmax_file_bytes = 1\n", c),
              "test.toml:2: log.max_file_bytes: must be an integer in [4096, 1099511627776] (got "
              "1)");
    const std::string syntax = applyError("[estimator\n", c);
    EXPECT_EQ(syntax.rfind("test.toml:1:", 0), 0U) << syntax;
}

TEST(PipelineConfig, DaemonSectionsAreCheckedAndIgnored) {
    PipelineConfig c = defaultPipelineConfig();
    const std::string before = toToml(c);
    auto r = applyPipelineToml(
        "[source]\nkind = \"sim\"\n[socket]\nmax_clients = 2\n[log]\nenabled = false\n"
        "[pipeline]\ncapture_queue_frames = 1\n",
        "test.toml", "/base", c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(toToml(c), before);
    EXPECT_EQ(applyError("[socket]\nmode = \"0777\"\n", c).rfind("test.toml:2: socket.mode: ", 0),
              0U);
    EXPECT_EQ(toToml(c), before);
}

TEST(PipelineConfig, AFailedApplyChangesNothing) {
    PipelineConfig c = defaultPipelineConfig();
    applyError("[detection]\nevery_frames = 3\n[estimator]\nrobust = 2\n", c);
    EXPECT_EQ(c.detection.every_frames, 10);
}

TEST(PipelineConfig, FileErrorsAndRelativePaths) {
    test::TempDir dir("pipeline_config");
    PipelineConfig c = defaultPipelineConfig();
    auto missing = applyPipelineFile(dir.path() / "none.toml", c);
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().code, core::ErrorCode::kIo);
    EXPECT_NE(missing.error().message.find("none.toml: cannot read configuration: no such file"),
              std::string::npos);
    const auto file = dir.path() / "scaled.toml";
    std::ofstream(file)
        << "[estimator]\npriors = \"priors.toml\"\n[detection]\nevery_frames = -1\n";
    auto bad = applyPipelineFile(file, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(
        bad.error().message,
        file.string() + ":4: detection.every_frames: must be an integer in [1, 100000] (got -1)");
    std::ofstream(file) << "[estimator]\npriors = \"priors.toml\"\n";
    ASSERT_TRUE(applyPipelineFile(file, c).ok());
    EXPECT_EQ(c.priors_path, dir.path() / "priors.toml");
}

TEST(PipelineConfig, Overrides) {
    PipelineConfig c = defaultPipelineConfig();
    ASSERT_TRUE(applyPipelineOverrides({"estimator.robust=false", "detection.every_frames=30",
                                        "estimator.variance=paper", "detector.model=/m/x.onnx"},
                                       c)
                    .ok());
    EXPECT_FALSE(c.estimator.likelihood.robust);
    EXPECT_EQ(c.detection.every_frames, 30);
    EXPECT_EQ(c.estimator.likelihood.variance_model, core::VarianceModel::kPaper);
    EXPECT_EQ(c.detector.model_path, std::filesystem::path("/m/x.onnx"));

    auto bad = applyPipelineOverrides({"estimator.robust=maybe"}, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message,
              "--set estimator.robust=maybe: estimator.robust: must be true or false (got "
              "\"maybe\")");
    auto form = applyPipelineOverrides({"robust=true"}, c);
    ASSERT_FALSE(form.ok());
    EXPECT_NE(form.error().message.find("expected section.key=value"), std::string::npos);
    auto unknown = applyPipelineOverrides({"estimator.nope=1"}, c);
    ASSERT_FALSE(unknown.ok());
    EXPECT_EQ(
        unknown.error().message.rfind("--set estimator.nope=1: estimator.nope: unknown key", 0), 0U)
        << unknown.error().message;
}

TEST(PipelineConfig, ToTomlRoundTrips) {
    PipelineConfig a = defaultPipelineConfig();
    a.detector.classes = {"cup", "dining table"};
    a.detector.model_path = "/m/y.onnx";
    a.priors_path = "/etc/scaled/priors.toml";
    a.estimator.likelihood.outlier_weight = core::Scalar(0.125);
    const std::string text = toToml(a);
    PipelineConfig b;
    auto r = applyPipelineToml(text, "dump", "/", b);
    ASSERT_TRUE(r.ok()) << r.error().message << "\n" << text;
    EXPECT_EQ(toToml(b), text);
    EXPECT_EQ(pipelineConfigKeys().size(),
              static_cast<std::size_t>(std::count(text.begin(), text.end(), '=')));
}

}  // namespace
}  // namespace scaled::daemon
