// field-log: a field log (the daemon's JSON lines, docs/field-log.md) into
// scale-eval's CSV files, poses.csv and the metric trajectories (TUM), a
// summary and the figures.
//
//   field-log LOG_DIR_OR_FILE [--out DIR] [--json] [--no-plots] [--title TEXT]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 no readable line in the log, 66
// log not found, 69 figures not drawn (the CSV files are written), 73 cannot
// write --out, 74 the log cannot be read.

#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/drivers/fieldlog/field_log.h>

#include "field_log_report.h"
#include "plot.h"
#include "sysexits.h"

namespace {

using namespace scaled::tools;  // NOLINT(google-build-using-namespace)

void usage(std::FILE* to) {
    std::fprintf(
        to,
        "usage: field-log LOG_DIR_OR_FILE [--out DIR] [--json] [--no-plots] [--title TEXT]\n"
        "\n"
        "Reads a field log (a directory of scaled-*.jsonl files, or one file; partial and\n"
        "corrupt lines are skipped and counted) and prints a summary.\n"
        "  --out DIR       write frames.csv, updates.csv, observations.csv (scale-eval's\n"
        "                  columns; ground-truth columns empty), objects.csv (the OBJECT\n"
        "                  lines of the object model), poses.csv (the POSE lines),\n"
        "                  trajectory_metric_epoch<N>.tum (the metric poses of each map, TUM;\n"
        "                  _run<R>_epoch<N> with several runs) and trajectory_metric.tum (the\n"
        "                  longest), summary.json and fig_c_estimates.png, fig_d_rel_error.png,\n"
        "                  fig_g_trajectory.png (tools/scale_eval_plot.py)\n"
        "  --json          print the summary as one JSON object\n"
        "  --no-plots      with --out: write the CSV files only\n"
        "  --title TEXT    appended to the figure titles\n"
        "Exit codes: 64 usage, 65 no readable line, 66 log not found, 69 figures not drawn\n"
        "(CSV files kept), 73 cannot write --out, 74 cannot read the log.\n");
}

}  // namespace

int main(int argc, char** argv) {
    std::string log;
    std::string out_dir;
    std::string title;
    bool json = false;
    bool plots = true;
    for (int i = 1; i < argc; ++i) {
        const std::string_view a =
            argv[i];  // NOLINT(cppcoreguidelines-pro-bounds-pointer-arithmetic)
        const auto value = [&](std::string& into) {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "field-log: %s needs a value\n", argv[i]);  // NOLINT
                return false;
            }
            into = argv[++i];  // NOLINT(cppcoreguidelines-pro-bounds-pointer-arithmetic)
            return true;
        };
        if (a == "--help" || a == "-h") {
            usage(stdout);
            return 0;
        }
        if (a == "--json") {
            json = true;
        } else if (a == "--no-plots") {
            plots = false;
        } else if (a == "--out") {
            if (!value(out_dir)) {
                return kExUsage;
            }
        } else if (a == "--title") {
            if (!value(title)) {
                return kExUsage;
            }
        } else if (a.size() > 1 && a[0] == '-') {
            std::fprintf(stderr, "field-log: unknown option %s\n", argv[i]);  // NOLINT
            usage(stderr);
            return kExUsage;
        } else if (log.empty()) {
            log = a;
        } else {
            std::fprintf(stderr, "field-log: more than one log given ('%s', '%s')\n", log.c_str(),
                         argv[i]);  // NOLINT
            return kExUsage;
        }
    }
    if (log.empty()) {
        std::fprintf(stderr, "field-log: a log directory or file is required\n");
        usage(stderr);
        return kExUsage;
    }
    if (out_dir.empty() && (!title.empty() || !plots)) {
        std::fprintf(stderr, "field-log: --title and --no-plots need --out\n");
        return kExUsage;
    }

    auto contents = scaled::drivers::fieldlog::readFieldLog(log);
    if (!contents) {
        std::fprintf(stderr, "field-log: %s\n", contents.error().message.c_str());
        return contents.error().code == scaled::core::ErrorCode::kNotFound ? kExNoInput : kExIoErr;
    }
    const FieldLogAnalysis analysis = analyseFieldLog(*contents, log);
    for (const auto& p : analysis.problems) {
        std::fprintf(stderr, "field-log: %s\n", p.c_str());
    }
    if (json) {
        std::printf("%s\n", toJson(analysis).c_str());
    } else {
        std::printf("%s", toText(analysis).c_str());
    }
    if (analysis.lines == 0) {
        std::fprintf(stderr, "field-log: %s: no readable line\n", log.c_str());
        return kExDataErr;
    }
    if (!out_dir.empty()) {
        if (auto ok = writeFieldLogOutputs(analysis, out_dir); !ok) {
            std::fprintf(stderr, "field-log: %s\n", ok.error().message.c_str());
            return kExCantCreat;
        }
        if (plots) {
            // Grown from empty: GCC 14's -Warray-bounds misreads a
            // one-element initializer list that grows (a false positive).
            std::vector<std::string> extra;
            extra.reserve(3);
            extra.emplace_back("--no-curves");
            if (!title.empty()) {
                extra.emplace_back("--title");
                extra.push_back(title);
            }
            if (const int rc = drawFigures("field-log", out_dir, extra); rc != 0) {
                return rc;
            }
        }
    }
    return 0;
}
