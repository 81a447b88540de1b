// field-log: a field log (the daemon's JSON lines, docs/field-log.md) into
// scale-eval's CSV files, objects.csv, poses.csv, windows.csv and the metric
// trajectories (TUM), a summary and the figures.
//
//   field-log LOG_DIR_OR_FILE [--out DIR] [--json] [--no-plots] [--title TEXT]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 no readable line in the log, 66
// log not found, 69 figures not drawn (the CSV files are written), 73 cannot
// write --out, 74 the log cannot be read. The options are on CLI11
// (tools/common/cli.h).

#include <cstdio>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/drivers/fieldlog/field_log.h>

#include "cli.h"
#include "field_log_report.h"
#include "plot.h"
#include "sysexits.h"

namespace {

using namespace scaled::tools;  // NOLINT(google-build-using-namespace)

constexpr const char* kFooter =
    "usage: field-log LOG_DIR_OR_FILE [--out DIR] [--json] [--no-plots] [--title TEXT]\n"
    "Reads a field log (a directory of scaled-*.jsonl files, or one file; partial and\n"
    "corrupt lines are skipped and counted) and prints a summary. --out writes\n"
    "frames.csv, updates.csv, observations.csv (scale-eval's columns; ground-truth columns\n"
    "empty), objects.csv (the OBJECT lines of the object model), poses.csv (the POSE\n"
    "lines), windows.csv (the WINDOW lines: window optimisations and their camera),\n"
    "trajectory_metric_epoch<N>.tum (the metric poses of each map, TUM;\n"
    "_run<R>_epoch<N> with several runs) and trajectory_metric.tum (the longest),\n"
    "summary.json and fig_c_estimates.png, fig_d_rel_error.png, fig_g_trajectory.png\n"
    "(tools/scale_eval_plot.py).\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 65 no readable line; 66 log not found;\n"
    "69 figures not drawn (CSV files kept); 73 cannot write --out; 74 cannot read the log.";

// The command line, checked.
struct Options {
    std::vector<std::string> logs;  // the positional argument(s); one is allowed
    std::string log;
    std::string out_dir;
    std::string title;
    bool json = false;
    bool plots = true;
};

constexpr OptionSpec<Options> kOptions[] = {
    {"--out", "DIR", "write the CSV files, trajectories, summary.json and figures there",
     [](std::string_view v, Options& o) {
         o.out_dir = v;
         return true;
     }},
    {"--json", nullptr, "print the summary as one JSON object",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
    {"--no-plots", nullptr, "with --out: write the CSV files only",
     [](std::string_view, Options& o) {
         o.plots = false;
         return true;
     }},
    {"--title", "TEXT", "appended to the figure titles (with --out)",
     [](std::string_view v, Options& o) {
         o.title = v;
         return true;
     }},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app(
        "field-log: a field log (the daemon's JSON lines) into scale-eval's CSV files, poses,\n"
        "the metric trajectories, a summary and the figures.",
        "field-log");
    configureApp(app, kFooter);
    app.add_option("LOG_DIR_OR_FILE", o.logs,
                   "a directory of scaled-*.jsonl files, or one file (required)")
        ->type_name("PATH");
    OptionTable<Options> table(kOptions);
    table.addTo(app);
    if (auto rc = parseArgs(app, argc, argv)) {
        return rc;
    }
    if (auto bad = table.takeInto(app, o)) {
        return usageError(app, *bad);
    }
    if (o.logs.empty() || o.logs.front().empty()) {
        return usageError(app, "a log directory or file is required");
    }
    if (o.logs.size() > 1) {
        return usageError(app,
                          "more than one log given ('" + o.logs[0] + "', '" + o.logs[1] + "')");
    }
    o.log = o.logs.front();
    if (o.out_dir.empty() && (!o.title.empty() || !o.plots)) {
        return usageError(app, "--title and --no-plots need --out");
    }
    return std::nullopt;
}

// --out: the files, then (unless --no-plots) the figures; the exit code.
int writeOutputs(const FieldLogAnalysis& analysis, const Options& o) {
    if (auto ok = writeFieldLogOutputs(analysis, o.out_dir); !ok) {
        std::fprintf(stderr, "field-log: %s\n", ok.error().message.c_str());
        return kExCantCreat;
    }
    if (!o.plots) {
        return 0;
    }
    // Grown from empty: GCC 14's -Warray-bounds misreads a
    // one-element initializer list that grows (a false positive).
    std::vector<std::string> extra;
    extra.reserve(3);
    extra.emplace_back("--no-curves");
    if (!o.title.empty()) {
        extra.emplace_back("--title");
        extra.push_back(o.title);
    }
    return drawFigures("field-log", o.out_dir, extra);
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    auto contents = scaled::drivers::fieldlog::readFieldLog(o.log);
    if (!contents) {
        std::fprintf(stderr, "field-log: %s\n", contents.error().message.c_str());
        return contents.error().code == scaled::core::ErrorCode::kNotFound ? kExNoInput : kExIoErr;
    }
    const FieldLogAnalysis analysis = analyseFieldLog(*contents, o.log);
    for (const auto& p : analysis.problems) {
        std::fprintf(stderr, "field-log: %s\n", p.c_str());
    }
    if (o.json) {
        std::printf("%s\n", toJson(analysis).c_str());
    } else {
        std::printf("%s", toText(analysis).c_str());
    }
    if (analysis.lines == 0) {
        std::fprintf(stderr, "field-log: %s: no readable line\n", o.log.c_str());
        return kExDataErr;
    }
    return o.out_dir.empty() ? 0 : writeOutputs(analysis, o);
}

}  // namespace

int main(int argc, char** argv) {
    return runGuarded("field-log", run, argc, argv);
}
