// slam-run: the EKF MonoSLAM tracker over a dataset, an image folder or a
// video, with a TUM-format trajectory and a JSON summary (ground-truth metrics
// where available).
//
//   slam-run --dataset DIR|VIDEO [--format tum|kitti|folder|video] [--frames A:B]
//            [--out traj.txt] [--json] [--camera camera.txt | --intrinsics fx,fy,cx,cy]
//            [--fps HZ] [--max-features N] [--max-measured N] [--no-warp] [--seed N]
//            [--verbose]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 bad data, 66 dataset not found,
// 73 cannot write the trajectory. The options are on CLI11 (tools/common/cli.h).

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>
#include <vector>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "args.h"
#include "cli.h"
#include "slam_run.h"
#include "sysexits.h"

namespace {

using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::OptionSpec;
using scaled::tools::parseNumber;

constexpr const char* kFooter =
    "usage: slam-run --dataset DIR|VIDEO [--format tum|kitti|folder|video] [--frames A:B]\n"
    "                [--stride N] [--blank A:B]...\n"
    "                [--out TRAJ.txt] [--json] [--camera FILE | --intrinsics fx,fy,cx,cy]\n"
    "                [--fps HZ] [--max-features N] [--max-measured N] [--no-warp]\n"
    "                [--seed N] [--set KEY=VALUE]... [--window N] [--gyro-sim D:B]\n"
    "                [--window-out CSV] [--verbose]\n"
    "Runs the EKF MonoSLAM tracker over a TUM-layout or KITTI-odometry dataset, a folder of\n"
    "images or a video file, writes the trajectory (TUM format, SLAM units, world = first\n"
    "camera) and prints a summary (with ground-truth metrics when the dataset has them).\n"
    "Options are applied in the order given; a later one overrides an earlier one.\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 65 bad data (a dataset, camera file or\n"
    "frame that does not parse, no intrinsics, nothing to track); 66 the dataset or the\n"
    "--camera file does not exist; 73 cannot write --out or --window-out.";

// The command line, checked.
struct Options {
    std::filesystem::path dataset;
    std::filesystem::path out;
    std::filesystem::path window_out;
    std::filesystem::path camera_file;
    std::optional<scaled::core::CameraIntrinsics> intrinsics;
    bool json = false;
    bool verbose = false;
    scaled::drivers::dataset::DatasetOptions dataset_options;
    scaled::tools::SlamRunOptions run;
    // The tracker's settings as `tracker.KEY=VALUE` assignments, in the order
    // given (--set and its shorthands), applied together after parsing as
    // the daemon applies its --set: checked against config/scaled.toml's ranges.
    std::vector<std::string> tracker_sets;
};

// A shorthand of --set: its value checked as a number here, its range by the
// daemon's registry.
bool setTracker(std::string_view key, std::string_view value, Options& o) {
    double v = 0;
    if (!parseNumber(value, v)) {
        return false;
    }
    o.tracker_sets.push_back("tracker." + std::string(key) + "=" + std::string(value));
    return true;
}

bool takeFormat(std::string_view v,
                std::optional<scaled::drivers::dataset::DatasetFormat>& format) {
    format = scaled::drivers::dataset::parseDatasetFormat(v);
    return format.has_value();
}

// The options in the order of the usage line; `take` checks a value as the
// hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--dataset", "DIR|VIDEO", "the dataset directory, image folder or video file (required)",
     [](std::string_view v, Options& o) {
         o.dataset = std::string(v);
         return true;
     }},
    {"--format", "tum|kitti|folder|video", "the dataset's layout (default: detected)",
     [](std::string_view v, Options& o) { return takeFormat(v, o.dataset_options.format); }},
    {"--frames", "A:B", "frames A (inclusive) to B (exclusive); either may be omitted",
     [](std::string_view v, Options& o) {
         return scaled::tools::parseFrameRange(v, o.run.first_frame, o.run.end_frame);
     }},
    {"--stride", "N", "every Nth frame of the range (a 30 Hz sequence at 10 Hz: 3)",
     [](std::string_view v, Options& o) {
         return parseNumber(v, o.run.selection.stride) && o.run.selection.stride >= 1;
     }},
    {"--blank", "A:B", "frames A to B-1 delivered black (loss and recovery); repeatable",
     [](std::string_view v, Options& o) {
         auto r = scaled::drivers::source::parseBlankRange(v);
         if (r.ok()) {
             o.run.selection.blank.push_back(*r);
         }
         return r.ok();
     }},
    {"--out", "TRAJ.txt", "write the trajectory there (TUM format, SLAM units)",
     [](std::string_view v, Options& o) {
         o.out = std::string(v);
         return true;
     }},
    {"--json", nullptr, "print the summary as one JSON object",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
    scaled::tools::cameraFileOption<Options>(),
    {"--intrinsics", "fx,fy,cx,cy", "the camera's intrinsics (pixels); overrides the dataset's",
     [](std::string_view v, Options& o) {
         scaled::core::CameraIntrinsics k;
         const bool ok = scaled::tools::parseIntrinsics(v, k);
         o.intrinsics = k;
         return ok;
     }},
    {"--fps", "HZ",
     "frame rate of an image folder without times.txt, or of a\n"
     "video whose container has none (default 30)",
     [](std::string_view v, Options& o) {
         double& fps = o.dataset_options.folder_fps;
         return parseNumber(v, fps) && std::isfinite(fps) && fps > 0 && fps <= 1e9;
     }},
    {"--max-features", "N", "the map's features at most (= --set max_features=N)",
     [](std::string_view v, Options& o) { return setTracker("max_features", v, o); }},
    {"--max-measured", "N", "features measured per frame at most (= --set max_measured=N)",
     [](std::string_view v, Options& o) { return setTracker("max_measured", v, o); }},
    {"--no-warp", nullptr, "no patch warping (= --set warp_patches=0)",
     [](std::string_view, Options& o) {
         o.tracker_sets.emplace_back("tracker.warp_patches=false");
         return true;
     }},
    {"--seed", "N", "the tracker's random seed (RANSAC; --gyro-sim's bias)",
     [](std::string_view v, Options& o) { return setTracker("seed", v, o); }},
    {"--set", "KEY=VALUE",
     "a key of the daemon's [tracker] section (config/scaled.toml),\n"
     "e.g. --set sigma_a=2, --set window_ba=false; repeatable",
     [](std::string_view v, Options& o) {
         o.tracker_sets.push_back("tracker." + std::string(v));
         return v.find('=') != std::string_view::npos;
     }},
    {"--window", "N",
     "tracked frames of the sliding-window Sim(3) scale whose\n"
     "range (max/min) --json reports as window_scale (default 150,\n"
     "at least 3)",
     [](std::string_view v, Options& o) {
         return parseNumber(v, o.run.window_frames) && o.run.window_frames >= 3;
     }},
    {"--gyro-sim", "D:B",
     "the gyro prior fed by a gyro simulated from the ground truth\n"
     "(200 Hz, white noise D rad/s/sqrt(Hz), a bias drawn with\n"
     "sigma B rad/s from the seed): what a gyro would give on a\n"
     "sequence without one",
     [](std::string_view v, Options& o) {
         scaled::drivers::imu::SimulatedGyroOptions g;
         const bool ok = scaled::tools::parseGyroSim(v, g.noise_density, g.bias_sigma_radps);
         if (ok) {
             o.run.gyro_sim = g;
         }
         return ok;
     }},
    {"--window-out", "CSV",
     "that scale per window as CSV (t_s of the window's last\n"
     "frame, scale), for tools/plot_window_scale.py",
     [](std::string_view v, Options& o) {
         o.window_out = std::string(v);
         return !o.window_out.empty();
     }},
    {"--verbose", nullptr, "a line per frame on stderr (the tracker's statistics)",
     [](std::string_view, Options& o) {
         o.verbose = true;
         return true;
     }},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app("slam-run: the EKF MonoSLAM tracker over a dataset, an image folder or a video.",
                 "slam-run");
    if (auto rc = scaled::tools::parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    if (o.dataset.empty()) {
        return scaled::tools::usageError(app, "--dataset DIR|VIDEO is required");
    }
    if (o.intrinsics && !o.camera_file.empty()) {
        return scaled::tools::usageError(app, "give --camera or --intrinsics, not both");
    }
    scaled::daemon::PipelineConfig p = scaled::daemon::defaultPipelineConfig();
    if (auto set = scaled::daemon::applyPipelineOverrides(o.tracker_sets, p); !set) {
        return scaled::tools::usageError(app, set.error().message);
    }
    o.run.tracker = p.tracker;
    return std::nullopt;
}

// The dataset and the --camera file: there and readable; nullopt when fine,
// else the exit code (said on stderr).
std::optional<int> readInputs(Options& o) {
    std::error_code ec;
    if (!std::filesystem::exists(o.dataset, ec)) {
        std::fprintf(stderr, "slam-run: %s: no such dataset directory or video file\n",
                     o.dataset.c_str());
        return kExNoInput;
    }
    if (!o.camera_file.empty()) {
        auto k = scaled::drivers::dataset::readTumCameraFile(o.camera_file);
        if (!k) {
            std::fprintf(stderr, "slam-run: --camera: %s\n", k.error().message.c_str());
            return k.error().code == scaled::core::ErrorCode::kNotFound ? kExNoInput : kExDataErr;
        }
        o.dataset_options.intrinsics = *k;
    }
    return std::nullopt;
}

// The camera: the dataset's intrinsics or --intrinsics, the image size from
// the dataset or its first frame; nullopt after saying why not.
std::optional<scaled::core::PinholeRadialCamera> cameraFor(
    scaled::drivers::source::FrameSource& src, const Options& o) {
    scaled::core::CameraIntrinsics k = src.info().intrinsics;
    if (o.intrinsics) {
        // Image size from the dataset when it knows it; else from the first frame.
        const int w = k.width_px;
        const int h = k.height_px;
        k = *o.intrinsics;
        k.width_px = w;
        k.height_px = h;
    } else if (!src.info().has_intrinsics) {
        std::fprintf(stderr,
                     "slam-run: %s has no camera intrinsics (no camera.txt or calib.txt): give "
                     "--camera FILE or --intrinsics fx,fy,cx,cy\n",
                     o.dataset.c_str());
        return std::nullopt;
    }
    if (k.width_px <= 0 || k.height_px <= 0) {
        scaled::drivers::source::Frame first;
        if (auto got = src.next(first); !got || !*got) {
            std::fprintf(stderr, "slam-run: %s: cannot read the first frame%s%s\n",
                         o.dataset.c_str(), got ? "" : ": ",
                         got ? "" : got.error().message.c_str());
            return std::nullopt;
        }
        k.width_px = first.gray.cols;
        k.height_px = first.gray.rows;
    }
    auto camera = scaled::core::PinholeRadialCamera::create(k);
    if (!camera) {
        std::fprintf(stderr, "slam-run: %s\n", camera.error().message.c_str());
        return std::nullopt;
    }
    return *camera;
}

// The progress on stderr: a line per frame with --verbose, else a status line
// on a terminal, else nothing.
void setProgress(const Options& o, scaled::tools::SlamRunOptions& run) {
    if (o.verbose) {
        run.progress = [](std::size_t done, std::size_t,
                          const scaled::drivers::vision::TrackStats& s) {
            std::fprintf(stderr,
                         "frame %zu %s map %d xyz %d visible %d searched %d matched %d inliers %d "
                         "rescued %d added %d ncc_evals %d coarse %d/%d reloc %d/%d near %d\n",
                         done - 1, scaled::core::slam::toString(s.health), s.features,
                         s.xyz_features, s.visible, s.predicted, s.matched, s.inliers, s.rescued,
                         s.added, s.search_evaluations, s.coarse_matches, s.coarse_searches,
                         s.relocalise_inliers, s.relocalise_candidates, s.near_loss ? 1 : 0);
        };
    } else if (isatty(STDERR_FILENO) == 1) {
        run.progress = [](std::size_t done, std::size_t total,
                          const scaled::drivers::vision::TrackStats& s) {
            if (done % 10 == 0 || done == total) {
                std::fprintf(stderr, "\r%zu/%zu frames  %s  features %d  measured %d   ", done,
                             total, scaled::core::slam::toString(s.health), s.features,
                             s.inliers + s.rescued);
                if (done == total) {
                    std::fputc('\n', stderr);
                }
            }
        };
    }
}

// The dataset's notes, but the missing intrinsics the command line gave.
void printNotes(const scaled::drivers::source::FrameSource& src, const Options& o) {
    for (const auto& note : src.info().notes) {
        if ((o.intrinsics || !o.camera_file.empty()) && note.starts_with("no intrinsics")) {
            continue;  // given on the command line
        }
        std::fprintf(stderr, "slam-run: note: %s\n", note.c_str());
    }
}

// --out and --window-out; nullopt when written, else the exit code.
std::optional<int> writeFiles(const scaled::tools::SlamRunResult& r, const Options& o) {
    if (!o.out.empty()) {
        if (auto w = scaled::drivers::dataset::writeTumTrajectory(o.out, r.t_ns, r.poses); !w) {
            std::fprintf(stderr, "slam-run: %s\n", w.error().message.c_str());
            return kExCantCreat;
        }
    }
    if (!o.window_out.empty()) {
        if (!r.window_scale) {
            std::fprintf(stderr,
                         "slam-run: %s: no window scale to write (it needs ground truth for "
                         "every tracked frame and at least --window frames)\n",
                         o.window_out.c_str());
            return kExDataErr;
        }
        if (auto w = scaled::tools::writeWindowScales(o.window_out, r); !w) {
            std::fprintf(stderr, "slam-run: %s\n", w.error().message.c_str());
            return kExCantCreat;
        }
    }
    return std::nullopt;
}

void printSummary(const scaled::tools::SlamRunResult& r, const Options& o) {
    if (o.json) {
        std::printf("%s\n", scaled::tools::toJson(r, o.dataset.string()).c_str());
        return;
    }
    std::printf("frames %zu, tracked %zu, re-initialisations %d, relocalisations %d\n", r.frames,
                r.tracked_frames, r.reinitialisations, r.relocalisations);
    std::printf("features measured per frame %.1f (map %.1f), %.2f ms per frame (max %.2f)\n",
                r.mean_features_measured, r.mean_features_in_map, r.ms_per_frame,
                r.ms_per_frame_max);
    if (r.has_gt) {
        std::printf(
            "path %.3f m, ATE %.4f m (%.2f%% of the path), scale %.4f m/unit, "
            "drift between thirds %.3f\n",
            r.path_length_m, r.ate_rmse_m, 100 * r.ate_rmse_m / r.path_length_m, r.scale_to_gt,
            r.scale_drift_thirds);
    }
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    if (auto rc = readInputs(o)) {
        return *rc;
    }
    auto source = scaled::drivers::dataset::openDataset(o.dataset, o.dataset_options);
    if (!source) {
        std::fprintf(stderr, "slam-run: %s\n", source.error().message.c_str());
        return kExDataErr;
    }
    auto& src = **source;
    const auto camera = cameraFor(src, o);
    if (!camera) {
        return kExDataErr;
    }
    setProgress(o, o.run);
    if (o.run.gyro_sim) {
        o.run.gyro_sim->seed = o.run.tracker.slam.seed;  // one seed per run
    }
    const auto result = scaled::tools::runSlam(src, *camera, o.run);
    if (!result) {
        std::fprintf(stderr, "slam-run: %s\n", result.error().message.c_str());
        return kExDataErr;
    }
    printNotes(src, o);
    if (auto rc = writeFiles(*result, o)) {
        return *rc;
    }
    printSummary(*result, o);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return scaled::tools::runGuarded("slam-run", run, argc, argv);
}
