#pragma once

// A simulated scene for the scale estimator: objects of known size standing on
// a horizontal support, a camera moving in front of them, EKF-like noisy map
// features on the objects' surfaces, and noisy detection boxes. The SLAM frame
// is the metric world scaled by 1/d_true and moved by a fixed rigid transform,
// so the estimator must recover d_true.
//
// Noise model (all seeded, all documented in docs/method.md):
// - Feature estimate = truth + L_k z_j, with z_j ~ N(0, I) drawn once per
//   feature (the error of an EKF estimate is correlated in time) and
//   P_k = L_k L_k^T = R_ray diag(s_perp^2, s_perp^2, s_par^2) R_ray^T in the
//   frame of the viewing ray at first sight (depth z): s_perp = z sigma_theta
//   with sigma_theta = pixel_sigma / f, and s_par the fusion of the initial
//   inverse-depth prior (z * depth_rel_sigma0) with triangulation over the
//   largest baseline b seen so far (z^2 sigma_theta / b):
//   1/s_par^2 = 1/(z depth_rel_sigma0)^2 + b^2 / (z^2 sigma_theta)^2.
//   The covariance handed to the estimator is P_k (in SLAM units).
// - Boxes: the bounding box of the projected silhouette (rims of cylinders,
//   corners of boxes, through the distorted camera), each edge moved by
//   N(0, box_sigma_px^2); objects not wholly in view are not detected.

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <scaled/core/scale/scale_estimator.h>

namespace scaled::papersim {

using core::Scalar;
using core::Vec3;

enum class Shape : std::uint8_t { kCylinder, kBox };

struct SimObject {
    std::string class_name;
    Shape shape = Shape::kCylinder;
    Vec3 base_W = Vec3::Zero();  // centre of the bottom face, metres, z up
    Scalar height_m = 0;
    Scalar radius_m = 0;  // cylinder
    Scalar width_m = 0;   // box, along world x
    Scalar depth_m = 0;   // box, along world y
};

struct TrajectorySpec {
    Vec3 look_centre_W = Vec3(0, 0, 1);  // the camera faces +y towards this point
    Scalar distance_m = Scalar(1.2);     // from the camera to look_centre along y
    Scalar sweep_x_m = Scalar(0.3);      // lateral amplitude
    Scalar sweep_y_m = Scalar(0.1);      // forward/back amplitude
    Scalar sweep_z_m = Scalar(0.03);     // vertical amplitude
    Scalar roll_deg = 1;                 // amplitude of roll
    Scalar pitch_deg = 2;                // amplitude of pitch around its mean
    Scalar yaw_deg = 2;                  // amplitude of yaw
};

struct NoiseSpec {
    Scalar pixel_sigma = 1;                 // feature angular noise, in pixels
    Scalar depth_rel_sigma0 = Scalar(0.5);  // initial depth std / depth
    Scalar box_sigma_px = 2;                // detection box edge noise
    int features_per_object = 12;
};

struct ExperimentSpec {
    std::string name;
    std::string description;
    std::vector<SimObject> objects;
    core::PriorTable priors;
    TrajectorySpec trajectory;
    NoiseSpec noise;
    core::EstimatorConfig estimator;
    core::CameraIntrinsics camera;
    Scalar d_true = Scalar(0.37);  // metres per SLAM unit
    int frames = 300;
    int detect_every = 10;
    std::uint32_t seed = 1;
};

struct UpdatePoint {
    int frame = 0;
    int observations = 0;
    core::ScaleSummary summary;
    Scalar rel_error = 0;
};

struct ExperimentResult {
    std::string name;
    int updates = 0;               // detection frames that added >= 1 observation
    int converged_at_update = -1;  // first update after which the state stays converged
    Scalar median_rel_error = 0;   // over updates from converged_at_update on
    Scalar std_rel_error = 0;
    Scalar final_rel_error = 0;
    // Fraction of the updates after convergence whose 95% interval holds d_true
    // (calibration: about 0.95 for an honest posterior).
    Scalar ci95_coverage = 0;
    core::ScaleSummary final_summary;
    std::vector<UpdatePoint> series;
    std::array<int, static_cast<std::size_t>(core::ExtentStatus::kCount)> rejected{};
    std::string error;  // non-empty if the experiment could not run
};

ExperimentResult runExperiment(const ExperimentSpec& spec);

}  // namespace scaled::papersim
