// measure-heights: the true heights of the objects a detector sees in an RGB-D
// sequence with ground-truth poses, for scene-specific ("near-exact") priors.
//
//   measure-heights --dataset DIR [--model PATH] [--every N] [--classes a,b,...]
//                   [--min-views N] [--views] [--draw DIR] [--json]
//
// Method (details in measure.h / measure.cpp and docs/accuracy.md):
//   1. Every N-th frame: depth in metres, back-projected with the sequence's
//      intrinsics and put in the world with the ground-truth pose; heights
//      are coordinates along up = -gravity (gravity.txt).
//   2. The floor: the lowest horizontal plane (peak of the histogram of the
//      heights of every 8th pixel of every used frame) holding >= 2 % of them.
//   3. Each detection of a class of interest: the colour-to-depth shift of
//      the frame (chamfer match of depth discontinuities to colour edges),
//      the nearest dominant depth mode of the box centre, the box pixels in
//      that depth band = the object; top = 99th percentile of their heights
//      (tables: the highest horizontal plane in the box), bottom = the floor
//      (floor-standing classes) or the 1st percentile (objects on counters).
//   4. Views of one class whose world centroids are within a class radius
//      (horizontal distance) are one instance; per instance the median height
//      and its MAD over views.
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 bad data (no gravity, no depth,
// no ground truth), 66 dataset or model not found, 73 cannot write --draw. The
// options are on CLI11 (tools/common/cli.h).

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/dataset/depth_image.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/source/frame_source.h>

#include "args.h"
#include "cli.h"
#include "json.h"
#include "measure.h"
#include "sysexits.h"

namespace {

namespace hx = scaled::tools::heights;
using scaled::core::ErrorCode;
using scaled::core::Vec3;
using scaled::drivers::detector::DnnDetector;
using scaled::drivers::source::FrameSource;
using scaled::tools::jsonNumber;
using scaled::tools::jsonString;
using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::OptionSpec;

constexpr const char* kDefaultClasses =
    "chair,cup,dining table,microwave,tv,bottle,sink,oven,refrigerator,book,bowl,potted plant,"
    "vase";

constexpr const char* kFooter =
    "usage: measure-heights --dataset DIR [--model PATH] [--every N] [--classes a,b,...]\n"
    "                       [--min-views N] [--views] [--draw DIR] [--json]\n"
    "Measures the true vertical extent (metres, along -gravity) of every detected object of\n"
    "the given classes from the depth maps and ground-truth poses of an RGB-D sequence\n"
    "(TUM layout with depth.txt, groundtruth.txt, gravity.txt), groups the detections of one\n"
    "physical object across frames, and prints per object the median height over its views.\n"
    "Defaults: --model $SCALED_SHARED_DIR/models/yolox_nano.onnx (SCALED_SHARED_DIR\n"
    "defaults to ../shared); detector input 416, score 0.3. Options are applied in the order\n"
    "given; a later one overrides an earlier one.\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 65 bad data (no gravity, no depth, no\n"
    "ground truth, a frame or model that does not load); 66 the dataset or the model does\n"
    "not exist; 73 cannot write into --draw.";

bool parsePositive(std::string_view s, int& out) {
    const std::string str(s);
    char* end = nullptr;
    const long v = std::strtol(str.c_str(), &end, 10);
    if (str.empty() || end != str.c_str() + str.size() || v < 1 || v > 1000000) {
        return false;
    }
    out = static_cast<int>(v);
    return true;
}

std::vector<std::string> splitClasses(std::string_view text) {
    std::vector<std::string> out;
    std::size_t start = 0;
    while (start <= text.size()) {
        const std::size_t comma = std::min(text.find(',', start), text.size());
        std::string_view item = text.substr(start, comma - start);
        while (!item.empty() && item.front() == ' ') {
            item.remove_prefix(1);
        }
        while (!item.empty() && item.back() == ' ') {
            item.remove_suffix(1);
        }
        if (!item.empty()) {
            out.emplace_back(item);
        }
        start = comma + 1;
    }
    return out;
}

struct View {
    std::int64_t frame = 0;
    std::string class_name;
    float score = 0;
    scaled::core::BoundingBox box;
    hx::Shift shift;
    hx::ViewMeasurement m;
    int instance = -1;
};

struct Instance {
    std::string class_name;
    int id = 0;
    Vec3 centroid = Vec3::Zero();
    std::vector<double> heights;  // one per view
    std::vector<double> tops;     // above the floor
    std::vector<double> bottoms;  // above the floor
    double median_m = 0;
    double mad_m = 0;
};

cv::Scalar colourOf(std::size_t i) {
    static const cv::Scalar kColours[] = {{0, 255, 0},   {255, 128, 0}, {0, 128, 255},
                                          {255, 0, 255}, {0, 255, 255}, {255, 255, 0}};
    return kColours[i % 6];
}

bool drawFrame(const std::filesystem::path& dir, const scaled::drivers::source::Frame& frame,
               const cv::Mat& depth, const std::vector<View>& views, std::size_t first) {
    cv::Mat left = frame.color.clone();
    cv::Mat d8;
    depth.convertTo(d8, CV_8U, 255.0 / hx::kMaxDepthM);
    cv::Mat right;
    cv::cvtColor(d8, right, cv::COLOR_GRAY2BGR);
    for (std::size_t i = first; i < views.size(); ++i) {
        const View& v = views[i];
        const cv::Scalar c = colourOf(i);
        const cv::Rect r(
            cv::Point(static_cast<int>(v.box.x_min_px), static_cast<int>(v.box.y_min_px)),
            cv::Point(static_cast<int>(v.box.x_max_px), static_cast<int>(v.box.y_max_px)));
        cv::rectangle(left, r, c, 2);
        char label[96];
        std::snprintf(label, sizeof label, "%zu %s %.2f", i, v.class_name.c_str(),
                      v.m.ok ? v.m.top_m - v.m.bottom_m : -1.0);
        cv::putText(left, label, r.tl() + cv::Point(2, 14), cv::FONT_HERSHEY_SIMPLEX, 0.45, c, 1);
        cv::rectangle(right, v.m.depth_box, c, 1);
    }
    // Masks of large boxes first, so that small objects stay visible.
    std::vector<std::size_t> order;
    for (std::size_t i = first; i < views.size(); ++i) {
        order.push_back(i);
    }
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return views[a].m.depth_box.area() > views[b].m.depth_box.area();
    });
    for (const std::size_t i : order) {
        if (!views[i].m.mask.empty()) {
            right.setTo(colourOf(i), views[i].m.mask);
        }
    }
    cv::Mat both;
    cv::hconcat(left, right, both);
    char name[32];
    std::snprintf(name, sizeof name, "%06lld.png", static_cast<long long>(frame.id));
    try {
        return cv::imwrite((dir / name).string(), both);
    } catch (const cv::Exception&) {
        return false;
    }
}

