// scaled-detect: the object detector on one image, so a user can check a
// model on their own scene before trusting the scale it gives.
//
//   scaled-detect --image FILE [--model PATH] [--family yolox|darknet] [--weights PATH]
//                 [--names PATH] [--size N] [--score T] [--nms T] [--classes a,b]
//                 [--threads N] [--json] [--draw OUT.png]
//
// Exit codes (sysexits): 0 ok, 64 usage, 65 the model or image cannot be
// decoded, 66 a file not found, 73 cannot write --draw.

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include <scaled/drivers/dataset/image_file.h>
#include <scaled/drivers/detector/dnn_detector.h>

#include "args.h"
#include "detect_report.h"
#include "sysexits.h"

namespace {

using scaled::tools::kExCantCreat;
using scaled::tools::kExDataErr;
using scaled::tools::kExNoInput;
using scaled::tools::kExUsage;

using scaled::core::ErrorCode;
using scaled::drivers::detector::DetectorConfig;

void usage(std::FILE* out) {
    std::fputs(
        "usage: scaled-detect --image FILE [--model PATH] [--family yolox|darknet]\n"
        "                     [--weights PATH] [--names PATH] [--size N] [--score T] [--nms T]\n"
        "                     [--classes NAME,NAME...] [--threads N] [--json] [--draw OUT.png]\n"
        "Runs the object detector (OpenCV DNN, CPU) on one image and prints its detections:\n"
        "one line per box `class score x_min y_min x_max y_max` (pixels), or one JSON object\n"
        "with --json. --draw writes the image with the boxes drawn.\n"
        "Defaults: --model $SCALED_SHARED_DIR/models/yolox_nano.onnx (SCALED_SHARED_DIR\n"
        "defaults to ../shared); a .cfg model is Darknet, with its .weights next to it;\n"
        "--names coco.names next to the model; --size 416; --score 0.3; --nms 0.45.\n",
        out);
}

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

}  // namespace

int main(int argc, char** argv) {
    std::filesystem::path image_path;
    std::optional<std::filesystem::path> draw_path;
    std::optional<std::string> family_text;
    bool json = false;
    DetectorConfig config;
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
        if (i + 1 >= argc) {
            std::fprintf(stderr, "scaled-detect: %s\n",
                         a.starts_with("--")
                             ? (std::string(a) + " needs a value").c_str()
                             : ("unexpected argument '" + std::string(a) + "'").c_str());
            usage(stderr);
            return kExUsage;
        }
        const std::string_view v = argv[++i];
        bool ok = true;
        if (a == "--image") {
            image_path = v;
        } else if (a == "--model") {
            config.model_path = v;
        } else if (a == "--family") {
            family_text = std::string(v);
        } else if (a == "--weights") {
            config.weights_path = v;
        } else if (a == "--names") {
            config.names_path = v;
        } else if (a == "--size") {
            ok = parseInt(v, config.input_size_px);
        } else if (a == "--score") {
            ok = parseFloat(v, config.score_threshold);
        } else if (a == "--nms") {
            ok = parseFloat(v, config.nms_iou_threshold);
        } else if (a == "--threads") {
            ok = parseInt(v, config.threads);
        } else if (a == "--classes") {
            config.classes = scaled::tools::splitList(v);
        } else if (a == "--draw") {
            draw_path = std::filesystem::path(v);
        } else {
            std::fprintf(stderr, "scaled-detect: unknown option '%s'\n", argv[i - 1]);
            usage(stderr);
            return kExUsage;
        }
        if (!ok) {
            std::fprintf(stderr, "scaled-detect: %s: not a number: '%s'\n", argv[i - 1], argv[i]);
            return kExUsage;
        }
    }
    if (image_path.empty()) {
        std::fputs("scaled-detect: --image FILE is required\n", stderr);
        usage(stderr);
        return kExUsage;
    }
    if (config.model_path.empty()) {
        config.model_path = scaled::tools::defaultModelPath();
    }
    config.family = scaled::drivers::detector::familyFromPath(config.model_path);
    if (family_text) {
        auto f = scaled::drivers::detector::parseModelFamily(*family_text);
        if (!f) {
            std::fprintf(stderr, "scaled-detect: --family: %s\n", f.error().message.c_str());
            return kExUsage;
        }
        config.family = *f;
    }
    if (auto valid = scaled::drivers::detector::validate(config); !valid) {
        std::fprintf(stderr, "scaled-detect: %s\n", valid.error().message.c_str());
        return kExUsage;
    }

    auto image = scaled::drivers::dataset::loadImage(image_path);
    if (!image) {
        std::fprintf(stderr, "scaled-detect: %s\n", image.error().message.c_str());
        return exitCodeFor(image.error().code);
    }
    auto detector = scaled::drivers::detector::DnnDetector::create(config);
    if (!detector) {
        std::fprintf(stderr, "scaled-detect: %s\n", detector.error().message.c_str());
        return exitCodeFor(detector.error().code);
    }
    scaled::drivers::detector::DetectionResult result;
    if (auto ok = (*detector)->detect(*image, 0, 0, result); !ok) {
        std::fprintf(stderr, "scaled-detect: %s: %s\n", image_path.c_str(),
                     ok.error().message.c_str());
        return kExDataErr;
    }
    const std::string text =
        json ? scaled::tools::detectionsJson(image_path, (*detector)->info(), result)
             : scaled::tools::detectionsText(result);
    std::fputs(text.c_str(), stdout);
    if (draw_path) {
        if (auto ok = scaled::tools::drawDetections(*image, result, *draw_path); !ok) {
            std::fprintf(stderr, "scaled-detect: %s\n", ok.error().message.c_str());
            return kExCantCreat;
        }
    }
    return 0;
}
