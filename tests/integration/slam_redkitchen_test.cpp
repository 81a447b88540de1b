// The tracker on real data: 7-Scenes redkitchen, 600 frames, 4.8 m of
// handheld motion. The figures are in docs/accuracy.md; this test holds the
// issue's bounds. Skips when ../shared is absent.

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "shared_data.h"
#include "slam_run.h"

namespace scaled::tools {
namespace {

TEST(SlamRedkitchen, TracksEveryFrameWithSmallErrorAndDrift) {
    SCALED_REQUIRE_DATASET(dir, "redkitchen");
    auto source = drivers::openDataset(dir);
    ASSERT_TRUE(source.ok()) << source.error().message;
    auto camera = core::PinholeRadialCamera::create((*source)->info().intrinsics);
    ASSERT_TRUE(camera.ok());
    SlamRunOptions opt;  // the defaults slam-run uses
    const auto r = runSlam(**source, *camera, opt);
    ASSERT_TRUE(r.ok()) << r.error().message;
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

}  // namespace
}  // namespace scaled::tools