// The command line, checked.
struct Options {
    std::filesystem::path dataset;
    std::filesystem::path model;
    std::optional<std::filesystem::path> draw_dir;
    int every = 10;
    int min_views = 3;
    bool json = false;
    bool list_views = false;
    std::vector<std::string> classes = splitClasses(kDefaultClasses);
};

// The options in the order of the usage line; `take` checks a value as the
// hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--dataset", "DIR",
     "the RGB-D sequence (TUM layout with depth.txt, groundtruth.txt,\n"
     "gravity.txt; required)",
     [](std::string_view v, Options& o) {
         o.dataset = v;
         return true;
     }},
    {"--model", "PATH",
     "the detector's model (default\n"
     "$SCALED_SHARED_DIR/models/yolox_nano.onnx)",
     [](std::string_view v, Options& o) {
         o.model = v;
         return true;
     }},
    {"--every", "N", "run the detector on every N-th frame (default 10)",
     [](std::string_view v, Options& o) { return parsePositive(v, o.every); },
     "not a positive integer: '{}'"},
    {"--classes", "a,b,...",
     "COCO class names (default: chair,cup,dining table,microwave,tv,\n"
     "bottle,sink,oven,refrigerator,book,bowl,potted plant,vase)",
     [](std::string_view v, Options& o) {
         o.classes = splitClasses(v);
         return !o.classes.empty();
     },
     "no class names"},
    {"--min-views", "N",
     "objects seen fewer times are listed but left out of the class\n"
     "summary (default 3)",
     [](std::string_view v, Options& o) { return parsePositive(v, o.min_views); },
     "not a positive integer: '{}'"},
    {"--views", nullptr, "also print every single measurement",
     [](std::string_view, Options& o) {
         o.list_views = true;
         return true;
     }},
    {"--draw", "DIR",
     "write DIR/NNNNNN.png: colour with boxes | depth with the segmented\n"
     "object pixels",
     [](std::string_view v, Options& o) {
         o.draw_dir = std::filesystem::path(v);
         return true;
     }},
    {"--json", nullptr, "print one JSON object",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
};

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app(
        "measure-heights: the true heights of the objects a detector sees in an RGB-D "
        "sequence\nwith ground-truth poses.",
        "measure-heights");
    if (auto rc = scaled::tools::parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    if (o.dataset.empty()) {
        return scaled::tools::usageError(app, "--dataset DIR is required");
    }
    if (o.model.empty()) {
        o.model = scaled::tools::defaultModelPath();
    }
    return std::nullopt;
}

