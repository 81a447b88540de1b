// EKF MonoSLAM behaviour on the point-level simulation (no images).

#include <algorithm>
#include <array>
#include <limits>
#include <set>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include <scaled/core/geometry/trajectory_alignment.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/quaternion.h>

#include "point_slam_sim.h"
#include "scalar_tolerance.h"
#include "scene.h"

namespace scaled::core::slam {
namespace {

using test::PointSimOptions;
using test::PointSlamSim;

struct RunResult {
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    int bad_frames = 0;
    int xyz_features = 0;
    SlamHealth health = SlamHealth::kOk;
};

RunResult run(const PointSimOptions& opt, const SlamConfig& config, EkfSlam* out = nullptr) {
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, config);
    EXPECT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    RunResult r;
    std::set<std::uint64_t> xyz_ids;
    for (int k = 0; k < opt.frames; ++k) {
        const auto report = sim.step(*slam, k);
        r.bad_frames += report.bad_frame ? 1 : 0;
        r.est.push_back(slam->pose().p_CinW);
        r.gt.push_back(sim.truthInC0(Scalar(k) / opt.fps).p_CinW);
        for (const auto& f : slam->features()) {
            if (f.kind == FeatureKind::kXyz) {
                xyz_ids.insert(f.id);
            }
        }
    }
    r.xyz_features = static_cast<int>(xyz_ids.size());
    r.health = slam->health();
    if (out != nullptr) {
        *out = std::move(*slam);
    }
    return r;
}

TEST(EkfSlam, ValidateNamesTheField) {
    SlamConfig c;
    c.sigma_rho = -1;
    const auto r = validate(c);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("sigma_rho"), std::string::npos);
    c = SlamConfig{};
    c.max_measured = c.max_features + 1;
    EXPECT_FALSE(EkfSlam::create(test::makeCamera(), c).ok());
}

TEST(EkfSlam, RescalingTheMapKeepsEveryPredictedPixel) {
    // The map's unit is not observable: scaling every position about any
    // centre (and inverse depths by the inverse) predicts the same pixels.
    PointSimOptions opt;
    opt.frames = 60;
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    for (int k = 0; k < opt.frames; ++k) {
        sim.step(*slam, k);
    }
    ASSERT_FALSE(slam->observations().empty());
    std::vector<FeaturePrediction> before;
    for (const auto& p : slam->predictMeasurements()) {
        before.push_back(p);
    }
    ASSERT_GT(before.size(), 10U);
    const Mat6x6 P_before = slam->poseCovariance();
    const Vec3 v_before = slam->velocityW();
    const Vec3 centre = slam->pose().p_CinW + Vec3(Scalar(0.1), Scalar(-0.2), Scalar(0.3));
    const Vec3 p_before = slam->pose().p_CinW;
    const Scalar s = Scalar(1.7);
    slam->rescaleMap(s, centre);
    EXPECT_TRUE(slam->pose().p_CinW.isApprox(centre + s * (p_before - centre),
                                             Scalar(test::tolerance(1e-9, 1e-4))));
    EXPECT_TRUE(slam->velocityW().isApprox(s * v_before, Scalar(test::tolerance(1e-9, 1e-4))));
    const Mat6x6 P_after = slam->poseCovariance();
    const Mat3 Ppp_expected = s * s * P_before.topLeftCorner<3, 3>();
    const Mat3 Ptt_expected = P_before.bottomRightCorner<3, 3>();
    const auto tol = Scalar(test::tolerance(1e-9, 1e-4));
    EXPECT_TRUE((P_after.topLeftCorner<3, 3>().isApprox(Ppp_expected, tol)));
    EXPECT_TRUE((P_after.bottomRightCorner<3, 3>().isApprox(Ptt_expected, tol)));
    const auto after = slam->predictMeasurements();
    ASSERT_EQ(after.size(), before.size());
    for (size_t i = 0; i < after.size(); ++i) {
        EXPECT_EQ(after[i].id, before[i].id);
        EXPECT_LT((after[i].h_px - before[i].h_px).norm(), Scalar(test::tolerance(1e-6, 1e-2)))
            << "feature " << i;
        EXPECT_TRUE(after[i].S.isApprox(before[i].S, Scalar(test::tolerance(1e-6, 1e-2))))
            << "feature " << i;
    }
}

