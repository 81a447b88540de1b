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
// The options are on CLI11 (tools/common/cli.h).

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>

#include "cli.h"
#include "sysexits.h"

namespace {

namespace fs = std::filesystem;
using scaled::tools::kExCantCreat;
using scaled::tools::kExUsage;
using scaled::tools::OptionSpec;

constexpr double kTumDepthPerMetre = 5000.0;

constexpr const char* kFooter =
    "usage: synth-render --out DIR [--frames N] [--seed S] [--width W] [--height H]\n"
    "                    [--fx F] [--k1 K1] [--k2 K2] [--fps HZ] [--speed SCALE]\n"
    "                    [--shake RAD] [--noise SIGMA] [--no-aa] [--depth]\n"
    "Renders N frames (default 300) of a textured 6 x 5 x 3 m room along a smooth\n"
    "handheld-like loop, W x H pixels (default 640 x 480), focal length F pixels\n"
    "(default 525, principal point at the image centre, radial distortion K1 K2,\n"
    "default 0), at HZ frames per second (default 30), with Gaussian pixel noise\n"
    "SIGMA grey levels (default 1), the camera shaken by RAD radians RMS per axis at\n"
    "2-8 Hz when --shake is given, and writes rgb/, rgb.txt, groundtruth.txt (TUM,\n"
    "camera-to-world), camera.txt and gravity.txt into DIR; with --depth also\n"
    "depth/ and depth.txt (16-bit PNG, 5000 per metre).\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 73 an output could not be created.";

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
    double shake_rad = 0.0;
    double noise = 1.0;
    double k1 = 0.0;
    double k2 = 0.0;
    bool antialias = true;
    bool depth = false;
};

constexpr const char* kInvalid = "invalid value '{}'";

