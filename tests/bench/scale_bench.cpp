// One observation update of the scale estimator (geometry + likelihood +
// posterior) at several grid sizes. Results: docs/benchmarks.md.

#include <array>
#include <vector>

#include <Eigen/Geometry>
#include <benchmark/benchmark.h>

#include <scaled/core/scale/object_likelihood.h>
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
        UpdateStats st = est.update(snap, dets);  // DoNotOptimize(const T&) is deprecated
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

// ---- the object model (issue 18) ------------------------------------------

// One object's likelihood over the grid from its views (the closed form per
// grid point), with the chair prior in its partial-visibility mixture.
void BM_ObjectLikelihood(benchmark::State& state) {
    const auto grid =
        ScaleGrid::create({Scalar(0.01), Scalar(100), static_cast<int>(state.range(0))}).value();
    auto chair = HeightPrior::fromNormal("chair", 0.9, 0.1, 0.6, 1.3, 24, true).value();
    (void)chair.setWidth(0.25, 0.15);
    const auto prior = ApparentHeightPrior::create(chair, 0.5, {}).value();
    std::vector<ObjectViewExtent> views;
    for (int k = 0; k < state.range(1); ++k) {
        const Scalar kappa = 0.2 + 0.02 * k;
        views.push_back({(0.9 + kappa * 0.25) / 0.5 * (1 + 0.01 * (k % 3)), kappa, 0.05});
    }
    std::vector<Scalar> log_l(grid.size());
    ObjectLikelihoodConfig lc;
    lc.outlier_weight = 0.05;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        const bool ok = evaluateObjectLogLikelihood(views, prior, grid, lc, log_l);
        benchmark::DoNotOptimize(log_l.data());
        if (!ok) {
            state.SkipWithError("no likelihood");
            break;
        }
    }
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ObjectLikelihood)->ArgsProduct({{1024}, {1, 8, 32}});
BENCHMARK(BM_ObjectLikelihood)->Args({512, 32})->Args({2048, 32});

// A whole update of the object model: n chairs in a row seen by a camera
// sliding past them, every object detected in every update (association,
// anchors, every object evaluated again, the posterior from all of them).
// Measured in steady state: 32 updates before timing, so every object keeps
// max_views = 32 views.
void BM_ObjectUpdate(benchmark::State& state) {
    const auto cam = PinholeRadialCamera::create({500, 500, 320, 240, 0, 0, 640, 480}).value();
    const int n = static_cast<int>(state.range(0));
    PriorTable priors;
    priors.add(HeightPrior::fromNormal("chair", 0.9, 0.1, 0.6, 1.3, 24, true).value());
    EstimatorConfig cfg;
    cfg.model = EstimatorModel::kObject;
    cfg.likelihood.robust = true;
    cfg.likelihood.partial_visibility = true;
    cfg.extent.compensate_roll = true;
    auto est = ScaleEstimator::create(cfg, priors, cam).value();
    std::vector<Vec3> centres;
    for (int i = 0; i < n; ++i) {
        centres.emplace_back(-2.0 + 4.0 * (i + 0.5) / n, 5.5 + 0.5 * (i % 2), 0);
    }
    const auto pose = [](int k) {
        CameraPose p;
        Mat3 R0;
        R0 << 1, 0, 0, 0, 0, 1, 0, -1, 0;
        const Scalar x = -1.5 + 0.05 * (k % 60);
        p.R_CtoW = Eigen::AngleAxis<Scalar>(-0.1 * x, Vec3::UnitZ()).toRotationMatrix() * R0 *
                   Eigen::AngleAxis<Scalar>(-0.35, Vec3::UnitX()).toRotationMatrix();
        p.p_CinW = Vec3(x, 0, 2.4);
        return p;
    };
    const auto boxes = [&](const CameraPose& p, std::vector<Detection>& dets) {
        dets.clear();
        for (const Vec3& c : centres) {
            BoundingBox b{1e9, 1e9, -1e9, -1e9};
            for (int corner = 0; corner < 8; ++corner) {
                const Vec3 q = c + Vec3((corner & 1) ? 0.3 : -0.3, (corner & 2) ? 0.3 : -0.3,
                                        (corner & 4) ? 1.8 : 0.0);
                const auto px = cam.project(p.R_CtoW.transpose() * (q - p.p_CinW));
                if (!px) {
                    return;
                }
                b = {std::min(b.x_min_px, px->x()), std::min(b.y_min_px, px->y()),
                     std::max(b.x_max_px, px->x()), std::max(b.y_max_px, px->y())};
            }
            dets.push_back({b, "chair", 0.9});
        }
    };
    std::vector<Detection> dets;
    std::vector<MapFeature> features(40);
    for (std::size_t i = 0; i < features.size(); ++i) {
        features[i].p_FinW = Vec3(-2.0 + 0.1 * static_cast<Scalar>(i), 8, 1);
    }
    FrameSnapshot snap;
    snap.features = features;
    int k = 0;
    for (; k < 32; ++k) {
        snap.pose = pose(k);
        boxes(snap.pose, dets);
        (void)est.update(snap, dets);
    }
    int used = 0;
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        state.PauseTiming();
        snap.pose = pose(k);
        snap.frame_id = k++;
        boxes(snap.pose, dets);
        state.ResumeTiming();
        UpdateStats st = est.update(snap, dets);
        used = st.objects_used;
        benchmark::DoNotOptimize(st);
    }
    state.counters["objects_used"] = used;
    state.counters["table_KiB"] = static_cast<double>(est.objects()->memoryBytes()) / 1024;
    state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ObjectUpdate)->Arg(1)->Arg(5)->Arg(10)->Arg(20)->Unit(benchmark::kMicrosecond);

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
