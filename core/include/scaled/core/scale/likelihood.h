#pragma once

// L(d) = sum_m f(d D - H_m; sigma) p_c(H_m), evaluated in the log domain on the
// scale grid. f is a Gaussian density in metres.

#include <cstdint>
#include <span>

#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/scale_grid.h>
#include <scaled/core/scale/vertical_extent.h>

namespace scaled::core {

enum class VarianceModel : std::uint8_t {
    // The paper's convention: sigma^2 = sigma_D^2 D^2, sigma_D from 2 J P J^T.
    kPaper,
    // Error propagation: sigma = d * sqrt(sigma_D_feature^2 + sigma_D_box^2),
    // i.e. the SLAM-unit uncertainty of D (feature covariance through the full
    // geometry, plus box-edge pixel noise) scaled to metres by the candidate d.
    // The likelihood is the density of the measurement D,
    //   p(D | d) = sum_m p_m N(D; H_m / d, sigma_D^2) = d * sum_m p_m f(d D - H_m; d sigma_D),
    // so it carries the factor d (without it every observation pulls d low by
    // about (sigma_D / D)^2).
    kPropagated,
};

struct LikelihoodConfig {
    VarianceModel variance_model = VarianceModel::kPaper;
    // Robust mixture: (1 - w) L(d) + w / outlier_height_range_m. Off by default.
    bool robust = false;
    Scalar outlier_weight = Scalar(0.05);
    Scalar outlier_height_range_m = 5;
    // Partial visibility (beyond the paper): with probability partial_weight the
    // box covers only part of the object (occluded by something in front, e.g.
    // a chair behind a table), and the measured extent d D is then uniform in
    // (0, H). Such an observation bounds d from above instead of fixing it:
    //   L(d) = (1 - w) L_full(d) + w sum_m p_m 1[d D < H_m] / H_m
    // (times d under kPropagated, as L_full). Off by default (the paper); when
    // on, w is the prior's partialProbability() where it gives one (>= 0),
    // else partial_weight.
    bool partial_visibility = false;
    Scalar partial_weight = 0;
    // Lower bound on sigma in metres (keeps very confident features from
    // producing likelihoods narrower than anything they can justify).
    Scalar min_sigma_m = Scalar(0.002);
};

// Writes log L(d_j) for every grid point into log_l (size grid.size()).
// Returns false (and writes nothing) when the input cannot give a finite
// likelihood: empty prior, D not positive or not finite.
//
// Besides the model variance, two discretisation terms are added: the prior's
// bin width (w^2/12: a bin stands for an interval of heights) and the grid's
// own resolution ((d D Delta)^2 / 12 with Delta the log-spacing), so that a
// likelihood narrower than a grid bin is never missed between grid points.
bool evaluateLogLikelihood(const VerticalExtent& extent, const HeightPrior& prior,
                           const ScaleGrid& grid, const LikelihoodConfig& config,
                           std::span<Scalar> log_l);

// The mode of a log-likelihood on the grid, refined by a parabola in log d.
Scalar gridMode(const ScaleGrid& grid, std::span<const Scalar> log_values);

}  // namespace scaled::core
