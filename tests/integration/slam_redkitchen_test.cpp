// The tracker on real data: 7-Scenes redkitchen, 600 frames, 4.8 m of
// handheld motion. The figures are in docs/accuracy.md; this test holds the
// issue's bounds. Skips when ../shared is absent.

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <gtest/gtest.h>

#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/vision/mono_tracker.h>

#include "shared_data.h"
#include "slam_run.h"

namespace scaled::tools {
namespace {

// slam-run's library over a shared dataset (redkitchen, or KITTI 00 below)
// with these options.
core::Result<SlamRunResult> runDataset(const std::filesystem::path& dir,
                                       const SlamRunOptions& opt) {
    auto source = drivers::dataset::openDataset(dir);
    if (!source) {
        return source.error();
    }
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    if (!camera) {
        return camera.error();
    }
    return runSlam(**source, *camera, opt);
}

TEST(SlamRedkitchen, TracksEveryFrameWithSmallErrorAndDrift) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    SlamRunOptions opt;  // the defaults slam-run uses
    // The first frame with a feature converted to XYZ (its depth converged):
    // none in the map's first second, then some (docs/slam.md: 2-4 s in).
    std::optional<std::size_t> first_xyz_frame;
    bool counts_consistent = true;
    opt.progress = [&](std::size_t done, std::size_t, const drivers::vision::TrackStats& s) {
        counts_consistent = counts_consistent && s.xyz_features <= s.features;
        if (!first_xyz_frame && s.xyz_features > 0) {
            first_xyz_frame = done - 1;
        }
    };
    const auto r = runDataset(dir, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_TRUE(counts_consistent);
    ASSERT_TRUE(first_xyz_frame.has_value()) << "no feature's depth converged";
    EXPECT_GE(*first_xyz_frame, 30U);
    EXPECT_LE(*first_xyz_frame, 150U);
    std::printf(
        "redkitchen: %zu/%zu tracked, %d re-init, ATE %.4f m of %.3f m (%.2f%%), "
        "scale %.4f, drift %.3f, %.1f measured, %.2f ms/frame\n",
        r->tracked_frames, r->frames, r->reinitialisations, r->ate_rmse_m, r->path_length_m,
        100 * r->ate_rmse_m / r->path_length_m, r->scale_to_gt, r->scale_drift_thirds,
        r->mean_features_measured, r->ms_per_frame);
    EXPECT_EQ(r->frames, 600U);
    EXPECT_EQ(r->tracked_frames, 600U);
    EXPECT_EQ(r->reinitialisations, 0);
    ASSERT_TRUE(r->has_gt);
    EXPECT_NEAR(r->path_length_m, 4.8, 0.1);
    EXPECT_LE(r->ate_rmse_m, 0.02 * r->path_length_m);
    EXPECT_LT(std::abs(r->scale_drift_thirds - 1), 0.10);
}

// One map over the run, the camera found in it again once: no new map, one
// trajectory in one frame and scale, ATE at most max_ate of the path.
void expectOneMapRelocalisedOnce(const char* run, const SlamRunResult& r, double max_ate) {
    std::printf(
        "redkitchen, %s: %d relocalisation(s) (%d verified, %d features removed) after %d "
        "frames, %d re-init, ATE %.2f%%\n",
        run, r.relocalisations, r.relocalisations_verified, r.relocalise_dropped_features,
        r.relocalising_frames, r.reinitialisations, 100 * r.ate_rmse_m / r.path_length_m);
    EXPECT_EQ(r.reinitialisations, 0);
    EXPECT_EQ(r.relocalisations, 1);
    ASSERT_TRUE(r.has_gt);
    EXPECT_LE(r.ate_rmse_m, max_ate * r.path_length_m);
}

// Issue 21: 20 black frames (a covered lens, 0.67 s) in the middle of the
// sequence. The map is kept and the camera found in it again.
TEST(SlamRedkitchen, ACoveredLensIsRecoveredInTheSameMap) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    SlamRunOptions opt;
    opt.selection.blank.push_back({300, 320});
    const auto r = runDataset(dir, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
    expectOneMapRelocalisedOnce("frames 300-319 black", *r, 0.02);
    // Lost after lost_after_frames black frames; back on the first frames
    // with light (the others of the 20 are black).
    EXPECT_LE(r->relocalising_frames, 15);
}

// Issue 21: the same outage with seed 7. The first PnP pose has 5-6 inliers
// of 12-17 candidates (the guided search around the last well-tracked pose,
// 20 frames old); searched again around that hypothesis the features give a
// pose with enough inliers (tracker.relocalise_verify_px). Without that step
// this seed started a new map 3 s later.
TEST(SlamRedkitchen, AWeakRelocalisationIsVerifiedAndKeepsTheMap) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    SlamRunOptions opt;
    opt.tracker.slam.seed = 7;
    opt.selection.blank.push_back({300, 320});
    const auto r = runDataset(dir, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
    expectOneMapRelocalisedOnce("seed 7, frames 300-319 black", *r, 0.02);
    EXPECT_EQ(r->relocalisations_verified, 1);
    EXPECT_LE(r->relocalising_frames, 15);
}

// Seed 6 without the near-loss rule (tracker.near_loss_ratio = 0; the
// default relocalises this run at frame 48, next test) nearly loses the camera
// at frame 44 and tracks with one or two inliers until it is lost at frame 56,
// adding features all along from poses it was guessing. It is relocalised on
// the next frame; those features are removed (a new map is not started, and
// the scale evidence is kept). The map is not as good as the other seeds'
// (docs/slam.md): ATE 3.6%.
TEST(SlamRedkitchen, FeaturesAddedWhileLostAreRemovedAtRelocalisation) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    SlamRunOptions opt;
    opt.tracker.slam.seed = 6;
    opt.tracker.near_loss_ratio = 0;
    const auto r = runDataset(dir, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
    expectOneMapRelocalisedOnce("seed 6", *r, 0.05);
    EXPECT_GE(r->relocalise_dropped_features, 10);
    EXPECT_GE(r->tracked_frames, 598U);
}

// Issue 19: seeds 5, 6 and 11 nearly lose the camera at frames 44-56 (a shake
// of the handheld camera): for a dozen frames the update accepts 1-8 of 35-40
// features searched in small gates, and the filter, sure of a wrong
// prediction, drags its map along (ATE 2.46, 3.62 and 10.55% without the rule;
// seed 11's map collapses to a third of its unit). Four such frames in a row
// (tracker.near_loss_ratio, near_loss_frames) are a loss: the camera is found
// again in the same map at once. Measured 1.75, 1.79, 1.80% (docs/slam.md
// "Near-losses").
TEST(SlamRedkitchen, ANearLossIsRelocalisedBeforeTheMapFollowsIt) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    for (const std::uint64_t seed : {std::uint64_t{5}, std::uint64_t{6}, std::uint64_t{11}}) {
        SlamRunOptions opt;
        opt.tracker.slam.seed = seed;
        const auto r = runDataset(dir, opt);
        ASSERT_TRUE(r.ok()) << r.error().message;
        ASSERT_TRUE(r->has_gt);
        std::printf("redkitchen seed %llu: %d near-loss frames, %d relocalisation(s), ATE %.2f%%\n",
                    static_cast<unsigned long long>(seed), r->near_loss_frames, r->relocalisations,
                    100 * r->ate_rmse_m / r->path_length_m);
        EXPECT_GE(r->near_loss_frames, 4) << seed;
        EXPECT_GE(r->relocalisations, 1) << seed;
        EXPECT_EQ(r->reinitialisations, 0) << seed;
        EXPECT_GE(r->tracked_frames, 598U) << seed;
        EXPECT_LE(r->ate_rmse_m, 0.02 * r->path_length_m) << seed;
    }
    // The collapse the rule prevents.
    SlamRunOptions off;
    off.tracker.slam.seed = 11;
    off.tracker.near_loss_ratio = 0;
    const auto r = runDataset(dir, off);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->near_loss_frames, 0);
    EXPECT_GT(r->ate_rmse_m, 0.05 * r->path_length_m);
}

