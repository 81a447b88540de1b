// scaled-detect: the object detector on one image, so a user can check a
// model on their own scene before trusting the scale it gives.
//
//   scaled-detect --image FILE [--model PATH] [--family yolox|darknet] [--weights PATH]
//                 [--names PATH] [--size N] [--score T] [--nms T] [--classes a,b]
//                 [--threads N] [--json] [--draw OUT.png]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 the model or image cannot be
// decoded, 66 a file not found, 73 cannot write --draw. The options are on
// CLI11 (tools/common/cli.h).

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include <scaled/drivers/dataset/image_file.h>
#include <scaled/drivers/detector/dnn_detector.h>

#include "args.h"
#include "cli.h"
#include "detect_report.h"
#include "sysexits.h"

namespace {

using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::OptionSpec;

using scaled::core::ErrorCode;
using scaled::drivers::detector::DetectorConfig;

constexpr const char* kFooter =
    "usage: scaled-detect --image FILE [--model PATH] [--family yolox|darknet]\n"
    "                     [--weights PATH] [--names PATH] [--size N] [--score T] [--nms T]\n"
    "                     [--classes NAME,NAME...] [--threads N] [--json] [--draw OUT.png]\n"
    "Runs the object detector (OpenCV DNN, CPU) on one image and prints its detections:\n"
    "one line per box `class score x_min y_min x_max y_max` (pixels), or one JSON object\n"
    "with --json. --draw writes the image with the boxes drawn.\n"
    "Defaults: --model $SCALED_SHARED_DIR/models/yolox_nano.onnx (SCALED_SHARED_DIR\n"
    "defaults to ../shared); a .cfg model is Darknet, with its .weights next to it;\n"
    "--names coco.names next to the model; --size 416; --score 0.3; --nms 0.45.\n"
    "Exit codes (sysexits.h): 0 success; 64 usage (also: a detector setting out of its\n"
    "range); 65 the model or image cannot be decoded; 66 a file not found; 73 cannot\n"
    "write --draw.";

int exitCodeFor(ErrorCode code) {
    return code == ErrorCode::kNotFound ? kExNoInput : kExDataErr;
}

bool parseInt(std::string_view s, int& out) {
    const std::string str(s);
    char* end = nullptr;
    const long v = std::strtol(str.c_str(), &end, 10);
    if (str.empty() || end != str.c_str() + str.size() || v < -1000000 || v > 1000000) {
        return false;
    }
    out = static_cast<int>(v);
    return true;
}

bool parseFloat(std::string_view s, float& out) {
    const std::string str(s);
    char* end = nullptr;
    const float v = std::strtof(str.c_str(), &end);
    if (str.empty() || end != str.c_str() + str.size()) {
        return false;
    }
    out = v;
    return true;
}

// The command line, checked.
struct Options {
    std::filesystem::path image_path;
    std::optional<std::filesystem::path> draw_path;
    std::optional<std::string> family_text;
    bool json = false;
    DetectorConfig config;
};

constexpr const char* kNotANumber = "not a number: '{}'";

// The options in the order of the usage line; `take` checks a value as the
// hand-written parser did.
constexpr OptionSpec<Options> kOptions[] = {
    {"--image", "FILE", "the image (required)",
     [](std::string_view v, Options& o) {
         o.image_path = v;
         return true;
     }},
    {"--model", "PATH", "the model: .onnx (YOLOX) or .cfg (Darknet)",
     [](std::string_view v, Options& o) {
         o.config.model_path = v;
         return true;
     }},
    {"--family", "yolox|darknet", "the model's family (default: from the model's name)",
     [](std::string_view v, Options& o) {
         o.family_text = std::string(v);
         return true;
     }},
    {"--weights", "PATH", "a Darknet model's weights (default: the .cfg's, .weights)",
     [](std::string_view v, Options& o) {
         o.config.weights_path = v;
         return true;
     }},
    {"--names", "PATH", "the class names, one a line (default: coco.names next to the model)",
     [](std::string_view v, Options& o) {
         o.config.names_path = v;
         return true;
     }},
    {"--size", "N", "the detector's input size, pixels (default 416)",
     [](std::string_view v, Options& o) { return parseInt(v, o.config.input_size_px); },
     kNotANumber},
    {"--score", "T", "the lowest score kept (default 0.3)",
     [](std::string_view v, Options& o) { return parseFloat(v, o.config.score_threshold); },
     kNotANumber},
    {"--nms", "T", "the non-maximum suppression's IoU threshold (default 0.45)",
     [](std::string_view v, Options& o) { return parseFloat(v, o.config.nms_iou_threshold); },
     kNotANumber},
    {"--classes", "NAME,NAME...", "keep these classes only",
     [](std::string_view v, Options& o) {
         o.config.classes = scaled::tools::splitList(v);
         return true;
     }},
    {"--threads", "N", "OpenCV DNN's threads",
     [](std::string_view v, Options& o) { return parseInt(v, o.config.threads); }, kNotANumber},
    {"--json", nullptr, "print one JSON object",
     [](std::string_view, Options& o) {
         o.json = true;
         return true;
     }},
    {"--draw", "OUT.png", "write the image with the boxes drawn",
     [](std::string_view v, Options& o) {
         o.draw_path = std::filesystem::path(v);
         return true;
     }},
};

// The model's family and the detector's settings; nullopt when fine, else
// the usage error.
std::optional<std::string> checkConfig(Options& o) {
    auto& config = o.config;
    if (config.model_path.empty()) {
        config.model_path = scaled::tools::defaultModelPath();
    }
    config.family = scaled::drivers::detector::familyFromPath(config.model_path);
    if (o.family_text) {
        auto f = scaled::drivers::detector::parseModelFamily(*o.family_text);
        if (!f) {
            return "--family: " + f.error().message;
        }
        config.family = *f;
    }
    if (auto valid = scaled::drivers::detector::validate(config); !valid) {
        return valid.error().message;
    }
    return std::nullopt;
}

// The command line into `o`; nullopt to go on, else the exit code (--help
// printed, or the usage error).
std::optional<int> parseOptions(int argc, char** argv, Options& o) {
    CLI::App app(
        "scaled-detect: the object detector on one image, to check a model on a scene before\n"
        "trusting the scale it gives.",
        "scaled-detect");
    if (auto rc = scaled::tools::parseToolOptions(app, kFooter, kOptions, argc, argv, o)) {
        return rc;
    }
    if (o.image_path.empty()) {
        return scaled::tools::usageError(app, "--image FILE is required");
    }
    if (auto bad = checkConfig(o)) {
        return scaled::tools::usageError(app, *bad);
    }
    return std::nullopt;
}

int run(int argc, char** argv) {
    Options o;
    if (auto rc = parseOptions(argc, argv, o)) {
        return *rc;
    }
    auto image = scaled::drivers::dataset::loadImage(o.image_path);
    if (!image) {
        std::fprintf(stderr, "scaled-detect: %s\n", image.error().message.c_str());
        return exitCodeFor(image.error().code);
    }
    auto detector = scaled::drivers::detector::DnnDetector::create(o.config);
    if (!detector) {
        std::fprintf(stderr, "scaled-detect: %s\n", detector.error().message.c_str());
        return exitCodeFor(detector.error().code);
    }
    scaled::drivers::detector::DetectionResult result;
    if (auto ok = (*detector)->detect(*image, 0, 0, result); !ok) {
        std::fprintf(stderr, "scaled-detect: %s: %s\n", o.image_path.c_str(),
                     ok.error().message.c_str());
        return kExDataErr;
    }
    const std::string text =
        o.json ? scaled::tools::detectionsJson(o.image_path, (*detector)->info(), result)
               : scaled::tools::detectionsText(result);
    std::fputs(text.c_str(), stdout);
    if (o.draw_path) {
        if (auto ok = scaled::tools::drawDetections(*image, result, *o.draw_path); !ok) {
            std::fprintf(stderr, "scaled-detect: %s\n", ok.error().message.c_str());
            return kExCantCreat;
        }
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return scaled::tools::runGuarded("scaled-detect", run, argc, argv);
}
