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
// Exit codes (sysexits): 0 ok, 64 bad usage, 65 a bad --trajectory file (66
// missing), 73 an output could not be created.
// The options are on CLI11 (tools/common/cli.h).

#include <algorithm>
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
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/drivers/dataset/dataset_tum.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>

#include "cli.h"
#include "sysexits.h"

namespace {

namespace fs = std::filesystem;
using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::kExUsage;
using scaled::tools::OptionSpec;

constexpr double kTumDepthPerMetre = 5000.0;

constexpr const char* kFooter =
    "usage: synth-render --out DIR [--frames N] [--seed S] [--width W] [--height H]\n"
    "                    [--fx F] [--k1 K1] [--k2 K2] [--fps HZ] [--speed SCALE]\n"
    "                    [--shake RAD] [--noise SIGMA] [--no-aa] [--depth]\n"
    "                    [--rolling-shutter S] [--exposure S] [--texture R]\n"
    "                    [--trajectory DIR]\n"
    "Renders N frames (default 300) of a textured 6 x 5 x 3 m room along a smooth\n"
    "handheld-like loop, W x H pixels (default 640 x 480), focal length F pixels\n"
    "(default 525, principal point at the image centre, radial distortion K1 K2,\n"
    "default 0), at HZ frames per second (default 30), with Gaussian pixel noise\n"
    "SIGMA grey levels (default 1), the camera shaken by RAD radians RMS per axis at\n"
    "2-8 Hz when --shake is given, and writes rgb/, rgb.txt, groundtruth.txt (TUM,\n"
    "camera-to-world), camera.txt and gravity.txt into DIR; with --depth also\n"
    "depth/ and depth.txt (16-bit PNG, 5000 per metre). With --trajectory DIR the camera\n"
    "follows the first N poses of DIR/groundtruth.txt (TUM: t tx ty tz qx qy qz qw,\n"
    "camera-to-world), a frame at each pose's time (made relative to the first),\n"
    "turned so that DIR/gravity.txt's down is the room's, and with the mean of the poses\n"
    "read (N and the next) on the room's axis at 1.45 m: the same motion with exact\n"
    "ground truth. Depth images are the first row's view.\n"
    "A frame's time stamp and ground-truth pose are those of its first row's exposure\n"
    "centre; with --rolling-shutter S row r is seen S r / (H - 1) seconds later, and\n"
    "--exposure E averages 8 views spread over E seconds around each row's time.\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 65 a bad --trajectory file; 66 its\n"
    "files missing; 73 an output could not be created.";

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
    std::string trajectory_dir;      // --trajectory: a dataset's ground truth instead of the loop
    double rolling_shutter_s = 0.0;  // readout time from the first row to the last
    double exposure_s = 0.0;         // motion blur: the exposure time of each row
    double texture_richness = 1.0;   // shapes and noise contrast of the textures
    bool fps_given = false;
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
     [](std::string_view v, Options& o) {
         o.fps_given = true;
         return parseDouble(v, 0.1, 1000.0, &o.fps);
     },
     kInvalid},
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
    {"--rolling-shutter", "S",
     "rolling shutter: seconds from the first row's exposure to the last's, 0 to 0.1 "
     "(default 0)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.0, 0.1, &o.rolling_shutter_s); },
     kInvalid},
    {"--exposure", "S", "motion blur: each row exposed for S seconds, 0 to 0.1 (default 0: none)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.0, 0.1, &o.exposure_s); },
     kInvalid},
    {"--texture", "R",
     "texture richness: shapes per square metre and noise contrast relative to the default, "
     "0.01 to 1 (default 1)",
     [](std::string_view v, Options& o) { return parseDouble(v, 0.01, 1.0, &o.texture_richness); },
     kInvalid},
    {"--trajectory", "DIR",
     "follow the ground truth of the dataset in DIR (groundtruth.txt, gravity.txt) instead "
     "of the loop",
     [](std::string_view v, Options& o) {
         o.trajectory_dir = std::string(v);
         return !v.empty();
     },
     kInvalid},
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
    if (!o.trajectory_dir.empty() && (o.speed != 1.0 || o.shake_rad != 0.0 || o.fps_given)) {
        return scaled::tools::usageError(app,
                                         "--trajectory follows a recorded motion at its own "
                                         "times: --fps, --speed and --shake do not apply");
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

// The camera's pose at any time: the loop's, or the recording's interpolated
// between its poses (held at its ends).
class PoseAtTime {
public:
    PoseAtTime(const scaled::drivers::synth::Trajectory& traj, bool recorded,
               const std::vector<scaled::drivers::synth::Frame>& frames)
        : traj_(&traj), recorded_(recorded), frames_(&frames) {}

    [[nodiscard]] scaled::core::CameraPose operator()(double t_s) const {
        if (!recorded_) {
            return traj_->poseAt(t_s);
        }
        const auto& f = *frames_;
        const auto t_ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
        if (t_ns <= f.front().t_ns) {
            return f.front().pose_CtoW;
        }
        if (t_ns >= f.back().t_ns) {
            return f.back().pose_CtoW;
        }
        const auto next = std::upper_bound(
            f.begin(), f.end(), t_ns,
            [](std::int64_t t, const scaled::drivers::synth::Frame& x) { return t < x.t_ns; });
        const auto& b = *next;
        const auto& a = *(next - 1);
        const double u = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
        scaled::core::CameraPose p;
        p.p_CinW =
            (a.pose_CtoW.p_CinW.cast<double>() * (1.0 - u) + b.pose_CtoW.p_CinW.cast<double>() * u)
                .cast<scaled::core::Scalar>();
        const Eigen::Quaterniond qa(a.pose_CtoW.R_CtoW.cast<double>());
        const Eigen::Quaterniond qb(b.pose_CtoW.R_CtoW.cast<double>());
        p.R_CtoW = qa.slerp(u, qb).toRotationMatrix().cast<scaled::core::Scalar>();
        return p;
    }

private:
    const scaled::drivers::synth::Trajectory* traj_;
    bool recorded_;
    const std::vector<scaled::drivers::synth::Frame>* frames_;
};

// One frame's image: a single view, or with --rolling-shutter / --exposure the
// rows' own views averaged over the exposure, then the pixel noise.
void renderImage(const Options& opts, const scaled::core::PinholeRadialCamera& cam,
                 scaled::drivers::synth::Renderer& renderer, const PoseAtTime& poseAt,
                 const scaled::drivers::synth::Frame& frame, std::size_t index, cv::Mat& image,
                 cv::Mat* depth) {
    if (opts.rolling_shutter_s <= 0.0 && opts.exposure_s <= 0.0) {
        renderer.render(cam, frame.pose_CtoW, image, depth, index);
        return;
    }
    if (depth != nullptr) {  // the depth of the frame's pose, its first row's
        renderer.renderDepth(cam, frame.pose_CtoW, *depth);
    }
    // The views without noise: the frame's noise is added once, below.
    const scaled::drivers::synth::RenderOptions with_noise = renderer.options();
    scaled::drivers::synth::RenderOptions noise_free = with_noise;
    noise_free.noise_sigma = 0.0;
    renderer.setOptions(noise_free);
    constexpr int kExposureSamples = 8;
    const int samples = opts.exposure_s > 0.0 ? kExposureSamples : 1;
    const double t0 = static_cast<double>(frame.t_ns) * 1e-9;
    const int h = cam.height();
    std::vector<scaled::core::CameraPose> row_poses(static_cast<std::size_t>(h));
    cv::Mat sum = cv::Mat::zeros(h, cam.width(), CV_32FC1);
    cv::Mat view;
    cv::Mat view_f;
    for (int k = 0; k < samples; ++k) {
        const double offset = samples > 1 ? opts.exposure_s * ((k + 0.5) / samples - 0.5) : 0.0;
        for (int r = 0; r < h; ++r) {
            const double row_s = h > 1 ? opts.rolling_shutter_s * r / (h - 1) : 0.0;
            row_poses[static_cast<std::size_t>(r)] = poseAt(t0 + row_s + offset);
        }
        if (!renderer.renderRows(cam, row_poses, view, 0)) {
            break;  // cannot happen: one pose per row
        }
        view.convertTo(view_f, CV_32FC1);
        sum += view_f;
    }
    renderer.setOptions(with_noise);
    sum /= static_cast<double>(samples);
    if (opts.noise > 0.0) {
        cv::Mat noise(sum.size(), CV_32FC1);
        cv::RNG rng(static_cast<std::uint64_t>(opts.seed) * 1000003ULL + index);
        rng.fill(noise, cv::RNG::NORMAL, 0.0, opts.noise);
        sum += noise;
    }
    sum.convertTo(image, CV_8UC1);  // rounds and saturates
}

// Every frame: its image (and depth) file and its text lines; 0, or
// kExCantCreat (said).
int renderFrames(const Options& opts, const scaled::core::PinholeRadialCamera& cam,
                 scaled::drivers::synth::Renderer& renderer, const PoseAtTime& poseAt,
                 const std::vector<scaled::drivers::synth::Frame>& frames, const fs::path& dir,
                 TextFiles& files) {
    cv::Mat image;
    cv::Mat depth;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto& f = frames[i];
        renderImage(opts, cam, renderer, poseAt, f, i, image, opts.depth ? &depth : nullptr);
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

// The data lines (not blank, not '#') of a text file, with their line numbers;
// nullopt (said) when it cannot be read.
std::optional<std::vector<std::pair<int, std::string>>> dataLines(const fs::path& path) {
    std::ifstream in(path);
    if (!in) {
        std::cerr << "synth-render: cannot read " << path.string() << "\n";
        return std::nullopt;
    }
    std::vector<std::pair<int, std::string>> lines;
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
        const auto first = line.find_first_not_of(" \t\r");
        if (first != std::string::npos && line[first] != '#') {
            lines.emplace_back(number, line);
        }
    }
    return lines;
}

// DIR/groundtruth.txt (its first max_poses poses, and one more when there is one
// so that a frame's last rows and exposure have a pose to move towards) and
// DIR/gravity.txt; 0, or an exit code (said, with the file and line).
int readRecording(const fs::path& dir, long max_poses,
                  std::vector<scaled::drivers::synth::RecordedPose>& poses,
                  scaled::core::Vec3& down_W) {
    using scaled::core::Scalar;
    const fs::path gt_path = dir / "groundtruth.txt";
    const fs::path gravity_path = dir / "gravity.txt";
    const auto gt = dataLines(gt_path);
    if (!gt) {
        return kExNoInput;
    }
    if (!fs::exists(gravity_path)) {
        std::cerr << "synth-render: cannot read " << gravity_path.string() << "\n";
        return kExNoInput;
    }
    for (const auto& [number, line] : *gt) {
        if (static_cast<long>(poses.size()) > max_poses) {
            break;
        }
        std::istringstream fields(line);
        double v[8] = {};
        for (double& x : v) {
            fields >> x;
        }
        constexpr double kMaxSeconds = 9e9;  // nanoseconds fit an int64
        if (!fields || !std::isfinite(v[0]) || v[0] < 0 || v[0] >= kMaxSeconds) {
            std::cerr << "synth-render: " << gt_path.string() << ":" << number
                      << ": expected 't tx ty tz qx qy qz qw' with t in seconds, in [0, 9e9)\n";
            return kExDataErr;
        }
        const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
        if (!(q.norm() > 0.5 && q.norm() < 1.5)) {
            std::cerr << "synth-render: " << gt_path.string() << ":" << number
                      << ": the quaternion is not a rotation\n";
            return kExDataErr;
        }
        scaled::drivers::synth::RecordedPose p;
        p.t_ns = std::llround(v[0] * 1e9);
        p.line = number;
        p.pose_CtoW.p_CinW = Eigen::Vector3d(v[1], v[2], v[3]).cast<Scalar>();
        p.pose_CtoW.R_CtoW = q.normalized().toRotationMatrix().cast<Scalar>();
        if (!poses.empty() && p.t_ns <= poses.back().t_ns) {
            std::cerr << "synth-render: " << gt_path.string() << ":" << number
                      << ": timestamps must increase\n";
            return kExDataErr;
        }
        poses.push_back(p);
    }
    if (poses.empty()) {
        std::cerr << "synth-render: " << gt_path.string() << ": no poses\n";
        return kExDataErr;
    }
    // The dataset reader's own check of gravity.txt (a unit vector, file and line named).
    const auto down = scaled::drivers::dataset::readGravityFile(gravity_path);
    if (!down) {
        std::cerr << "synth-render: " << down.error().message << "\n";
        return kExDataErr;
    }
    down_W = *down;
    return 0;
}

// The frames to render: the loop, or the recording placed in the room (placed:
// every pose read, one more than the frames when the recording has it); 0 or an
// exit code (said).
int makeFrames(const Options& opts, const scaled::drivers::synth::SceneConfig& scene_config,
               const scaled::drivers::synth::Trajectory& traj,
               std::vector<scaled::drivers::synth::Frame>& frames,
               std::vector<scaled::drivers::synth::Frame>& placed) {
    if (opts.trajectory_dir.empty()) {
        frames = traj.makeSequence(static_cast<int>(opts.frames), opts.fps);
        return 0;
    }
    std::vector<scaled::drivers::synth::RecordedPose> poses;
    scaled::core::Vec3 down_W;
    if (const int rc = readRecording(opts.trajectory_dir, opts.frames, poses, down_W); rc != 0) {
        return rc;
    }
    constexpr double kHeightM = 1.45;
    constexpr double kMarginM = 0.3;
    auto placed_poses = scaled::drivers::synth::placeRecordedTrajectory(
        poses, down_W, scene_config.room, scene_config.furniture, scaled::core::Vec3::Zero(),
        kHeightM, kMarginM);
    if (!placed_poses) {
        std::cerr << "synth-render: "
                  << (fs::path(opts.trajectory_dir) / "groundtruth.txt").string() << ": "
                  << placed_poses.error().message << "\n";
        return kExDataErr;
    }
    placed = std::move(*placed_poses);
    frames.assign(placed.begin(), placed.begin() + std::min<std::ptrdiff_t>(
                                                       static_cast<std::ptrdiff_t>(opts.frames),
                                                       static_cast<std::ptrdiff_t>(placed.size())));
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
    scene_config.texture_richness = static_cast<scaled::core::Scalar>(opts.texture_richness);
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
    std::vector<scaled::drivers::synth::Frame> frames;
    std::vector<scaled::drivers::synth::Frame> placed;
    if (const int rc = makeFrames(opts, scene_config, *traj, frames, placed); rc != 0) {
        return rc;
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
    const PoseAtTime poseAt(*traj, !opts.trajectory_dir.empty(), placed);
    if (const int rc = renderFrames(opts, *cam, renderer, poseAt, frames, dir, files); rc != 0) {
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
