// Floating vs fixed-point scale posterior (fixed_posterior.h): one
// observation's likelihood + posterior update, the likelihood alone, and
// summary(), with the daemon's defaults (1024 bins, propagated variance,
// robust, partial visibility) and realistic priors built in code (core does
// no I/O). Results: docs/benchmarks.md.

#include <vector>

#include <benchmark/benchmark.h>

#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/scale_posterior.h>

namespace {

using namespace scaled::core;

// range(1): 0 = bottle (24 bins, 0.26 +- 0.06 m), 1 = chair (64 bins,
// 0.85 +- 0.12 m, partial probability 0.3, as config/priors.toml's chair).
HeightPrior prior(std::int64_t which) {
    if (which == 0) {
        return HeightPrior::fromNormal("bottle", Scalar(0.26), Scalar(0.06), Scalar(0.15),
                                       Scalar(0.40), 24, true)
            .value();
    }
    auto chair = HeightPrior::fromNormal("chair", Scalar(0.85), Scalar(0.12), Scalar(0.5),
                                         Scalar(1.2), 64, true)
                     .value();
    (void)chair.setPartialProbability(Scalar(0.3));
    return chair;
}

LikelihoodConfig daemonLikelihood() {
    LikelihoodConfig c;
    c.variance_model = VarianceModel::kPropagated;
    c.robust = true;
    c.outlier_weight = Scalar(0.05);
    c.outlier_height_range_m = 5;
    c.partial_visibility = true;
    c.min_sigma_m = Scalar(0.002);
    return c;
}

PosteriorConfig posteriorConfig(PosteriorArithmetic a, int bins) {
    PosteriorConfig c;
    c.grid = {Scalar(0.01), Scalar(100), bins};
    c.arithmetic = a;
    return c;
}

VerticalExtent extent(std::int64_t which) {
    VerticalExtent e;
    e.D = which == 0 ? Scalar(0.33) : Scalar(1.1);
    e.sigma_D_paper = Scalar(0.03);
    e.sigma_D_feature = Scalar(0.02) * e.D;
    e.sigma_D_box = Scalar(0.01) * e.D;
    return e;
}

// Args: grid bins, prior (0 bottle, 1 chair).
void BM_UpdateFloating(benchmark::State& state) {
    auto p = ScalePosterior::create(
                 posteriorConfig(PosteriorArithmetic::kFloating, static_cast<int>(state.range(0))))
                 .value();
    const auto h = prior(state.range(1));
    const auto e = extent(state.range(1));
    const auto lc = daemonLikelihood();
    std::vector<Scalar> log_l(p.grid().size());
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(evaluateLogLikelihood(e, h, p.grid(), lc, log_l));
        benchmark::DoNotOptimize(p.addLogLikelihood(log_l, 1));
    }
    state.SetItemsProcessed(state.iterations());
}

void BM_UpdateFixed(benchmark::State& state) {
    auto p = ScalePosterior::create(
                 posteriorConfig(PosteriorArithmetic::kFixed, static_cast<int>(state.range(0))))
                 .value();
    const auto h = prior(state.range(1));
    const auto e = extent(state.range(1));
    auto fl = FixedLikelihood::create(p.grid(), daemonLikelihood()).value();
    std::vector<LogQ16> log_l(p.grid().size());
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(fl.evaluate(e, h, log_l));
        benchmark::DoNotOptimize(p.addFixedLogLikelihood(log_l, 1));
    }
    state.SetItemsProcessed(state.iterations());
}

void BM_LikelihoodFloating(benchmark::State& state) {
    const auto g =
        ScaleGrid::create({Scalar(0.01), Scalar(100), static_cast<int>(state.range(0))}).value();
    const auto h = prior(state.range(1));
    const auto e = extent(state.range(1));
    const auto lc = daemonLikelihood();
    std::vector<Scalar> log_l(g.size());
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(evaluateLogLikelihood(e, h, g, lc, log_l));
        benchmark::ClobberMemory();
    }
}

void BM_LikelihoodFixed(benchmark::State& state) {
    const auto g =
        ScaleGrid::create({Scalar(0.01), Scalar(100), static_cast<int>(state.range(0))}).value();
    const auto h = prior(state.range(1));
    const auto e = extent(state.range(1));
    auto fl = FixedLikelihood::create(g, daemonLikelihood()).value();
    std::vector<LogQ16> log_l(g.size());
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(fl.evaluate(e, h, log_l));
        benchmark::ClobberMemory();
    }
}

// summary() of a posterior that has seen 50 observations (range(1) = 1:
// fixed arithmetic).
void BM_Summary(benchmark::State& state) {
    const auto a =
        state.range(1) != 0 ? PosteriorArithmetic::kFixed : PosteriorArithmetic::kFloating;
    auto p = ScalePosterior::create(posteriorConfig(a, static_cast<int>(state.range(0)))).value();
    const auto h = prior(0);
    const auto e = extent(0);
    const auto lc = daemonLikelihood();
    std::vector<Scalar> log_l(p.grid().size());
    std::vector<LogQ16> fixed_l(p.grid().size());
    auto fl = FixedLikelihood::create(p.grid(), lc).value();
    for (int i = 0; i < 50; ++i) {
        if (a == PosteriorArithmetic::kFixed) {
            (void)fl.evaluate(e, h, fixed_l);
            (void)p.addFixedLogLikelihood(fixed_l, 1);
        } else {
            (void)evaluateLogLikelihood(e, h, p.grid(), lc, log_l);
            (void)p.addLogLikelihood(log_l, 1);
        }
    }
    for (auto _ : state) {  // NOLINT(clang-analyzer-deadcode.DeadStores): benchmark idiom
        benchmark::DoNotOptimize(p.summary());
    }
}

BENCHMARK(BM_UpdateFloating)->ArgsProduct({{1024}, {0, 1}});
BENCHMARK(BM_UpdateFixed)->ArgsProduct({{1024}, {0, 1}});
BENCHMARK(BM_LikelihoodFloating)->ArgsProduct({{1024}, {0, 1}});
BENCHMARK(BM_LikelihoodFixed)->ArgsProduct({{1024}, {0, 1}});
BENCHMARK(BM_Summary)->ArgsProduct({{1024}, {0, 1}});

}  // namespace

BENCHMARK_MAIN();
