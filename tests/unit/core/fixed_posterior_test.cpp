// The fixed-point posterior and likelihood (fixed_point.h, fixed_posterior.h)
// against their floating-point references.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/fixed_point.h>
#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/likelihood.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/scale/scale_posterior.h>

namespace scaled::core {
namespace {

using namespace fixed;  // NOLINT(google-build-using-namespace): test of this namespace

double q16(std::int64_t v) {
    return std::ldexp(static_cast<double>(v), -kLogFracBits);
}
double q30(std::int64_t v) {
    return std::ldexp(static_cast<double>(v), -kProbFracBits);
}
double q24(std::int64_t v) {
    return std::ldexp(static_cast<double>(v), -kLog2FracBits);
}

// ---- Tables ----------------------------------------------------------------

TEST(FixedPoint, Exp2AndExpAccuracy) {
    // 2^-u over [0, 40] in steps finer than the table: relative error
    // <= 1e-7 (+ half a unit of Q30 once the value is small).
    double worst_rel = 0;
    for (std::int64_t u = 0; u < (std::int64_t{40} << kLog2FracBits); u += 4099) {
        const double exact = std::exp2(-q24(u));
        const double err = std::abs(q30(exp2NegQ30(u)) - exact);
        EXPECT_LE(err, 1e-7 * exact + 1.0 / static_cast<double>(kProbOne)) << q24(u);
        if (exact > 0.1) {
            worst_rel = std::max(worst_rel, err / exact);
        }
    }
    EXPECT_LT(worst_rel, 1e-7);
    // exp(-x), x in Q16 nats: the input's own rounding (x is exact here).
    for (std::int64_t x = 0; x < (std::int64_t{40} << kLogFracBits); x += 37) {
        const double exact = std::exp(-q16(x));
        EXPECT_NEAR(q30(expNegQ30(x)), exact, 2e-7 * exact + 1.0 / static_cast<double>(kProbOne))
            << q16(x);
    }
    // The mantissa/exponent split: 2^y for y in [-40, 40].
    for (std::int64_t y = -(std::int64_t{40} << kLog2FracBits);
         y < (std::int64_t{40} << kLog2FracBits); y += 98317) {
        const Exp2Split s = exp2Split(y);
        EXPECT_GT(s.mantissa, kProbOne / 2);
        EXPECT_LE(s.mantissa, kProbOne);
        const double v = std::ldexp(static_cast<double>(s.mantissa), s.exponent - kProbFracBits);
        EXPECT_NEAR(v / std::exp2(q24(y)), 1.0, 1e-7) << q24(y);
    }
}

TEST(FixedPoint, LogAccuracy) {
    // log2 of integers: <= 2e-7 log2 units (table interpolation + Q24 rounding).
    std::mt19937_64 rng(5);
    for (int i = 0; i < 200000; ++i) {
        const std::uint64_t v = (rng() >> (rng() % 63)) | 1U;
        EXPECT_NEAR(q24(log2Q24(v)), std::log2(static_cast<double>(v)), 2e-7) << v;
    }
    // ln in Q16 nats: within one unit of Q16 (1.5e-5 nats).
    for (int i = 0; i < 100000; ++i) {
        const std::uint64_t v = (rng() >> (rng() % 60)) | 1U;
        EXPECT_NEAR(q16(lnQ16(v, 30)), std::log(static_cast<double>(v)) - 30 * std::log(2.0),
                    1.0 / static_cast<double>(kLogOne))
            << v;
    }
}

TEST(FixedPoint, LogSumExpAccuracy) {
    // log(e^a + e^b): within two units of Q16 (3e-5 nats) for any a - b.
    for (std::int64_t a = -(std::int64_t{50} << kLogFracBits);
         a <= (std::int64_t{50} << kLogFracBits); a += 7919) {
        const std::int64_t b = 12345;
        const double exact =
            std::max(q16(a), q16(b)) + std::log1p(std::exp(-std::abs(q16(a) - q16(b))));
        EXPECT_NEAR(q16(logAddExpQ16(a, b)), exact, 2.0 / static_cast<double>(kLogOne)) << q16(a);
    }
    for (std::int64_t a = -(std::int64_t{40} << kLog2FracBits);
         a <= (std::int64_t{40} << kLog2FracBits); a += 99991) {
        const double exact = std::log2(std::exp2(q24(a)) + std::exp2(0.3));
        EXPECT_NEAR(q24(log2AddExp2Q24(a, std::llround(std::ldexp(0.3, kLog2FracBits)))), exact,
                    3e-7)
            << q24(a);
    }
}

// ---- Likelihood ------------------------------------------------------------

ScaleGrid grid(int bins = 1024) {
    return ScaleGrid::create({Scalar(0.01), Scalar(100), bins}).value();
}

HeightPrior bottle(int bins = 24) {
    return HeightPrior::fromNormal("bottle", Scalar(0.26), Scalar(0.06), Scalar(0.15), Scalar(0.40),
                                   bins, true)
        .value();
}

HeightPrior twoHeights() {
    const std::vector<Scalar> hs{Scalar(0.9), Scalar(1.1)};
    const std::vector<Scalar> ps{Scalar(0.25), Scalar(0.75)};
    return HeightPrior::fromHistogram("x", hs, ps, 0, true).value();
}

struct Case {
    const char* name;
    LikelihoodConfig config;
    VerticalExtent extent;
    HeightPrior prior;
};

std::vector<Case> likelihoodCases() {
    std::vector<Case> cases;
    VerticalExtent e;
    e.D = Scalar(0.5);
    e.sigma_D_paper = Scalar(0.04);
    e.sigma_D_feature = Scalar(0.01);
    e.sigma_D_box = Scalar(0.005);
    LikelihoodConfig paper;
    paper.variance_model = VarianceModel::kPaper;
    cases.push_back({"paper", paper, e, bottle()});
    LikelihoodConfig prop;
    prop.variance_model = VarianceModel::kPropagated;
    cases.push_back({"propagated", prop, e, twoHeights()});
    LikelihoodConfig robust = prop;
    robust.robust = true;
    robust.outlier_weight = Scalar(0.05);
    robust.outlier_height_range_m = 5;
    cases.push_back({"propagated+robust", robust, e, bottle()});
    LikelihoodConfig partial = robust;
    partial.partial_visibility = true;
    partial.partial_weight = Scalar(0.2);
    cases.push_back({"propagated+robust+partial (daemon)", partial, e, bottle()});
    HeightPrior occluded = bottle();
    EXPECT_TRUE(occluded.setPartialProbability(Scalar(0.4)).ok());
    cases.push_back({"partial from the prior", partial, e, occluded});
    LikelihoodConfig paper_robust = paper;
    paper_robust.robust = true;
    paper_robust.partial_visibility = true;
    paper_robust.partial_weight = Scalar(0.3);
    cases.push_back({"paper+robust+partial", paper_robust, e, bottle(64)});
    // min_sigma_m dominating: a very confident feature.
    LikelihoodConfig tight = prop;
    tight.min_sigma_m = Scalar(0.02);
    VerticalExtent sharp = e;
    sharp.sigma_D_feature = Scalar(1e-5);
    sharp.sigma_D_box = 0;
    cases.push_back({"min_sigma", tight, sharp, twoHeights()});
    // A prior with a bin width (the discretisation term) and a tiny D.
    const std::vector<Scalar> hs{Scalar(0.7), Scalar(0.75), Scalar(0.8)};
    const std::vector<Scalar> ps{Scalar(0.2), Scalar(0.5), Scalar(0.3)};
    VerticalExtent small = e;
    small.D = Scalar(0.02);
    cases.push_back({"bin width, small D", paper, small,
                     HeightPrior::fromHistogram("t", hs, ps, Scalar(0.05), true).value()});
    // Large D: the peak near the lower grid end, most bins outside every window.
    VerticalExtent large = e;
    large.D = Scalar(20);
    cases.push_back({"large D", robust, large, bottle()});
    return cases;
}

// Near the peak (within 20 nats of the maximum) the fixed likelihood agrees
// with evaluateLogLikelihood to 1e-4 nats (measured: <= 5e-5 against both the
// double and the float build's reference; 2e-4 allowed for float); the mode is
// within half a bin. Everywhere it keeps the
// floating shape within 1e-4 relative down to its saturation.
TEST(FixedLikelihood, AgreesWithTheFloatingLikelihoodForEveryOption) {
    const auto g = grid();
    const double near_tol = sizeof(Scalar) == sizeof(double) ? 1e-4 : 2e-4;
    for (const Case& c : likelihoodCases()) {
        std::vector<Scalar> ref(g.size());
        ASSERT_TRUE(evaluateLogLikelihood(c.extent, c.prior, g, c.config, ref)) << c.name;
        auto fl = FixedLikelihood::create(g, c.config);
        ASSERT_TRUE(fl.ok()) << c.name << ": " << fl.error().message;
        std::vector<LogQ16> out(g.size());
        ASSERT_TRUE(fl->evaluate(c.extent, c.prior, out)) << c.name;
        const double mx = static_cast<double>(*std::max_element(ref.begin(), ref.end()));
        double worst_near = 0;
        for (std::size_t j = 0; j < g.size(); ++j) {
            const double r = static_cast<double>(ref[j]) - mx;
            const double f = q16(out[j]);
            if (r > -20) {
                worst_near = std::max(worst_near, std::abs(f - r));
            } else if (r > q16(kFixedLogLikelihoodMin) * 0.999) {
                EXPECT_NEAR(f, r, 1e-4 * std::abs(r) + near_tol) << c.name << " bin " << j;
            } else {
                EXPECT_LE(f, r * 0.999 > q16(kFixedLogLikelihoodMin)
                                 ? r * 0.999
                                 : q16(kFixedLogLikelihoodMin) * 0.999)
                    << c.name << " bin " << j;
            }
        }
        EXPECT_LT(worst_near, near_tol) << c.name;
        EXPECT_NEAR(std::log(gridModeFixed(g, out) / gridMode(g, ref)), 0,
                    0.5 * static_cast<double>(g.delta()))
            << c.name;
    }
}

TEST(FixedLikelihood, RejectsWhatTheFloatingOneRejectsAndUnsupportedConfigs) {
    const auto g = grid();
    auto fl = FixedLikelihood::create(g, {}).value();
    std::vector<LogQ16> out(g.size(), 123);
    VerticalExtent e;
    e.D = 0;
    EXPECT_FALSE(fl.evaluate(e, bottle(), out));
    e.D = Scalar(std::nan(""));
    EXPECT_FALSE(fl.evaluate(e, bottle(), out));
    e.D = 1;
    e.sigma_D_feature = Scalar(INFINITY);
    EXPECT_FALSE(fl.evaluate(e, bottle(), out));
    e.sigma_D_feature = 0;
    std::vector<LogQ16> wrong(10);
    EXPECT_FALSE(fl.evaluate(e, bottle(), wrong));
    EXPECT_EQ(out[0], 123);
    LikelihoodConfig c;
    c.min_sigma_m = Scalar(1e-6);
    const auto bad = FixedLikelihood::create(g, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("min_sigma_m"), std::string::npos);
}

// ---- Posterior -------------------------------------------------------------

PosteriorConfig posteriorConfig(PosteriorArithmetic a, Scalar drift = 0) {
    PosteriorConfig c;
    c.grid = {Scalar(0.01), Scalar(100), 1024};
    c.arithmetic = a;
    c.drift_sigma_log = drift;
    return c;
}

TEST(FixedPosterior, SaturatesAtTheFloorNeverWraps) {
    auto p = ScalePosterior::create(posteriorConfig(PosteriorArithmetic::kFixed)).value();
    const FixedPosterior* fp = p.fixedPosterior();
    if (fp == nullptr) {
        FAIL() << "no fixed posterior";
    }
    const auto g = p.grid();
    std::vector<LogQ16> l(g.size(), 0);
    for (std::size_t j = 0; j < g.size(); ++j) {
        l[j] = j == 700 ? 0 : kFixedLogLikelihoodMin;  // the most extreme likelihood there is
    }
    for (int i = 0; i < 100; ++i) {
        ASSERT_TRUE(p.addFixedLogLikelihood(l, 1));
    }
    const auto fixed_density = fp->logDensityFixed();
    const LogQ16 floor_q = -1000 * static_cast<LogQ16>(kLogOne);
    for (std::size_t j = 0; j < g.size(); ++j) {
        EXPECT_EQ(fixed_density[j], j == 700 ? 0 : floor_q) << j;
        EXPECT_EQ(p.logDensity()[j], j == 700 ? Scalar(0) : Scalar(-1000)) << j;
    }
    const ScaleSummary s = p.summary();
    EXPECT_NEAR(std::log(s.map / g.d(700)), 0, 1e-6);
    EXPECT_EQ(s.observations, 100);
    // Out-of-range input is rejected as a whole.
    l[3] = 1;
    EXPECT_FALSE(p.addFixedLogLikelihood(l, 1));
    l[3] = kFixedLogLikelihoodMin - 1;
    EXPECT_FALSE(p.addFixedLogLikelihood(l, 1));
    l[3] = 0;
    EXPECT_FALSE(p.addFixedLogLikelihood(l, 0));
    EXPECT_EQ(p.observations(), 100);
    // Floors the int32 accumulator cannot hold are refused at create.
    auto c = posteriorConfig(PosteriorArithmetic::kFixed);
    c.log_floor = -20000;
    EXPECT_FALSE(ScalePosterior::create(c).ok());
    c.arithmetic = PosteriorArithmetic::kFloating;
    EXPECT_TRUE(ScalePosterior::create(c).ok());
}

TEST(FixedPosterior, StartsUniformAndResetForgets) {
    auto p = ScalePosterior::create(posteriorConfig(PosteriorArithmetic::kFixed)).value();
    auto s = p.summary();
    EXPECT_EQ(s.state, ScaleState::kNoData);
    EXPECT_NEAR(std::log10(s.ci95.lo), -2 + 4 * 0.025, 0.01);
    EXPECT_NEAR(std::log10(s.ci95.hi), -2 + 4 * 0.975, 0.01);
    EXPECT_NEAR(std::log10(s.ci68.lo), -2 + 4 * 0.16, 0.01);
    EXPECT_NEAR(std::log10(s.ci68.hi), -2 + 4 * 0.84, 0.01);
    const auto g = p.grid();
    std::vector<Scalar> l(g.size());
    for (std::size_t j = 0; j < g.size(); ++j) {
        const Scalar r = g.logD(j) - std::log(Scalar(2));
        l[j] = -r * r / Scalar(2 * 0.01 * 0.01);
    }
    ASSERT_TRUE(p.addLogLikelihood(l));
    s = p.summary();
    EXPECT_EQ(s.state, ScaleState::kConverged);
    EXPECT_NEAR(s.map, 2, 0.01);
    EXPECT_NEAR(s.mean, 2 * std::exp(0.5 * 0.01 * 0.01), 0.002);
    p.reset();
    EXPECT_EQ(p.observations(), 0);
    for (const Scalar v : p.logDensity()) {
        ASSERT_EQ(v, 0);
    }
    EXPECT_EQ(p.summary().state, ScaleState::kNoData);
}

// A seeded synthetic sequence: bottles (0.26 +- 0.06 m) seen at d = 0.8 m per
// unit with 5% noise on D, 5% outliers, the daemon's likelihood options.
struct Observation {
    VerticalExtent extent;
    Scalar weight = 1;
};

std::vector<Observation> syntheticSequence(unsigned seed, int n) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> height(0.26, 0.06);
    std::normal_distribution<double> noise(0, 0.05);
    std::uniform_real_distribution<double> uniform(0, 1);
    std::vector<Observation> out;
    for (int i = 0; i < n; ++i) {
        const double h = std::clamp(height(rng), 0.15, 0.40);
        double D = h / 0.8 * (1 + noise(rng));
        if (uniform(rng) < 0.05) {
            D *= 0.3 + 2 * uniform(rng);  // outlier
        }
        Observation o;
        o.extent.D = static_cast<Scalar>(D);
        o.extent.sigma_D_paper = Scalar(0.05);
        o.extent.sigma_D_feature = static_cast<Scalar>(0.03 * D);
        o.extent.sigma_D_box = static_cast<Scalar>(0.02 * D);
        o.weight = i % 3 == 0 ? Scalar(0.5) : Scalar(1);
        out.push_back(o);
    }
    return out;
}

void expectAgreement(const ScaleSummary& a, const ScaleSummary& b, const ScaleGrid& g,
                     const std::string& what) {
    EXPECT_LE(std::abs(std::log(a.map / b.map)), static_cast<double>(g.delta())) << what;
    EXPECT_NEAR(a.ci95.lo / b.ci95.lo, 1, 0.01) << what;
    EXPECT_NEAR(a.ci95.hi / b.ci95.hi, 1, 0.01) << what;
    EXPECT_NEAR(a.ci68.lo / b.ci68.lo, 1, 0.01) << what;
    EXPECT_NEAR(a.ci68.hi / b.ci68.hi, 1, 0.01) << what;
    EXPECT_NEAR(a.mean / b.mean, 1, 0.01) << what;
    EXPECT_EQ(a.state, b.state) << what;
}

TEST(FixedPosterior, MatchesTheFloatingPosteriorOnASyntheticSequence) {
    for (const Scalar drift : {Scalar(0), Scalar(0.02)}) {
        for (const VarianceModel model : {VarianceModel::kPropagated, VarianceModel::kPaper}) {
            LikelihoodConfig lc;
            lc.variance_model = model;
            lc.robust = true;
            lc.partial_visibility = true;
            lc.partial_weight = Scalar(0.1);
            auto floating =
                ScalePosterior::create(posteriorConfig(PosteriorArithmetic::kFloating, drift))
                    .value();
            auto fixed_p =
                ScalePosterior::create(posteriorConfig(PosteriorArithmetic::kFixed, drift)).value();
            const auto& g = floating.grid();
            auto fl = FixedLikelihood::create(g, lc).value();
            const auto prior = bottle();
            std::vector<Scalar> ref(g.size());
            std::vector<LogQ16> out(g.size());
            const auto seq = syntheticSequence(model == VarianceModel::kPaper ? 11 : 7, 300);
            for (std::size_t i = 0; i < seq.size(); ++i) {
                ASSERT_TRUE(evaluateLogLikelihood(seq[i].extent, prior, g, lc, ref));
                ASSERT_TRUE(floating.addLogLikelihood(ref, seq[i].weight));
                ASSERT_TRUE(fl.evaluate(seq[i].extent, prior, out));
                ASSERT_TRUE(fixed_p.addFixedLogLikelihood(out, seq[i].weight));
                if (i == 0 || i == 4 || i == 19 || i == 99 || i + 1 == seq.size()) {
                    expectAgreement(
                        fixed_p.summary(), floating.summary(), g,
                        std::string(model == VarianceModel::kPaper ? "paper" : "propagated") +
                            " drift " + std::to_string(drift) + " after " + std::to_string(i + 1));
                }
            }
            EXPECT_NEAR(fixed_p.summary().map, 0.8, 0.1);
        }
    }
}

// ---- Estimator -------------------------------------------------------------

TEST(FixedPosterior, EstimatorSelectsTheArithmeticByConfig) {
    const auto cam =
        PinholeRadialCamera::create({500, 500, 320, 240, Scalar(-0.05), Scalar(0.01), 640, 480})
            .value();
    CameraPose pose;
    pose.R_CtoW << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    MapFeature feature;
    feature.p_FinW = Vec3(0, 2, 0);
    feature.P_FinW = Vec3(Scalar(1e-4), Scalar(4e-4), Scalar(1e-4)).asDiagonal();
    FrameSnapshot snap;
    snap.pose = pose;
    snap.features = std::span<const MapFeature>(&feature, 1);
    const std::vector<Detection> dets{Detection{{300, 115, 340, 315}, "bottle", 1}};
    EstimatorConfig cfg;
    cfg.likelihood.variance_model = VarianceModel::kPropagated;
    cfg.likelihood.robust = true;
    cfg.likelihood.partial_visibility = true;
    PriorTable priors;
    priors.add(bottle());
    auto floating = ScaleEstimator::create(cfg, priors, cam).value();
    cfg.posterior.arithmetic = PosteriorArithmetic::kFixed;
    auto fixed_est = ScaleEstimator::create(cfg, priors, cam).value();
    EXPECT_EQ(fixed_est.posterior().arithmetic(), PosteriorArithmetic::kFixed);
    std::vector<ObservationRecord> ra(1);
    std::vector<ObservationRecord> rb(1);
    for (int i = 0; i < 10; ++i) {
        ASSERT_EQ(floating.update(snap, dets, ra).observations, 1);
        ASSERT_EQ(fixed_est.update(snap, dets, rb).observations, 1);
    }
    const auto& g = floating.posterior().grid();
    EXPECT_LE(std::abs(std::log(rb[0].local_estimate / ra[0].local_estimate)),
              static_cast<double>(g.delta()));
    expectAgreement(fixed_est.summary(), floating.summary(), g, "estimator");
    EXPECT_EQ(fixed_est.posterior().observations(), 10);
    EXPECT_EQ(fixed_est.posterior().logDensity().size(), g.size());
    fixed_est.reset();
    EXPECT_EQ(fixed_est.summary().state, ScaleState::kNoData);
    // Configs the fixed formats cannot hold are refused, with the reason.
    cfg.likelihood.min_sigma_m = Scalar(1e-7);
    const auto bad = ScaleEstimator::create(cfg, priors, cam);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("fixed"), std::string::npos);
}

}  // namespace
}  // namespace scaled::core
