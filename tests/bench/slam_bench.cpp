// Tracker cost per frame (front end + EKF, detection excluded) at 640x480 with
// 25, 50 and 100 features measured per frame, one thread: on rendered frames
// of the synthetic room (always available) and on 7-Scenes redkitchen (when
// ../shared is present; also at 10 Hz, and at 30 Hz without the pyramid and
// relocalisation's descriptors); and corner detection alone on one frame of each.
// Results: docs/benchmarks.md.

#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>
#include <vector>

#include <benchmark/benchmark.h>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/imu/simulated_gyro.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>
#include <scaled/drivers/vision/corner_detector.h>
#include <scaled/drivers/vision/mono_tracker.h>
#include <scaled/drivers/vision/small_image_rotation.h>

#include "shared_dir.h"

namespace {

using namespace scaled;

struct Sequence {
    std::unique_ptr<core::PinholeRadialCamera> camera;
    std::vector<std::int64_t> t_ns;
    std::vector<cv::Mat> gray;
    // A 200 Hz gyro simulated from the ground truth over the whole sequence
    // (drivers/imu/simulated_gyro.h), for the gyro prior's cost.
    std::vector<core::ImuSample> gyro;
};

constexpr int kFrames = 150;

const Sequence& syntheticSequence() {
    static const Sequence seq = [] {
        Sequence s;
        core::CameraIntrinsics k{500, 500, 320, 240, 0, 0, 640, 480};
        s.camera = std::make_unique<core::PinholeRadialCamera>(
            core::PinholeRadialCamera::create(k).value());
        auto scene = drivers::synth::Scene::create();
        drivers::synth::RenderOptions ro;
        ro.noise_sigma = 2.0;
        drivers::synth::Renderer renderer(*scene, ro);
        const auto frames = drivers::synth::Trajectory::create()->makeSequence(kFrames);
        for (std::size_t i = 0; i < frames.size(); ++i) {
            cv::Mat g;
            renderer.render(*s.camera, frames[i].pose_CtoW, g, nullptr, i);
            s.t_ns.push_back(frames[i].t_ns);
            s.gray.push_back(g);
        }
        return s;
    }();
    return seq;
}

std::unique_ptr<Sequence> loadRedkitchen(int stride) {
    auto src = drivers::dataset::openDataset(test::sharedDataset("redkitchen"));
    if (!src) {
        return nullptr;
    }
    auto s = std::make_unique<Sequence>();
    std::vector<core::Mat3> R_gt;
    s->camera = std::make_unique<core::PinholeRadialCamera>(
        core::PinholeRadialCamera::create((*src)->info().intrinsics).value());
    drivers::source::Frame f;
    for (int i = 0; i < kFrames; ++i) {
        if (!(*src)->seek(static_cast<std::size_t>(i) * static_cast<std::size_t>(stride))) {
            return nullptr;
        }
        auto got = (*src)->next(f);
        if (!got || !*got) {
            return nullptr;
        }
        s->t_ns.push_back(f.t_ns);
        s->gray.push_back(f.gray.clone());
        if (!f.T_CtoW_gt) {
            return nullptr;
        }
        R_gt.push_back(f.T_CtoW_gt->R_CtoW);
    }
    auto sim = drivers::imu::SimulatedGyro::create({});
    if (!sim) {
        return nullptr;
    }
    for (std::size_t k = 1; k < s->t_ns.size(); ++k) {
        const auto part = sim->between(s->t_ns[k - 1], R_gt[k - 1], s->t_ns[k], R_gt[k]);
        // Each interval's samples end where the next one's begin: keep one.
        s->gyro.insert(s->gyro.end(), part.begin() + (k > 1 ? 1 : 0), part.end());
    }
    return s;
}

// The first 150 frames of redkitchen (30 Hz), or every third of the first 450
// (10 Hz: the coarse-to-fine search at work).
const Sequence* redkitchenSequence() {
    static const std::unique_ptr<Sequence> seq = loadRedkitchen(1);
    return seq.get();
}
const Sequence* redkitchen10HzSequence() {
    static const std::unique_ptr<Sequence> seq = loadRedkitchen(3);
    return seq.get();
}

void runTracker(benchmark::State& state, const Sequence& seq, bool before_issue21 = false,
                bool gyro = false, bool window_ba = true) {
    const int n = static_cast<int>(state.range(0));
    drivers::vision::TrackerConfig config;
    config.window_ba.enabled = window_ba;
    if (before_issue21) {
        // No pyramid, no relocalisation (no descriptors kept): the tracker's
        // work before issue 21, for the cost comparison.
        config.pyramid_levels = 0;
        config.relocalise_s = 0;
    }
    config.slam.max_measured = n;
    config.slam.min_visible = n;
    config.slam.max_features = n + n / 2;
    config.max_new_per_frame = std::max(10, n / 4);
    auto tracker = drivers::vision::MonoTracker::create(*seq.camera, config);
    core::slam::ImuWindow imu;
    imu.samples = seq.gyro;
    std::size_t i = 0;
    double measured = 0;
    double frames = 0;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        if (i == seq.gray.size()) {
            state.PauseTiming();
            tracker->reset();
            i = 0;
            state.ResumeTiming();
        }
        const auto stats = tracker->processFrame(seq.t_ns[i], seq.gray[i], gyro ? &imu : nullptr);
        measured += stats.inliers + stats.rescued;
        frames += 1;
        ++i;
    }
    state.counters["measured"] = measured / frames;
}

