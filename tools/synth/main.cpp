// synth-render: renders a synthetic sequence of the textured room along the
// ground-truth trajectory, in a TUM-like layout (as the 7-Scenes redkitchen
// conversion used by the project):
//
//   DIR/rgb/NNNNNN.png   8-bit grayscale frames
//   DIR/rgb.txt          "t rgb/NNNNNN.png" per frame (t in seconds)
//   DIR/groundtruth.txt  "t tx ty tz qx qy qz qw" per frame, camera-to-world
//   DIR/camera.txt       "# width height fx fy cx cy" then the numbers (plus k1 k2
//                        when --k1/--k2 give radial distortion)
//   DIR/gravity.txt      unit down vector in the world frame after a comment
//   DIR/depth.txt, DIR/depth/NNNNNN.png   with --depth: exact depth along the optical
//                        axis, 16-bit PNG at 5000 units per metre (as TUM RGB-D)
//
// Timestamps are written with nine decimals, so they are the exact nanoseconds.
// Exit codes (sysexits): 0 ok, 64 bad usage, 73 an output could not be created.

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>

#include "sysexits.h"

namespace {

using scaled::tools::kExCantCreat;
using scaled::tools::kExUsage;

constexpr double kTumDepthPerMetre = 5000.0;

void usage(std::FILE* out) {
    std::fputs(
        "usage: synth-render --out DIR [--frames N] [--seed S] [--width W] [--height H]\n"
        "                    [--fx F] [--k1 K1] [--k2 K2] [--fps HZ] [--speed SCALE]\n"
        "                    [--noise SIGMA] [--no-aa] [--depth]\n"
        "Renders N frames (default 300) of a textured 6 x 5 x 3 m room along a smooth\n"
        "handheld-like loop, W x H pixels (default 640 x 480), focal length F pixels\n"
        "(default 525, principal point at the image centre, radial distortion K1 K2,\n"
        "default 0), at HZ frames per second (default 30), with Gaussian pixel noise\n"
        "SIGMA grey levels (default 1), and writes rgb/, rgb.txt, groundtruth.txt (TUM,\n"
        "camera-to-world), camera.txt and gravity.txt into DIR; with --depth also\n"
        "depth/ and depth.txt (16-bit PNG, 5000 per metre).\n"
        "Exit codes: 0 ok, 64 bad usage, 73 an output could not be created.\n",
        out);
}

bool parseInt(std::string_view s, long lo, long hi, long* out) {
    const std::string str(s);
    char* end = nullptr;
    const long v = std::strtol(str.c_str(), &end, 10);
    if (str.empty() || end != str.c_str() + str.size() || v < lo || v > hi) {
        return false;
    }
    *out = v;
    return true;
}

bool parseDouble(std::string_view s, double lo, double hi, double* out) {
    const std::string str(s);
    char* end = nullptr;
    const double v = std::strtod(str.c_str(), &end);
    if (str.empty() || end != str.c_str() + str.size() || !std::isfinite(v) || v < lo || v > hi) {
        return false;
    }
    *out = v;
    return true;
}

struct Options {
    std::string out_dir;
    long frames = 300;
    long seed = 1;
    long width = 640;
    long height = 480;
    double fx = 525.0;
    double fps = 30.0;
    double speed = 1.0;
    double noise = 1.0;
    double k1 = 0.0;
    double k2 = 0.0;
    bool antialias = true;
    bool depth = false;
};

// Parses argv into opts; returns 0, or the exit code to stop with (-1: --help).
int parseArgs(int argc, char** argv, Options* opts) {
    for (int i = 1; i < argc; ++i) {
        const std::string_view a = argv[i];
        if (a == "--help" || a == "-h") {
            usage(stdout);
            return -1;
        }
        if (a == "--no-aa") {
            opts->antialias = false;
            continue;
        }
        if (a == "--depth") {
            opts->depth = true;
            continue;
        }
        if (i + 1 >= argc) {
            std::cerr << "synth-render: unknown argument or missing value: '" << a << "'\n";
            usage(stderr);
            return kExUsage;
        }
        const std::string_view v = argv[++i];
        bool ok = true;
        if (a == "--out") {
            opts->out_dir = std::string(v);
            ok = !v.empty();
        } else if (a == "--frames") {
            ok = parseInt(v, 1, 1000000, &opts->frames);
        } else if (a == "--seed") {
            ok = parseInt(v, 0, 2147483647L, &opts->seed);
        } else if (a == "--width") {
            ok = parseInt(v, 16, 8192, &opts->width);
        } else if (a == "--height") {
            ok = parseInt(v, 16, 8192, &opts->height);
        } else if (a == "--fx") {
            ok = parseDouble(v, 1.0, 1e5, &opts->fx);
        } else if (a == "--k1") {
            ok = parseDouble(v, -2.0, 2.0, &opts->k1);
        } else if (a == "--k2") {
            ok = parseDouble(v, -2.0, 2.0, &opts->k2);
        } else if (a == "--fps") {
            ok = parseDouble(v, 0.1, 1000.0, &opts->fps);
        } else if (a == "--speed") {
            ok = parseDouble(v, 0.01, 4.0, &opts->speed);
        } else if (a == "--noise") {
            ok = parseDouble(v, 0.0, 100.0, &opts->noise);
        } else {
            std::cerr << "synth-render: unknown argument '" << a << "'\n";
            usage(stderr);
            return kExUsage;
        }
        if (!ok) {
            std::cerr << "synth-render: " << a << ": invalid value '" << v << "'\n";
            return kExUsage;
        }
    }
    if (opts->out_dir.empty()) {
        std::cerr << "synth-render: --out DIR is required\n";
        usage(stderr);
        return kExUsage;
    }
    return 0;
}

std::string frameName(const char* dir, std::size_t i) {
    char buf[48];
    std::snprintf(buf, sizeof(buf), "%s/%06zu.png", dir, i);
    return buf;
}

// Exact decimal seconds of a non-negative timestamp.
std::string seconds(std::int64_t t_ns) {
    char buf[48];
    std::snprintf(buf, sizeof(buf), "%lld.%09lld", static_cast<long long>(t_ns / 1000000000),
                  static_cast<long long>(t_ns % 1000000000));
    return buf;
}

// Depth in metres -> TUM 16-bit depth (5000 per metre, 0 = no depth).
cv::Mat tumDepth(const cv::Mat& depth_m) {
    cv::Mat out(depth_m.size(), CV_16UC1);
    for (int r = 0; r < depth_m.rows; ++r) {
        const auto* d = depth_m.ptr<float>(r);
        auto* o = out.ptr<std::uint16_t>(r);
        for (int c = 0; c < depth_m.cols; ++c) {
            const double v = static_cast<double>(d[c]) * kTumDepthPerMetre;
            o[c] = std::isfinite(v) && v > 0 && v < 65535.0
                       ? static_cast<std::uint16_t>(std::lround(v))
                       : std::uint16_t{0};
        }
    }
    return out;
}

int run(const Options& opts) {
    namespace fs = std::filesystem;
    using scaled::core::Scalar;

    scaled::core::CameraIntrinsics k;
    k.fx = static_cast<Scalar>(opts.fx);
    k.fy = static_cast<Scalar>(opts.fx);
    k.cx = static_cast<Scalar>(static_cast<double>(opts.width) / 2.0);
    k.cy = static_cast<Scalar>(static_cast<double>(opts.height) / 2.0);
    k.k1 = static_cast<Scalar>(opts.k1);
    k.k2 = static_cast<Scalar>(opts.k2);
    k.width_px = static_cast<int>(opts.width);
    k.height_px = static_cast<int>(opts.height);
    auto cam = scaled::core::PinholeRadialCamera::create(k);
    if (!cam) {
        std::cerr << "synth-render: " << cam.error().message << "\n";
        return kExUsage;
    }
    scaled::drivers::synth::SceneConfig scene_config;
    scene_config.seed = static_cast<std::uint64_t>(opts.seed);
    auto scene = scaled::drivers::synth::Scene::create(scene_config);
    scaled::drivers::synth::TrajectoryConfig traj_config;
    traj_config.seed = static_cast<std::uint64_t>(opts.seed);
    traj_config.speed_scale = opts.speed;
    auto traj = scaled::drivers::synth::Trajectory::create(traj_config);
    if (!scene || !traj) {
        std::cerr << "synth-render: " << (!scene ? scene.error().message : traj.error().message)
                  << "\n";
        return kExUsage;
    }

    const fs::path dir(opts.out_dir);
    std::error_code ec;
    std::vector<std::string> subdirs = {"rgb"};
    if (opts.depth) {
        subdirs.emplace_back("depth");
    }
    for (const auto& sub : subdirs) {
        fs::create_directories(dir / sub, ec);
        if (ec) {
            std::cerr << "synth-render: cannot create " << (dir / sub).string() << ": "
                      << ec.message() << "\n";
            return kExCantCreat;
        }
    }
    std::ofstream rgb_txt(dir / "rgb.txt");
    std::ofstream gt_txt(dir / "groundtruth.txt");
    std::ofstream camera_txt(dir / "camera.txt");
    std::ofstream gravity_txt(dir / "gravity.txt");
    std::ofstream depth_txt;
    if (opts.depth) {
        depth_txt.open(dir / "depth.txt");
    }
    if (!rgb_txt || !gt_txt || !camera_txt || !gravity_txt || (opts.depth && !depth_txt)) {
        std::cerr << "synth-render: cannot create the text files in " << dir.string() << "\n";
        return kExCantCreat;
    }
    const bool distorted = opts.k1 != 0.0 || opts.k2 != 0.0;
    camera_txt.precision(12);
    camera_txt << (distorted ? "# width height fx fy cx cy k1 k2\n"
                             : "# width height fx fy cx cy\n")
               << k.width_px << " " << k.height_px << " " << opts.fx << " " << opts.fx << " "
               << static_cast<double>(k.cx) << " " << static_cast<double>(k.cy);
    if (distorted) {
        camera_txt << " " << opts.k1 << " " << opts.k2;
    }
    camera_txt << "\n";
    if (opts.depth) {
        depth_txt << "# synthetic depth along the optical axis, 16-bit PNG, 5000 per metre\n"
                  << "# timestamp filename\n";
    }
    const auto g = scaled::drivers::synth::gravityDirectionW();
    gravity_txt << "# unit gravity (down) direction in the world frame: gx gy gz\n"
                << static_cast<double>(g.x()) << " " << static_cast<double>(g.y()) << " "
                << static_cast<double>(g.z()) << "\n";
    rgb_txt << "# synthetic grayscale images (scaled synth-render, seed " << opts.seed << ")\n"
            << "# timestamp filename\n";
    gt_txt << "# ground truth trajectory, camera-to-world (scaled synth-render, seed " << opts.seed
           << ")\n"
           << "# timestamp tx ty tz qx qy qz qw\n";

    scaled::drivers::synth::RenderOptions render_options;
    render_options.antialias = opts.antialias;
    render_options.noise_sigma = opts.noise;
    render_options.noise_seed = static_cast<std::uint64_t>(opts.seed);
    scaled::drivers::synth::Renderer renderer(*scene, render_options);
    const auto frames = traj->makeSequence(static_cast<int>(opts.frames), opts.fps);
    cv::Mat image;
    cv::Mat depth;
    gt_txt.precision(9);
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto& f = frames[i];
        renderer.render(*cam, f.pose_CtoW, image, opts.depth ? &depth : nullptr, i);
        const std::string name = frameName("rgb", i);
        if (!cv::imwrite((dir / name).string(), image)) {
            std::cerr << "synth-render: cannot write " << (dir / name).string() << "\n";
            return kExCantCreat;
        }
        const std::string t = seconds(f.t_ns);
        rgb_txt << t << " " << name << "\n";
        if (opts.depth) {
            const std::string depth_name = frameName("depth", i);
            if (!cv::imwrite((dir / depth_name).string(), tumDepth(depth))) {
                std::cerr << "synth-render: cannot write " << (dir / depth_name).string() << "\n";
                return kExCantCreat;
            }
            depth_txt << t << " " << depth_name << "\n";
        }
        const Eigen::Quaterniond q(f.pose_CtoW.R_CtoW.cast<double>());
        const Eigen::Vector3d p = f.pose_CtoW.p_CinW.cast<double>();
        gt_txt << t << " " << p.x() << " " << p.y() << " " << p.z() << " " << q.x() << " " << q.y()
               << " " << q.z() << " " << q.w() << "\n";
    }
    rgb_txt.flush();
    gt_txt.flush();
    camera_txt.flush();
    gravity_txt.flush();
    depth_txt.flush();
    if (!rgb_txt || !gt_txt || !camera_txt || !gravity_txt || (opts.depth && !depth_txt)) {
        std::cerr << "synth-render: error writing the text files in " << dir.string() << "\n";
        return kExCantCreat;
    }
    std::cout << "synth-render: " << frames.size() << " frames, "
              << static_cast<double>(scaled::drivers::synth::pathLength(frames))
              << " m of path, in " << dir.string() << "\n";
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    Options opts;
    const int status = parseArgs(argc, argv, &opts);
    if (status != 0) {
        return status < 0 ? 0 : status;
    }
    try {
        return run(opts);
    } catch (const std::exception& e) {  // cv::imwrite and the filesystem may throw
        std::cerr << "synth-render: " << e.what() << "\n";
        return kExCantCreat;
    }
}
