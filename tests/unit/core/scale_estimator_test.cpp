#include <array>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/scale_estimator.h>

#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core {
namespace {

using test::boxOf;
using test::lookAlongY;
using test::makeCamera;

PriorTable priors() {
    PriorTable t;
    const std::vector<Scalar> h{0.30};
    const std::vector<Scalar> p{1};
    t.add(HeightPrior::fromHistogram("bottle", h, p, 0, true).value());
    t.add(
        HeightPrior::fromHistogram("dining table", std::vector<Scalar>{0.75}, p, 0, false).value());
    return t;
}

// One bottle, 0.30 m tall, seen from 1.5 m, in a SLAM frame with scale d = 0.5
// (SLAM units = metres / 0.5). Four features on its axis.
struct Scene {
    Scalar d = 0.5;
    PinholeRadialCamera cam = makeCamera();
    CameraPose pose_S = lookAlongY(Vec3::Zero());
    std::vector<MapFeature> features;
    BoundingBox box;

    Scene() {
        const Vec3 base_S(0, 1.5 / d, -0.1 / d);
        const Vec3 top_S = base_S + Vec3(0, 0, 0.30 / d);
        box = boxOf(cam, pose_S, {base_S, top_S}, 15);
        for (const Scalar f : {0.2, 0.4, 0.6, 0.8}) {
            MapFeature mf;
            mf.p_FinW = base_S + Vec3(0, 0, f * 0.30 / d);
            mf.P_FinW = Mat3::Identity() * 1e-6;
            features.push_back(mf);
        }
    }
    FrameSnapshot snapshot() const {
        FrameSnapshot s;
        s.pose = pose_S;
        s.features = features;
        return s;
    }
};

TEST(ScaleEstimator, RecoversTheScaleOfOneObject) {
    const Scene sc;
    EstimatorConfig cfg;
    auto est = ScaleEstimator::create(cfg, priors(), sc.cam);
    ASSERT_TRUE(est.ok()) << est.error().message;
    std::array<Detection, 1> dets{Detection{sc.box, "bottle", 0.9}};
    std::array<ObservationRecord, 8> records{};
    const UpdateStats st = est->update(sc.snapshot(), dets, records);
    EXPECT_EQ(st.observations, 4);
    EXPECT_EQ(st.detections_used, 1);
    EXPECT_EQ(st.records_written, 4);
    for (int i = 0; i < 4; ++i) {
        EXPECT_EQ(records[static_cast<std::size_t>(i)].feature_index, i);
        // Float: 1e-6 relative to the 3-unit depth of the scene.
        EXPECT_NEAR(records[static_cast<std::size_t>(i)].D, 0.6, test::tolerance(1e-9, 3e-6));
        EXPECT_NEAR(records[static_cast<std::size_t>(i)].local_estimate, 0.5, 0.5 * 1e-3);
    }
    const ScaleSummary s = est->summary();
    EXPECT_NEAR(s.map, 0.5, 0.5 * 1e-3);
    EXPECT_EQ(s.observations, 4);
    EXPECT_LT(s.ci95.lo, 0.5);
    EXPECT_GT(s.ci95.hi, 0.5);
}

// SIGHUP reload: new priors apply to later updates, the evidence stays.
TEST(ScaleEstimator, SetPriorsKeepsThePosterior) {
    const Scene sc;
    auto est = ScaleEstimator::create(EstimatorConfig{}, priors(), sc.cam);
    ASSERT_TRUE(est.ok()) << est.error().message;
    std::array<Detection, 1> dets{Detection{sc.box, "bottle", 0.9}};
    est->update(sc.snapshot(), dets);
    const ScaleSummary before = est->summary();
    ASSERT_EQ(before.observations, 4);

    // The same bottle believed twice as tall: the next update pulls d up, on
    // top of the kept evidence (8 observations; both sets of four are sharp,
    // so the MAP lands near one of them, not necessarily in between).
    PriorTable taller;
    taller.add(HeightPrior::fromHistogram("bottle", std::vector<Scalar>{0.60},
                                          std::vector<Scalar>{1}, 0, true)
                   .value());
    ASSERT_TRUE(est->setPriors(std::move(taller)).ok());
    ASSERT_NE(est->priors().find("bottle"), nullptr);
    EXPECT_EQ(est->priors().find("dining table"), nullptr);
    EXPECT_EQ(est->summary().observations, 4);
    est->update(sc.snapshot(), dets);
    const ScaleSummary after = est->summary();
    EXPECT_EQ(after.observations, 8);
    EXPECT_GT(after.map, 0.5 * 1.05);
    // Without the new priors the same update keeps d at 0.5.
    auto twin = ScaleEstimator::create(EstimatorConfig{}, priors(), sc.cam);
    ASSERT_TRUE(twin.ok());
    twin->update(sc.snapshot(), dets);
    twin->update(sc.snapshot(), dets);
    EXPECT_NEAR(twin->summary().map, 0.5, 0.5 * 1e-3);
}

TEST(ScaleEstimator, SkipsUnknownNonUprightAndWeakDetections) {
    const Scene sc;
    EstimatorConfig cfg;
    cfg.min_detection_score = 0.5;
    auto est = ScaleEstimator::create(cfg, priors(), sc.cam);
    ASSERT_TRUE(est.ok());
    const std::array<Detection, 3> dets{Detection{sc.box, "unicorn", 0.9},
                                        Detection{sc.box, "dining table", 0.9},
                                        Detection{sc.box, "bottle", 0.4}};
    const UpdateStats st = est->update(sc.snapshot(), dets);
    EXPECT_EQ(st.observations, 0);
    EXPECT_EQ(st.detections_skipped, 3);
    EXPECT_EQ(est->summary().state, ScaleState::kNoData);

    cfg.use_non_upright = true;
    cfg.min_detection_score = 0;
    auto est2 = ScaleEstimator::create(cfg, priors(), sc.cam);
    ASSERT_TRUE(est2.ok());
    const UpdateStats st2 = est2->update(sc.snapshot(), dets);
    EXPECT_EQ(st2.detections_used, 2);  // dining table now counts, unicorn never
    EXPECT_EQ(st2.observations, 8);
}

TEST(ScaleEstimator, PerBoxWeightingCountsABoxOnce) {
    const Scene sc;
    EstimatorConfig one;
    one.weighting = ObservationWeighting::kPerBox;
    auto per_box = ScaleEstimator::create(one, priors(), sc.cam);
    ASSERT_TRUE(per_box.ok());
    std::array<Detection, 1> dets{Detection{sc.box, "bottle", 1}};
    std::array<ObservationRecord, 8> records{};
    per_box->update(sc.snapshot(), dets, records);
    EXPECT_NEAR(records[0].weight, 0.25, 1e-15);

    // Same posterior as one feature alone with weight 1.
    Scene single = sc;
    single.features.resize(1);
    auto alone = ScaleEstimator::create(EstimatorConfig{}, priors(), sc.cam);
    ASSERT_TRUE(alone.ok());
    alone->update(single.snapshot(), dets);
    const auto a = per_box->posterior().logDensity();
    const auto b = alone->posterior().logDensity();
    // Float: the four features' D differ by rounding (up to 5e-6 relative, as
    // above), and l = -(d D - H)^2 / 2 s^2 moves by sqrt(2 |l|) (H / s) times
    // that, with H / s ~ 35 here (s ~ 3% of d D, mostly the 2 px box noise).
    for (std::size_t j = 0; j < a.size(); ++j) {
        ASSERT_NEAR(a[j], b[j], test::tolerance(1e-9, 3e-4 * (1 + std::sqrt(std::abs(b[j])))));
    }
}

TEST(ScaleEstimator, CountsRejectionsAndNeverProducesNaN) {
    const Scene sc;
    auto est = ScaleEstimator::create(EstimatorConfig{}, priors(), sc.cam);
    ASSERT_TRUE(est.ok());
    // A truncated box (touching the top border) and a box around nothing.
    BoundingBox truncated = sc.box;
    truncated.y_min_px = 0;
    const std::array<Detection, 2> dets{Detection{truncated, "bottle", 1},
                                        Detection{BoundingBox{0, 0, 5, 5}, "bottle", 1}};
    const UpdateStats st = est->update(sc.snapshot(), dets);
    EXPECT_EQ(st.observations, 0);
    EXPECT_EQ(st.rejected[static_cast<std::size_t>(ExtentStatus::kTruncatedBox)], 4);
    EXPECT_EQ(est->summary().state, ScaleState::kNoData);
    // Degenerate map: a NaN feature and a singular covariance do not poison the posterior.
    Scene bad = sc;
    bad.features[0].p_FinW.x() = std::numeric_limits<Scalar>::quiet_NaN();
    bad.features[1].P_FinW = Mat3::Zero();
    bad.features[2].P_FinW(0, 0) = std::numeric_limits<Scalar>::infinity();
    const std::array<Detection, 1> one{Detection{sc.box, "bottle", 1}};
    est->update(bad.snapshot(), one);
    for (const Scalar v : est->posterior().logDensity()) {
        ASSERT_TRUE(std::isfinite(v));
    }
    EXPECT_TRUE(std::isfinite(est->summary().map));
}

TEST(ScaleEstimator, RejectsBadConfiguration) {
    const Scene sc;
    EXPECT_FALSE(ScaleEstimator::create(EstimatorConfig{}, PriorTable{}, sc.cam).ok());
    EstimatorConfig c;
    c.max_features_per_box = 0;
    EXPECT_FALSE(ScaleEstimator::create(c, priors(), sc.cam).ok());
    c = {};
    c.likelihood.robust = true;
    c.likelihood.outlier_weight = 1.5;
    EXPECT_FALSE(ScaleEstimator::create(c, priors(), sc.cam).ok());
}

// EstimatorLimits' bounds are accepted as the configuration stores them, in
// Scalar: with Scalar = float, 0.99 is 0.99f, a little above the double 0.99.
TEST(ScaleEstimator, AcceptsItsLimitsAtTheirBounds) {
    const Scene sc;
    EstimatorConfig c;
    c.likelihood.partial_weight = static_cast<Scalar>(EstimatorLimits::partial_weight.hi);
    c.likelihood.min_sigma_m = static_cast<Scalar>(EstimatorLimits::min_sigma_m.hi);
    c.max_features_per_box = static_cast<int>(EstimatorLimits::max_features_per_box.hi);
    c.min_detection_score = static_cast<Scalar>(EstimatorLimits::min_detection_score.hi);
    auto est = ScaleEstimator::create(c, priors(), sc.cam);
    EXPECT_TRUE(est.ok()) << est.error().message;
    c.max_features_per_box = static_cast<int>(EstimatorLimits::max_features_per_box.hi) + 1;
    auto past = ScaleEstimator::create(c, priors(), sc.cam);
    ASSERT_FALSE(past.ok());
    EXPECT_EQ(past.error().message,
              "scale estimator: max_features_per_box must be in [1, 4096] (got 4097)");
}

}  // namespace
}  // namespace scaled::core