TEST(EkfSlam, TracksTheSimulatedPathWithArbitraryScale) {
    PointSimOptions opt;
    opt.frames = 300;
    const auto r = run(opt, test::pointSimSlamConfig());
    EXPECT_EQ(r.health, SlamHealth::kOk);
    EXPECT_EQ(r.bad_frames, 0);
    const auto a = alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok()) << a.error().message;
    const Scalar len = pathLength(r.gt);
    EXPECT_LT(a->ate_rmse, Scalar(0.01) * len) << "path " << len << " m";
    // The unit is the initial depth guess (rho0 = 1), not metres: the scale is
    // not 1 but must be positive and finite.
    EXPECT_GT(a->scale, 0);
}

TEST(EkfSlam, KnownDepthGivesMetricScale) {
    PointSimOptions opt;
    opt.frames = 150;
    opt.known_depth_rel_sigma = Scalar(0.02);
    const auto r = run(opt, test::pointSimSlamConfig());
    const auto a = alignTrajectories(r.est, r.gt);
    ASSERT_TRUE(a.ok());
    EXPECT_NEAR(a->scale, 1, 0.05);
    // With the scale pinned, depth uncertainties shrink below the linearity
    // threshold and features are converted to XYZ. (With an unknown scale the
    // global scale uncertainty keeps sigma_rho / rho large: few convert.)
    EXPECT_GT(r.xyz_features, 20);
}

// Mean normalised innovation squared per feature-age bin over a run.
std::array<double, UpdateReport::kAgeBins> nisByAge(Scalar pixel_noise_px, int& accepted,
                                                    std::array<int, UpdateReport::kAgeBins>& n) {
    PointSimOptions opt;
    opt.frames = 300;
    opt.pixel_noise_px = pixel_noise_px;
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    EXPECT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    std::array<double, UpdateReport::kAgeBins> sum{};
    n = {};
    accepted = 0;
    for (int k = 0; k < opt.frames; ++k) {
        const UpdateReport report = sim.step(*slam, k);
        accepted += report.low_innovation_inliers + report.rescued;
        for (size_t b = 0; b < sum.size(); ++b) {
            sum[b] += static_cast<double>(report.nis_sum[b]);
            n[b] += report.nis_count[b];
        }
    }
    for (size_t b = 0; b < sum.size(); ++b) {
        sum[b] = n[b] > 0 ? sum[b] / n[b] : 0;
    }
    return sum;
}

TEST(EkfSlam, InnovationsByFeatureAgeShowAnOverconfidentFilter) {
    // Matching noise as the filter assumes (1 px): every age bin at or under
    // the 2 of a consistent 2-dof innovation (under: this configuration's
    // motion noise is generous for the smooth simulated path, and the gates
    // cut the tail; measured 0.54 / 0.67 / 0.85 / 1.15). Noise 2 px against
    // an assumed 1: about 3.5x that in every bin (measured 1.9 / 2.8 / 3.2 /
    // 3.4), the sign of an overconfident filter the statistic exists to show.
    int accepted = 0;
    std::array<int, UpdateReport::kAgeBins> n{};
    const auto right = nisByAge(1, accepted, n);
    int counted = 0;
    for (size_t b = 0; b < right.size(); ++b) {
        counted += n[b];
        if (n[b] > 200) {
            EXPECT_GT(right[b], 0.3) << "bin " << b;
            EXPECT_LT(right[b], 2.0) << "bin " << b;
        }
    }
    EXPECT_EQ(counted, accepted);  // every accepted match is in one bin
    EXPECT_GT(n[0] + n[1], 500);   // young features are measured (914)
    const auto over = nisByAge(2, accepted, n);
    for (size_t b = 0; b < over.size(); ++b) {
        if (n[b] > 200) {
            EXPECT_GT(over[b], 2.5 * right[b]) << "bin " << b;
        }
    }
}

TEST(EkfSlam, OnePointRansacRejectsGrossOutliers) {
    PointSimOptions opt;
    opt.frames = 200;
    opt.outlier_fraction = Scalar(0.2);
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    int outliers = 0;
    int accepted_outliers = 0;
    std::vector<Vec3> est;
    std::vector<Vec3> gt;
    for (int k = 0; k < opt.frames; ++k) {
        sim.step(*slam, k);
        for (const auto id : sim.outlierIds()) {
            ++outliers;
            for (const auto& f : slam->features()) {
                if (f.id == id && f.measured) {
                    ++accepted_outliers;
                }
            }
        }
        est.push_back(slam->pose().p_CinW);
        gt.push_back(sim.truthInC0(Scalar(k) / opt.fps).p_CinW);
    }
    ASSERT_GT(outliers, 500);
    // Outliers 5-15 px off: a few of the smallest can pass the rescue gate
    // when the filter is uncertain; nearly all must go.
    EXPECT_LT(accepted_outliers, outliers / 20) << accepted_outliers << " of " << outliers;
    const auto a = alignTrajectories(est, gt);
    ASSERT_TRUE(a.ok());
    EXPECT_LT(a->ate_rmse, Scalar(0.02) * pathLength(gt));
}

