// scale-sim: the paper's three experiments in simulation.
//
//   scale-sim [--json] [--seed N] [--variance paper|propagated]
//             [--weighting feature|box] [--roll-compensation on|off]
//             [--robust] [--drift SIGMA] [--arithmetic floating|fixed]
//
// Exit codes (sysexits): 0 ok, 64 bad usage, 70 an experiment could not run.

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <string_view>

#include "experiments.h"
#include "sysexits.h"

namespace {

using scaled::tools::kExSoftware;
using scaled::tools::kExUsage;

void usage(std::FILE* out) {
    std::fputs(
        "usage: scale-sim [--json] [--seed N] [--variance paper|propagated]\n"
        "                 [--weighting feature|box] [--roll-compensation on|off]\n"
        "                 [--robust] [--drift SIGMA_LOG] [--arithmetic floating|fixed]\n"
        "Runs the paper's three experiments (four equal bottles, a microwave, four\n"
        "bottles of four heights) in simulation and reports the relative error of\n"
        "the scale estimate after convergence. --arithmetic fixed runs the posterior\n"
        "and likelihood in integer fixed point (docs/numerics.md).\n",
        out);
}

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

}  // namespace

int main(int argc, char** argv) {
    using scaled::core::ObservationWeighting;
    using scaled::core::VarianceModel;
    bool json = false;
    std::uint32_t seed = 1;
    auto config = scaled::papersim::defaultSimEstimatorConfig();
    for (int i = 1; i < argc; ++i) {
        const std::string_view a = argv[i];
        const auto next = [&]() -> std::string_view {
            if (i + 1 >= argc) {
                std::cerr << "scale-sim: " << a << " needs a value\n";
                std::exit(kExUsage);
            }
            return argv[++i];
        };
        if (a == "--json") {
            json = true;
        } else if (a == "--help" || a == "-h") {
            usage(stdout);
            return 0;
        } else if (a == "--seed") {
            const auto v = next();
            if (!parseUint(v, &seed)) {
                std::cerr << "scale-sim: --seed: not a non-negative integer: '" << v << "'\n";
                return kExUsage;
            }
        } else if (a == "--variance") {
            const auto v = next();
            if (v == "paper") {
                config.likelihood.variance_model = VarianceModel::kPaper;
            } else if (v == "propagated") {
                config.likelihood.variance_model = VarianceModel::kPropagated;
            } else {
                std::cerr << "scale-sim: --variance: expected paper or propagated, got '" << v
                          << "'\n";
                return kExUsage;
            }
        } else if (a == "--weighting") {
            const auto v = next();
            if (v == "feature") {
                config.weighting = ObservationWeighting::kPerFeature;
            } else if (v == "box") {
                config.weighting = ObservationWeighting::kPerBox;
            } else {
                std::cerr << "scale-sim: --weighting: expected feature or box, got '" << v << "'\n";
                return kExUsage;
            }
        } else if (a == "--roll-compensation") {
            const auto v = next();
            if (v == "on" || v == "off") {
                config.extent.compensate_roll = v == "on";
            } else {
                std::cerr << "scale-sim: --roll-compensation: expected on or off, got '" << v
                          << "'\n";
                return kExUsage;
            }
        } else if (a == "--robust") {
            config.likelihood.robust = true;
        } else if (a == "--drift") {
            const std::string v(next());
            char* end = nullptr;
            const double s = std::strtod(v.c_str(), &end);
            if (end == v.c_str() || *end != '\0' || !(s >= 0) || s > 1) {
                std::cerr << "scale-sim: --drift: expected a number in [0, 1], got '" << v << "'\n";
                return kExUsage;
            }
            config.posterior.drift_sigma_log = static_cast<scaled::core::Scalar>(s);
        } else if (a == "--arithmetic") {
            const auto v = next();
            if (v == "floating" || v == "fixed") {
                config.posterior.arithmetic = v == "fixed"
                                                  ? scaled::core::PosteriorArithmetic::kFixed
                                                  : scaled::core::PosteriorArithmetic::kFloating;
            } else {
                std::cerr << "scale-sim: --arithmetic: expected floating or fixed, got '" << v
                          << "'\n";
                return kExUsage;
            }
        } else {
            std::cerr << "scale-sim: unknown argument '" << a << "'\n";
            usage(stderr);
            return kExUsage;
        }
    }

    int status = 0;
    std::vector<scaled::papersim::ExperimentResult> results;
    for (const auto& spec : scaled::papersim::paperExperiments(seed, config)) {
        results.push_back(scaled::papersim::runExperiment(spec));
        if (!results.back().error.empty()) {
            std::cerr << "scale-sim: " << spec.name << ": " << results.back().error << "\n";
            status = kExSoftware;
        }
    }

    const char* variance =
        config.likelihood.variance_model == VarianceModel::kPaper ? "paper" : "propagated";
    const char* weighting =
        config.weighting == ObservationWeighting::kPerFeature ? "feature" : "box";
    const char* roll = config.extent.compensate_roll ? "on" : "off";
    if (json) {
        std::printf(
            "{\"config\":{\"seed\":%u,\"variance\":\"%s\",\"weighting\":\"%s\","
            "\"roll_compensation\":\"%s\",\"robust\":%s,\"drift_sigma_log\":%.6g,"
            "\"arithmetic\":\"%s\"},",
            seed, variance, weighting, roll, config.likelihood.robust ? "true" : "false",
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
        return status;
    }
    std::printf(
        "seed %u, variance %s, weighting %s, roll compensation %s, robust %s, drift %g, "
        "arithmetic %s\n",
        seed, variance, weighting, roll, config.likelihood.robust ? "on" : "off",
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
    return status;
}
