#include <algorithm>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/likelihood.h>

#include "scalar_tolerance.h"

namespace scaled::core {
namespace {

ScaleGrid grid(int bins = 1024) {
    return ScaleGrid::create({0.01, 100, bins}).value();
}

HeightPrior single(Scalar h, Scalar width = 0) {
    const std::vector<Scalar> hs{h};
    const std::vector<Scalar> ps{1};
    return HeightPrior::fromHistogram("x", hs, ps, width, true).value();
}

Scalar logNormal(Scalar r, Scalar var) {
    return -0.5 * std::log(2 * std::numbers::pi * var) - r * r / (2 * var);
}

TEST(ScaleGrid, IsLogSpaced) {
    const auto g = grid(1024);
    EXPECT_EQ(g.size(), 1024U);
    // Float: 1e-6 relative; an index is off by about eps |log d| / delta.
    EXPECT_NEAR(g.dMin(), 0.01, test::tolerance(1e-15, 1e-8));
    EXPECT_NEAR(g.dMax(), 100, test::tolerance(1e-10, 1e-4));
    EXPECT_NEAR(g.delta(), std::log(1e4) / 1023, test::tolerance(1e-15, 1e-8));
    EXPECT_NEAR(g.d(512) / g.d(511), std::exp(g.delta()), test::tolerance(1e-12, 1e-6));
    EXPECT_NEAR(g.indexOf(g.d(100)), 100, test::tolerance(1e-9, 1e-4));
    EXPECT_FALSE(ScaleGrid::create({0, 1, 100}).ok());
    EXPECT_FALSE(ScaleGrid::create({2, 1, 100}).ok());
    EXPECT_FALSE(ScaleGrid::create({0.1, 1, 4}).ok());
}

TEST(Likelihood, PaperVarianceByHand) {
    const auto g = grid();
    VerticalExtent e;
    e.D = 0.5;
    e.sigma_D_paper = 0.04;
    LikelihoodConfig cfg;
    cfg.variance_model = VarianceModel::kPaper;
    std::vector<Scalar> l(g.size());
    ASSERT_TRUE(evaluateLogLikelihood(e, single(1.0, 0.02), g, cfg, l));
    for (const std::size_t j : {100U, 600U, 700U, 1000U}) {
        const Scalar d = g.d(j);
        const Scalar res = e.D * g.delta();
        // sigma^2 = (sigma_D D)^2 + w^2/12 + (d D delta)^2/12
        const Scalar var = std::pow(0.04 * 0.5, 2) + 0.02 * 0.02 / 12 + d * d * res * res / 12;
        EXPECT_NEAR(l[j], logNormal(d * 0.5 - 1.0, var),
                    test::tolerance(1e-9, 1e-6) * (1 + std::abs(l[j])))
            << j;
    }
    EXPECT_NEAR(gridMode(g, l), 2.0, 2.0 * g.delta() * 0.1);
}

TEST(Likelihood, PropagatedIsTheDensityOfD) {
    const auto g = grid();
    VerticalExtent e;
    e.D = 0.5;
    e.sigma_D_feature = 0.01;
    e.sigma_D_box = 0.005;
    LikelihoodConfig cfg;
    cfg.variance_model = VarianceModel::kPropagated;
    const std::vector<Scalar> hs{0.9, 1.1};
    const std::vector<Scalar> ps{0.25, 0.75};
    const auto prior = HeightPrior::fromHistogram("x", hs, ps, 0, true).value();
    std::vector<Scalar> l(g.size());
    ASSERT_TRUE(evaluateLogLikelihood(e, prior, g, cfg, l));
    for (const std::size_t j : {200U, 650U, 700U, 900U}) {
        const Scalar d = g.d(j);
        const Scalar res = e.D * g.delta();
        // N(D; H/d, s^2) summed over H, written in metres: d * N(dD; H, d^2 s^2).
        const Scalar var = d * d * (0.01 * 0.01 + 0.005 * 0.005 + res * res / 12);
        const Scalar expected =
            std::log(d) + std::log(0.25 * std::exp(logNormal(d * 0.5 - 0.9, var)) +
                                   0.75 * std::exp(logNormal(d * 0.5 - 1.1, var)));
        EXPECT_NEAR(l[j], expected, 1e-9 * (1 + std::abs(expected))) << j;
    }
}

TEST(Likelihood, AlwaysFiniteAndRobustFloor) {
    const auto g = grid();
    std::vector<Scalar> l(g.size());
    LikelihoodConfig cfg;
    for (const Scalar D : {1e-9, 1e-3, 1.0, 1e3, 1e6}) {
        VerticalExtent e;
        e.D = D;
        e.sigma_D_paper = 1e-6;
        ASSERT_TRUE(evaluateLogLikelihood(e, single(0.3), g, cfg, l));
        for (const Scalar v : l) {
            ASSERT_TRUE(std::isfinite(v)) << "D=" << D;
        }
    }
    cfg.robust = true;
    cfg.outlier_weight = 0.1;
    cfg.outlier_height_range_m = 4;
    VerticalExtent e;
    e.D = 1;
    e.sigma_D_paper = 0.01;
    ASSERT_TRUE(evaluateLogLikelihood(e, single(0.3), g, cfg, l));
    // The outlier floor w / R holds where an outlier can be, d D in (0, R];
    // no object is taller than R, so beyond it only the inlier term is left.
    for (std::size_t j = 0; j < g.size(); ++j) {
        if (g.d(j) * e.D <= 4) {
            // Float: the floor itself is log(w / R) rounded to float.
            EXPECT_GE(l[j], std::log(0.1 / 4) - test::tolerance(1e-12, 1e-6)) << "d = " << g.d(j);
        } else {
            EXPECT_LT(l[j], std::log(0.1 / 4) - 100) << "d = " << g.d(j);
        }
    }
    EXPECT_NEAR(l.front(), std::log(0.1 / 4), test::tolerance(1e-9, 1e-6));
}

TEST(Likelihood, PartialVisibilityBoundsTheScaleFromAbove) {
    // A box showing 40% of a 0.9 m object (D = 0.36 at d = 1): without the
    // partial term the likelihood peaks at d = 2.5; with it, d = 1 is as
    // likely as any d with d D < 0.9 except near the full-height peak.
    const auto g = grid();
    std::vector<Scalar> off(g.size());
    std::vector<Scalar> on(g.size());
    LikelihoodConfig cfg;
    cfg.variance_model = VarianceModel::kPropagated;
    VerticalExtent e;
    e.D = Scalar(0.36);
    e.sigma_D_feature = Scalar(0.01);
    const HeightPrior chair = single(0.9);
    ASSERT_TRUE(evaluateLogLikelihood(e, chair, g, cfg, off));
    cfg.partial_visibility = true;
    cfg.partial_weight = Scalar(0.5);
    ASSERT_TRUE(evaluateLogLikelihood(e, chair, g, cfg, on));
    const auto at = [&](const std::vector<Scalar>& l, Scalar d) {
        return l[static_cast<std::size_t>(std::lround(g.indexOf(d)))];
    };
    EXPECT_NEAR(gridMode(g, off), 2.5, 0.02);
    EXPECT_LT(at(off, 1) - at(off, Scalar(2.5)), -50);  // off: d = 1 is excluded
    // On: at d = 1 the partial term 0.5 d / H carries the likelihood ...
    EXPECT_NEAR(at(on, 1), std::log(0.5 * 1 / 0.9), 0.02);
    // ... beyond H / D = 2.5 the object would be taller than the class allows:
    // only the full-visibility term's tail is left.
    EXPECT_LT(at(on, 4), at(on, 1) - 50);
    // The switch alone does nothing while neither the config nor the prior
    // gives a weight.
    cfg.partial_weight = 0;
    ASSERT_TRUE(evaluateLogLikelihood(e, chair, g, cfg, on));
    EXPECT_EQ(on, off);
    // A prior's own probability takes precedence over the config's.
    HeightPrior occluded = single(0.9);
    ASSERT_TRUE(occluded.setPartialProbability(Scalar(0.5)).ok());
    ASSERT_TRUE(evaluateLogLikelihood(e, occluded, g, cfg, on));
    EXPECT_NEAR(at(on, 1), std::log(0.5 * 1 / 0.9), 0.02);
    EXPECT_FALSE(occluded.setPartialProbability(1).ok());
}

TEST(Likelihood, RejectsInputThatCannotGiveALikelihood) {
    const auto g = grid();
    std::vector<Scalar> l(g.size(), 123);
    VerticalExtent e;
    e.D = 0;
    EXPECT_FALSE(evaluateLogLikelihood(e, single(0.3), g, {}, l));
    e.D = std::nan("");
    EXPECT_FALSE(evaluateLogLikelihood(e, single(0.3), g, {}, l));
    e.D = 1;
    std::vector<Scalar> wrong(10);
    EXPECT_FALSE(evaluateLogLikelihood(e, single(0.3), g, {}, wrong));
    EXPECT_EQ(l[0], 123);
}

}  // namespace
}  // namespace scaled::core