TEST(EkfSlam, MapPointsCarryConsistentCovariances) {
    PointSimOptions opt;
    opt.frames = 120;
    opt.known_depth_rel_sigma = Scalar(0.02);
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    for (int k = 0; k < opt.frames; ++k) {
        sim.step(*slam, k);
    }
    std::vector<MapPoint> pts;
    slam->mapPoints(pts);
    ASSERT_GT(pts.size(), 15U);
    int in_view = 0;
    Scalar nees = 0;
    for (const auto& p : pts) {
        // Symmetric positive definite 3x3, and the truth within reach of it.
        EXPECT_LE((p.P_FinW - p.P_FinW.transpose()).cwiseAbs().maxCoeff(), 1e-12);
        Eigen::SelfAdjointEigenSolver<Mat3> es(p.P_FinW);
        EXPECT_GT(es.eigenvalues().minCoeff(), 0);
        const Vec3 e = p.p_FinW - sim.pointInC0(p.id);
        nees += e.dot(p.P_FinW.ldlt().solve(e));
        in_view += p.in_view ? 1 : 0;
        if (p.in_view) {
            const auto px =
                cam.project(slam->pose().R_CtoW.transpose() * (p.p_FinW - slam->pose().p_CinW));
            ASSERT_TRUE(px.has_value());
            // Float: two projections (f = 500) in different orders, ~1e-6
            // relative each; the pixel spacing near 640 px is 6e-5.
            EXPECT_LE((*px - p.px).norm(), test::tolerance(1e-6, 5e-4));
        }
    }
    EXPECT_GT(in_view, 10);
    // Mean point NEES of a 3-dof error: expect about 3; a loose bound catches
    // gross inconsistency (100x overconfidence).
    EXPECT_LT(nees / Scalar(pts.size()), 30);
}

