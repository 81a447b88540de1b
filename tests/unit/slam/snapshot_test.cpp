// SlamSnapshot: the SLAM state of a detected frame, for a detection that
// comes back k frames late (issue 4).

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <new>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/scale/scale_estimator.h>
#include <scaled/core/slam/ekf_slam.h>
#include <scaled/core/slam/quaternion.h>
#include <scaled/core/slam/slam_snapshot.h>

#include "allocation_counter.h"
#include "point_slam_sim.h"
#include "scene.h"

namespace scaled::core::slam {
namespace {

using test::PointSimOptions;
using test::PointSlamSim;

constexpr std::string_view kClass = "post";
constexpr Scalar kHeightM = 0.5;

PointSimOptions simOptions() {
    PointSimOptions o;
    o.seed = 7;
    o.fps = 30;
    // Features start at their true depth (2%): SLAM units are metres, so the
    // true scale is d = 1 and the synchronous estimate can be checked.
    o.known_depth_rel_sigma = Scalar(0.02);
    return o;
}

// The point simulation and a filter running on it.
struct Rig {
    PinholeRadialCamera cam = test::makeCamera(0, 0, 500);
    PointSimOptions opt = simOptions();
    PointSlamSim sim{cam, opt};
    EkfSlam slam = EkfSlam::create(cam, test::pointSimSlamConfig()).value();
    int next_frame = 0;

