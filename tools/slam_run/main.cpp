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
// 73 cannot write the trajectory.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/dataset/trajectory_io.h>

#include "args.h"
#include "slam_run.h"
#include "sysexits.h"

namespace {

using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::kExUsage;
using scaled::tools::parseIntrinsics;
using scaled::tools::parseNumber;

using scaled::core::Scalar;

void usage(std::FILE* out) {
    std::fputs(
        "usage: slam-run --dataset DIR|VIDEO [--format tum|kitti|folder|video] [--frames A:B]\n"
        "                [--stride N] [--blank A:B]...\n"
        "                [--out TRAJ.txt] [--json] [--camera FILE | --intrinsics fx,fy,cx,cy]\n"
        "                [--fps HZ] [--max-features N] [--max-measured N] [--no-warp]\n"
        "                [--seed N] [--set KEY=VALUE]... [--window N] [--gyro-sim D:B]\n"
        "                [--window-out CSV] [--verbose]\n"
        "Runs the EKF MonoSLAM tracker over a TUM-layout or KITTI-odometry dataset, a folder of\n"
        "images or a video file, writes the trajectory (TUM format, SLAM units, world = first\n"
        "camera) and prints a summary.\n"
        "  --camera FILE  intrinsics `width height fx fy cx cy [k1 k2]` (camera.txt format);\n"
        "                 overrides the dataset's\n"
        "  --stride N     every Nth frame of the range (a 30 Hz sequence at 10 Hz: 3)\n"
        "  --blank A:B    frames A to B-1 delivered black (loss and recovery); repeatable\n"
        "  --gyro-sim D:B the gyro prior fed by a gyro simulated from the ground truth (200 Hz,\n"
        "                 white noise D rad/s/sqrt(Hz), a bias drawn with sigma B rad/s from the\n"
        "                 seed): what a gyro would give on a sequence without one\n"
        "  --fps HZ       frame rate of an image folder without times.txt, or of a video whose\n"
        "                 container has none (default 30)\n"
        "  --window N     tracked frames of the sliding-window Sim(3) scale whose range\n"
        "                 (max/min) --json reports as window_scale (default 150)\n"
        "  --window-out F that scale per window as CSV (t_s of the window's last frame, scale),\n"
        "                 for tools/plot_window_scale.py\n",
        out);
}

// --set KEY=VALUE: the tracker's tuning knobs, for experiments.
bool setParameter(std::string_view kv, scaled::drivers::vision::TrackerConfig& c) {
    const auto eq = kv.find('=');
    if (eq == std::string_view::npos) {
        return false;
    }
    const std::string key(kv.substr(0, eq));
    const std::string val(kv.substr(eq + 1));
    char* end = nullptr;
    const double v = std::strtod(val.c_str(), &end);
    if (val.empty() || end != val.c_str() + val.size()) {
        return false;
    }
    auto& s = c.slam;
    const auto i = static_cast<int>(v);
    if (key == "sigma_a") {
        s.motion.sigma_a = Scalar(v);
    } else if (key == "sigma_alpha") {
        s.motion.sigma_alpha = Scalar(v);
    } else if (key == "pixel_sigma_px") {
        s.pixel_sigma_px = Scalar(v);
    } else if (key == "init_sigma_v") {
        s.init_sigma_v = Scalar(v);
    } else if (key == "init_sigma_w") {
        s.init_sigma_w = Scalar(v);
    } else if (key == "rho0") {
        s.rho0 = Scalar(v);
    } else if (key == "sigma_rho") {
        s.sigma_rho = Scalar(v);
    } else if (key == "linearity_threshold") {
        s.linearity_threshold = Scalar(v);
    } else if (key == "max_features") {
        s.max_features = i;
    } else if (key == "max_measured") {
        s.max_measured = i;
    } else if (key == "min_visible") {
        s.min_visible = i;
    } else if (key == "image_margin_px") {
        s.image_margin_px = Scalar(v);
    } else if (key == "chi2_gate") {
        s.chi2_gate = Scalar(v);
    } else if (key == "ransac_threshold_px") {
        s.ransac_threshold_px = Scalar(v);
    } else if (key == "ransac_max_hypotheses") {
        s.ransac_max_hypotheses = i;
    } else if (key == "ransac_min_hypotheses") {
        s.ransac_min_hypotheses = i;
    } else if (key == "delete_min_attempts") {
        s.delete_min_attempts = i;
    } else if (key == "delete_min_ratio") {
        s.delete_min_ratio = Scalar(v);
    } else if (key == "min_inliers") {
        s.min_inliers = i;
    } else if (key == "lost_after_frames") {
        s.lost_after_frames = i;
    } else if (key == "min_ncc") {
        c.match.min_ncc = v;
    } else if (key == "max_search_pixels") {
        c.match.max_search_pixels = i;
    } else if (key == "relocalise_s") {
        c.relocalise_s = v;
    } else if (key == "relocalise_min_inliers") {
        c.relocalise_min_inliers = i;
    } else if (key == "relocalise_reproj_px") {
        c.relocalise_reproj_px = v;
    } else if (key == "relocalise_corners") {
        c.relocalise_corners = i;
    } else if (key == "relocalise_max_brief_distance") {
        c.relocalise_max_brief_distance = i;
    } else if (key == "relocalise_search_px") {
        c.relocalise_search_px = v;
    } else if (key == "relocalise_max_rel_sigma") {
        c.relocalise_max_rel_sigma = v;
    } else if (key == "use_gyro") {
        c.use_gyro = v != 0;
    } else if (key == "gyro_noise_density") {
        c.gyro_noise_density = v;
    } else if (key == "gyro_bias_sigma_radps") {
        c.gyro_bias_sigma_radps = v;
    } else if (key == "gyro_max_gap_s") {
        c.gyro_max_gap_s = v;
    } else if (key == "gyro_bias_time_s") {
        c.gyro_bias_time_s = v;
    } else if (key == "feature_border_px") {
        c.feature_border_px = i;
    } else if (key == "pyramid_levels") {
        c.pyramid_levels = i;
    } else if (key == "coarse_min_fraction") {
        c.coarse_min_fraction = v;
    } else if (key == "coarse_max_search_pixels") {
        c.coarse_max_search_pixels = i;
    } else if (key == "coarse_min_ncc") {
        c.coarse_min_ncc = v;
    } else if (key == "patch_size") {
        c.patch_size = i;
    } else if (key == "patch_source_size") {
        c.patch_source_size = i;
    } else if (key == "warp_patches") {
        c.warp_patches = v != 0;
    } else if (key == "free_radius_px") {
        c.free_radius_px = i;
    } else if (key == "max_new_per_frame") {
        c.max_new_per_frame = i;
    } else if (key == "corner_quality") {
        c.corners.quality_level = v;
    } else if (key == "corner_min_distance_px") {
        c.corners.min_distance_px = i;
    } else {
        return false;
    }
    return true;
}

}  // namespace