// The dataset, the model and --draw's directory are there; nullopt when they
// are, else the exit code (said on stderr).
std::optional<int> checkPaths(const Options& o) {
    std::error_code ec;
    if (!std::filesystem::exists(o.dataset, ec)) {
        std::fprintf(stderr, "measure-heights: %s: no such dataset\n", o.dataset.c_str());
        return kExNoInput;
    }
    if (!std::filesystem::is_regular_file(o.model, ec)) {
        std::fprintf(stderr, "measure-heights: %s: no such model file\n", o.model.c_str());
        return kExNoInput;
    }
    if (o.draw_dir && !std::filesystem::is_directory(*o.draw_dir, ec)) {
        std::fprintf(stderr, "measure-heights: --draw %s: not a directory\n", o.draw_dir->c_str());
        return kExCantCreat;
    }
    return std::nullopt;
}

// The sequence has gravity, intrinsics and depth; nullopt when it has, else the
// exit code (said on stderr).
std::optional<int> checkSequence(const scaled::drivers::source::SequenceInfo& info,
                                 const Options& o) {
    if (!info.gravity_down_W) {
        std::fprintf(stderr, "measure-heights: %s: no gravity direction (gravity.txt)\n",
                     o.dataset.c_str());
        return kExDataErr;
    }
    if (!info.has_intrinsics || info.depth_scale_m <= 0) {
        std::fprintf(stderr, "measure-heights: %s: needs camera intrinsics and depth maps\n",
                     o.dataset.c_str());
        return kExDataErr;
    }
    return std::nullopt;
}

scaled::core::Result<std::unique_ptr<DnnDetector>> createDetector(const Options& o) {
    scaled::drivers::detector::DetectorConfig dc;
    dc.model_path = o.model;
    dc.family = scaled::drivers::detector::familyFromPath(o.model);
    dc.input_size_px = 416;
    dc.classes = o.classes;
    return DnnDetector::create(dc);
}

// The frames measure-heights uses: every N-th with ground truth and depth, as
// DepthViews (depth in metres, the intrinsics, the true pose, up).
class ViewReader {
public:
    ViewReader(FrameSource& source, int every, const Vec3& up_W)
        : source_(source), every_(every), up_W_(up_W) {}