    Rig() { slam.initialise(sim.timeNs(0), sim.gravityDownC0()); }
    [[nodiscard]] Scalar time(int frame) const { return Scalar(frame) / opt.fps; }
    // Runs frames up to and including `last`.
    void runTo(int last) {
        for (; next_frame <= last; ++next_frame) {
            sim.step(slam, next_frame);
        }
    }
};

ScaleEstimator makeEstimator(const PinholeRadialCamera& cam) {
    PriorTable priors;
    const std::array<Scalar, 1> h{kHeightM};
    const std::array<Scalar, 1> p{1};
    priors.add(HeightPrior::fromHistogram(std::string(kClass), h, p, 0, true).value());
    return ScaleEstimator::create(EstimatorConfig{}, std::move(priors), cam).value();
}

// The detector's answer at a frame: boxes around synthetic "posts", vertical
// segments kHeightM tall through the true positions of tracked features, each
// box the true projection of the post (top and bottom) widened by a few
// pixels. Posts whose box leaves the image or contains another feature's
// projection are skipped (so that every box measures its own post).
std::vector<Detection> detectPosts(const Rig& rig, const SlamSnapshot& snap, int frame,
                                   int max_posts) {
    const CameraPose truth = test::pointSimPose(rig.time(frame));
    const auto w = Scalar(rig.cam.width());
    const auto h = Scalar(rig.cam.height());
    const auto info = snap.featureInfo();
    std::vector<Detection> out;
    for (const SnapshotFeature& f : info) {
        if (static_cast<int>(out.size()) == max_posts) {
            break;
        }
        if (!f.in_view || !f.measured) {
            continue;
        }
        // The feature sits at 30-70% of the post's height, varying by id.
        const Scalar below = kHeightM * (Scalar(0.3) + Scalar(0.1) * Scalar(f.id % 5));
        const Vec3 p = rig.sim.pointOf(f.id);
        const Vec3 bottom = p - below * Vec3::UnitZ();
        const Vec3 top = bottom + kHeightM * Vec3::UnitZ();
        if (!test::projectW(rig.cam, truth, bottom) || !test::projectW(rig.cam, truth, top)) {
            continue;
        }
        const BoundingBox b = test::boxOf(rig.cam, truth, {bottom, top}, 6);
        if (b.x_min_px < 10 || b.y_min_px < 10 || b.x_max_px > w - 10 || b.y_max_px > h - 10) {
            continue;
        }
        const bool crowded = std::any_of(info.begin(), info.end(), [&](const SnapshotFeature& o) {
            return o.id != f.id && o.px.x() > b.x_min_px - 5 && o.px.x() < b.x_max_px + 5 &&
                   o.px.y() > b.y_min_px - 5 && o.px.y() < b.y_max_px + 5;
        });
        if (!crowded) {
            out.push_back(Detection{b, kClass, 1});
        }
    }
    return out;
}

// ---------------------------------------------------------------------------
// The scenario: detections every few frames, answered synchronously (A),
// k frames late with the snapshot of the detected frame (B_k), and k frames
// late against the filter's live state (C_k, the naive alternative).

constexpr std::array<int, 3> kDelays{1, 3, 10};
constexpr int kFirstDetection = 30;
constexpr int kDetectionEvery = 6;
constexpr int kLastDetection = 120;
constexpr int kPostsPerFrame = 3;

struct Posterior {
    ScaleSummary summary;
    std::vector<Scalar> log_density;
    int observations = 0;
    int rejected = 0;
};

Posterior posteriorOf(const ScaleEstimator& est, int rejected) {
    Posterior p;
    p.summary = est.summary();
    const auto ld = est.posterior().logDensity();
    p.log_density.assign(ld.begin(), ld.end());
    p.observations = est.posterior().observations();
    p.rejected = rejected;
    return p;
}

struct ScenarioResult {
    Posterior sync;
    std::array<Posterior, kDelays.size()> delayed;
    std::array<Posterior, kDelays.size()> naive;
    Scalar grid_delta = 0;  // log-spacing of the scale grid
    int detection_frames = 0;
    int detections = 0;
};

int rejections(const UpdateStats& st) {
    int n = 0;
    for (const int r : st.rejected) {
        n += r;
    }
    return n;
}

ScenarioResult runScenario() {
    Rig rig;
    ScaleEstimator sync = makeEstimator(rig.cam);
    std::vector<ScaleEstimator> delayed;
    std::vector<ScaleEstimator> naive;
    for (std::size_t i = 0; i < kDelays.size(); ++i) {
        delayed.push_back(makeEstimator(rig.cam));
        naive.push_back(makeEstimator(rig.cam));
    }
    std::array<int, kDelays.size()> delayed_rejected{};
    std::array<int, kDelays.size()> naive_rejected{};
    int sync_rejected = 0;

    struct Pending {
        SlamSnapshot snap;
        std::vector<Detection> detections;
    };
    std::map<int, Pending> pending;  // by detected frame
    SlamSnapshot live = SlamSnapshot::create(rig.slam.config().max_features).value();
    const int max_delay = *std::max_element(kDelays.begin(), kDelays.end());
    ScenarioResult res;
    for (int f = 0; f <= kLastDetection + max_delay; ++f) {
        rig.runTo(f);
        if (f >= kFirstDetection && f <= kLastDetection &&
            (f - kFirstDetection) % kDetectionEvery == 0) {
            Pending p{SlamSnapshot::create(rig.slam.config().max_features).value(), {}};
            const CaptureReport rep = p.snap.capture(rig.slam, f, 1);
            EXPECT_EQ(rep.status, CaptureStatus::kOk);
            p.detections = detectPosts(rig, p.snap, f, kPostsPerFrame);
            sync_rejected += rejections(sync.update(p.snap.view(), p.detections));
            ++res.detection_frames;
            res.detections += static_cast<int>(p.detections.size());
            pending.emplace(f, std::move(p));
        }
        for (std::size_t i = 0; i < kDelays.size(); ++i) {
            const auto it = pending.find(f - kDelays[i]);
            if (it == pending.end()) {
                continue;
            }
            const std::vector<Detection>& boxes = it->second.detections;
            delayed_rejected[i] += rejections(delayed[i].update(it->second.snap.view(), boxes));
            (void)live.capture(rig.slam, f, 1);
            naive_rejected[i] += rejections(naive[i].update(live.view(), boxes));
        }
    }
    res.sync = posteriorOf(sync, sync_rejected);
    for (std::size_t i = 0; i < kDelays.size(); ++i) {
        res.delayed[i] = posteriorOf(delayed[i], delayed_rejected[i]);
        res.naive[i] = posteriorOf(naive[i], naive_rejected[i]);
    }
    res.grid_delta = sync.posterior().grid().delta();
    return res;
}

const ScenarioResult& scenario() {
    static const ScenarioResult r = runScenario();
    return r;
}

TEST(SlamSnapshot, DelayedUpdateWithTheSnapshotEqualsTheSynchronousOne) {
    const ScenarioResult& r = scenario();
    ASSERT_GE(r.detection_frames, 10);
    ASSERT_GE(r.detections, 20);
    const ScaleSummary& a = r.sync.summary;
    ASSERT_GE(r.sync.observations, 20);
    // The scenario is what it claims: SLAM units are about metres (d = 1).
    EXPECT_NEAR(a.map, 1, 0.05);
    EXPECT_LT(a.ci95.lo, a.map);
    EXPECT_GT(a.ci95.hi, a.map);
    std::printf("sync: %d detections on %d frames, %d observations, MAP %.5f, 95%% [%.5f, %.5f]\n",
                r.detections, r.detection_frames, r.sync.observations, a.map, a.ci95.lo, a.ci95.hi);
    for (std::size_t i = 0; i < kDelays.size(); ++i) {
        SCOPED_TRACE(testing::Message() << "delay k = " << kDelays[i]);
        const Posterior& b = r.delayed[i];
        EXPECT_EQ(b.observations, r.sync.observations);
        EXPECT_EQ(b.rejected, r.sync.rejected);
        EXPECT_NEAR(b.summary.map, a.map, 1e-9);
        EXPECT_NEAR(b.summary.ci95.lo, a.ci95.lo, 1e-9);
        EXPECT_NEAR(b.summary.ci95.hi, a.ci95.hi, 1e-9);
        ASSERT_EQ(b.log_density.size(), r.sync.log_density.size());
        Scalar max_diff = 0;
        for (std::size_t j = 0; j < b.log_density.size(); ++j) {
            max_diff = std::max(max_diff, std::abs(b.log_density[j] - r.sync.log_density[j]));
        }
        EXPECT_LE(max_diff, 1e-9);
    }
}

TEST(SlamSnapshot, TheLiveStateWithLateBoxesGivesADifferentPosterior) {
    // The naive alternative: the boxes of frame j against the filter's state at
    // j + k. The camera has moved, so features leave the boxes they belong to
    // and the rest are measured through the wrong rays.
    const ScenarioResult& r = scenario();
    const ScaleSummary& a = r.sync.summary;
    for (std::size_t i = 0; i < kDelays.size(); ++i) {
        const Posterior& c = r.naive[i];
        const Scalar bins = std::abs(std::log(c.summary.map / a.map)) / r.grid_delta;
        Scalar max_diff = 0;
        for (std::size_t j = 0; j < c.log_density.size(); ++j) {
            max_diff = std::max(max_diff, std::abs(c.log_density[j] - r.sync.log_density[j]));
        }
        std::printf(
            "naive k=%2d: %d observations (sync %d), %d rejected, MAP %.5f (%.1f bins from sync), "
            "max |log p diff| %.3g\n",
            kDelays[i], c.observations, r.sync.observations, c.rejected, c.summary.map, bins,
            max_diff);
        if (kDelays[i] == 10) {
            // 10 frames (1/3 s) late: most observations are lost, and what is
            // left puts the MAP outside the synchronous 95% interval.
            EXPECT_LE(2 * c.observations, r.sync.observations);
            EXPECT_TRUE(c.summary.map < a.ci95.lo || c.summary.map > a.ci95.hi)
                << c.summary.map << " in [" << a.ci95.lo << ", " << a.ci95.hi << "]";
            EXPECT_GT(max_diff, 1);
        }
    }
}

// ---------------------------------------------------------------------------
// The snapshot's content and its capacity contract.

void expectSameAsFilter(const SlamSnapshot& snap, const EkfSlam& slam) {
    EXPECT_EQ(snap.timestampNs(), slam.timestampNs());
    EXPECT_EQ(snap.slamFrameIndex(), slam.frameIndex());
    EXPECT_EQ(snap.health(), slam.health());
    EXPECT_EQ(snap.pose().R_CtoW, slam.pose().R_CtoW);
    EXPECT_EQ(snap.pose().p_CinW, slam.pose().p_CinW);
    EXPECT_EQ(snap.poseCovariance(), slam.poseCovariance());
    EXPECT_EQ(snap.upW(), slam.upW());
    std::vector<MapPoint> pts;
    slam.mapPoints(pts);
    ASSERT_EQ(snap.size(), static_cast<int>(pts.size()));
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const MapFeature& f = snap.features()[i];
        const SnapshotFeature& info = snap.featureInfo()[i];
        EXPECT_EQ(info.id, pts[i].id);
        EXPECT_EQ(info.kind, pts[i].kind);
        EXPECT_EQ(info.in_view, pts[i].in_view);
        EXPECT_EQ(info.measured, pts[i].measured);
        EXPECT_LE((info.px - pts[i].px).norm(), 1e-12);
        EXPECT_LE((f.p_FinW - pts[i].p_FinW).norm(), 1e-12);
        EXPECT_LE((f.P_FinW - pts[i].P_FinW).norm(), 1e-12);
    }
}

TEST(SlamSnapshot, CarriesTheFrameIdEpochAndTheFiltersState) {
    Rig rig;
    rig.runTo(45);
    // With known depths the tracked features are all XYZ by now: add an
    // inverse-depth one, and one at negative inverse depth (left out).
    rig.slam.makeRoom(2);
    const std::uint64_t id_inv = rig.slam.addFeature(Vec2(320, 240));
    const std::uint64_t id_neg = rig.slam.addFeature(Vec2(200, 240), Scalar(-0.1), Scalar(0.5));
    ASSERT_NE(id_inv, 0U);
    ASSERT_NE(id_neg, 0U);
    auto snap = SlamSnapshot::create(rig.slam.config().max_features);
    ASSERT_TRUE(snap.ok()) << snap.error().message;
    const CaptureReport rep = snap->capture(rig.slam, 1234, 7);
    EXPECT_EQ(rep.status, CaptureStatus::kOk);
    EXPECT_EQ(rep.dropped, 0);
    EXPECT_EQ(rep.captured, snap->size());
    EXPECT_TRUE(snap->valid());
    EXPECT_EQ(snap->frameId(), 1234);
    EXPECT_EQ(snap->epoch(), 7U);
    EXPECT_EQ(snap->slamFrameIndex(), 45);
    EXPECT_GT(snap->size(), 15);
    expectSameAsFilter(*snap, rig.slam);
    // The position-only accessor agrees with the map point, feature by feature.
    int inverse_depth = 0;
    for (int slot = 0; slot < static_cast<int>(rig.slam.features().size()); ++slot) {
        MapPoint m;
        Vec3 p = Vec3::Constant(Scalar(-7));
        const bool finite = rig.slam.mapPoint(slot, m);
        EXPECT_EQ(rig.slam.pointInWorld(slot, p), finite) << slot;
        if (finite) {
            EXPECT_EQ(p, m.p_FinW) << slot;
        }
        inverse_depth +=
            rig.slam.features()[static_cast<std::size_t>(slot)].kind == FeatureKind::kInverseDepth
                ? 1
                : 0;
    }
    EXPECT_GE(inverse_depth, 2);
    const auto info = snap->featureInfo();
    const auto has = [&](std::uint64_t id) {
        return std::any_of(info.begin(), info.end(),
                           [&](const SnapshotFeature& f) { return f.id == id; });
    };
    EXPECT_TRUE(has(id_inv));
    EXPECT_FALSE(has(id_neg));
    EXPECT_EQ(snap->size() + 1, static_cast<int>(rig.slam.features().size()));
    EXPECT_EQ(info.back().kind, FeatureKind::kInverseDepth);
    EXPECT_EQ(info.front().kind, FeatureKind::kXyz);

    // view() is what ScaleEstimator::update takes, over the snapshot's storage.
    const FrameSnapshot v = snap->view();
    EXPECT_EQ(v.features.data(), snap->features().data());
    EXPECT_EQ(v.features.size(), snap->features().size());
    EXPECT_EQ(v.pose.p_CinW, snap->pose().p_CinW);
    EXPECT_EQ(v.up_W, snap->upW());

    // A re-initialised map: the caller bumps the epoch.
    rig.slam.initialise(rig.sim.timeNs(46), rig.sim.gravityDownC0());
    EXPECT_EQ(snap->capture(rig.slam, 1235, 8).status, CaptureStatus::kOk);
    EXPECT_EQ(snap->epoch(), 8U);
    EXPECT_EQ(snap->frameId(), 1235);
    EXPECT_EQ(snap->size(), 0);
}

TEST(SlamSnapshot, CarriedIntoTheServedFrameKeepsEveryProjection) {
    Rig rig;
    rig.runTo(45);
    auto plain = SlamSnapshot::create(rig.slam.config().max_features);
    auto carried = SlamSnapshot::create(rig.slam.config().max_features);
    ASSERT_TRUE(plain.ok() && carried.ok());
    (void)plain->capture(rig.slam, 1, 1);
    Sim3 T;
    T.scale = Scalar(1.3);
    T.R = rotationFromQuat(quatFromRotationVector(Vec3(0.05, -0.2, 0.1)));
    T.t = Vec3(0.4, -1.0, 2.0);
    EXPECT_FALSE(T.isIdentity());
    EXPECT_EQ(carried->capture(rig.slam, 1, 1, T).status, CaptureStatus::kOk);
    ASSERT_EQ(carried->size(), plain->size());
    ASSERT_GT(plain->size(), 15);
    // Rounding of the float build's core (and of double's) in relative terms.
    const Scalar tol = 100 * std::numeric_limits<Scalar>::epsilon();
    // A similarity of the world moves the camera with it: every point keeps
    // its direction from the camera (its pixel), its depth grows by scale.
    const CameraPose& a = plain->pose();
    const CameraPose& b = carried->pose();
    for (std::size_t i = 0; i < plain->features().size(); ++i) {
        const MapFeature& fa = plain->features()[i];
        const MapFeature& fb = carried->features()[i];
        const Vec3 p_a = a.R_CtoW.transpose() * (fa.p_FinW - a.p_CinW);
        const Vec3 p_b = b.R_CtoW.transpose() * (fb.p_FinW - b.p_CinW);
        EXPECT_LT((p_b - T.scale * p_a).norm(), tol * (1 + p_a.norm())) << i;
        const Scalar trace_a = fa.P_FinW.trace();
        EXPECT_NEAR(fb.P_FinW.trace(), T.scale * T.scale * trace_a, tol * trace_a) << i;
    }
    EXPECT_LT((carried->upW() - T.R * plain->upW()).norm(), tol);
    // Position variance grows by scale^2; the camera-frame attitude's is kept.
    const Mat6x6& Pa = plain->poseCovariance();
    const Mat6x6& Pb = carried->poseCovariance();
    const Scalar pos_a = Pa.topLeftCorner<3, 3>().trace();
    const Scalar pos_b = Pb.topLeftCorner<3, 3>().trace();
    EXPECT_NEAR(pos_b, T.scale * T.scale * pos_a, tol * pos_a);
    const Mat3 att_a = Pa.bottomRightCorner<3, 3>();
    const Mat3 att_b = Pb.bottomRightCorner<3, 3>();
    EXPECT_EQ(att_b, att_a);
    EXPECT_LT((Pb - Pb.transpose()).norm(), tol * Pb.norm());
    // The view the estimator gets is the carried one.
    EXPECT_EQ(carried->view().pose.p_CinW, b.p_CinW);
}

TEST(SlamSnapshot, DoesNotAliasTheFilter) {
    Rig rig;
    rig.runTo(40);
    SlamSnapshot snap = SlamSnapshot::create(rig.slam.config().max_features).value();
    snap.capture(rig.slam, 40, 1);
    const SlamSnapshot copy = snap;  // deep copy of the captured values
    std::vector<MapPoint> before;
    rig.slam.mapPoints(before);
    rig.runTo(50);
    std::vector<MapPoint> after;
    rig.slam.mapPoints(after);
    // The filter moved on: the camera and the shared features changed...
    EXPECT_GT((rig.slam.pose().p_CinW - copy.pose().p_CinW).norm(), 1e-3);
    int shared = 0;
    Scalar moved = 0;
    for (const MapPoint& a : after) {
        for (const MapPoint& b : before) {
            if (a.id == b.id) {
                ++shared;
                moved = std::max(moved, (a.p_FinW - b.p_FinW).norm());
            }
        }
    }
    EXPECT_GT(shared, 10);
    EXPECT_GT(moved, 1e-4);
    // ...the snapshot did not.
    ASSERT_EQ(snap.size(), copy.size());
    EXPECT_EQ(snap.pose().p_CinW, copy.pose().p_CinW);
    EXPECT_EQ(snap.poseCovariance(), copy.poseCovariance());
    EXPECT_EQ(snap.slamFrameIndex(), 40);
    for (int i = 0; i < snap.size(); ++i) {
        const auto u = static_cast<std::size_t>(i);
        EXPECT_EQ(snap.featureInfo()[u].id, before[u].id);
        EXPECT_EQ(snap.features()[u].p_FinW, copy.features()[u].p_FinW);
        EXPECT_EQ(snap.features()[u].P_FinW, copy.features()[u].P_FinW);
    }
}

TEST(SlamSnapshot, CapturesWithoutAllocatingAfterReserve) {
    Rig rig;
    rig.runTo(5);
    SlamSnapshot snap;
    ASSERT_TRUE(snap.reserve(rig.slam.config().max_features).ok());
    EXPECT_EQ(snap.capacity(), rig.slam.config().max_features);
    snap.capture(rig.slam, 5, 1);  // the buffers exist before the first capture
    const MapFeature* features = snap.features().data();
    const SnapshotFeature* info = snap.featureInfo().data();
    std::int64_t allocations = 0;
    int max_size = 0;
    for (int f = 6; f <= 80; ++f) {
        rig.runTo(f);
        const std::int64_t n0 = test::allocationCount();
        const CaptureReport rep = snap.capture(rig.slam, f, 1);
        allocations += test::allocationCount() - n0;
        ASSERT_EQ(rep.status, CaptureStatus::kOk);
        ASSERT_EQ(snap.features().data(), features);
        ASSERT_EQ(snap.featureInfo().data(), info);
        ASSERT_EQ(snap.view().features.data(), features);
        max_size = std::max(max_size, snap.size());
    }
    EXPECT_EQ(allocations, 0);
    EXPECT_EQ(snap.capacity(), rig.slam.config().max_features);
    EXPECT_GT(max_size, 20);
    // The counter does count: a copy allocates.
    const std::int64_t n0 = test::allocationCount();
    const SlamSnapshot copy = snap;
    EXPECT_GT(test::allocationCount() - n0, 0);
    EXPECT_EQ(copy.size(), snap.size());
}

TEST(SlamSnapshot, TruncatesToCapacityAndReportsTheRest) {
    Rig rig;
    rig.runTo(30);
    std::vector<MapPoint> pts;
    rig.slam.mapPoints(pts);
    ASSERT_GT(pts.size(), 10U);
    SlamSnapshot snap = SlamSnapshot::create(8).value();
    const MapFeature* features = snap.features().data();
    const std::int64_t n0 = test::allocationCount();
    const CaptureReport rep = snap.capture(rig.slam, 30, 3);
    EXPECT_EQ(test::allocationCount() - n0, 0);
    EXPECT_EQ(rep.status, CaptureStatus::kTruncated);
    EXPECT_STREQ(toString(rep.status), "truncated");
    EXPECT_EQ(rep.captured, 8);
    EXPECT_EQ(rep.dropped, static_cast<int>(pts.size()) - 8);
    EXPECT_EQ(snap.dropped(), rep.dropped);
    EXPECT_EQ(snap.size(), 8);
    EXPECT_EQ(snap.features().data(), features);
    EXPECT_TRUE(snap.valid());
    // The oldest features, in the filter's order, with their full geometry.
    for (std::size_t i = 0; i < 8; ++i) {
        EXPECT_EQ(snap.featureInfo()[i].id, pts[i].id);
        EXPECT_EQ(snap.features()[i].p_FinW, pts[i].p_FinW);
    }
    // Capacity 0 is allowed: everything is dropped.
    SlamSnapshot none;
    const CaptureReport rep0 = none.capture(rig.slam, 30, 3);
    EXPECT_EQ(rep0.status, CaptureStatus::kTruncated);
    EXPECT_EQ(rep0.dropped, static_cast<int>(pts.size()));
    EXPECT_EQ(none.size(), 0);
}

TEST(SlamSnapshot, AnUninitialisedFilterGivesAnEmptySnapshot) {
    const PinholeRadialCamera cam = test::makeCamera(0, 0, 500);
    const EkfSlam slam = EkfSlam::create(cam, test::pointSimSlamConfig()).value();
    SlamSnapshot snap = SlamSnapshot::create(16).value();
    const CaptureReport rep = snap.capture(slam, 5, 2);
    EXPECT_EQ(rep.status, CaptureStatus::kUninitialised);
    EXPECT_EQ(rep.captured, 0);
    EXPECT_FALSE(snap.valid());
    EXPECT_EQ(snap.health(), SlamHealth::kUninitialised);
    EXPECT_EQ(snap.frameId(), 5);
    EXPECT_EQ(snap.epoch(), 2U);
    EXPECT_EQ(snap.size(), 0);
    EXPECT_TRUE(snap.view().features.empty());
    // Harmless to the estimator: no observation.
    ScaleEstimator est = makeEstimator(cam);
    const std::array<Detection, 1> dets{Detection{BoundingBox{100, 100, 200, 300}, kClass, 1}};
    EXPECT_EQ(est.update(snap.view(), dets).observations, 0);
    EXPECT_EQ(est.summary().state, ScaleState::kNoData);
}

TEST(SlamSnapshot, ReserveRejectsBadCapacities) {
    SlamSnapshot snap;
    const auto r = snap.reserve(-1);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(r.error().message.find("max_features"), std::string::npos);
    EXPECT_FALSE(SlamSnapshot::create(SlamSnapshot::kMaxCapacity + 1).ok());
    EXPECT_TRUE(SlamSnapshot::create(0).ok());
}

TEST(SlamSnapshot, SwapHandsOverWithoutCopying) {
    // The hand-over between the tracking and the detection side: swap.
    Rig rig;
    rig.runTo(20);
    SlamSnapshot a = SlamSnapshot::create(60).value();
    SlamSnapshot b = SlamSnapshot::create(60).value();
    a.capture(rig.slam, 20, 1);
    rig.runTo(21);
    b.capture(rig.slam, 21, 1);
    const MapFeature* pa = a.features().data();
    const MapFeature* pb = b.features().data();
    const int na = a.size();
    const std::int64_t n0 = test::allocationCount();
    std::swap(a, b);
    EXPECT_EQ(test::allocationCount() - n0, 0);
    EXPECT_EQ(a.frameId(), 21);
    EXPECT_EQ(b.frameId(), 20);
    EXPECT_EQ(a.features().data(), pb);
    EXPECT_EQ(b.features().data(), pa);
    EXPECT_EQ(b.view().features.data(), pa);
    EXPECT_EQ(b.size(), na);
    EXPECT_EQ(a.capacity(), 60);
    EXPECT_EQ(b.capacity(), 60);
    static_assert(std::is_nothrow_move_constructible_v<SlamSnapshot>);
    static_assert(std::is_nothrow_move_assignable_v<SlamSnapshot>);
}

}  // namespace
}  // namespace scaled::core::slam
