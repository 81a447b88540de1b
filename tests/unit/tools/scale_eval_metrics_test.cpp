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