    // nullopt: the next view is in `dv` (its frame in frame()); else 0 at the
    // end of the sequence, or the exit code (said on stderr).
    std::optional<int> next(hx::DepthView& dv) {
        const auto& info = source_.info();
        while (true) {
            auto more = source_.next(frame_);
            if (!more) {
                std::fprintf(stderr, "measure-heights: %s\n", more.error().message.c_str());
                return kExDataErr;
            }
            if (!*more) {
                return 0;
            }
            if (frame_.id % every_ != 0 || !frame_.T_CtoW_gt || !frame_.depth_path) {
                continue;
            }
            auto depth = scaled::drivers::dataset::loadDepthMetres(frame_, info);
            if (!depth) {
                std::fprintf(stderr, "measure-heights: %s\n", depth.error().message.c_str());
                return kExDataErr;
            }
            dv.depth = *depth;
            dv.k = info.intrinsics;
            dv.T_CtoW = *frame_.T_CtoW_gt;
            dv.up_W = up_W_;
            return std::nullopt;
        }
    }

    // Back to the first frame; nullopt when there, else the exit code.
    std::optional<int> rewind() {
        if (auto rewound = source_.seek(0); !rewound) {
            std::fprintf(stderr, "measure-heights: %s\n", rewound.error().message.c_str());
            return kExDataErr;
        }
        return std::nullopt;
    }

    [[nodiscard]] const scaled::drivers::source::Frame& frame() const { return frame_; }

private:
    FrameSource& source_;
    int every_;
    Vec3 up_W_;
    scaled::drivers::source::Frame frame_;
};

// What the whole run finds, for the report.
struct Findings {
    Vec3 up_W = Vec3::UnitZ();
    int frames_used = 0;
    std::vector<double> camera_heights;
    std::vector<hx::Plane> planes;
    std::optional<hx::Plane> floor;
    std::vector<View> views;
    std::vector<Instance> instances;
    std::size_t rejected = 0;

    [[nodiscard]] double floorHeight() const { return floor ? floor->height_m : 0.0; }
};

// Pass 1: the heights of every 8th pixel of every used frame give the scene's
// horizontal planes (floor, table and counter tops); the floor is the lowest
// with >= 2 % of the samples. nullopt when done, else the exit code.
std::optional<int> surveyScene(ViewReader& reader, const Options& o, Findings& f) {
    std::vector<float> scene_heights;
    hx::DepthView dv;
    while (true) {
        if (const auto done = reader.next(dv)) {
            if (*done != 0) {
                return *done;
            }
            break;
        }
        hx::appendHeights(dv, 8, scene_heights);
        f.camera_heights.push_back(dv.cameraHeight());
        ++f.frames_used;
    }
    if (f.frames_used == 0) {
        std::fprintf(stderr, "measure-heights: %s: no frame with depth and ground truth\n",
                     o.dataset.c_str());
        return kExDataErr;
    }
    f.planes = hx::findPlanes(scene_heights, 0.01);
    for (const hx::Plane& p : f.planes) {
        if (p.fraction >= 0.02) {
            f.floor = p;
            break;
        }
    }
    if (!f.floor) {
        std::fputs(
            "measure-heights: no floor plane found (floor-standing classes use their own "
            "lowest pixel)\n",
            stderr);
    }
    return std::nullopt;
}

// One measurement per detection of the frame of `dv`, with --draw its picture;
// nullopt when done, else the exit code.
std::optional<int> measureFrame(const scaled::drivers::source::Frame& frame,
                                const hx::DepthView& dv, DnnDetector& detector, const Options& o,
                                Findings& f) {
    scaled::drivers::detector::DetectionResult result;
    if (auto ok = detector.detect(frame.color, frame.id, frame.t_ns, result); !ok) {
        std::fprintf(stderr, "measure-heights: frame %lld: %s\n", static_cast<long long>(frame.id),
                     ok.error().message.c_str());
        return kExDataErr;
    }
    if (result.detections.empty()) {
        return std::nullopt;
    }
    hx::Shift shift;
    try {
        shift = hx::estimateShift(frame.color, dv.depth);
    } catch (const cv::Exception& e) {
        std::fprintf(stderr, "measure-heights: frame %lld: %s\n", static_cast<long long>(frame.id),
                     e.what());
        return kExDataErr;
    }
    auto& views = f.views;
    const std::size_t first = views.size();
    for (const auto& d : result.detections) {
        View v;
        v.frame = frame.id;
        v.class_name = std::string(d.class_name);
        v.score = d.score;
        v.box = d.box;
        v.shift = shift;
        v.m = hx::measureView(dv, d.box, shift, hx::classRule(v.class_name), f.planes,
                              o.draw_dir.has_value());
        views.push_back(std::move(v));
    }
    if (o.draw_dir) {
        if (!drawFrame(*o.draw_dir, frame, dv.depth, views, first)) {
            std::fprintf(stderr, "measure-heights: cannot write into %s\n", o.draw_dir->c_str());
            return kExCantCreat;
        }
        for (std::size_t i = first; i < views.size(); ++i) {
            views[i].m.mask.release();
        }
    }
    return std::nullopt;
}