int main(int argc, char** argv) {
    std::filesystem::path dataset;
    std::filesystem::path out;
    std::filesystem::path window_out;
    bool json = false;
    bool verbose = false;
    scaled::drivers::dataset::DatasetOptions dopt;
    scaled::tools::SlamRunOptions ropt;
    std::optional<scaled::core::CameraIntrinsics> intrinsics;
    std::filesystem::path camera_file;
    for (int i = 1; i < argc; ++i) {
        const std::string_view a = argv[i];
        auto value = [&]() -> std::optional<std::string_view> {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "slam-run: %s needs a value\n", argv[i]);
                return std::nullopt;
            }
            return std::string_view(argv[++i]);
        };
        if (a == "--help" || a == "-h") {
            usage(stdout);
            return 0;
        }
        if (a == "--json") {
            json = true;
            continue;
        }
        if (a == "--verbose") {
            verbose = true;
            continue;
        }
        if (a == "--no-warp") {
            ropt.tracker.warp_patches = false;
            continue;
        }
        const auto v = value();
        if (!v) {
            return kExUsage;
        }
        bool ok = true;
        if (a == "--dataset") {
            dataset = std::string(*v);
        } else if (a == "--out") {
            out = std::string(*v);
        } else if (a == "--window-out") {
            window_out = std::string(*v);
            ok = !window_out.empty();
        } else if (a == "--format") {
            if (*v == "tum") {
                dopt.format = scaled::drivers::dataset::DatasetFormat::kTum;
            } else if (*v == "kitti") {
                dopt.format = scaled::drivers::dataset::DatasetFormat::kKitti;
            } else if (*v == "folder") {
                dopt.format = scaled::drivers::dataset::DatasetFormat::kImageFolder;
            } else if (*v == "video") {
                dopt.format = scaled::drivers::dataset::DatasetFormat::kVideo;
            } else {
                ok = false;
            }
        } else if (a == "--frames") {
            ok = scaled::tools::parseFrameRange(*v, ropt.first_frame, ropt.end_frame);
        } else if (a == "--stride") {
            ok = parseNumber(*v, ropt.selection.stride) && ropt.selection.stride >= 1;
        } else if (a == "--blank") {
            auto r = scaled::drivers::source::parseBlankRange(*v);
            ok = r.ok();
            if (ok) {
                ropt.selection.blank.push_back(*r);
            }
        } else if (a == "--gyro-sim") {
            scaled::drivers::imu::SimulatedGyroOptions g;
            ok = scaled::tools::parseGyroSim(*v, g.noise_density, g.bias_sigma_radps);
            if (ok) {
                ropt.gyro_sim = g;
            }
        } else if (a == "--intrinsics") {
            scaled::core::CameraIntrinsics k;
            ok = parseIntrinsics(*v, k);
            intrinsics = k;
        } else if (a == "--camera") {
            camera_file = std::string(*v);
            ok = !camera_file.empty();
        } else if (a == "--fps") {
            ok = parseNumber(*v, dopt.folder_fps) && std::isfinite(dopt.folder_fps) &&
                 dopt.folder_fps > 0 && dopt.folder_fps <= 1e9;
        } else if (a == "--max-features") {
            ok = parseNumber(*v, ropt.tracker.slam.max_features);
        } else if (a == "--max-measured") {
            ok = parseNumber(*v, ropt.tracker.slam.max_measured);
        } else if (a == "--set") {
            ok = setParameter(*v, ropt.tracker);
        } else if (a == "--window") {
            ok = parseNumber(*v, ropt.window_frames) && ropt.window_frames >= 3;
        } else if (a == "--seed") {
            ok = parseNumber(*v, ropt.tracker.slam.seed);
        } else {
            std::fprintf(stderr, "slam-run: unknown option %s\n", argv[i - 1]);
            usage(stderr);
            return kExUsage;
        }
        if (!ok) {
            std::fprintf(stderr, "slam-run: bad value for %s: '%s'\n", argv[i - 1], argv[i]);
            return kExUsage;
        }
    }
    if (dataset.empty()) {
        std::fprintf(stderr, "slam-run: --dataset DIR|VIDEO is required\n");
        usage(stderr);
        return kExUsage;
    }
    if (intrinsics && !camera_file.empty()) {
        std::fprintf(stderr, "slam-run: give --camera or --intrinsics, not both\n");
        return kExUsage;
    }
    std::error_code ec;
    if (!std::filesystem::exists(dataset, ec)) {
        std::fprintf(stderr, "slam-run: %s: no such dataset directory or video file\n",
                     dataset.c_str());
        return kExNoInput;
    }
    if (!camera_file.empty()) {
        auto k = scaled::drivers::dataset::readTumCameraFile(camera_file);
        if (!k) {
            std::fprintf(stderr, "slam-run: --camera: %s\n", k.error().message.c_str());
            return k.error().code == scaled::core::ErrorCode::kNotFound ? kExNoInput : kExDataErr;
        }
        dopt.intrinsics = *k;
    }
    auto source = scaled::drivers::dataset::openDataset(dataset, dopt);
    if (!source) {
        std::fprintf(stderr, "slam-run: %s\n", source.error().message.c_str());
        return kExDataErr;
    }
    auto& src = **source;
    scaled::core::CameraIntrinsics k = src.info().intrinsics;
    if (intrinsics) {
        // Image size from the dataset when it knows it; else from the first frame.
        const int w = k.width_px;
        const int h = k.height_px;
        k = *intrinsics;
        k.width_px = w;
        k.height_px = h;
    } else if (!src.info().has_intrinsics) {
        std::fprintf(stderr,
                     "slam-run: %s has no camera intrinsics (no camera.txt or calib.txt): give "
                     "--camera FILE or --intrinsics fx,fy,cx,cy\n",
                     dataset.c_str());
        return kExDataErr;
    }
    if (k.width_px <= 0 || k.height_px <= 0) {
        scaled::drivers::source::Frame first;
        if (auto got = src.next(first); !got || !*got) {
            std::fprintf(stderr, "slam-run: %s: cannot read the first frame%s%s\n", dataset.c_str(),
                         got ? "" : ": ", got ? "" : got.error().message.c_str());
            return kExDataErr;
        }
        k.width_px = first.gray.cols;
        k.height_px = first.gray.rows;
    }
    const auto camera = scaled::core::PinholeRadialCamera::create(k);
    if (!camera) {
        std::fprintf(stderr, "slam-run: %s\n", camera.error().message.c_str());
        return kExDataErr;
    }
    const bool tty = isatty(STDERR_FILENO) == 1;
    if (verbose) {
        ropt.progress = [](std::size_t done, std::size_t,
                           const scaled::drivers::vision::TrackStats& s) {
            std::fprintf(stderr,
                         "frame %zu %s map %d visible %d searched %d matched %d inliers %d "
                         "rescued %d added %d ncc_evals %d coarse %d/%d reloc %d/%d\n",
                         done - 1, scaled::core::slam::toString(s.health), s.features, s.visible,
                         s.predicted, s.matched, s.inliers, s.rescued, s.added,
                         s.search_evaluations, s.coarse_matches, s.coarse_searches,
                         s.relocalise_inliers, s.relocalise_candidates);
        };
    } else if (tty) {
        ropt.progress = [](std::size_t done, std::size_t total,
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
    if (ropt.gyro_sim) {
        ropt.gyro_sim->seed = ropt.tracker.slam.seed;  // one seed per run
    }
    const auto result = scaled::tools::runSlam(src, *camera, ropt);
    if (!result) {
        std::fprintf(stderr, "slam-run: %s\n", result.error().message.c_str());
        return kExDataErr;
    }
    for (const auto& note : src.info().notes) {
        if ((intrinsics || !camera_file.empty()) && note.starts_with("no intrinsics")) {
            continue;  // given on the command line
        }
        std::fprintf(stderr, "slam-run: note: %s\n", note.c_str());
    }
    if (!out.empty()) {
        if (auto w = scaled::drivers::dataset::writeTumTrajectory(out, result->t_ns, result->poses);
            !w) {
            std::fprintf(stderr, "slam-run: %s\n", w.error().message.c_str());
            return kExCantCreat;
        }
    }
    if (!window_out.empty()) {
        if (!result->window_scale) {
            std::fprintf(stderr,
                         "slam-run: %s: no window scale to write (it needs ground truth for "
                         "every tracked frame and at least --window frames)\n",
                         window_out.c_str());
            return kExDataErr;
        }
        if (auto w = scaled::tools::writeWindowScales(window_out, *result); !w) {
            std::fprintf(stderr, "slam-run: %s\n", w.error().message.c_str());
            return kExCantCreat;
        }
    }
    if (json) {
        std::printf("%s\n", scaled::tools::toJson(*result, dataset.string()).c_str());
    } else {
        const auto& r = *result;
        std::printf("frames %zu, tracked %zu, re-initialisations %d, relocalisations %d\n",
                    r.frames, r.tracked_frames, r.reinitialisations, r.relocalisations);
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
    return 0;
}
