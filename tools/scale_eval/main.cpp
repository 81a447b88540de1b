// scale-eval: the tracker, the detector and the scale estimator over a recorded
// sequence with ground truth; reports how the metric scale estimate compares
// with the truth (docs/accuracy.md).
//
//   scale-eval --dataset DIR [--format tum|kitti|folder|video] [--config FILE]
//              [--set section.key=value]... [--frames A:B] [--out DIR] [--json]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 bad data, 66 dataset, model or
// priors not found, 69 figures not drawn (python3-matplotlib missing; the CSV
// files are written), 73 cannot write --out, 78 bad configuration. The options
// are on CLI11 (tools/common/cli.h).

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unistd.h>
#include <vector>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/priors/priors_toml.h>

#include "args.h"
#include "cli.h"
#include "plot.h"
#include "scale_eval.h"
#include "sysexits.h"

namespace {

using namespace scaled::tools;  // NOLINT(google-build-using-namespace): a tool's main

constexpr const char* kFooter =
    "usage: scale-eval --dataset DIR [--format tum|kitti|folder|video] [--config FILE]\n"
    "                  [--set section.key=value]... [--frames A:B] [--out DIR] [--json]\n"
    "                  [--stride N] [--blank A:B]...\n"
    "                  [--camera FILE | --intrinsics fx,fy,cx,cy] [--window N] [--delta N]\n"
    "                  [--no-plots] [--truth-geometry] [--gyro-sim D:B]\n"
    "Runs EKF MonoSLAM, the object detector (synchronously, every detection.every_frames\n"
    "frames) and the metric scale estimator over a dataset and compares the estimate with\n"
    "the ground truth (Sim(3) alignment of the trajectory).\n"
    "Configuration: built-in defaults, then --config, then --set. The model defaults to\n"
    "$SCALED_SHARED_DIR/models/yolox_nano.onnx (../shared), the priors to config/priors.toml\n"
    "of the source tree. Options are applied in the order given; a later one overrides an\n"
    "earlier one.\n"
    "Exit codes (sysexits.h): 0 success; 64 usage (also: a dataset without intrinsics and no\n"
    "--intrinsics); 65 bad data (also: a --camera file that does not parse); 66 the dataset,\n"
    "model, configuration, priors or --camera file does not exist; 69 figures not drawn\n"
    "(python3-matplotlib missing; the CSV files are written); 73 cannot write --out;\n"
    "78 configuration error (--config, --set, the priors, the model).";

// The command line, checked (the configuration is read later).
struct Options {
    std::filesystem::path dataset;
    std::filesystem::path config_file;
    std::vector<std::string> overrides;
    std::filesystem::path camera_file;
    std::string out_dir;
    bool json = false;
    bool plots = true;
    scaled::drivers::dataset::DatasetOptions dataset_options;
    EvalOptions eval;
};

bool takeFormat(std::string_view v,
                std::optional<scaled::drivers::dataset::DatasetFormat>& format) {
    format = scaled::drivers::dataset::parseDatasetFormat(v);
    return format.has_value();
}

// The options in the order of the usage line; `take` checks a value as the
// hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--dataset", "DIR", "the dataset directory or video file (required)",
     [](std::string_view v, Options& o) {
         o.dataset = std::string(v);
         return true;
     }},
    {"--format", "tum|kitti|folder|video", "the dataset's layout (default: detected)",
     [](std::string_view v, Options& o) { return takeFormat(v, o.dataset_options.format); }},
    {"--config", "FILE",
     "pipeline configuration (TOML, see config/scaled.toml); built-in\n"
     "defaults otherwise",
     [](std::string_view v, Options& o) {
         o.config_file = std::string(v);
         return true;
     }},
    {"--set", "K=V",
     "override one key after the file, e.g. --set\n"
     "estimator.robust=true, --set detection.every_frames=5,\n"
     "--set estimator.priors=FILE; repeatable",
     [](std::string_view v, Options& o) {
         o.overrides.emplace_back(v);
         return true;
     }},
    {"--frames", "A:B", "frames A (inclusive) to B (exclusive); either may be omitted",
     [](std::string_view v, Options& o) {
         return parseFrameRange(v, o.eval.first_frame, o.eval.end_frame);
     }},
    {"--out", "DIR",
     "write frames.csv, updates.csv, observations.csv, posterior.csv,\n"
     "likelihoods.csv, summary.json, config.toml and the figures\n"
     "fig_{a,b,c,d}_*.png (tools/scale_eval_plot.py, python3-matplotlib)",
     [](std::string_view v, Options& o) {
         o.out_dir = std::string(v);
         return !o.out_dir.empty();
     }},
    {"--json", nullptr, "print one JSON object on stdout (progress stays on stderr)",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
    {"--stride", "N", "every Nth frame of the range (a 30 Hz sequence at 10 Hz: 3)",
     [](std::string_view v, Options& o) {
         return parseNumber(v, o.eval.selection.stride) && o.eval.selection.stride >= 1;
     }},
    {"--blank", "A:B", "frames A to B-1 delivered black (loss and recovery); repeatable",
     [](std::string_view v, Options& o) {
         auto r = scaled::drivers::source::parseBlankRange(v);
         if (r.ok()) {
             o.eval.selection.blank.push_back(*r);
         }
         return r.ok();
     }},
    cameraFileOption<Options>(),
    {"--intrinsics", "fx,fy,cx,cy", "the camera's intrinsics (pixels); overrides the dataset's",
     [](std::string_view v, Options& o) {
         scaled::core::CameraIntrinsics k;
         const bool ok = parseIntrinsics(v, k);
         o.dataset_options.intrinsics = k;
         return ok;
     }},
    {"--window", "N", "frames of the sliding-window ground-truth scale (default 150, >= 3)",
     [](std::string_view v, Options& o) {
         return parseNumber(v, o.eval.window_frames) && o.eval.window_frames >= 3;
     }},
    {"--delta", "N",
     "frames between the camera positions of the distance errors\n"
     "(default 30)",
     [](std::string_view v, Options& o) {
         return parseNumber(v, o.eval.distance_delta_frames) && o.eval.distance_delta_frames >= 1;
     }},
    {"--no-plots", nullptr, "with --out: write the CSV files only",
     [](std::string_view, Options& o) {
         o.plots = false;
         return true;
     }},
    {"--truth-geometry", nullptr,
     "give the estimator the ground-truth camera poses and gravity\n"
     "(metric: the true scale is 1): the evidence with a right map;\n"
     "on KITTI the vertical (the tracker's too) is the first camera's +y",
     [](std::string_view, Options& o) {
         o.eval.truth_geometry = true;
         o.dataset_options.gravity_from_groundtruth = true;
         return true;
     }},
    {"--depth-unit", nullptr,
     "the map's metres per unit by the dataset's depth images on every\n"
     "tracked frame (frames.csv map_unit_depth; JSON map_unit_depth:\n"
     "its window range, and the motion's scale_true_window over it)",
     [](std::string_view, Options& o) {
         o.eval.depth_unit = true;
         return true;
     }},
    {"--gyro-sim", "D:B",
     "the gyro prior fed by a gyro simulated from the ground truth\n"
     "(200 Hz, white noise D rad/s/sqrt(Hz), a bias drawn with\n"
     "sigma B rad/s from tracker.seed): what a gyro would give on a\n"
     "sequence without one",
     [](std::string_view v, Options& o) {
         scaled::drivers::imu::SimulatedGyroOptions g;
         const bool ok = parseGyroSim(v, g.noise_density, g.bias_sigma_radps);
         if (ok) {
             o.eval.gyro_sim = g;
         }
         return ok;
     }},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app(
        "scale-eval: the tracker, the detector and the metric scale estimator over a recorded\n"
        "sequence, against its ground truth.",
        "scale-eval");
    if (auto rc = parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    if (o.dataset.empty()) {
        return usageError(app, "--dataset is required");
    }
    if (o.dataset_options.intrinsics && !o.camera_file.empty()) {
        return usageError(app, "give --camera or --intrinsics, not both");
    }
    return std::nullopt;
}

// The configuration: built-in defaults, then the file, then --set; the priors
// and the model where the configuration names none. nullopt when fine, else
// the exit code (said on stderr).
std::optional<int> loadConfig(Options& o) {
    auto& cfg = o.eval.config;
    cfg = scaled::daemon::defaultPipelineConfig();
    if (!o.config_file.empty()) {
        if (auto ok = scaled::daemon::applyPipelineFile(o.config_file, cfg); !ok) {
            std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
            return ok.error().code == scaled::core::ErrorCode::kIo ? kExNoInput : kExConfig;
        }
    }
    if (auto ok = scaled::daemon::applyPipelineOverrides(o.overrides, cfg); !ok) {
        std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
        return kExConfig;
    }
    if (cfg.priors_path.empty()) {
        cfg.priors_path = std::filesystem::path(SCALED_SOURCE_DIR) / "config" / "priors.toml";
    }
    const auto shared_model =
        defaultModelPath(std::filesystem::path(SCALED_SOURCE_DIR) / ".." / "shared");
    std::error_code model_ec;
    if (cfg.detector.model_path.empty()) {
        cfg.detector.model_path = shared_model;
    } else if (!std::filesystem::exists(cfg.detector.model_path, model_ec) &&
               std::filesystem::exists(shared_model, model_ec)) {
        // config/scaled.toml names the installed model; in a source tree the
        // development copy is in ../shared. Said, not silent.
        std::fprintf(stderr, "scale-eval: %s not found; using %s\n",
                     cfg.detector.model_path.c_str(), shared_model.c_str());
        cfg.detector.model_path = shared_model;
    }
    return std::nullopt;
}

// What evaluate() runs on.
struct Inputs {
    scaled::core::PriorTable priors;
    std::unique_ptr<scaled::drivers::source::FrameSource> source;
    std::unique_ptr<scaled::drivers::detector::DnnDetector> detector;
};

// The priors, the dataset (with intrinsics) and the detector, in that order;
// nullopt when all are there, else the exit code (said on stderr).
std::optional<int> openInputs(const Options& o, Inputs& in) {
    const auto& cfg = o.eval.config;
    auto priors = scaled::drivers::priors::loadPriorsFile(cfg.priors_path);
    if (!priors) {
        std::fprintf(stderr, "scale-eval: %s\n", priors.error().message.c_str());
        return priors.error().code == scaled::core::ErrorCode::kIo ? kExNoInput : kExConfig;
    }
    in.priors = std::move(*priors);
    auto dataset_options = o.dataset_options;
    if (!o.camera_file.empty()) {
        auto k = scaled::drivers::dataset::readTumCameraFile(o.camera_file);
        if (!k) {
            std::fprintf(stderr, "scale-eval: --camera: %s\n", k.error().message.c_str());
            return k.error().code == scaled::core::ErrorCode::kNotFound ? kExNoInput : kExDataErr;
        }
        dataset_options.intrinsics = *k;
    }
    auto source = scaled::drivers::dataset::openDataset(o.dataset, dataset_options);
    if (!source) {
        std::fprintf(stderr, "scale-eval: %s\n", source.error().message.c_str());
        return source.error().code == scaled::core::ErrorCode::kParse ? kExDataErr : kExNoInput;
    }
    in.source = std::move(*source);
    if (!in.source->info().has_intrinsics) {
        std::fprintf(stderr,
                     "scale-eval: %s: no camera intrinsics in the dataset; give "
                     "--camera FILE or --intrinsics fx,fy,cx,cy\n",
                     o.dataset.string().c_str());
        return kExUsage;
    }
    auto detector = scaled::drivers::detector::DnnDetector::create(cfg.detector);
    if (!detector) {
        std::fprintf(stderr, "scale-eval: %s\n", detector.error().message.c_str());
        return detector.error().code == scaled::core::ErrorCode::kInvalidArgument ? kExConfig
                                                                                  : kExNoInput;
    }
    in.detector = std::move(*detector);
    return std::nullopt;
}

// The scale on a terminal's status line, every 5th frame.
void setProgress(EvalOptions& opt) {
    if (isatty(STDERR_FILENO) != 1) {
        return;
    }
    opt.progress = [](std::size_t done, std::size_t total, const scaled::core::ScaleSummary& s) {
        if (done % 5 != 0 && done != total) {
            return;
        }
        if (s.state == scaled::core::ScaleState::kNoData) {
            std::fprintf(stderr, "\r  frame %zu/%zu  scale: no data yet            ", done, total);
        } else {
            std::fprintf(stderr, "\r  frame %zu/%zu  scale %.4f [%.4f, %.4f] %-10s", done, total,
                         static_cast<double>(s.map), static_cast<double>(s.ci95.lo),
                         static_cast<double>(s.ci95.hi), scaled::core::toString(s.state));
        }
        if (done == total) {
            std::fputc('\n', stderr);
        }
    };
}

void printText(const EvalResult& r, const std::string& json) {
    std::printf("%s: %zu frames, %zu tracked, %zu lost, %d map(s), %zu updates, %zu observations\n",
                r.dataset.c_str(), r.frames, r.tracked_frames, r.tracking_lost_frames, r.epochs,
                r.updates.size(), r.observations.size());
    if (r.converged_update) {
        const auto& u = r.updates[*r.converged_update];
        std::printf("converged at frame %lld (update %zu)\n", static_cast<long long>(u.frame),
                    *r.converged_update);
    } else {
        std::printf("not converged: no scale is claimed\n");
    }
    std::printf("%s\n", json.c_str());
}

// The summary on stdout, then --out's files and figures; the exit code.
int report(const EvalResult& result, const Options& o) {
    const std::string summary = toJson(result, o.eval);
    if (o.json) {
        std::printf("%s\n", summary.c_str());
    } else {
        printText(result, summary);
    }
    if (o.out_dir.empty()) {
        return 0;
    }
    if (auto ok = writeOutputs(result, o.eval, o.out_dir); !ok) {
        std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
        return kExCantCreat;
    }
    return o.plots ? drawFigures("scale-eval", o.out_dir) : 0;
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    if (auto rc = loadConfig(o)) {
        return *rc;
    }
    Inputs in;
    if (auto rc = openInputs(o, in)) {
        return *rc;
    }
    o.eval.keep_curves = !o.out_dir.empty();
    setProgress(o.eval);
    if (o.eval.gyro_sim) {
        o.eval.gyro_sim->seed = o.eval.config.tracker.slam.seed;  // one seed per run
    }
    auto result = evaluate(*in.source, *in.detector, in.priors, o.eval);
    if (!result) {
        std::fprintf(stderr, "scale-eval: %s\n", result.error().message.c_str());
        return kExDataErr;
    }
    return report(*result, o);
}

}  // namespace

int main(int argc, char** argv) {
    return runGuarded("scale-eval", run, argc, argv);
}
