#pragma once

// The likelihood of one physical object over the global scale d: one unknown
// height for all of its views (docs/method.md, "Object-level evidence").
//
// An object o of class c has one apparent height h (its real height H, or the
// visible part of it, see ApparentHeightPrior) and one horizontal extent w
// along the line of sight, w ~ N(mu_w, sigma_w^2) from the class. View k
// measures, on the vertical line through the object's anchor, the extent D_k
// in SLAM units (vertical_extent.h), and
//
//     d D_k = h + kappa_k w + d e_k,    e_k ~ N(0, sigma_k^2)     (SLAM units)
//
// with kappa_k = (|tan t_k| + |tan b_k|) / 2 from the elevations t_k, b_k of
// the top and bottom points seen from the camera (known from the geometry,
// whatever d is): the box of a solid object seen from above spans its far top
// edge and its near bottom edge. For fixed d the views are linear-Gaussian in
// (h, w); w is integrated out in closed form, and h against the class prior:
//
//     L_o(d) = sum_m P(h_m) int N(w) prod_k N(D_k; (h_m + kappa_k w) / d, sigma_k^2) dw.
//
// Twenty views of one chair are one chair: the product runs over the views of
// one object, and the height prior enters once per object, so n views can
// never narrow the posterior below what the class spread allows.
//
// Two terms make it robust and honest:
//   - rel_sigma: a relative error common to all views of the object (the
//     anchor's depth uncertainty, a box that is consistently too large for
//     this object): the apparent height is h (1 + r), r ~ N(0, rel_sigma^2).
//   - outlier_weight epsilon: with that probability the object is not what the
//     class says (a wrong class, a poster of a chair) and its views measure an
//     unknown height, log-uniform over the height grid; this term is flat in d,
//     so no single object can push the posterior by more than about
//     log(1 / epsilon) against the others.
// The arithmetic of one object runs in double (sums over views whose terms can
// cancel at extreme d), the result is stored in Scalar.

#include <cstdint>
#include <span>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/core/scale/scale_grid.h>
#include <scaled/core/types.h>

namespace scaled::core {

// One view of an object, measured on the vertical line through its anchor.
struct ObjectViewExtent {
    Scalar D = 0;        // SLAM units
    Scalar kappa = 0;    // (|tan t| + |tan b|) / 2 of the top and bottom points
    Scalar sigma_D = 0;  // random (per-view) error of D, SLAM units
};

// The prior over an object's apparent height h on a log-spaced height grid:
// the class prior, mixed with probability partial_weight with the height of
// a partly hidden object (a uniform fraction of H: sum_m p_m / H_m 1[h < H_m],
// e.g. a chair behind a table shows only its backrest). One visible fraction
// per object, not per view. Built once per class (allocates).
class ApparentHeightPrior {
public:
    struct GridSpec {
        // 192 bins over 5 mm..20 m: 4.4% apart, each standing for an interval
        // (its variance is added), below the 5% common error of an object.
        int bins = 192;
        Scalar h_min_m = Scalar(0.005);
        Scalar h_max_m = 20;
    };
    static Result<ApparentHeightPrior> create(const HeightPrior& prior, Scalar partial_weight,
                                              const GridSpec& grid);

    [[nodiscard]] std::size_t size() const { return log_mass_.size(); }
    [[nodiscard]] Scalar height(std::size_t m) const { return heights_[m]; }
    [[nodiscard]] Scalar logMass(std::size_t m) const { return log_mass_[m]; }
    // Variance of a height within its bin (width^2 / 12), metres^2.
    [[nodiscard]] Scalar binVariance(std::size_t m) const { return bin_var_[m]; }
    [[nodiscard]] Scalar logHMin() const { return log_h_min_; }
    [[nodiscard]] Scalar logStep() const { return log_step_; }
    [[nodiscard]] Scalar widthMean() const { return width_mean_m_; }
    [[nodiscard]] Scalar widthStd() const { return width_std_m_; }

private:
    ApparentHeightPrior() = default;

    Scalar log_h_min_ = 0;
    Scalar log_step_ = 0;
    Scalar width_mean_m_ = 0;
    Scalar width_std_m_ = 0;
    std::vector<Scalar> heights_;
    std::vector<Scalar> log_mass_;  // -inf where the mass is 0
    std::vector<Scalar> bin_var_;
};

struct ObjectLikelihoodConfig {
    bool width_model = true;          // use the class's width (else w = 0)
    Scalar rel_sigma = Scalar(0.05);  // common relative error of the object's views
    Scalar outlier_weight = 0;        // epsilon, in [0, 1)
};

// Writes log L_o(d_j), shifted to a maximum of 0, for every grid point. Returns
// false (and writes nothing) without views, with a non-positive or non-finite
// D or sigma, or when log_l is not the grid's size. Does not allocate.
bool evaluateObjectLogLikelihood(std::span<const ObjectViewExtent> views,
                                 const ApparentHeightPrior& prior, const ScaleGrid& grid,
                                 const ObjectLikelihoodConfig& config, std::span<Scalar> log_l);

// The best-fitting apparent height (metres) of the views at scale d, with the
// width at its mean: the least-squares h of d D_k = h + kappa_k mu_w. 0 without views.
Scalar objectHeightAt(std::span<const ObjectViewExtent> views, Scalar width_mean_m, Scalar d);

}  // namespace scaled::core
