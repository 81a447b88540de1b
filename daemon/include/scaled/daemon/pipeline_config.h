#pragma once

// The pipeline's configuration: tracker, detector, scale estimator and the
// detection schedule, read from TOML (config/scaled.toml documents every key).
//
// Every key is checked: a wrong type, a value outside its range or an unknown
// key is an Error whose message reads `FILE:LINE: section.key: what is wrong
// (got VALUE)`. Keys that are absent keep the defaults of PipelineConfig.
// Relative paths in a file are resolved against the file's directory.
//
// Overrides (`--set section.key=value` on a command line) are TOML lines
// applied after the file with the same checks; their paths resolve against
// the working directory. Cross-field checks (grid_d_max > grid_d_min, ...)
// run once after all of them.
//
// One field registry serves this and the daemon's configuration
// (daemon_config.h). The functions here read a whole daemon file: the
// daemon's sections ([source] [socket] [log] [pipeline]) are checked like the
// rest (an unknown key or a bad value there is still an error) and then
// ignored, so `scale-eval --config config/scaled.toml` works.

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/vision/mono_tracker.h>

namespace scaled::daemon {

struct DetectionSchedule {
    int every_frames = 10;  // run the detector on every Nth frame of the map (the paper: 10)
    // Which frame of each every_frames: frame 1 + phase_frames + k * every_frames
    // of the map (its first is frame 0). Key detection.phase_frames, in
    // [0, every_frames). An evaluation axis like the RANSAC seed: which views
    // the estimator gets moves its result (docs/accuracy.md, "The detector's
    // phase"); 0 everywhere else.
    int phase_frames = 0;
    // No detection in a map's first min_map_age_s seconds of frame time: its
    // unit is still moving (redkitchen: the Sim(3) scale of the trajectory so
    // far by 30-50% in the first two seconds), and an object measured then
    // keeps that unit (docs/accuracy.md, "A map's first seconds"). Applies to
    // both schedules; a relocalisation keeps the map's age. Key
    // detection.min_map_age_s, in [0, 3600].
    double min_map_age_s = 2.0;
    // When > 0, run the detector at most this often instead (seconds of frame
    // time between the frames handed to it); every_frames is then ignored.
    // Key detection.period_s, in [0, 3600]. scale-eval follows the same
    // schedule (frame_step.h: FrameStep::detectionDue).
    double period_s = 0;
};

// The map the scale estimator measures (estimator.map): the served pose's,
// the window bundle adjustment's frame and unit (the default: the scale
// served is metres per the served pose's unit), or the filter's own (the
// ablation; docs/accuracy.md). The same without tracker.window_ba.
enum class EstimatorMap : std::uint8_t { kServed, kFilter };

struct PipelineConfig {
    drivers::vision::TrackerConfig tracker;
    drivers::detector::DetectorConfig detector;
    core::EstimatorConfig estimator;
    EstimatorMap estimator_map = EstimatorMap::kServed;
    // Poses are given in metres only while the scale's 95% interval is at most
    // this fraction of the scale (wideForPoses() below): a wider one
    // leaves POSE's metric members null (the pose in map units stays), and
    // scale-eval's metric trajectory leaves those frames out.
    double pose_max_rel_width95 = 1.0;
    std::filesystem::path priors_path;  // empty: the caller's default (config/priors.toml)
    DetectionSchedule detection;
};

// Whether a scale (its MAP and 95% interval) is too loose to put poses in
// metres: ci95_hi - ci95_lo above config.pose_max_rel_width95 times the scale,
// or no finite positive scale. The daemon's POSE (ScaleReport::wide_for_poses)
// and scale-eval's metric trajectory both follow it.
[[nodiscard]] bool wideForPoses(const PipelineConfig& config, double scale, double ci95_lo,
                                double ci95_hi);

// The defaults scaled ships with (chosen in docs/accuracy.md from the
// redkitchen ablations); they differ from the paper-literal core defaults.
PipelineConfig defaultPipelineConfig();

// Applies a TOML document to `config` (keys absent from the text keep their
// value). source_name names the text in messages; base_dir resolves relative
// paths.
core::Status applyPipelineToml(std::string_view toml_text, std::string_view source_name,
                               const std::filesystem::path& base_dir, PipelineConfig& config);

// Reads a file and applies it (relative paths against the file's directory).
core::Status applyPipelineFile(const std::filesystem::path& path, PipelineConfig& config);

// Applies `section.key=value` overrides, each in turn (paths against the
// working directory). A string value may be given without quotes.
core::Status applyPipelineOverrides(const std::vector<std::string>& assignments,
                                    PipelineConfig& config);

// Every key as `section.key`, in file order (for --help and the tests).
std::vector<std::string> pipelineConfigKeys();

// The configuration as TOML (every key, resolved paths), for logs and reports.
std::string toToml(const PipelineConfig& config);

}  // namespace scaled::daemon
