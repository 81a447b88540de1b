#pragma once

// field-log's work: a field log read back (drivers/field_log.h) turned into
// scale-eval's CSV shapes (frames.csv, updates.csv, observations.csv, the
// ground-truth columns left empty), objects.csv (the object model's OBJECT
// lines), poses.csv and the metric trajectories in TUM format (POSE lines),
// windows.csv (WINDOW lines) and a summary (docs/field-log.md).

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/drivers/fieldlog/field_log.h>

namespace scaled::tools {

struct FieldLogAnalysis {
    std::string log;  // the path given
    std::size_t files = 0;
    std::size_t lines = 0;          // valid JSON object lines
    std::size_t corrupt_lines = 0;  // from the reader
    std::size_t partial_lines = 0;
    std::size_t unknown_lines = 0;  // valid JSON without a known "class"
    std::size_t bad_fields = 0;     // a known class with a field of the wrong type
    std::vector<std::string> problems;
    std::map<std::string, std::size_t> classes;  // lines per class

    std::size_t runs = 0;  // START lines
    std::string release;   // of the last START
    std::string source;
    std::size_t stops = 0;
    std::string last_stop_reason;
    std::size_t errors = 0;
    std::string last_error;  // "where: message"
    std::size_t state_changes = 0;
    std::size_t detection_runs = 0;
    std::size_t boxes = 0;
    std::size_t epochs = 0;  // distinct (run, epoch) pairs
    std::optional<std::int64_t> first_mono_ns;
    std::optional<std::int64_t> last_mono_ns;
    double time_span_s = 0;  // sum over runs of last - first mono_ns

    // The last SCALE line.
    struct LastScale {
        std::int64_t frame_id = -1;
        std::uint64_t epoch = 0;
        std::string state;
        std::optional<double> scale;
        std::optional<double> ci95_lo;
        std::optional<double> ci95_hi;
        int observations = 0;
    };
    std::optional<LastScale> last_scale;

    // CSV rows (without the header), in log order.
    std::vector<std::string> frame_rows;
    std::vector<std::string> update_rows;
    std::vector<std::string> observation_rows;
    std::vector<std::string> object_rows;  // OBJECT lines (estimator.model = "object")
    std::vector<std::string> pose_rows;    // POSE lines (poses.csv)
    std::size_t metric_poses = 0;          // POSE lines with a metric position
    std::vector<std::string> window_rows;  // WINDOW lines (windows.csv)

    // The metric poses of one map: a (run, epoch) with at least one POSE line
    // with a position, in the epoch's gravity-aligned frame G (metres,
    // camera to G), in log order. A pose whose t_ns is not at least 1 us
    // after the previous one of its trajectory is left out (and named in
    // problems). `file`: trajectory_metric_epoch<N>.tum, or
    // trajectory_metric_run<R>_epoch<N>.tum when the log holds several runs.
    struct Trajectory {
        std::size_t run = 0;
        std::int64_t epoch = 0;
        std::string file;
        std::vector<std::int64_t> t_ns;
        std::vector<core::CameraPose> poses;
    };
    std::vector<Trajectory> trajectories;
    // The index in `trajectories` written again as trajectory_metric.tum:
    // the one with the most poses (the later one of equals); none without.
    std::optional<std::size_t> main_trajectory;
};

FieldLogAnalysis analyseFieldLog(const drivers::fieldlog::FieldLogContents& contents,
                                 const std::string& log);

// summary.json (one line).
std::string toJson(const FieldLogAnalysis& a);

// A few lines for a terminal.
std::string toText(const FieldLogAnalysis& a);

// frames.csv, updates.csv, observations.csv, objects.csv, poses.csv,
// windows.csv, the trajectories' TUM files (and trajectory_metric.tum) and summary.json into
// `out_dir` (created if needed). Errors name the file.
core::Status writeFieldLogOutputs(const FieldLogAnalysis& a, const std::string& out_dir);

}  // namespace scaled::tools
