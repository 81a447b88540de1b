// scale-eval's metrics on series with known answers: the convergence rule,
// error statistics, and the ground-truth scale of a trajectory.

#include <cmath>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "scale_eval.h"

namespace scaled::tools {
namespace {

UpdateRow update(double map, double rel_width, std::optional<double> truth,
                 core::ScaleState state = core::ScaleState::kConverging) {
    UpdateRow u;
    u.scale.map = static_cast<core::Scalar>(map);
    u.scale.rel_width95 = static_cast<core::Scalar>(rel_width);
    u.scale.state = state;
    u.scale_true = truth;
    u.scale_true_window = truth ? std::optional<double>(*truth * 1.1) : std::nullopt;
    return u;
}

TEST(ScaleEvalMetrics, ConvergedAtIsTheFirstUpdateAfterWhichItStaysNarrow) {
    // Narrow at 1, wide again at 2, narrow from 3 on: convergence is update 3.
    const std::vector<UpdateRow> u = {update(1, 0.5, 1), update(1, 0.05, 1), update(1, 0.2, 1),
                                      update(1, 0.09, 1), update(1, 0.08, 1)};
    EXPECT_EQ(convergedAt(u, 0.1), std::optional<std::size_t>(3));
    EXPECT_EQ(convergedAt(u, 0.6), std::optional<std::size_t>(0));
    EXPECT_FALSE(convergedAt(u, 0.08).has_value());  // the last is not narrower than 0.08
    EXPECT_FALSE(convergedAt({}, 0.1).has_value());
    // An update without data never counts as converged.
    const std::vector<UpdateRow> none = {update(1, 0, 1, core::ScaleState::kNoData)};
    EXPECT_FALSE(convergedAt(none, 0.1).has_value());
}

TEST(ScaleEvalMetrics, RelativeErrorsFromAnUpdateOn) {
    const std::vector<UpdateRow> u = {update(2.0, 0.5, 1.0), update(1.02, 0.05, 1.0),
                                      update(0.96, 0.05, 1.0), update(1.0, 0.05, std::nullopt),
                                      update(1.01, 0.05, 1.0)};
    const ErrorStats e = relativeErrors(u, 1, false);
    EXPECT_EQ(e.count, 3);  // the update without truth is left out
    ASSERT_TRUE(e.median && e.std && e.max);
    EXPECT_NEAR(*e.median, 0.02, 1e-12);
    EXPECT_NEAR(*e.max, 0.04, 1e-12);
    EXPECT_NEAR(
        *e.std,
        std::sqrt(((0.02 - 0.07 / 3) * (0.02 - 0.07 / 3) + (0.04 - 0.07 / 3) * (0.04 - 0.07 / 3) +
                   (0.01 - 0.07 / 3) * (0.01 - 0.07 / 3)) /
                  3),
        1e-12);
    // Against the window truth (1.1 here): |1.02 / 1.1 - 1| etc.
    const ErrorStats w = relativeErrors(u, 4, true);
    ASSERT_TRUE(w.median);
    EXPECT_NEAR(*w.median, 1 - 1.01 / 1.1, 1e-12);
    EXPECT_FALSE(describe({}).median.has_value());
    EXPECT_NEAR(*describe({3, 1, 2, 10}).median, 2.5, 1e-12);
}

FrameRow frameRow(int epoch, std::optional<double> window, bool full) {
    FrameRow f;
    f.epoch = epoch;
    f.scale_true_window = window;
    f.window_full = full;
    return f;
}

TEST(ScaleEvalMetrics, MapScaleDriftPerEpochAndAgainstTheAverage) {
    // Epoch 0: full windows from 1.0 to 1.2 (range 1.2); the partial window
    // of 0.5 before it counts for nothing. Epoch 1 starts a new map at 3.0
    // and wanders to 3.3 (range 1.1): the run's range is the larger, 1.2.
    const std::vector<FrameRow> f = {frameRow(0, 0.5, false),        frameRow(0, 1.0, true),
                                     frameRow(0, 1.2, true),         frameRow(0, 1.1, true),
                                     frameRow(1, 3.0, true),         frameRow(1, 3.3, true),
                                     frameRow(1, std::nullopt, true)};
    std::vector<UpdateRow> u = {update(1, 0.5, 1.0), update(1, 0.5, 2.0),
                                update(1, 0.5, std::nullopt)};
    u[1].scale_true_window = 1.7;  // 15% under the average (the others 10% over)
    const MapScaleDrift d = mapScaleDrift(f, u);
    ASSERT_TRUE(d.window_range && d.window_max_dev);
    EXPECT_NEAR(*d.window_range, 1.2, 1e-12);
    EXPECT_NEAR(*d.window_max_dev, 0.15, 1e-12);
    // No full window, no truth: nothing to report.
    const MapScaleDrift none =
        mapScaleDrift(std::vector<FrameRow>{frameRow(0, 1.0, false)}, std::vector<UpdateRow>{});
    EXPECT_FALSE(none.window_range.has_value());
    EXPECT_FALSE(none.window_max_dev.has_value());
}

TEST(ScaleEvalMetrics, GeometryUnitOverTheTruthsWindowAndAgainstTheMotion) {
    // Window of 4 frames. Epoch 0: the depth images say 1.0 per unit on
    // frames 0-3 and 1.2 from frame 4 on, while the motion's window truth is
    // 1.0 throughout: the geometry's window medians go 1.0, 1.1 (frames 2-5:
    // 1.0, 1.0, 1.2, 1.2), 1.2 (range 1.2) and the motion over them 1.0 to
    // 1/1.2 (range 1.2). A frame without a depth reading counts for nothing;
    // a window with fewer than half its frames read is skipped. Epoch 1 is a
    // new map: its windows do not reach back into epoch 0.
    std::vector<FrameRow> f;
    const double geo[] = {1.0, 1.0, 1.0, 1.0, 1.2, 1.2, 1.2, 1.2};
    for (int k = 0; k < 8; ++k) {
        FrameRow r = frameRow(0, 1.0, k >= 3);
        r.map_unit_depth = geo[k];
        f.push_back(r);
    }
    f[6].map_unit_depth.reset();
    for (int k = 0; k < 4; ++k) {
        FrameRow r = frameRow(1, 2.0, true);  // full at once: only its own frames count
        r.map_unit_depth = k < 1 ? std::optional<double>(4.0) : std::nullopt;
        f.push_back(r);
    }
    const GeometryUnit g = geometryUnit(f, 4);
    EXPECT_EQ(g.frames, 8);
    ASSERT_TRUE(g.median && g.window_range && g.motion_over_geometry_range);
    EXPECT_NEAR(*g.median, 1.1, 1e-12);  // 1.0 x4, 1.2 x3 and 4.0: between 1.0 and 1.2
    EXPECT_NEAR(*g.window_range, 1.2, 1e-12);
    EXPECT_NEAR(*g.motion_over_geometry_range, 1.2, 1e-12);
    // Without depth readings nothing is reported.
    const GeometryUnit none = geometryUnit(std::vector<FrameRow>{frameRow(0, 1.0, true)}, 4);
    EXPECT_EQ(none.frames, 0);
    EXPECT_FALSE(none.median || none.window_range || none.motion_over_geometry_range);
}

// A straight-ish walk at 0.5 m/s (30 frames a second) seen by a map at half
// the scale; the estimate served at each frame is `served` (0: none yet).
std::vector<FrameRow> walk(int frames, double served, int epoch_break = -1,
                           double rel_width95 = 0.2) {
    std::vector<FrameRow> rows;
    for (int k = 0; k < frames; ++k) {
        FrameRow f;
        f.frame = k;
        f.t_s = k / 30.0;
        f.epoch = epoch_break >= 0 && k >= epoch_break ? 1 : 0;
        f.has_position = true;
        const double t = f.t_s;
        f.p_gt = core::Vec3(static_cast<core::Scalar>(0.5 * t),
                            static_cast<core::Scalar>(0.1 * std::sin(t)), 0);
        f.p_map = f.p_gt / 2;
        if (served > 0) {
            f.scale.state = core::ScaleState::kConverging;
            f.scale.map = static_cast<core::Scalar>(served);
            f.scale.ci95.lo = static_cast<core::Scalar>(served * (1 - rel_width95 / 2));
            f.scale.ci95.hi = static_cast<core::Scalar>(served * (1 + rel_width95 / 2));
        }
        rows.push_back(f);
    }
    return rows;
}

TEST(ScaleEvalMetrics, MetricTrajectoryUsesTheServedScaleNotAFittedOne) {
    const daemon::PipelineConfig defaults = daemon::defaultPipelineConfig();
    // Served exactly: no error at all.
    const MetricTrajectory exact = metricTrajectory(walk(300, 2.0), 0.05, defaults);
    EXPECT_EQ(exact.frames, 300);
    ASSERT_TRUE(exact.ate_m && exact.distance_1s.median_rel && exact.distance_5s.median_rel);
    EXPECT_LT(*exact.ate_m, 1e-5);
    EXPECT_LT(*exact.distance_1s.median_rel, 1e-5);
    // 10% too large: every displacement 10% long, and an ATE no Sim(3) fit
    // would show (only rotation and translation are fitted).
    const MetricTrajectory over = metricTrajectory(walk(300, 2.2), 0.05, defaults);
    ASSERT_TRUE(over.ate_m && over.ate_percent_of_path);
    EXPECT_NEAR(*over.distance_1s.median_rel, 0.1, 1e-4);
    EXPECT_NEAR(*over.distance_5s.median_rel, 0.1, 1e-4);
    EXPECT_EQ(over.distance_1s.pairs, 300 - 30);
    EXPECT_EQ(over.distance_5s.pairs, 300 - 150);
    EXPECT_GT(*over.ate_m, 0.05);  // 10% of a 5 m walk, half of it at the ends
    EXPECT_GT(*over.ate_percent_of_path, 1.0);
    // Nothing served: nothing to report.
    const MetricTrajectory none = metricTrajectory(walk(300, 0), 0.05, defaults);
    EXPECT_EQ(none.frames, 0);
    EXPECT_FALSE(none.ate_m.has_value());
    EXPECT_EQ(none.distance_1s.pairs, 0);
    // A new map at frame 200: no pair spans it, each epoch aligned alone.
    const MetricTrajectory split = metricTrajectory(walk(300, 2.0, 200), 0.05, defaults);
    EXPECT_EQ(split.frames, 300);
    EXPECT_EQ(split.distance_5s.pairs, 200 - 150);  // the second epoch lasts 3.3 s
    EXPECT_EQ(split.distance_1s.pairs, (200 - 30) + (100 - 30));
    // A scale whose 95% interval is wider than itself puts no pose in metres
    // (as the daemon's POSE), unless the configuration allows it.
    const MetricTrajectory loose = metricTrajectory(walk(300, 2.0, -1, 1.5), 0.05, defaults);
    EXPECT_EQ(loose.frames, 0);
    daemon::PipelineConfig lenient = defaults;
    lenient.pose_max_rel_width95 = 2;
    EXPECT_EQ(metricTrajectory(walk(300, 2.0, -1, 1.5), 0.05, lenient).frames, 300);
}

TEST(ScaleEvalMetrics, TruthScaleOfASimilarTrajectory) {
    // The ground truth is the estimate rotated, scaled by 2.5 and shifted.
    std::vector<core::Vec3> est;
    std::vector<core::Vec3> gt;
    const core::Mat3 R =
        Eigen::AngleAxis<core::Scalar>(core::Scalar(0.3), core::Vec3(0, 0, 1)).toRotationMatrix();
    for (int i = 0; i < 50; ++i) {
        const auto t = static_cast<core::Scalar>(i) / 10;
        const core::Vec3 p(std::sin(t), std::cos(2 * t), t / 3);
        est.push_back(p);
        gt.push_back(core::Scalar(2.5) * R * p + core::Vec3(1, 2, 3));
    }
    const auto s = truthScale(est, gt, 0.1);
    ASSERT_TRUE(s.has_value());
    EXPECT_NEAR(*s, 2.5, 1e-9);
    // A ground-truth path shorter than the minimum gives no scale.
    EXPECT_FALSE(truthScale(est, gt, 1000).has_value());
    EXPECT_FALSE(truthScale(std::span(est).first(2), std::span(gt).first(2), 0).has_value());
}

}  // namespace
}  // namespace scaled::tools
