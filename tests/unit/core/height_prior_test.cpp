#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/height_prior.h>

#include "scalar_tolerance.h"

namespace scaled::core {
namespace {

Scalar sum(std::span<const Scalar> v) {
    return std::accumulate(v.begin(), v.end(), Scalar(0));
}

TEST(HeightPrior, HistogramIsNormalisedSortedAndDropsZeroBins) {
    const std::vector<Scalar> h{0.3, 0.1, 0.2, 0.4};
    const std::vector<Scalar> p{2, 1, 0, 1};
    const auto prior = HeightPrior::fromHistogram("cup", h, p, 0.05, true);
    ASSERT_TRUE(prior.ok()) << prior.error().message;
    ASSERT_EQ(prior->size(), 3U);
    SCALED_EXPECT_SCALAR_EQ(prior->heights()[0], 0.1);
    SCALED_EXPECT_SCALAR_EQ(prior->heights()[1], 0.3);
    SCALED_EXPECT_SCALAR_EQ(prior->heights()[2], 0.4);
    SCALED_EXPECT_SCALAR_EQ(prior->probabilities()[1], 0.5);
    SCALED_EXPECT_SCALAR_EQ(prior->logProbabilities()[0], std::log(0.25));
    EXPECT_NEAR(sum(prior->probabilities()), 1, 1e-15);
    EXPECT_NEAR(prior->mean(), 0.1 * 0.25 + 0.3 * 0.5 + 0.4 * 0.25, test::tolerance(1e-15, 1e-6));
    EXPECT_TRUE(prior->upright());
    EXPECT_EQ(prior->className(), "cup");
    SCALED_EXPECT_SCALAR_EQ(prior->binWidth(), 0.05);
}

TEST(HeightPrior, NormalFormIntegratesTheTruncatedNormal) {
    const auto prior = HeightPrior::fromNormal("chair", 0.9, 0.1, 0.6, 1.2, 6, true);
    ASSERT_TRUE(prior.ok()) << prior.error().message;
    ASSERT_EQ(prior->size(), 6U);
    // Float: 1e-6 relative to the O(1) inputs.
    EXPECT_NEAR(prior->binWidth(), 0.1, test::tolerance(1e-15, 1e-6));
    EXPECT_NEAR(prior->heights()[0], 0.65, test::tolerance(1e-15, 1e-6));
    EXPECT_NEAR(prior->heights()[5], 1.15, test::tolerance(1e-15, 1e-6));
    // Symmetric about the mean; the centre bins hold Phi(1)-Phi(0) of N, renormalised
    // by the mass in [-3, 3] sigma.
    // Float: each bin is a difference of CDF values of order 1, each good to a
    // few 1e-7 absolute.
    EXPECT_NEAR(prior->probabilities()[0], prior->probabilities()[5], test::tolerance(1e-15, 1e-6));
    EXPECT_NEAR(prior->probabilities()[2], prior->probabilities()[3], test::tolerance(1e-15, 1e-6));
    const Scalar inside = std::erf(3 / std::sqrt(2.0));
    EXPECT_NEAR(prior->probabilities()[2], 0.5 * std::erf(1 / std::sqrt(2.0)) / inside,
                test::tolerance(1e-12, 1e-6));
    EXPECT_NEAR(prior->mean(), 0.9, test::tolerance(1e-12, 1e-6));
}

TEST(HeightPrior, HugeStdGivesAUniformPrior) {
    // 1e30 m, not 1e300 (not finite as a float): in both builds the CDF
    // differences over the bins underflow to zero, as they do for 1e300.
    const auto prior = HeightPrior::fromNormal("x", 0.5, 1e30, 0.1, 0.9, 8, true);
    ASSERT_TRUE(prior.ok()) << prior.error().message;
    for (const Scalar p : prior->probabilities()) {
        EXPECT_NEAR(p, 1.0 / 8, test::tolerance(1e-12, 1e-7));
    }
}

TEST(HeightPrior, RejectsBadInputWithClearMessages) {
    const std::vector<Scalar> h{0.1, 0.2};
    const std::vector<Scalar> p{1, 1};
    const std::vector<Scalar> one{1};
    const std::vector<Scalar> zeros{0, 0};
    const std::vector<Scalar> neg{0.1, -0.2};
    const std::vector<Scalar> nan{0.1, std::nan("")};
    struct Case {
        Result<HeightPrior> r;
        const char* expect;
    };
    const std::vector<Case> cases{
        {HeightPrior::fromHistogram("a", {}, {}, 0, true), "no heights"},
        {HeightPrior::fromHistogram("a", h, one, 0, true), "2 entries but probabilities has 1"},
        {HeightPrior::fromHistogram("a", h, zeros, 0, true), "sum to zero"},
        {HeightPrior::fromHistogram("a", neg, p, 0, true), "heights_m[1] must be > 0"},
        {HeightPrior::fromHistogram("a", h, nan, 0, true), "probabilities[1]"},
        {HeightPrior::fromHistogram("a", h, p, -1, true), "bin_width_m"},
        {HeightPrior::fromNormal("a", 0.5, 0, 0.1, 1, 10, true), "std_m must be > 0"},
        {HeightPrior::fromNormal("a", 0.5, 0.1, 1, 0.1, 10, true), "min_m < max_m"},
        {HeightPrior::fromNormal("a", 2, 0.1, 0.1, 1, 10, true), "outside [min_m, max_m]"},
        {HeightPrior::fromNormal("a", 0.5, 0.1, 0.1, 1, 0, true), "bins must be in"},
        {HeightPrior::fromNormal("a", 0.5, 0.1, 0.1, 1, 100000, true), "bins must be in"},
    };
    for (const auto& c : cases) {
        ASSERT_FALSE(c.r.ok()) << c.expect;
        EXPECT_NE(c.r.error().message.find(c.expect), std::string::npos) << c.r.error().message;
        EXPECT_NE(c.r.error().message.find("prior 'a'"), std::string::npos);
    }
}

TEST(HeightPrior, WidthIsOffUntilSetAndSetWidthChecksItsArguments) {
    const std::vector<Scalar> h{0.1};
    const std::vector<Scalar> p{1};
    auto prior = HeightPrior::fromHistogram("cup", h, p, 0, true);
    ASSERT_TRUE(prior.ok()) << prior.error().message;
    EXPECT_FALSE(prior->hasWidth());
    SCALED_EXPECT_SCALAR_EQ(prior->widthMean(), 0);
    SCALED_EXPECT_SCALAR_EQ(prior->widthStd(), 0);

    ASSERT_TRUE(prior->setWidth(Scalar(0.08), Scalar(0.01)).ok());
    EXPECT_TRUE(prior->hasWidth());
    SCALED_EXPECT_SCALAR_EQ(prior->widthMean(), 0.08);
    SCALED_EXPECT_SCALAR_EQ(prior->widthStd(), 0.01);
    // An exact width (std 0) is a width.
    ASSERT_TRUE(prior->setWidth(Scalar(0.5), 0).ok());
    EXPECT_TRUE(prior->hasWidth());
    SCALED_EXPECT_SCALAR_EQ(prior->widthStd(), 0);

    const Scalar inf = std::numeric_limits<Scalar>::infinity();
    const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
    struct Case {
        Scalar mean_m;
        Scalar std_m;
    };
    for (const Case c : {Case{-0.1, 0.01}, Case{0.1, -0.01}, Case{0, 0.01}, Case{nan, 0.01},
                         Case{0.1, nan}, Case{inf, 0.01}, Case{0.1, inf}}) {
        SCOPED_TRACE(testing::Message() << "mean " << c.mean_m << " std " << c.std_m);
        const auto r = prior->setWidth(c.mean_m, c.std_m);
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
        EXPECT_NE(r.error().message.find("prior 'cup'"), std::string::npos) << r.error().message;
        EXPECT_NE(r.error().message.find("width"), std::string::npos) << r.error().message;
        // A rejected width leaves the one set before.
        SCALED_EXPECT_SCALAR_EQ(prior->widthMean(), 0.5);
        SCALED_EXPECT_SCALAR_EQ(prior->widthStd(), 0);
    }

    // Mean 0 with std 0 switches the width off again.
    ASSERT_TRUE(prior->setWidth(0, 0).ok());
    EXPECT_FALSE(prior->hasWidth());
    SCALED_EXPECT_SCALAR_EQ(prior->widthMean(), 0);
}

TEST(HeightPrior, RelativeSpreadIncludesTheBinWidth) {
    // Heights 0.1, 0.3, 0.4 with 1/4, 1/2, 1/4 in bins 0.05 wide: mean 0.275,
    // variance sum p (h - mean)^2 + 0.05^2 / 12 (uniform within a bin).
    const std::vector<Scalar> h{0.1, 0.3, 0.4};
    const std::vector<Scalar> p{1, 2, 1};
    const auto prior = HeightPrior::fromHistogram("x", h, p, 0.05, true);
    ASSERT_TRUE(prior.ok()) << prior.error().message;
    const double mean = 0.275;
    const double between = 0.25 * 0.175 * 0.175 + 0.5 * 0.025 * 0.025 + 0.25 * 0.125 * 0.125;
    const double within = 0.05 * 0.05 / 12;
    EXPECT_NEAR(prior->relativeSpread(), std::sqrt(between + within) / mean,
                test::tolerance(1e-12, 1e-6));
    EXPECT_NEAR(prior->relativeSpread(), 0.399724, 1e-6);

    // Exact heights (bin width 0): the spread of the bins alone.
    const auto exact = HeightPrior::fromHistogram("x", h, p, 0, true);
    ASSERT_TRUE(exact.ok()) << exact.error().message;
    EXPECT_NEAR(exact->relativeSpread(), std::sqrt(between) / mean, test::tolerance(1e-12, 1e-6));

    // One bin: only its width spreads it; one exact height: no spread.
    const std::vector<Scalar> one_h{0.1};
    const std::vector<Scalar> one_p{1};
    EXPECT_NEAR(HeightPrior::fromHistogram("x", one_h, one_p, 0.02, true)->relativeSpread(),
                0.02 / std::sqrt(12.0) / 0.1, test::tolerance(1e-12, 1e-6));
    EXPECT_EQ(HeightPrior::fromHistogram("x", one_h, one_p, 0, true)->relativeSpread(), 0);

    // A finely binned normal: std / mean of the normal.
    const auto normal = HeightPrior::fromNormal("x", 1.0, 0.1, 0.5, 1.5, 200, true);
    ASSERT_TRUE(normal.ok()) << normal.error().message;
    EXPECT_NEAR(normal->relativeSpread(), 0.1, 1e-3);
}

TEST(PriorTable, FindsAndReplacesByName) {
    PriorTable t;
    const std::vector<Scalar> h{0.1};
    const std::vector<Scalar> p{1};
    const std::vector<Scalar> h2{0.2};
    t.add(HeightPrior::fromHistogram("cup", h, p, 0, true).value());
    t.add(HeightPrior::fromHistogram("tv", h, p, 0, true).value());
    t.add(HeightPrior::fromHistogram("cup", h2, p, 0, false).value());
    EXPECT_EQ(t.priors().size(), 2U);
    ASSERT_NE(t.find("cup"), nullptr);
    SCALED_EXPECT_SCALAR_EQ(t.find("cup")->heights()[0], 0.2);
    EXPECT_FALSE(t.find("cup")->upright());
    EXPECT_EQ(t.find("chair"), nullptr);
}

}  // namespace
}  // namespace scaled::core
