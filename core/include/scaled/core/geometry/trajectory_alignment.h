#pragma once

// Sim(3) alignment of an estimated trajectory to ground truth (Umeyama 1991)
// and the error figures the evaluation tools report.

#include <span>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/types.h>

namespace scaled::core {

// gt ~= scale * R * est + t.
struct Sim3Alignment {
    Scalar scale = 1;
    Mat3 R = Mat3::Identity();
    Vec3 t = Vec3::Zero();
    Scalar ate_rmse = 0;  // RMSE of |gt - (scale R est + t)|, ground-truth units
    int count = 0;
};

// Needs at least 3 matched positions that are not all collinear.
// With_scale = false gives the SE(3) alignment (scale fixed to 1).
Result<Sim3Alignment> alignTrajectories(std::span<const Vec3> est, std::span<const Vec3> gt,
                                        bool with_scale = true);

// Length of the polyline through the positions.
Scalar pathLength(std::span<const Vec3> positions);

// Scale drift: the Sim(3) scale fitted on the first third divided by the one
// fitted on the last third (1 = no drift). Needs 9 positions or more.
Result<Scalar> scaleDriftBetweenThirds(std::span<const Vec3> est, std::span<const Vec3> gt);

// Sliding-window scale: the Sim(3) scale fitted on every run of `window`
// consecutive matched positions, so a map whose scale wanders shows it even
// when its ends agree (which the thirds ratio would miss).
struct WindowScales {
    int window = 0;
    // scale[k]: the window of positions k .. k + window - 1 (NaN where that
    // window's alignment is degenerate: the estimate does not move).
    std::vector<Scalar> scale;
    Scalar min = 0;
    Scalar max = 0;
    Scalar range = 0;  // max / min (1 = the scale held); over the valid windows
    int valid = 0;     // windows with a scale
};

// Needs window >= 3 and at least `window` matched positions with one valid
// window among them. Evaluation code: allocates the result.
Result<WindowScales> slidingWindowScales(std::span<const Vec3> est, std::span<const Vec3> gt,
                                         int window);

}  // namespace scaled::core