// KITTI 00 (160 frames at 10 Hz, a car driving), seed 2, with MonoSLAM's
// velocity noise (sigma_a_reference_hz = 0; the default tracks this run in one
// map): the filter is lost at frame 84 with 4 features of 80 known well enough
// to relocalise against (far features, their depth still open). No pose can
// have the 10 inliers relocalisation asks for, so the map is given up at once
// and a new one started: 158 of 160 frames tracked (129 when it looked for 3 s).
// (The rotation check, tracker.rotation_check_radps, fires on one frame of this
// run and the loss does not happen: 160 tracked, ATE 7.60% against 7.11%; it is
// off here, for the loss this test is about.)
TEST(SlamKitti, AMapWithTooFewKnownFeaturesIsGivenUpAtOnce) {
    SCALED_REQUIRE_DATASET(dir, "kitti00");
    SlamRunOptions opt;
    opt.tracker.slam.seed = 2;
    opt.tracker.slam.motion.reference_hz = 0;
    opt.tracker.rotation_check_radps = 0;
    const auto r = runDataset(dir, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
    std::printf("kitti00 seed 2: %zu/%zu tracked, %d re-init, %d relocalising frames\n",
                r->tracked_frames, r->frames, r->reinitialisations, r->relocalising_frames);
    EXPECT_EQ(r->reinitialisations, 1);
    EXPECT_EQ(r->relocalising_frames, 0);
    EXPECT_GE(r->tracked_frames, 144U);  // issue 21: at least 90% of 160
}

// Issue 21: KITTI 00 within 5% of its path. A car at 10 Hz with the velocity's
// noise as a random walk referenced at 30 Hz (sigma_a_reference_hz, the
// default): seeds 1, 2 and 6, the three beyond 5% with MonoSLAM's noise (7.17,
// 7.11 with a re-init, 5.89%), measured 1.85, 1.48, 0.76% (seeds 1-16: 0.76-2.44%,
// docs/slam.md).
TEST(SlamKitti, TheRandomWalkVelocityNoiseKeepsKittiWithinFivePercent) {
    SCALED_REQUIRE_DATASET(dir, "kitti00");
    for (const std::uint64_t seed : {std::uint64_t{1}, std::uint64_t{2}, std::uint64_t{6}}) {
        SlamRunOptions opt;
        opt.tracker.slam.seed = seed;
        const auto r = runDataset(dir, opt);
        ASSERT_TRUE(r.ok()) << r.error().message;
        ASSERT_TRUE(r->has_gt) << seed;
        std::printf("kitti00 seed %llu: ATE %.2f%% of the path, %d re-inits, %zu/%zu tracked\n",
                    static_cast<unsigned long long>(seed), 100 * r->ate_rmse_m / r->path_length_m,
                    r->reinitialisations, r->tracked_frames, r->frames);
        EXPECT_EQ(r->reinitialisations, 0) << seed;
        EXPECT_LE(r->ate_rmse_m, 0.05 * r->path_length_m) << seed;
        // A car's tenth of a second makes the gates outgrow the pixel budget:
        // frames searched coarse-to-fine, where a small share of accepted
        // matches is normal and never a near-loss (counted there too, two in a row
        // relocalised 9 of seeds 1-16, started 4 new maps and left 3 seeds
        // with 128-129 of 160 frames tracked).
        EXPECT_EQ(r->near_loss_frames, 0) << seed;
    }
}

// Issue 21: every third frame (10 Hz): the motion between frames is three
// times larger; the coarse-to-fine search keeps every frame tracked without a
// loss. The filter's start in motion turns 14 degrees where the camera turned
// 6 (docs/slam.md "A map started in motion"): the start check begins the map
// again (in the same frame and unit, not a new map) at 1.1 s, and the run is
// tracked to its end in it. Seed 8's filter turns away by less than 3 degrees
// a link: only the vertical chained from the map's start catches it (without:
// 13 degrees, ATE 3.66%).
TEST(SlamRedkitchen, TenHertzIsTrackedWithoutALoss) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    for (const std::uint64_t seed : {1U, 8U}) {
        SlamRunOptions opt;
        opt.selection.stride = 3;
        opt.tracker.slam.seed = seed;
        const auto r = runDataset(dir, opt);
        ASSERT_TRUE(r.ok()) << r.error().message;
        std::printf(
            "redkitchen at 10 Hz, seed %llu: %zu/%zu tracked, %d re-init, %zu start "
            "restarts, ATE %.2f%%\n",
            static_cast<unsigned long long>(seed), r->tracked_frames, r->frames,
            r->reinitialisations, r->start_restarts, 100 * r->ate_rmse_m / r->path_length_m);
        EXPECT_EQ(r->frames, 200U);
        EXPECT_EQ(r->tracked_frames, 200U) << "every frame, in one map; seed " << seed;
        EXPECT_EQ(r->reinitialisations, 0) << seed;
        EXPECT_GE(r->start_restarts, 1U) << "the start in motion is caught; seed " << seed;
        EXPECT_LE(r->start_restarts,
                  std::size_t{drivers::vision::TrackerConfig::kStartCheckMaxRestarts});
        ASSERT_TRUE(r->has_gt);
        // The 3%, over the whole run (3.4% and 3.7% before).
        EXPECT_LE(r->ate_rmse_m, 0.03 * r->path_length_m) << seed;
        ASSERT_TRUE(r->attitude_error_deg && r->attitude_error_deg->tilt_max);
        EXPECT_LT(*r->attitude_error_deg->tilt_max, 12.0) << "19-25 and 13 degrees before";
    }
}

}  // namespace
}  // namespace scaled::tools