// Pass 2: one measurement per detection; nullopt when done, else the exit code.
std::optional<int> measureViews(ViewReader& reader, DnnDetector& detector, const Options& o,
                                Findings& f) {
    if (auto rc = reader.rewind()) {
        return rc;
    }
    hx::DepthView dv;
    while (true) {
        if (const auto done = reader.next(dv)) {
            if (*done != 0) {
                return *done;
            }
            return std::nullopt;
        }
        if (auto rc = measureFrame(reader.frame(), dv, detector, o, f)) {
            return rc;
        }
    }
}

// The instances of one class: its views (`idx`) whose world centroids are
// within the class radius, their median height and its MAD.
void addClassInstances(const std::string& name, const std::vector<std::size_t>& idx, Findings& f) {
    const hx::ClassRule rule = hx::classRule(name);
    std::vector<Vec3> centroids;
    centroids.reserve(idx.size());
    for (const std::size_t i : idx) {
        centroids.push_back(f.views[i].m.centroid_W);
    }
    const std::vector<int> group = hx::groupInstances(centroids, f.up_W, rule.group_radius_m);
    const int n_groups = group.empty() ? 0 : *std::max_element(group.begin(), group.end()) + 1;
    const std::size_t base = f.instances.size();
    for (int g = 0; g < n_groups; ++g) {
        Instance inst;
        inst.class_name = name;
        inst.id = g;
        f.instances.push_back(inst);
    }
    std::vector<std::vector<Vec3>> members(static_cast<std::size_t>(n_groups));
    for (std::size_t k = 0; k < idx.size(); ++k) {
        View& v = f.views[idx[k]];
        Instance& inst = f.instances[base + static_cast<std::size_t>(group[k])];
        v.instance = static_cast<int>(base) + group[k];
        const double ground =
            (rule.bottom == hx::BottomRule::kFloor && f.floor) ? f.floor->height_m : v.m.bottom_m;
        inst.heights.push_back(v.m.top_m - ground);
        inst.tops.push_back(v.m.top_m - f.floorHeight());
        inst.bottoms.push_back(v.m.bottom_m - f.floorHeight());
        members[static_cast<std::size_t>(group[k])].push_back(v.m.centroid_W);
    }
    for (int g = 0; g < n_groups; ++g) {
        Instance& inst = f.instances[base + static_cast<std::size_t>(g)];
        std::vector<double> x;
        std::vector<double> y;
        std::vector<double> z;
        for (const Vec3& p : members[static_cast<std::size_t>(g)]) {
            x.push_back(p.x());
            y.push_back(p.y());
            z.push_back(p.z());
        }
        inst.centroid = Eigen::Vector3d(hx::median(x), hx::median(y), hx::median(z))
                            .cast<scaled::core::Scalar>();
        inst.median_m = hx::median(inst.heights);
        inst.mad_m = hx::mad(inst.heights);
    }
}

// The instances of every class, and the rejected views.
void findInstances(Findings& f) {
    std::map<std::string, std::vector<std::size_t>> by_class;
    for (std::size_t i = 0; i < f.views.size(); ++i) {
        if (f.views[i].m.ok) {
            by_class[f.views[i].class_name].push_back(i);
        }
    }
    for (const auto& [name, idx] : by_class) {
        addClassInstances(name, idx, f);
    }
    f.rejected = static_cast<std::size_t>(
        std::count_if(f.views.begin(), f.views.end(), [](const View& v) { return !v.m.ok; }));
}

