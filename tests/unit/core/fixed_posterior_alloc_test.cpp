// The fixed-point path allocates nothing after construction: likelihood
// evaluation, posterior update (with diffusion), summary and the estimator's
// update. A binary of its own: allocation_counter.cpp replaces the global
// operator new for the whole binary.

#include <array>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/fixed_posterior.h>
#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/scale/scale_posterior.h>

#include "allocation_counter.h"

namespace scaled::core {
namespace {

TEST(FixedPosteriorAllocation, UpdateAndSummaryDoNotAllocate) {
    PosteriorConfig pc;
    pc.arithmetic = PosteriorArithmetic::kFixed;
    pc.drift_sigma_log = Scalar(0.01);
    auto posterior = ScalePosterior::create(pc).value();
    LikelihoodConfig lc;
    lc.variance_model = VarianceModel::kPropagated;
    lc.robust = true;
    lc.partial_visibility = true;
    lc.partial_weight = Scalar(0.1);
    auto likelihood = FixedLikelihood::create(posterior.grid(), lc).value();
    const auto prior = HeightPrior::fromNormal("bottle", Scalar(0.26), Scalar(0.06), Scalar(0.15),
                                               Scalar(0.40), 24, true)
                           .value();
    std::vector<LogQ16> log_l(posterior.grid().size());
    VerticalExtent e;
    e.D = Scalar(0.33);
    e.sigma_D_feature = Scalar(0.01);
    e.sigma_D_box = Scalar(0.005);

    const std::int64_t before = test::allocationCount();
    Scalar sum = 0;
    for (int i = 0; i < 20; ++i) {
        ASSERT_TRUE(likelihood.evaluate(e, prior, log_l));
        ASSERT_TRUE(posterior.addFixedLogLikelihood(log_l, Scalar(0.5)));
        sum += posterior.summary().map + posterior.logDensity()[10] +
               gridModeFixed(posterior.grid(), log_l);
    }
    posterior.reset();
    EXPECT_EQ(test::allocationCount(), before);
    EXPECT_TRUE(std::isfinite(sum));
}

TEST(FixedPosteriorAllocation, EstimatorUpdateDoesNotAllocate) {
    const auto cam =
        PinholeRadialCamera::create({500, 500, 320, 240, Scalar(-0.05), Scalar(0.01), 640, 480})
            .value();
    MapFeature feature;
    feature.p_FinW = Vec3(0, 2, 0);
    feature.P_FinW = Vec3(Scalar(1e-4), Scalar(4e-4), Scalar(1e-4)).asDiagonal();
    FrameSnapshot snap;
    snap.pose.R_CtoW << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    snap.features = std::span<const MapFeature>(&feature, 1);
    const std::array<Detection, 1> dets{Detection{{300, 115, 340, 315}, "bottle", 1}};
    EstimatorConfig cfg;
    cfg.posterior.arithmetic = PosteriorArithmetic::kFixed;
    cfg.likelihood.variance_model = VarianceModel::kPropagated;
    cfg.likelihood.robust = true;
    cfg.likelihood.partial_visibility = true;
    PriorTable priors;
    priors.add(HeightPrior::fromNormal("bottle", Scalar(0.26), Scalar(0.06), Scalar(0.15),
                                       Scalar(0.40), 24, true)
                   .value());
    auto est = ScaleEstimator::create(cfg, priors, cam).value();
    std::array<ObservationRecord, 4> records{};
    const std::int64_t before = test::allocationCount();
    int observations = 0;
    for (int i = 0; i < 20; ++i) {
        observations += est.update(snap, dets, records).observations;
        (void)est.summary();
    }
    EXPECT_EQ(test::allocationCount(), before);
    EXPECT_EQ(observations, 20);
}

}  // namespace
}  // namespace scaled::core
