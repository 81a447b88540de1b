#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/scale_posterior.h>

namespace scaled::core {
namespace {

ScalePosterior make(Scalar converged = 0.10, Scalar drift = 0) {
    PosteriorConfig c;
    c.grid = {0.01, 100, 1024};
    c.converged_rel_width = converged;
    c.drift_sigma_log = drift;
    return ScalePosterior::create(c).value();
}

// A Gaussian in log d centred at log(centre) with std s.
std::vector<Scalar> logGaussian(const ScaleGrid& g, Scalar centre, Scalar s) {
    std::vector<Scalar> l(g.size());
    for (std::size_t j = 0; j < g.size(); ++j) {
        const Scalar r = g.logD(j) - std::log(centre);
        l[j] = -r * r / (2 * s * s);
    }
    return l;
}

TEST(ScalePosterior, StartsUniformWithNoData) {
    const auto p = make();
    const ScaleSummary s = p.summary();
    EXPECT_EQ(s.state, ScaleState::kNoData);
    EXPECT_EQ(s.observations, 0);
    // Uniform in log10 d over [-2, 2]: quantile q sits at -2 + 4 q.
    EXPECT_NEAR(std::log10(s.ci95.lo), -2 + 4 * 0.025, 0.01);
    EXPECT_NEAR(std::log10(s.ci95.hi), -2 + 4 * 0.975, 0.01);
    EXPECT_NEAR(std::log10(s.ci68.lo), -2 + 4 * 0.16, 0.01);
    EXPECT_NEAR(std::log10(s.ci68.hi), -2 + 4 * 0.84, 0.01);
}

TEST(ScalePosterior, SummaryOfAKnownPosterior) {
    auto p = make();
    const Scalar s = 0.05;
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, s)));
    const ScaleSummary sum = p.summary();
    const Scalar tol = p.grid().delta() * 0.05;
    EXPECT_NEAR(std::log(sum.map), std::log(2.0), tol);
    EXPECT_NEAR(std::log(sum.ci68.lo), std::log(2.0) - 0.9945 * s, tol * 2);
    EXPECT_NEAR(std::log(sum.ci68.hi), std::log(2.0) + 0.9945 * s, tol * 2);
    EXPECT_NEAR(std::log(sum.ci95.lo), std::log(2.0) - 1.96 * s, tol * 2);
    EXPECT_NEAR(std::log(sum.ci95.hi), std::log(2.0) + 1.96 * s, tol * 2);
    EXPECT_NEAR(sum.mean, 2.0 * std::exp(s * s / 2), 1e-4);
    EXPECT_EQ(sum.observations, 1);
    // 95% width ~ 2 * 1.96 * 0.05 = 19.6% > 10%: converging, not converged.
    EXPECT_EQ(sum.state, ScaleState::kConverging);
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, s)));
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, s)));
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, s)));
    // Four factors: std s/2 -> width 9.8% < 10%.
    EXPECT_EQ(p.summary().state, ScaleState::kConverged);
}

TEST(ScalePosterior, WeightTempersAFactor) {
    auto a = make();
    auto b = make();
    const auto l = logGaussian(a.grid(), 3.0, 0.1);
    ASSERT_TRUE(a.addLogLikelihood(l, 0.25));
    std::vector<Scalar> quarter(l);
    for (auto& v : quarter) {
        v *= 0.25;
    }
    ASSERT_TRUE(b.addLogLikelihood(quarter));
    for (std::size_t j = 0; j < a.grid().size(); ++j) {
        EXPECT_NEAR(a.logDensity()[j], b.logDensity()[j], 1e-12);
    }
    EXPECT_FALSE(a.addLogLikelihood(l, 0));
    EXPECT_FALSE(a.addLogLikelihood(l, 1.5));
}

TEST(ScalePosterior, CannotUnderflow) {
    // Thousands of very sharp, contradicting factors: every bin stays finite and
    // at or above the floor, the summary stays finite, and the posterior can move.
    auto p = make();
    const auto at_01 = logGaussian(p.grid(), 0.1, 1e-4);
    const auto at_10 = logGaussian(p.grid(), 10, 1e-4);
    for (int i = 0; i < 2000; ++i) {
        ASSERT_TRUE(p.addLogLikelihood(i % 2 == 0 ? at_01 : at_10));
    }
    for (const Scalar v : p.logDensity()) {
        ASSERT_TRUE(std::isfinite(v));
        ASSERT_GE(v, p.config().log_floor);
        ASSERT_LE(v, 0);
    }
    const ScaleSummary s = p.summary();
    EXPECT_TRUE(std::isfinite(s.map) && std::isfinite(s.mean) && std::isfinite(s.ci95.lo) &&
                std::isfinite(s.ci95.hi));
    EXPECT_EQ(s.observations, 2000);
}

TEST(ScalePosterior, RejectsNonFiniteLikelihoodWholesale) {
    auto p = make();
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, 0.1)));
    const std::vector<Scalar> before(p.logDensity().begin(), p.logDensity().end());
    auto bad = logGaussian(p.grid(), 5.0, 0.1);
    bad[17] = std::numeric_limits<Scalar>::quiet_NaN();
    EXPECT_FALSE(p.addLogLikelihood(bad));
    bad[17] = -std::numeric_limits<Scalar>::infinity();
    EXPECT_FALSE(p.addLogLikelihood(bad));
    EXPECT_FALSE(p.addLogLikelihood(std::vector<Scalar>(3, 0)));
    EXPECT_EQ(p.observations(), 1);
    for (std::size_t j = 0; j < before.size(); ++j) {
        ASSERT_EQ(before[j], p.logDensity()[j]);
    }
}

TEST(ScalePosterior, DiffusionWidensByTheDriftVariance) {
    auto p = make();
    const Scalar s = 0.03;
    const Scalar drift = 0.04;
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, s)));
    p.diffuse(drift);
    const ScaleSummary sum = p.summary();
    const Scalar expected = std::sqrt(s * s + drift * drift);  // 0.05
    EXPECT_NEAR((std::log(sum.ci68.hi) - std::log(sum.ci68.lo)) / 2 / 0.9945, expected,
                0.03 * expected);
    EXPECT_NEAR(std::log(sum.map), std::log(2.0), p.grid().delta() * 0.1);
}

TEST(ScalePosterior, ConfiguredDriftAppliesPerUpdateAndResetForgets) {
    auto p = make(0.10, 0.02);
    ASSERT_TRUE(p.addLogLikelihood(logGaussian(p.grid(), 2.0, 0.03)));
    const ScaleSummary s = p.summary();
    EXPECT_NEAR((std::log(s.ci68.hi) - std::log(s.ci68.lo)) / 2 / 0.9945,
                std::sqrt(0.03 * 0.03 + 0.02 * 0.02), 0.002);
    p.reset();
    EXPECT_EQ(p.summary().state, ScaleState::kNoData);
    EXPECT_EQ(p.logDensity()[10], 0);
}

TEST(ScalePosterior, RejectsBadConfig) {
    PosteriorConfig c;
    c.converged_rel_width = 0;
    EXPECT_FALSE(ScalePosterior::create(c).ok());
    c = {};
    c.log_floor = 1;
    EXPECT_FALSE(ScalePosterior::create(c).ok());
    c = {};
    c.drift_sigma_log = -1;
    EXPECT_FALSE(ScalePosterior::create(c).ok());
    c = {};
    c.grid.bins = 3;
    const auto r = ScalePosterior::create(c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("bins"), std::string::npos);
}

}  // namespace
}  // namespace scaled::core