std::string instanceJson(const Instance& in, const Options& o) {
    return "{\"class\":" + jsonString(in.class_name) + ",\"id\":" + std::to_string(in.id) +
           ",\"centroid_W\":[" + jsonNumber(in.centroid.x()) + "," + jsonNumber(in.centroid.y()) +
           "," + jsonNumber(in.centroid.z()) + "],\"views\":" + std::to_string(in.heights.size()) +
           ",\"height_m\":" + jsonNumber(in.median_m) + ",\"mad_m\":" + jsonNumber(in.mad_m) +
           ",\"top_above_floor_m\":" + jsonNumber(hx::median(in.tops)) +
           ",\"bottom_above_floor_m\":" + jsonNumber(hx::median(in.bottoms)) + ",\"summarised\":" +
           (static_cast<int>(in.heights.size()) >= o.min_views ? "true" : "false") + "}";
}

void printJson(const Findings& f, const Options& o) {
    const double cam_h = hx::median(f.camera_heights) - f.floorHeight();
    std::string s =
        "{\"dataset\":" + jsonString(o.dataset.string()) + ",\"every\":" + std::to_string(o.every) +
        ",\"frames\":" + std::to_string(f.frames_used) + ",\"up_W\":[" + jsonNumber(f.up_W.x()) +
        "," + jsonNumber(f.up_W.y()) + "," + jsonNumber(f.up_W.z()) + "]";
    if (f.floor) {
        s += ",\"floor\":{\"height_m\":" + jsonNumber(f.floor->height_m) +
             ",\"mad_m\":" + jsonNumber(f.floor->mad_m) +
             ",\"fraction\":" + jsonNumber(f.floor->fraction) + "}";
    }
    s += ",\"camera_height_above_floor_m\":" + jsonNumber(cam_h);
    s += ",\"planes\":[";
    for (std::size_t i = 0; i < f.planes.size(); ++i) {
        const hx::Plane& p = f.planes[i];
        s += std::string(i ? "," : "") + "{\"height_m\":" + jsonNumber(p.height_m) +
             ",\"above_floor_m\":" + jsonNumber(p.height_m - f.floorHeight()) +
             ",\"mad_m\":" + jsonNumber(p.mad_m) + ",\"fraction\":" + jsonNumber(p.fraction) + "}";
    }
    s += "],\"instances\":[";
    for (std::size_t i = 0; i < f.instances.size(); ++i) {
        s += std::string(i ? "," : "") + instanceJson(f.instances[i], o);
    }
    s += "],\"detections\":" + std::to_string(f.views.size()) +
         ",\"rejected\":" + std::to_string(f.rejected) + "}\n";
    std::fputs(s.c_str(), stdout);
}

// The text report's header: the sequence, up, the floor, the camera, the planes.
void printScene(const Findings& f, const Options& o) {
    std::printf("# measure-heights %s: %d frames (every %d), %zu detections, %zu rejected\n",
                o.dataset.c_str(), f.frames_used, o.every, f.views.size(), f.rejected);
    std::printf("# up_W = (%.4f, %.4f, %.4f)\n", static_cast<double>(f.up_W.x()),
                static_cast<double>(f.up_W.y()), static_cast<double>(f.up_W.z()));
    if (f.floor) {
        std::printf("# floor: height %.3f m (MAD %.3f m, %.1f %% of the samples)\n",
                    f.floor->height_m, f.floor->mad_m, 100 * f.floor->fraction);
    }
    std::printf("# camera: median %.3f m above the floor\n",
                hx::median(f.camera_heights) - f.floorHeight());
    std::printf("# horizontal planes (height above the floor, MAD, share of samples):\n");
    for (const hx::Plane& p : f.planes) {
        std::printf("#   %+.3f m  %.3f m  %.1f %%\n", p.height_m - f.floorHeight(), p.mad_m,
                    100 * p.fraction);
    }
}

