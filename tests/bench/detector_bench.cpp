// Object detector cost per image (pre-processing + forward pass +
// post-processing) for both model families at input sizes 320 and 416, with
// 1 and 2 OpenCV threads, on 7-Scenes redkitchen frame 0 (640x480 BGR). Wall
// time (the forward pass runs on OpenCV's worker threads). Needs ../shared
// (models and data); skips otherwise. Results: docs/benchmarks.md.

#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <benchmark/benchmark.h>

#include <scaled/drivers/detector/dnn_detector.h>

#include "shared_dir.h"

namespace {

using namespace scaled;

void BM_Detect(benchmark::State& state) {
    const auto family = state.range(0) == 0 ? drivers::detector::ModelFamily::kYolox
                                            : drivers::detector::ModelFamily::kDarknet;
    const auto model = test::sharedModel(family == drivers::detector::ModelFamily::kYolox
                                             ? "yolox_nano.onnx"
                                             : "yolo-fastest-1.1-xl.cfg");
    const auto image_path = test::sharedDataset("redkitchen") / "rgb" / "000000.jpg";
    if (!std::filesystem::is_regular_file(model) || !std::filesystem::is_regular_file(image_path)) {
        state.SkipWithError("../shared models or redkitchen not found (set SCALED_SHARED_DIR)");
        return;
    }
    drivers::detector::DetectorConfig config;
    config.family = family;
    config.model_path = model;
    config.input_size_px = static_cast<int>(state.range(1));
    config.threads = static_cast<int>(state.range(2));
    auto det = drivers::detector::DnnDetector::create(config);
    if (!det) {
        state.SkipWithError(det.error().message.c_str());
        return;
    }
    const cv::Mat image = cv::imread(image_path.string(), cv::IMREAD_COLOR);
    drivers::detector::DetectionResult result;
    double pre = 0;
    double forward = 0;
    double post = 0;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        if (!(*det)->detect(image, 0, 0, result)) {
            state.SkipWithError("detect failed");
            return;
        }
        pre += result.timing.pre_ms;
        forward += result.timing.forward_ms;
        post += result.timing.post_ms;
    }
    const auto n = static_cast<double>(state.iterations());
    state.counters["pre_ms"] = pre / n;
    state.counters["forward_ms"] = forward / n;
    state.counters["post_ms"] = post / n;
    state.counters["pre_post_pct"] = forward > 0 ? 100 * (pre + post) / forward : 0;
    state.counters["boxes"] = static_cast<double>(result.detections.size());
    state.SetLabel(std::string(drivers::detector::toString(family)) + " " +
                   std::to_string(config.input_size_px) + " threads " +
                   std::to_string(config.threads));
}

BENCHMARK(BM_Detect)
    ->ArgNames({"family", "size", "threads"})
    ->ArgsProduct({{0, 1}, {320, 416}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