void BM_TrackerSynthetic(benchmark::State& state) {
    cv::setNumThreads(1);  // one thread: OpenCV's corner response would otherwise fan out
    runTracker(state, syntheticSequence());
}

// Without the window bundle adjustment (tracker.window_ba = false): the
// filter alone, for the cost comparison.
void BM_TrackerSyntheticNoWindowBa(benchmark::State& state) {
    cv::setNumThreads(1);
    runTracker(state, syntheticSequence(), false, false, false);
}

// The tracker on a redkitchen sequence, or the benchmark skipped with the
// reason when ../shared is absent.
void runTrackerOn(benchmark::State& state, const Sequence* seq, bool before_issue21 = false,
                  bool gyro = false, bool window_ba = true) {
    cv::setNumThreads(1);
    if (seq == nullptr) {
        state.SkipWithError("data/redkitchen not found in ../shared (set SCALED_SHARED_DIR)");
        return;
    }
    runTracker(state, *seq, before_issue21, gyro, window_ba);
}

void BM_TrackerRedkitchenNoWindowBa(benchmark::State& state) {
    runTrackerOn(state, redkitchenSequence(), false, false, false);
}

void BM_TrackerRedkitchen(benchmark::State& state) {
    runTrackerOn(state, redkitchenSequence());
}

void BM_TrackerRedkitchenNoPyramid(benchmark::State& state) {
    runTrackerOn(state, redkitchenSequence(), true);
}

void BM_TrackerRedkitchen10Hz(benchmark::State& state) {
    runTrackerOn(state, redkitchen10HzSequence());
}

// The same with the gyro prior (a gyro simulated from the ground truth).
void BM_TrackerRedkitchen10HzGyro(benchmark::State& state) {
    runTrackerOn(state, redkitchen10HzSequence(), false, true);
}

void BM_TrackerRedkitchenGyro(benchmark::State& state) {
    runTrackerOn(state, redkitchenSequence(), false, true);
}

// Corner detection alone, as the tracker calls it in steady state: a frame at
// 640x480, a mask that allows everywhere, a few new corners wanted.
void runCorners(benchmark::State& state, const cv::Mat& gray) {
    cv::setNumThreads(1);
    drivers::vision::CornerConfig config;
    config.max_corners = static_cast<int>(state.range(0));
    const cv::Mat mask(gray.size(), CV_8UC1, cv::Scalar(255));
    std::vector<core::Vec2> corners;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        drivers::vision::detectCorners(gray, mask, config, corners);
        benchmark::DoNotOptimize(corners.data());
    }
    state.counters["corners"] = static_cast<double>(corners.size());
}

void BM_CornersSynthetic(benchmark::State& state) {
    runCorners(state, syntheticSequence().gray[kFrames / 2]);
}

void BM_CornersRedkitchen(benchmark::State& state) {
    const Sequence* seq = redkitchenSequence();
    if (seq == nullptr) {
        state.SkipWithError("data/redkitchen not found in ../shared (set SCALED_SHARED_DIR)");
        return;
    }
    runCorners(state, seq->gray[kFrames / 2]);
}

// The rotation check's small-image alignment (tracker.rotation_check_radps),
// as the tracker runs it on every frame: one push, aligned with the previous
// frame from the identity. Two consecutive redkitchen frames, alternated.
void BM_SmallImageRotationRedkitchen(benchmark::State& state) {
    const Sequence* seq = redkitchenSequence();
    if (seq == nullptr) {
        state.SkipWithError("data/redkitchen not found in ../shared (set SCALED_SHARED_DIR)");
        return;
    }
    const cv::Mat& a = seq->gray[kFrames / 2];
    const cv::Mat& b = seq->gray[kFrames / 2 + 1];
    const auto camera =
        core::PinholeRadialCamera::create({585, 585, 320, 240, 0, 0, 640, 480}).value();
    drivers::vision::SmallImageRotation sir;
    sir.create(a.cols, a.rows);
    bool flip = false;
    int iterations = 0;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        const auto r = sir.push(flip ? a : b, camera, core::Mat3::Identity(), core::Vec3::Zero());
        iterations += r ? r->iterations : 0;
        benchmark::DoNotOptimize(r);
        flip = !flip;
    }
    state.counters["iterations"] =
        benchmark::Counter(static_cast<double>(iterations), benchmark::Counter::kAvgIterations);
}

BENCHMARK(BM_CornersSynthetic)->Arg(10)->Arg(100)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SmallImageRotationRedkitchen)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_CornersRedkitchen)->Arg(10)->Arg(100)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_TrackerSynthetic)->Arg(25)->Arg(30)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchen)->Arg(25)->Arg(30)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchenNoPyramid)->Arg(30)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerSyntheticNoWindowBa)->Arg(30)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchenNoWindowBa)->Arg(30)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchen10Hz)->Arg(30)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchen10HzGyro)->Arg(30)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_TrackerRedkitchenGyro)->Arg(30)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
