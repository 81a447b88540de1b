// One observation update of the scale estimator (geometry + likelihood +
// posterior) at several grid sizes. Results: docs/benchmarks.md.

#include <array>
#include <vector>

#include <benchmark/benchmark.h>

#include <scaled/core/scale/scale_estimator.h>

#include "experiments.h"

namespace {

using namespace scaled::core;

struct Fixture {
    PinholeRadialCamera cam =
        PinholeRadialCamera::create({500, 500, 320, 240, -0.05, 0.01, 640, 480}).value();
    CameraPose pose;
    MapFeature feature;
    BoundingBox box{300, 115, 340, 315};

    Fixture() {
        pose.R_CtoW << 1, 0, 0, 0, 0, 1, 0, -1, 0;
        feature.p_FinW = Vec3(0, 2, 0);
        feature.P_FinW = Vec3(1e-4, 4e-4, 1e-4).asDiagonal();
    }
};

PriorTable bottlePrior(int bins) {
    PriorTable t;
    t.add(HeightPrior::fromNormal("bottle", 0.26, 0.06, 0.15, 0.40, bins, true).value());
    return t;
}

void runUpdate(benchmark::State& state, VarianceModel model, bool roll) {
    const Fixture fx;
    EstimatorConfig cfg;
    cfg.posterior.grid.bins = static_cast<int>(state.range(0));
    cfg.likelihood.variance_model = model;
    cfg.extent.compensate_roll = roll;
    auto est =
        ScaleEstimator::create(cfg, bottlePrior(static_cast<int>(state.range(1))), fx.cam).value();
    FrameSnapshot snap;
    snap.pose = fx.pose;
    snap.features = std::span<const MapFeature>(&fx.feature, 1);
    const std::array<Detection, 1> dets{Detection{fx.box, "bottle", 1}};
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        const UpdateStats st = est.update(snap, dets);
        benchmark::DoNotOptimize(st);
        if (st.observations != 1) {
            state.SkipWithError("no observation");
            break;
        }
        if (est.posterior().observations() > 200) {
            est.reset();  // keep the posterior in its usual range
        }
    }
    state.SetItemsProcessed(state.iterations());
}

void BM_ObservationUpdatePaper(benchmark::State& s) {
    runUpdate(s, VarianceModel::kPaper, false);
}
void BM_ObservationUpdatePropagatedRoll(benchmark::State& s) {
    runUpdate(s, VarianceModel::kPropagated, true);
}

// Args: grid bins, prior histogram bins.
BENCHMARK(BM_ObservationUpdatePaper)->ArgsProduct({{512, 1024, 2048}, {24}});
BENCHMARK(BM_ObservationUpdatePropagatedRoll)->ArgsProduct({{512, 1024, 2048}, {24}});
BENCHMARK(BM_ObservationUpdatePaper)->Args({1024, 1})->Args({1024, 64});

// The observation geometry alone, with and without the propagated variance
// (range(0) = 1: numeric Jacobians w.r.t. the feature and the four box edges).
void BM_VerticalExtent(benchmark::State& state) {
    const Fixture fx;
    ExtentConfig cfg;
    cfg.propagate_variance = state.range(0) != 0;
    const Vec3 up(0, 0, 1);
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(
            measureVerticalExtent(fx.cam, fx.pose, up, fx.feature, fx.box, cfg));
    }
}
BENCHMARK(BM_VerticalExtent)->Arg(0)->Arg(1);

void BM_Summary(benchmark::State& state) {
    PosteriorConfig c;
    c.grid.bins = static_cast<int>(state.range(0));
    const auto p = ScalePosterior::create(c).value();
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(p.summary());
    }
}
BENCHMARK(BM_Summary)->Arg(512)->Arg(1024)->Arg(2048);

void BM_SimExperiment(benchmark::State& state) {
    const auto specs =
        scaled::papersim::paperExperiments(1, scaled::papersim::defaultSimEstimatorConfig());
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(scaled::papersim::runExperiment(specs[0]));
    }
}
BENCHMARK(BM_SimExperiment)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