// A row per instance, then per class the instances with >= --min-views views.
void printInstances(const Findings& f, const Options& o) {
    std::printf("\n%-14s %3s %25s %5s %8s %7s %7s %7s %8s %8s\n", "class", "id", "centroid_W (m)",
                "views", "height", "MAD", "min", "max", "top/fl", "bot/fl");
    for (const Instance& in : f.instances) {
        std::printf("%-14s %3d (%7.3f,%7.3f,%7.3f) %5zu %8.3f %7.3f %7.3f %7.3f %8.3f %8.3f%s\n",
                    in.class_name.c_str(), in.id, static_cast<double>(in.centroid.x()),
                    static_cast<double>(in.centroid.y()), static_cast<double>(in.centroid.z()),
                    in.heights.size(), in.median_m, in.mad_m,
                    *std::min_element(in.heights.begin(), in.heights.end()),
                    *std::max_element(in.heights.begin(), in.heights.end()), hx::median(in.tops),
                    hx::median(in.bottoms),
                    static_cast<int>(in.heights.size()) >= o.min_views ? "" : "  (few views)");
    }
    std::printf("\n# per class (instances with >= %d views): heights in metres\n", o.min_views);
    std::map<std::string, std::vector<const Instance*>> summary;
    for (const Instance& in : f.instances) {
        if (static_cast<int>(in.heights.size()) >= o.min_views) {
            summary[in.class_name].push_back(&in);
        }
    }
    for (const auto& [name, list] : summary) {
        std::printf("%-14s", name.c_str());
        for (const Instance* in : list) {
            std::printf("  %.3f +- %.3f (%zu views)", in->median_m, in->mad_m, in->heights.size());
        }
        std::printf("\n");
    }
}

// --views: every single measurement.
void printViews(const Findings& f) {
    std::printf(
        "\n# views: index frame class score box shift(ok) pixels near_m top bottom "
        "instance | reject\n");
    for (std::size_t i = 0; i < f.views.size(); ++i) {
        const View& v = f.views[i];
        const double fl = f.floorHeight();
        std::printf(
            "%4zu %4lld %-12s %.2f [%4.0f %4.0f %4.0f %4.0f] (%+3d,%+3d %s) %6d %5.2f "
            "%6.3f %6.3f %3d %s\n",
            i, static_cast<long long>(v.frame), v.class_name.c_str(), static_cast<double>(v.score),
            static_cast<double>(v.box.x_min_px), static_cast<double>(v.box.y_min_px),
            static_cast<double>(v.box.x_max_px), static_cast<double>(v.box.y_max_px), v.shift.dx,
            v.shift.dy, v.shift.ok ? "ok" : "--", v.m.pixels, v.m.near_m, v.m.top_m - fl,
            v.m.bottom_m - fl, v.instance, v.m.reject.c_str());
    }
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    if (auto rc = checkPaths(o)) {
        return *rc;
    }
    auto source = scaled::drivers::dataset::openDataset(o.dataset);
    if (!source) {
        std::fprintf(stderr, "measure-heights: %s\n", source.error().message.c_str());
        return source.error().code == ErrorCode::kNotFound ? kExNoInput : kExDataErr;
    }
    if (auto rc = checkSequence((*source)->info(), o)) {
        return *rc;
    }
    Findings f;
    f.up_W = -(*source)->info().gravity_down_W->normalized();
    auto detector = createDetector(o);
    if (!detector) {
        std::fprintf(stderr, "measure-heights: %s\n", detector.error().message.c_str());
        return detector.error().code == ErrorCode::kNotFound ? kExNoInput : kExDataErr;
    }
    ViewReader reader(**source, o.every, f.up_W);
    if (auto rc = surveyScene(reader, o, f)) {
        return *rc;
    }
    if (auto rc = measureViews(reader, **detector, o, f)) {
        return *rc;
    }
    findInstances(f);
    if (o.json) {
        printJson(f, o);
        return 0;
    }
    printScene(f, o);
    printInstances(f, o);
    if (o.list_views) {
        printViews(f);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return scaled::tools::runGuarded("measure-heights", run, argc, argv);
}
