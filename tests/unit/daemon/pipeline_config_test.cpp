// The pipeline configuration: every key checked, errors that name the file,
// line, key and value; overrides; relative paths; a round trip through toToml.

#include <filesystem>
#include <fstream>
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
    EXPECT_EQ(c.estimator.likelihood.variance_model, core::VarianceModel::kPropagated);
    EXPECT_EQ(c.estimator.weighting, core::ObservationWeighting::kPerFeature);
    EXPECT_TRUE(c.estimator.likelihood.robust);
    EXPECT_TRUE(c.estimator.likelihood.partial_visibility);
    EXPECT_TRUE(c.estimator.extent.compensate_roll);
    EXPECT_EQ(c.estimator.posterior.arithmetic, core::PosteriorArithmetic::kFloating);
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
    EXPECT_EQ(applyError("[estimator]\nposterior_arithmetic = \"fixed\"\nmin_sigma_m = 0\n", c),
              "test.toml:3: estimator.min_sigma_m: must be >= 1e-05 with "
              "estimator.posterior_arithmetic = \"fixed\" (got 0)");
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
    EXPECT_EQ(c.detector.family, detector::ModelFamily::kDarknet);
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
              "variance, robust, outlier_weight, outlier_height_range_m, partial_visibility, "
              "partial_weight, min_sigma_m, weighting, use_non_upright, min_detection_score, "
              "max_features_per_box, compensate_roll, propagate_variance, box_edge_sigma_px, "
              "border_margin_px, min_extent_px, grid_d_min, grid_d_max, grid_bins, "
              "converged_rel_width, drift_sigma_log, posterior_arithmetic)");
    EXPECT_EQ(applyError("\n[estimatr]\n", c),
              "test.toml:2: estimatr: unknown section (allowed: source, tracker, detector, "
              "detection, estimator, camera, gpio, pipeline, socket, log)");
    EXPECT_EQ(applyError("[detection]\nevery_frames = 0\n", c),
              "test.toml:2: detection.every_frames: must be an integer in [1, 100000] (got 0)");
    EXPECT_EQ(applyError("[detection]\nevery_frames = 2.5\n", c),
              "test.toml:2: detection.every_frames: must be an integer in [1, 100000] (got 2.5)");
    EXPECT_EQ(applyError("[estimator]\nvariance = \"exact\"\n", c),
              "test.toml:2: estimator.variance: must be one of \"paper\", \"propagated\" (got "
              "\"exact\")");
    EXPECT_EQ(applyError("[estimator]\nrobust = 1\n", c),
              "test.toml:2: estimator.robust: must be true or false (got 1)");
    EXPECT_EQ(applyError("[estimator]\noutlier_weight = 0\n", c),
              "test.toml:2: estimator.outlier_weight: must be a number in (0, 1] (got 0)");
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
