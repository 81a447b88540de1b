// scale-eval: the tracker, the detector and the scale estimator over a recorded
// sequence with ground truth; reports how the metric scale estimate compares
// with the truth (docs/accuracy.md).
//
//   scale-eval --dataset DIR [--format tum|kitti|folder|video] [--config FILE]
//              [--set section.key=value]... [--frames A:B] [--out DIR] [--json]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 bad data, 66 dataset, model or
// priors not found, 69 figures not drawn (python3-matplotlib missing; the CSV
// files are written), 73 cannot write --out, 78 bad configuration.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <unistd.h>
#include <vector>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/priors/priors_toml.h>

#include "args.h"
#include "plot.h"
#include "scale_eval.h"
#include "sysexits.h"

namespace {

using namespace scaled::tools;  // NOLINT(google-build-using-namespace): a tool's main

void usage(std::FILE* out) {
    std::fputs(
        "usage: scale-eval --dataset DIR [--format tum|kitti|folder|video] [--config FILE]\n"
        "                  [--set section.key=value]... [--frames A:B] [--out DIR] [--json]\n"
        "                  [--stride N] [--blank A:B]...\n"
        "                  [--intrinsics fx,fy,cx,cy] [--window N] [--delta N] [--no-plots]\n"
        "                  [--truth-geometry] [--gyro-sim D:B]\n"
        "Runs EKF MonoSLAM, the object detector (synchronously, every detection.every_frames\n"
        "frames) and the metric scale estimator over a dataset and compares the estimate with\n"
        "the ground truth (Sim(3) alignment of the trajectory).\n"
        "  --config FILE   pipeline configuration (TOML, see config/scaled.toml); built-in\n"
        "                  defaults otherwise\n"
        "  --set K=V       override one key after the file, e.g. --set estimator.robust=true,\n"
        "                  --set detection.every_frames=5, --set estimator.priors=FILE\n"
        "  --frames A:B    frames A (inclusive) to B (exclusive); either may be omitted\n"
        "  --stride N      every Nth frame of the range (a 30 Hz sequence at 10 Hz: 3)\n"
        "  --blank A:B     frames A to B-1 delivered black (loss and recovery); repeatable\n"
        "  --gyro-sim D:B  the gyro prior fed by a gyro simulated from the ground truth (200 Hz,\n"
        "                  white noise D rad/s/sqrt(Hz), a bias drawn with sigma B rad/s from\n"
        "                  tracker.seed): what a gyro would give on a sequence without one\n"
        "  --out DIR       write frames.csv, updates.csv, observations.csv, posterior.csv,\n"
        "                  likelihoods.csv, summary.json, config.toml and the figures\n"
        "                  fig_{a,b,c,d}_*.png (tools/scale_eval_plot.py, python3-matplotlib)\n"
        "  --json          print one JSON object on stdout (progress stays on stderr)\n"
        "  --window N      frames of the sliding-window ground-truth scale (default 150)\n"
        "  --delta N       frames between the camera positions of the distance errors\n"
        "                  (default 30)\n"
        "  --no-plots      with --out: write the CSV files only\n"
        "  --truth-geometry give the estimator the ground-truth camera poses and gravity\n"
        "                  (metric: the true scale is 1): the evidence with a right map\n"
        "The model defaults to $SCALED_SHARED_DIR/models/yolox_nano.onnx (../shared), the\n"
        "priors to config/priors.toml of the source tree.\n",
        out);
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

}  // namespace

int main(int argc, char** argv) {
    std::filesystem::path dataset;
    std::filesystem::path config_file;
    std::vector<std::string> overrides;
    std::string out_dir;
    bool json = false;
    bool plots = true;
    scaled::drivers::dataset::DatasetOptions dopt;
    EvalOptions opt;
    for (int i = 1; i < argc; ++i) {
        const std::string_view a = argv[i];
        if (a == "--help" || a == "-h") {
            usage(stdout);
            return 0;
        }
        if (a == "--json") {
            json = true;
            continue;
        }
        if (a == "--no-plots") {
            plots = false;
            continue;
        }
        if (a == "--truth-geometry") {
            opt.truth_geometry = true;
            continue;
        }
        if (i + 1 >= argc) {
            std::fprintf(stderr, "scale-eval: %s needs a value (see --help)\n", argv[i]);
            return kExUsage;
        }
        const std::string_view v = argv[++i];
        bool ok = true;
        if (a == "--dataset") {
            dataset = std::string(v);
        } else if (a == "--config") {
            config_file = std::string(v);
        } else if (a == "--set") {
            overrides.emplace_back(v);
        } else if (a == "--out") {
            out_dir = std::string(v);
            ok = !out_dir.empty();
        } else if (a == "--format") {
            using scaled::drivers::dataset::DatasetFormat;
            if (v == "tum") {
                dopt.format = DatasetFormat::kTum;
            } else if (v == "kitti") {
                dopt.format = DatasetFormat::kKitti;
            } else if (v == "folder") {
                dopt.format = DatasetFormat::kImageFolder;
            } else if (v == "video") {
                dopt.format = DatasetFormat::kVideo;
            } else {
                ok = false;
            }
        } else if (a == "--frames") {
            ok = parseFrameRange(v, opt.first_frame, opt.end_frame);
        } else if (a == "--stride") {
            ok = parseNumber(v, opt.selection.stride) && opt.selection.stride >= 1;
        } else if (a == "--blank") {
            auto r = scaled::drivers::source::parseBlankRange(v);
            ok = r.ok();
            if (ok) {
                opt.selection.blank.push_back(*r);
            }
        } else if (a == "--gyro-sim") {
            scaled::drivers::imu::SimulatedGyroOptions g;
            ok = parseGyroSim(v, g.noise_density, g.bias_sigma_radps);
            if (ok) {
                opt.gyro_sim = g;
            }
        } else if (a == "--intrinsics") {
            scaled::core::CameraIntrinsics k;
            ok = parseIntrinsics(v, k);
            dopt.intrinsics = k;
        } else if (a == "--window") {
            ok = parseNumber(v, opt.window_frames) && opt.window_frames >= 3;
        } else if (a == "--delta") {
            ok = parseNumber(v, opt.distance_delta_frames) && opt.distance_delta_frames >= 1;
        } else {
            std::fprintf(stderr, "scale-eval: unknown option %s (see --help)\n", argv[i - 1]);
            return kExUsage;
        }
        if (!ok) {
            std::fprintf(stderr, "scale-eval: bad value for %s: '%s' (see --help)\n", argv[i - 1],
                         argv[i]);
            return kExUsage;
        }
    }
    if (dataset.empty()) {
        std::fprintf(stderr, "scale-eval: --dataset is required (see --help)\n");
        return kExUsage;
    }

    // Configuration: built-in defaults, then the file, then --set.
    opt.config = scaled::daemon::defaultPipelineConfig();
    if (!config_file.empty()) {
        if (auto ok = scaled::daemon::applyPipelineFile(config_file, opt.config); !ok) {
            std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
            return ok.error().code == scaled::core::ErrorCode::kIo ? kExNoInput : kExConfig;
        }
    }
    if (auto ok = scaled::daemon::applyPipelineOverrides(overrides, opt.config); !ok) {
        std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
        return kExConfig;
    }
    auto& cfg = opt.config;
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

    auto priors = scaled::drivers::priors::loadPriorsFile(cfg.priors_path);
    if (!priors) {
        std::fprintf(stderr, "scale-eval: %s\n", priors.error().message.c_str());
        return priors.error().code == scaled::core::ErrorCode::kIo ? kExNoInput : kExConfig;
    }
    auto source = scaled::drivers::dataset::openDataset(dataset, dopt);
    if (!source) {
        std::fprintf(stderr, "scale-eval: %s\n", source.error().message.c_str());
        return source.error().code == scaled::core::ErrorCode::kParse ? kExDataErr : kExNoInput;
    }
    if (!(*source)->info().has_intrinsics) {
        std::fprintf(stderr,
                     "scale-eval: %s: no camera intrinsics in the dataset; give "
                     "--intrinsics fx,fy,cx,cy\n",
                     dataset.string().c_str());
        return kExUsage;
    }
    auto detector = scaled::drivers::detector::DnnDetector::create(cfg.detector);
    if (!detector) {
        std::fprintf(stderr, "scale-eval: %s\n", detector.error().message.c_str());
        return detector.error().code == scaled::core::ErrorCode::kInvalidArgument ? kExConfig
                                                                                  : kExNoInput;
    }

    opt.keep_curves = !out_dir.empty();
    const bool tty = isatty(STDERR_FILENO) == 1;
    if (tty) {
        opt.progress = [](std::size_t done, std::size_t total,
                          const scaled::core::ScaleSummary& s) {
            if (done % 5 != 0 && done != total) {
                return;
            }
            if (s.state == scaled::core::ScaleState::kNoData) {
                std::fprintf(stderr, "\r  frame %zu/%zu  scale: no data yet            ", done,
                             total);
            } else {
                std::fprintf(stderr, "\r  frame %zu/%zu  scale %.4f [%.4f, %.4f] %-10s", done,
                             total, static_cast<double>(s.map), static_cast<double>(s.ci95.lo),
                             static_cast<double>(s.ci95.hi), scaled::core::toString(s.state));
            }
            if (done == total) {
                std::fputc('\n', stderr);
            }
        };
    }
    if (opt.gyro_sim) {
        opt.gyro_sim->seed = opt.config.tracker.slam.seed;  // one seed per run
    }
    auto result = evaluate(**source, **detector, *priors, opt);
    if (!result) {
        std::fprintf(stderr, "scale-eval: %s\n", result.error().message.c_str());
        return kExDataErr;
    }
    const std::string summary = toJson(*result, opt);
    if (json) {
        std::printf("%s\n", summary.c_str());
    } else {
        printText(*result, summary);
    }
    if (!out_dir.empty()) {
        if (auto ok = writeOutputs(*result, opt, out_dir); !ok) {
            std::fprintf(stderr, "scale-eval: %s\n", ok.error().message.c_str());
            return kExCantCreat;
        }
        if (plots) {
            if (const int rc = drawFigures("scale-eval", out_dir); rc != 0) {
                return rc;
            }
        }
    }
    return 0;
}