namespace scaled::core {
namespace {

// Brute force: every histogram term at every grid point.
std::vector<Scalar> bruteForce(const VerticalExtent& e, const HeightPrior& prior,
                               const ScaleGrid& g, const LikelihoodConfig& cfg) {
    std::vector<Scalar> out(g.size());
    const Scalar res = e.D * g.delta();
    for (std::size_t j = 0; j < g.size(); ++j) {
        const Scalar d = g.d(j);
        Scalar var = prior.binWidth() * prior.binWidth() / 12 + d * d * res * res / 12;
        var += cfg.variance_model == VarianceModel::kPaper
                   ? std::pow(e.sigma_D_paper * e.D, 2)
                   : d * d * (std::pow(e.sigma_D_feature, 2) + std::pow(e.sigma_D_box, 2));
        var = std::max(var, cfg.min_sigma_m * cfg.min_sigma_m);
        Scalar sum = 0;
        for (std::size_t m = 0; m < prior.size(); ++m) {
            sum +=
                prior.probabilities()[m] * std::exp(logNormal(d * e.D - prior.heights()[m], var));
        }
        out[j] =
            std::log(sum) + (cfg.variance_model == VarianceModel::kPropagated ? std::log(d) : 0);
    }
    return out;
}

TEST(Likelihood, WindowedSumMatchesBruteForceWhereItMatters) {
    const auto g = grid();
    const auto prior = HeightPrior::fromNormal("bottle", 0.26, 0.06, 0.15, 0.40, 24, true).value();
    for (const auto model : {VarianceModel::kPaper, VarianceModel::kPropagated}) {
        VerticalExtent e;
        e.D = 0.7;
        e.sigma_D_paper = 0.03;
        e.sigma_D_feature = 0.02;
        e.sigma_D_box = 0.01;
        LikelihoodConfig cfg;
        cfg.variance_model = model;
        std::vector<Scalar> l(g.size());
        ASSERT_TRUE(evaluateLogLikelihood(e, prior, g, cfg, l));
        const auto ref = bruteForce(e, prior, g, cfg);
        const Scalar peak = *std::max_element(ref.begin(), ref.end());
        for (std::size_t j = 0; j < g.size(); ++j) {
            // The terms dropped outside the window weigh less than e^-32 of the
            // peak density, so wherever the likelihood is within e^-20 of its peak
            // the windowed sum is exact to 1e-5 relative (e^-12); the far tail,
            // where brute force underflows, stays finite.
            if (std::isfinite(ref[j]) && ref[j] > peak - 20) {
                ASSERT_NEAR(l[j], ref[j], 1e-5) << j;
            }
            ASSERT_TRUE(std::isfinite(l[j]));
            // Float: the two sums of the same peak differ in the last bits.
            ASSERT_LE(l[j], peak + test::tolerance(1e-9, 1e-6));
        }
    }
}

}  // namespace
}  // namespace scaled::core