TEST(EkfSlam, RefusesBadTimestampsAndReportsLostTrack) {
    const auto cam = test::makeCamera(0, 0, 500);
    PointSimOptions opt;
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    EXPECT_EQ(slam->predict(1), SlamHealth::kUninitialised);
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    sim.step(*slam, 0);
    ASSERT_GT(slam->features().size(), 10U);
    EXPECT_EQ(slam->predict(sim.timeNs(0)), SlamHealth::kBadTimestamp);
    EXPECT_EQ(slam->predict(sim.timeNs(0) + 2'000'000'000), SlamHealth::kBadTimestamp);
    // No matches at all: the front end lost everything (e.g. a covered lens).
    for (int k = 1; k <= slam->config().lost_after_frames; ++k) {
        ASSERT_EQ(slam->predict(sim.timeNs(k)), SlamHealth::kOk);
        slam->predictMeasurements();
        const auto rep = slam->update({});
        EXPECT_TRUE(rep.bad_frame);
        slam->manageMap();
    }
    EXPECT_EQ(slam->health(), SlamHealth::kLost);
    // Re-initialisation starts a fresh map.
    slam->initialise(sim.timeNs(20), sim.gravityDownC0());
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    EXPECT_TRUE(slam->features().empty());
    EXPECT_EQ(slam->stateDim(), kCameraDim);
}

// The front end's verdict (a run of near-losses, MonoTracker): lost at once,
// until a relocalisation or a new map; nothing before a map exists.
TEST(EkfSlam, DeclaredLostUntilRelocalised) {
    const auto cam = test::makeCamera(0, 0, 500);
    PointSimOptions opt;
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->declareLost();
    EXPECT_EQ(slam->health(), SlamHealth::kUninitialised);
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    sim.step(*slam, 0);
    sim.step(*slam, 1);
    ASSERT_EQ(slam->health(), SlamHealth::kOk);
    const std::size_t features = slam->features().size();
    slam->declareLost();
    EXPECT_EQ(slam->health(), SlamHealth::kLost);
    EXPECT_EQ(slam->features().size(), features) << "the map is kept for relocalisation";
    ASSERT_TRUE(slam->relocalise(sim.timeNs(2), slam->pose(), 0.01, 0.01));
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
}

TEST(EkfSlam, NumericalHealthDetectsNanAndLossOfPositiveDefiniteness) {
    const int n = kCameraDim + 6;
    VecX x = VecX::Zero(n);
    x(kQuat) = 1;
    MatX P = MatX::Identity(n, n) * 1e-2;
    EXPECT_EQ(assessNumericalHealth(x, P), SlamHealth::kOk);
    VecX xn = x;
    xn(kCameraDim + 5) = std::numeric_limits<Scalar>::quiet_NaN();
    EXPECT_EQ(assessNumericalHealth(xn, P), SlamHealth::kNonFinite);
    MatX Pn = P;
    Pn(3, 15) = std::numeric_limits<Scalar>::infinity();
    EXPECT_EQ(assessNumericalHealth(x, Pn), SlamHealth::kNonFinite);
    MatX Pneg = P;
    Pneg(kCameraDim + 2, kCameraDim + 2) = -1e-6;
    EXPECT_EQ(assessNumericalHealth(x, Pneg), SlamHealth::kNotPositiveDefinite);
    // Positive diagonal but indefinite camera block (correlation > 1).
    MatX Pind = P;
    Pind(0, 1) = Pind(1, 0) = 0.05;
    EXPECT_EQ(assessNumericalHealth(x, Pind), SlamHealth::kNotPositiveDefinite);
}

TEST(EkfSlam, RejectsNonFiniteInputsWithoutCorruptingTheState) {
    const auto cam = test::makeCamera(0, 0, 500);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(0, Vec3(0, 1, 0));
    const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
    EXPECT_EQ(slam->addFeature(Vec2(nan, 100)), 0U);
    ASSERT_NE(slam->addFeature(Vec2(320, 240)), 0U);
    ASSERT_EQ(slam->predict(33'333'333), SlamHealth::kOk);
    ASSERT_EQ(slam->predictMeasurements().size(), 1U);
    const FeatureMatch bad{0, Vec2(nan, 240)};
    const auto rep = slam->update(std::span<const FeatureMatch>(&bad, 1));
    EXPECT_EQ(rep.matched, 0);
    EXPECT_EQ(slam->manageMap(), SlamHealth::kOk);
    EXPECT_TRUE(slam->state().allFinite());
}

TEST(EkfSlam, DeletesFeaturesThatAreNeverFoundAndCapsTheMap) {
    const auto cam = test::makeCamera(0, 0, 500);
    SlamConfig c = test::pointSimSlamConfig();
    c.max_features = 12;
    c.max_measured = 12;
    c.min_visible = 12;
    auto slam = EkfSlam::create(cam, c);
    ASSERT_TRUE(slam.ok());
    slam->initialise(0, Vec3(0, 1, 0));
    for (int i = 0; i < 20; ++i) {
        slam->addFeature(Vec2(50 + 25 * i, 240));
    }
    EXPECT_EQ(slam->features().size(), 12U) << "the map is capped";
    EXPECT_EQ(slam->stateDim(), kCameraDim + 6 * 12);
    // Search the features for delete_min_attempts frames and find only the
    // first 6: the others are deleted.
    for (int k = 1; k <= c.delete_min_attempts; ++k) {
        ASSERT_EQ(slam->predict(k * 33'333'333LL), SlamHealth::kOk);
        const auto preds = slam->predictMeasurements();
        std::vector<FeatureMatch> m;
        for (int i = 0; i < static_cast<int>(preds.size()); ++i) {
            if (preds[static_cast<size_t>(i)].id <= 6) {
                m.push_back({i, preds[static_cast<size_t>(i)].h_px});
            }
        }
        slam->update(m);
        slam->manageMap();
    }
    ASSERT_EQ(slam->features().size(), 6U);
    for (const auto& f : slam->features()) {
        EXPECT_LE(f.id, 6U);
    }
    EXPECT_EQ(slam->stateDim(), kCameraDim + 6 * 6);
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    // The covariance stayed symmetric through deletions.
    const auto P = slam->covariance();
    EXPECT_LE((P - P.transpose()).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(EkfSlam, FeaturesAddedAfterAFrameAreRemovedAndTheRestKept) {
    // After a loss the tracker removes the features it added while the
    // filter was guessing its pose (frames after the last well-tracked one).
    const auto cam = test::makeCamera(0, 0, 500);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(0, Vec3(0, 1, 0));
    std::vector<std::uint64_t> kept;
    kept.reserve(4);
    for (int i = 0; i < 4; ++i) {
        kept.push_back(slam->addFeature(Vec2(100 + 100 * i, 200)));
    }
    const std::int64_t last_good = slam->frameIndex();
    for (std::int64_t k = 1; k <= 2; ++k) {
        ASSERT_EQ(slam->predict(k * 33'333'333), SlamHealth::kOk);
        slam->predictMeasurements();
        slam->update({});
        slam->addFeature(Vec2(150 + 100 * static_cast<Scalar>(k), 300));
        slam->addFeature(Vec2(150 + 100 * static_cast<Scalar>(k), 350));
    }
    ASSERT_EQ(slam->features().size(), 8U);
    EXPECT_EQ(slam->features()[5].first_frame, 1);
    EXPECT_EQ(slam->removeFeaturesAddedAfter(slam->frameIndex()), 0);
    const VecX x_before = slam->state();
    const MatX P_before = slam->covariance();
    EXPECT_EQ(slam->removeFeaturesAddedAfter(last_good), 4);
    ASSERT_EQ(slam->features().size(), kept.size());
    for (std::size_t i = 0; i < kept.size(); ++i) {
        EXPECT_EQ(slam->features()[i].id, kept[i]);
        EXPECT_EQ(slam->features()[i].first_frame, last_good);
    }
    // The camera and the kept features keep their state and covariance.
    const int n = kCameraDim + 6 * 4;
    ASSERT_EQ(slam->stateDim(), n);
    EXPECT_EQ(slam->state(), x_before.head(n));
    EXPECT_EQ(slam->covariance(), P_before.topLeftCorner(n, n));
}

TEST(EkfSlam, RelocalisationPutsTheCameraBackIntoTheMapItLost) {
    // A metric map (features at their true depth) tracked for 30 frames, a
    // covered lens until the filter is lost, then the camera put back at its
    // true pose (what the tracker's PnP would find) 15 frames later.
    PointSimOptions opt;
    opt.known_depth_rel_sigma = Scalar(0.05);
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    for (int k = 0; k < 30; ++k) {
        sim.step(*slam, k);
    }
    ASSERT_EQ(slam->health(), SlamHealth::kOk);
    std::vector<std::pair<std::uint64_t, int>> attempts;
    for (const auto& f : slam->features()) {
        attempts.emplace_back(f.id, f.attempts);
    }
    const int lost_after = slam->config().lost_after_frames;
    ASSERT_GE(lost_after, slam->config().delete_min_attempts) << "the outage must be long enough";
    for (int k = 30; k < 30 + lost_after; ++k) {
        ASSERT_EQ(slam->predict(sim.timeNs(k)), SlamHealth::kOk);
        slam->predictMeasurements();
        EXPECT_TRUE(slam->update({}).bad_frame);
        slam->manageMap();
    }
    ASSERT_EQ(slam->health(), SlamHealth::kLost);
    // Frames with nothing matched do not count against the features: the
    // whole map is still there, its search counts unchanged.
    ASSERT_EQ(slam->features().size(), attempts.size());
    for (std::size_t i = 0; i < attempts.size(); ++i) {
        EXPECT_EQ(slam->features()[i].id, attempts[i].first);
        EXPECT_EQ(slam->features()[i].attempts, attempts[i].second);
    }

    const int k_back = 30 + lost_after + 5;
    const core::CameraPose truth = sim.truthInC0(Scalar(k_back) / opt.fps);
    const Scalar sigma_p = Scalar(0.02);
    const Scalar sigma_theta = Scalar(0.01);
    ASSERT_TRUE(slam->relocalise(sim.timeNs(k_back), truth, sigma_p, sigma_theta));
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    EXPECT_EQ(slam->timestampNs(), sim.timeNs(k_back));
    EXPECT_LT((slam->pose().p_CinW - truth.p_CinW).norm(), 1e-5);
    EXPECT_LT(rotationError(slam->pose().R_CtoW, truth.R_CtoW).norm(), 1e-5);
    EXPECT_EQ(slam->velocityW(), Vec3::Zero());
    const Mat6x6 Pp = slam->poseCovariance();
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(Pp(i, i), sigma_p * sigma_p, 1e-9);
        EXPECT_NEAR(Pp(3 + i, 3 + i), sigma_theta * sigma_theta, 1e-7);
    }
    const auto P = slam->covariance();
    EXPECT_EQ(P.topRightCorner(kCameraDim, P.cols() - kCameraDim).cwiseAbs().maxCoeff(), 0)
        << "the camera forgets its correlation with the map";
    EXPECT_EQ(slam->predict(sim.timeNs(k_back)), SlamHealth::kBadTimestamp)
        << "the clock moved to the relocalised frame";

    // Tracking resumes in the same map: the same features are found again
    // and the camera follows the truth.
    for (int k = k_back + 1; k < k_back + 90; ++k) {
        sim.step(*slam, k);
    }
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    const core::CameraPose end = sim.truthInC0(Scalar(k_back + 89) / opt.fps);
    EXPECT_LT((slam->pose().p_CinW - end.p_CinW).norm(), 0.05);
    std::uint64_t last_id_before = 0;
    for (const auto& [id, n] : attempts) {
        last_id_before = std::max(last_id_before, id);
    }
    int kept = 0;
    for (const auto& f : slam->features()) {
        kept += f.id <= last_id_before && f.matches > 0 ? 1 : 0;
    }
    EXPECT_GT(kept, 10) << "features from before the loss are measured again";
}

TEST(EkfSlam, RestartAtBeginsTheMapAgainInTheSameWorldFrame) {
    // A metric map tracked for 30 frames, then begun again (MonoTracker's
    // start check) with the camera at its true pose: no feature is kept, the
    // world's vertical and the frame count go on, and the features added
    // from there on (at their true depths) follow the truth in the same frame.
    PointSimOptions opt;
    opt.known_depth_rel_sigma = Scalar(0.05);
    const auto cam = test::makeCamera(0, 0, 500);
    PointSlamSim sim(cam, opt);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    core::CameraPose T;
    EXPECT_FALSE(slam->restartAt(1, T, 0.01, 0.01)) << "no map yet";
    slam->initialise(sim.timeNs(0), sim.gravityDownC0());
    for (int k = 0; k < 30; ++k) {
        sim.step(*slam, k);
    }
    ASSERT_EQ(slam->health(), SlamHealth::kOk);
    ASSERT_FALSE(slam->features().empty());
    const Vec3 up_W = slam->upW();
    const std::int64_t frame = slam->frameIndex();
    T.p_CinW = Vec3(std::numeric_limits<Scalar>::quiet_NaN(), 0, 0);
    EXPECT_FALSE(slam->restartAt(sim.timeNs(30), T, 0.01, 0.01));
    EXPECT_EQ(slam->frameIndex(), frame) << "a refused input changes nothing";

    const core::CameraPose truth = sim.truthInC0(Scalar(30) / opt.fps);
    const Scalar sigma_p = Scalar(0.02);
    const Scalar sigma_theta = Scalar(0.01);
    ASSERT_TRUE(slam->restartAt(sim.timeNs(30), truth, sigma_p, sigma_theta));
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    EXPECT_TRUE(slam->features().empty());
    EXPECT_EQ(slam->stateDim(), kCameraDim);
    EXPECT_EQ(slam->upW(), up_W);
    EXPECT_EQ(slam->frameIndex(), frame + 1);
    EXPECT_LT((slam->pose().p_CinW - truth.p_CinW).norm(), 1e-5);
    EXPECT_LT(rotationError(slam->pose().R_CtoW, truth.R_CtoW).norm(), 1e-5);
    const Mat6x6 Pp = slam->poseCovariance();
    for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(Pp(i, i), sigma_p * sigma_p, 1e-9);
        EXPECT_NEAR(Pp(3 + i, 3 + i), sigma_theta * sigma_theta, 1e-7);
    }
    for (int k = 31; k < 120; ++k) {
        sim.step(*slam, k);
    }
    EXPECT_EQ(slam->health(), SlamHealth::kOk);
    EXPECT_FALSE(slam->features().empty());
    const core::CameraPose end = sim.truthInC0(Scalar(119) / opt.fps);
    EXPECT_LT((slam->pose().p_CinW - end.p_CinW).norm(), 0.05);
}

TEST(EkfSlam, RelocaliseRefusesBadInput) {
    const auto cam = test::makeCamera(0, 0, 500);
    auto slam = EkfSlam::create(cam, test::pointSimSlamConfig());
    ASSERT_TRUE(slam.ok());
    core::CameraPose T;
    EXPECT_FALSE(slam->relocalise(1, T, 1, 1)) << "no map yet";
    slam->initialise(0, Vec3(0, 1, 0));
    T.p_CinW = Vec3(std::numeric_limits<Scalar>::quiet_NaN(), 0, 0);
    EXPECT_FALSE(slam->relocalise(1, T, 1, 1));
    EXPECT_TRUE(slam->state().allFinite());
}

}  // namespace
}  // namespace scaled::core::slam