// The options in the order of the usage line; `take` checks a value and its
// range as the hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--out", "DIR", "the sequence's directory (required)",
     [](std::string_view v, Options& o) {
         o.out_dir = std::string(v);
         return !v.empty();
     },
     kInvalid},
    {"--frames", "N", "frames to render, 1 to 1000000 (default 300)",
     [](std::string_view v, Options& o) { return parseInt(v, 1, 1000000, &o.frames); }, kInvalid},
    {"--seed", "S", "the scene's, trajectory's and noise's seed (default 1)",
     [](std::string_view v, Options& o) { return parseInt(v, 0, 2147483647L, &o.seed); }, kInvalid},
    {"--width", "W", "image width, 16 to 8192 pixels (default 640)",
     [](std::string_view v, Options& o) { return parseInt(v, 16, 8192, &o.width); }, kInvalid},
    {"--height", "H", "image height, 16 to 8192 pixels (default 480)",
     [](std::string_view v, Options& o) { return parseInt(v, 16, 8192, &o.height); }, kInvalid},
    {"--fx", "F", "focal length, 1 to 1e5 pixels (default 525)",
     [](std::string_view v, Options& o) { return parseDouble(v, 1.0, 1e5, &o.fx); }, kInvalid},
    {"--k1", "K1", "radial distortion, -2 to 2 (default 0)",
     [](std::string_view v, Options& o) { return parseDouble(v, -2.0, 2.0, &o.k1); }, kInvalid},
    {"--k2", "K2", "radial distortion, -2 to 2 (default 0)",
     [](std::string_view v, Options& o) { return parseDouble(v, -2.0, 2.0, &o.k2); }, kInvalid},
    {"--fps", "HZ", "frames per second, 0.1 to 1000 (default 30)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.1, 1000.0, &o.fps); }, kInvalid},
    {"--speed", "SCALE", "the trajectory's speed factor, 0.01 to 4 (default 1)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.01, 4.0, &o.speed); }, kInvalid},
    {"--shake", "RAD",
     "hand shake: RMS rotation about each camera axis, 0 to 0.1 rad, 2-8 Hz (default 0)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.0, 0.1, &o.shake_rad); },
     kInvalid},
    {"--noise", "SIGMA", "Gaussian pixel noise, 0 to 100 grey levels (default 1)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.0, 100.0, &o.noise); }, kInvalid},
    {"--no-aa", nullptr, "no antialiasing",
     [](std::string_view, Options& o) {
         o.antialias = false;
         return true;
     }},
    {"--depth", nullptr, "also write depth/ and depth.txt",
     [](std::string_view, Options& o) {
         o.depth = true;
         return true;
     }},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app(
        "synth-render: a synthetic sequence of a textured room along a known trajectory, in a\n"
        "TUM-like layout.",
        "synth-render");
    if (auto rc = scaled::tools::parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    if (o.out_dir.empty()) {
        return scaled::tools::usageError(app, "--out DIR is required");
    }
    return std::nullopt;
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

scaled::core::CameraIntrinsics intrinsicsOf(const Options& opts) {
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
    return k;
}

// The text files of the sequence.
struct TextFiles {
    std::ofstream rgb;
    std::ofstream gt;
    std::ofstream camera;
    std::ofstream gravity;
    std::ofstream depth;  // with --depth

    [[nodiscard]] bool good(bool with_depth) const {
        return rgb && gt && camera && gravity && (!with_depth || depth);
    }
};

// DIR/rgb (and DIR/depth) and the text files; 0, or kExCantCreat (said).
int openOutputs(const Options& opts, const fs::path& dir, TextFiles& files) {
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
    files.rgb.open(dir / "rgb.txt");
    files.gt.open(dir / "groundtruth.txt");
    files.camera.open(dir / "camera.txt");
    files.gravity.open(dir / "gravity.txt");
    if (opts.depth) {
        files.depth.open(dir / "depth.txt");
    }
    if (!files.good(opts.depth)) {
        std::cerr << "synth-render: cannot create the text files in " << dir.string() << "\n";
        return kExCantCreat;
    }
    return 0;
}

// camera.txt and gravity.txt whole, the headers of the others.
void writeHeaders(const Options& opts, const scaled::core::CameraIntrinsics& k, TextFiles& files) {
    const bool distorted = opts.k1 != 0.0 || opts.k2 != 0.0;
    files.camera.precision(12);
    files.camera << (distorted ? "# width height fx fy cx cy k1 k2\n"
                               : "# width height fx fy cx cy\n")
                 << k.width_px << " " << k.height_px << " " << opts.fx << " " << opts.fx << " "
                 << static_cast<double>(k.cx) << " " << static_cast<double>(k.cy);
    if (distorted) {
        files.camera << " " << opts.k1 << " " << opts.k2;
    }
    files.camera << "\n";
    if (opts.depth) {
        files.depth << "# synthetic depth along the optical axis, 16-bit PNG, 5000 per metre\n"
                    << "# timestamp filename\n";
    }
    const auto g = scaled::drivers::synth::gravityDirectionW();
    files.gravity << "# unit gravity (down) direction in the world frame: gx gy gz\n"
                  << static_cast<double>(g.x()) << " " << static_cast<double>(g.y()) << " "
                  << static_cast<double>(g.z()) << "\n";
    files.rgb << "# synthetic grayscale images (scaled synth-render, seed " << opts.seed << ")\n"
              << "# timestamp filename\n";
    files.gt << "# ground truth trajectory, camera-to-world (scaled synth-render, seed "
             << opts.seed << ")\n"
             << "# timestamp tx ty tz qx qy qz qw\n";
    files.gt.precision(9);
}

// Every frame: its image (and depth) file and its text lines; 0, or
// kExCantCreat (said).
int renderFrames(const Options& opts, const scaled::core::PinholeRadialCamera& cam,
                 scaled::drivers::synth::Renderer& renderer,
                 const std::vector<scaled::drivers::synth::Frame>& frames, const fs::path& dir,
                 TextFiles& files) {
    cv::Mat image;
    cv::Mat depth;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto& f = frames[i];
        renderer.render(cam, f.pose_CtoW, image, opts.depth ? &depth : nullptr, i);
        const std::string name = frameName("rgb", i);
        if (!cv::imwrite((dir / name).string(), image)) {
            std::cerr << "synth-render: cannot write " << (dir / name).string() << "\n";
            return kExCantCreat;
        }
        const std::string t = seconds(f.t_ns);
        files.rgb << t << " " << name << "\n";
        if (opts.depth) {
            const std::string depth_name = frameName("depth", i);
            if (!cv::imwrite((dir / depth_name).string(), tumDepth(depth))) {
                std::cerr << "synth-render: cannot write " << (dir / depth_name).string() << "\n";
                return kExCantCreat;
            }
            files.depth << t << " " << depth_name << "\n";
        }
        const Eigen::Quaterniond q(f.pose_CtoW.R_CtoW.cast<double>());
        const Eigen::Vector3d p = f.pose_CtoW.p_CinW.cast<double>();
        files.gt << t << " " << p.x() << " " << p.y() << " " << p.z() << " " << q.x() << " "
                 << q.y() << " " << q.z() << " " << q.w() << "\n";
    }
    return 0;
}

int render(const Options& opts) {
    const scaled::core::CameraIntrinsics k = intrinsicsOf(opts);
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
    traj_config.shake_rms_rad = opts.shake_rad;
    auto traj = scaled::drivers::synth::Trajectory::create(traj_config);
    if (!scene || !traj) {
        std::cerr << "synth-render: " << (!scene ? scene.error().message : traj.error().message)
                  << "\n";
        return kExUsage;
    }
    const fs::path dir(opts.out_dir);
    TextFiles files;
    if (const int rc = openOutputs(opts, dir, files); rc != 0) {
        return rc;
    }
    writeHeaders(opts, k, files);
    scaled::drivers::synth::RenderOptions render_options;
    render_options.antialias = opts.antialias;
    render_options.noise_sigma = opts.noise;
    render_options.noise_seed = static_cast<std::uint64_t>(opts.seed);
    scaled::drivers::synth::Renderer renderer(*scene, render_options);
    const auto frames = traj->makeSequence(static_cast<int>(opts.frames), opts.fps);
    if (const int rc = renderFrames(opts, *cam, renderer, frames, dir, files); rc != 0) {
        return rc;
    }
    for (std::ofstream* file :
         {&files.rgb, &files.gt, &files.camera, &files.gravity, &files.depth}) {
        file->flush();
    }
    if (!files.good(opts.depth)) {
        std::cerr << "synth-render: error writing the text files in " << dir.string() << "\n";
        return kExCantCreat;
    }
    std::cout << "synth-render: " << frames.size() << " frames, "
              << static_cast<double>(scaled::drivers::synth::pathLength(frames))
              << " m of path, in " << dir.string() << "\n";
    return 0;
}

int run(int argc, char** argv) {
    Options opts;
    if (auto rc = parseOptions(argc, argv, opts)) {
        return *rc;
    }
    try {
        return render(opts);
    } catch (const std::exception& e) {  // cv::imwrite and the filesystem may throw
        std::cerr << "synth-render: " << e.what() << "\n";
        return kExCantCreat;
    }
}

}  // namespace

int main(int argc, char** argv) {
    return scaled::tools::runGuarded("synth-render", run, argc, argv);
}
