// scale-sim: the paper's three experiments in simulation.
//
//   scale-sim [--json] [--seed N] [--variance paper|propagated]
//             [--weighting feature|box] [--roll-compensation on|off]
//             [--robust] [--drift SIGMA] [--arithmetic floating|fixed]
//
// Exit codes (sysexits): 0 ok, 64 bad usage, 70 an experiment could not run.
// The options are on CLI11 (tools/common/cli.h).

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "cli.h"
#include "experiments.h"
#include "sysexits.h"

namespace {

using scaled::core::ObservationWeighting;
using scaled::core::VarianceModel;
using scaled::tools::kExSoftware;
using scaled::tools::OptionSpec;

constexpr const char* kFooter =
    "usage: scale-sim [--json] [--seed N] [--variance paper|propagated]\n"
    "                 [--weighting feature|box] [--roll-compensation on|off]\n"
    "                 [--robust] [--drift SIGMA_LOG] [--arithmetic floating|fixed]\n"
    "Runs the paper's three experiments (four equal bottles, a microwave, four\n"
    "bottles of four heights) in simulation and reports the relative error of\n"
    "the scale estimate after convergence. --arithmetic fixed runs the posterior\n"
    "and likelihood in integer fixed point (docs/numerics.md).\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 70 an experiment could not run.";

// The command line, checked.
struct Options {
    bool json = false;
    std::uint32_t seed = 1;
    scaled::core::EstimatorConfig config = scaled::papersim::defaultSimEstimatorConfig();
};

bool parseUint(std::string_view s, std::uint32_t* out) {
    if (s.empty() || s.size() > 9) {
        return false;
    }
    std::uint32_t v = 0;
    for (const char c : s) {
        if (c < '0' || c > '9') {
            return false;
        }
        v = v * 10 + static_cast<std::uint32_t>(c - '0');
    }
    *out = v;
    return true;
}

bool takeDrift(std::string_view text, Options& o) {
    const std::string v(text);
    char* end = nullptr;
    const double s = std::strtod(v.c_str(), &end);
    if (end == v.c_str() || *end != '\0' || !(s >= 0) || s > 1) {
        return false;
    }
    o.config.posterior.drift_sigma_log = static_cast<scaled::core::Scalar>(s);
    return true;
}

// The options in the order of the usage line; `take` checks a value as the
// hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--json", nullptr, "print one JSON object (the configuration and every experiment)",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
    {"--seed", "N", "the simulation's random seed (default 1)",
     [](std::string_view v, Options& o) { return parseUint(v, &o.seed); },
     "not a non-negative integer: '{}'"},
    {"--variance", "paper|propagated", "the likelihood's variance model (default paper)",
     [](std::string_view v, Options& o) {
         auto& model = o.config.likelihood.variance_model;
         if (v == "paper" || v == "propagated") {
             model = v == "paper" ? VarianceModel::kPaper : VarianceModel::kPropagated;
             return true;
         }
         return false;
     },
     "expected paper or propagated, got '{}'"},
    {"--weighting", "feature|box", "an observation's weight: per feature or per box",
     [](std::string_view v, Options& o) {
         if (v == "feature" || v == "box") {
             o.config.weighting =
                 v == "feature" ? ObservationWeighting::kPerFeature : ObservationWeighting::kPerBox;
             return true;
         }
         return false;
     },
     "expected feature or box, got '{}'"},
    {"--roll-compensation", "on|off", "compensate the camera's roll in the objects' extents",
     [](std::string_view v, Options& o) {
         if (v == "on" || v == "off") {
             o.config.extent.compensate_roll = v == "on";
             return true;
         }
         return false;
     },
     "expected on or off, got '{}'"},
    {"--robust", nullptr, "the robust likelihood (outliers)",
     [](std::string_view, Options& o) {
         o.config.likelihood.robust = true;
         return true;
     }},
    {"--drift", "SIGMA_LOG", "the scale's drift per update (sigma of log scale, [0, 1])", takeDrift,
     "expected a number in [0, 1], got '{}'"},
    {"--arithmetic", "floating|fixed",
     "the posterior's and likelihood's arithmetic (fixed: integer fixed\n"
     "point, docs/numerics.md)",
     [](std::string_view v, Options& o) {
         if (v == "floating" || v == "fixed") {
             o.config.posterior.arithmetic = v == "fixed"
                                                 ? scaled::core::PosteriorArithmetic::kFixed
                                                 : scaled::core::PosteriorArithmetic::kFloating;
             return true;
         }
         return false;
     },
     "expected floating or fixed, got '{}'"},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app("scale-sim: the paper's three experiments in simulation.", "scale-sim");
    if (auto rc = scaled::tools::parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    return std::nullopt;
}

void printJson(const Options& o, const std::vector<scaled::papersim::ExperimentResult>& results,
               const char* variance, const char* weighting, const char* roll) {
    const auto& config = o.config;
    std::printf(
        "{\"config\":{\"seed\":%u,\"variance\":\"%s\",\"weighting\":\"%s\","
        "\"roll_compensation\":\"%s\",\"robust\":%s,\"drift_sigma_log\":%.6g,"
        "\"arithmetic\":\"%s\"},",
        o.seed, variance, weighting, roll, config.likelihood.robust ? "true" : "false",
        static_cast<double>(config.posterior.drift_sigma_log),
        scaled::core::toString(config.posterior.arithmetic));
    std::printf("\"experiments\":[");
    for (std::size_t i = 0; i < results.size(); ++i) {
        const auto& r = results[i];
        std::printf(
            "%s{\"name\":\"%s\",\"updates\":%d,\"converged_at_update\":%s,"
            "\"median_rel_error\":%.6g,\"std_rel_error\":%.6g,\"ci95_coverage\":%.4g,"
            "\"final_scale\":%.6g,"
            "\"final_ci95\":[%.6g,%.6g]}",
            i == 0 ? "" : ",", r.name.c_str(), r.updates,
            r.converged_at_update < 0 ? "null" : std::to_string(r.converged_at_update).c_str(),
            static_cast<double>(r.median_rel_error), static_cast<double>(r.std_rel_error),
            static_cast<double>(r.ci95_coverage), static_cast<double>(r.final_summary.map),
            static_cast<double>(r.final_summary.ci95.lo),
            static_cast<double>(r.final_summary.ci95.hi));
    }
    std::printf("]}\n");
}

void printTable(const Options& o, const std::vector<scaled::papersim::ExperimentResult>& results,
                const char* variance, const char* weighting, const char* roll) {
    const auto& config = o.config;
    std::printf(
        "seed %u, variance %s, weighting %s, roll compensation %s, robust %s, drift %g, "
        "arithmetic %s\n",
        o.seed, variance, weighting, roll, config.likelihood.robust ? "on" : "off",
        static_cast<double>(config.posterior.drift_sigma_log),
        scaled::core::toString(config.posterior.arithmetic));
    std::printf("%-28s %7s %10s %12s %12s %9s %10s\n", "experiment", "updates", "converged",
                "median_err", "std_err", "ci95_cov", "final_d");
    for (const auto& r : results) {
        std::printf(
            "%-28s %7d %10s %11.3f%% %11.3f%% %8.0f%% %10.4f\n", r.name.c_str(), r.updates,
            r.converged_at_update < 0 ? "never" : std::to_string(r.converged_at_update).c_str(),
            100 * static_cast<double>(r.median_rel_error),
            100 * static_cast<double>(r.std_rel_error), 100 * static_cast<double>(r.ci95_coverage),
            static_cast<double>(r.final_summary.map));
    }
    std::printf("(true scale 0.37 m per SLAM unit; errors over the updates after convergence)\n");
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    int status = 0;
    std::vector<scaled::papersim::ExperimentResult> results;
    for (const auto& spec : scaled::papersim::paperExperiments(o.seed, o.config)) {
        results.push_back(scaled::papersim::runExperiment(spec));
        if (!results.back().error.empty()) {
            std::cerr << "scale-sim: " << spec.name << ": " << results.back().error << "\n";
            status = kExSoftware;
        }
    }
    const auto& config = o.config;
    const char* variance =
        config.likelihood.variance_model == VarianceModel::kPaper ? "paper" : "propagated";
    const char* weighting =
        config.weighting == ObservationWeighting::kPerFeature ? "feature" : "box";
    const char* roll = config.extent.compensate_roll ? "on" : "off";
    if (o.json) {
        printJson(o, results, variance, weighting, roll);
    } else {
        printTable(o, results, variance, weighting, roll);
    }
    return status;
}

}  // namespace

int main(int argc, char** argv) {
    return scaled::tools::runGuarded("scale-sim", run, argc, argv);
}
