#pragma once

// Active search, as in MonoSLAM: a feature's template is looked for only inside
// the gate ellipse of its predicted measurement, (u - c)^T S^-1 (u - c) <= chi2,
// with S the 2x2 innovation covariance. The score is zero-mean normalised
// cross-correlation (NCC), computed exhaustively at every integer pixel of the
// ellipse and refined to sub-pixel by a quadratic fit around the best pixel.

#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include <scaled/core/types.h>
#include <scaled/drivers/vision/patch.h>

namespace scaled::drivers::vision {

struct MatchConfig {
    double chi2_gate = 9.21;           // 99% gate of a chi-square with 2 dof
    double min_ncc = 0.8;              // best NCC below this: no match
    int max_search_pixels = 4000;      // ellipses holding more pixels are not searched
    bool subpixel = true;              // quadratic refinement of the best pixel
    double min_template_stddev = 2.0;  // flatter templates (grey levels) are not searched
};

struct Match {
    core::Vec2 px = core::Vec2::Zero();  // matched position of the template centre
    double ncc = 0;                      // NCC at the best integer pixel
    int evaluated = 0;                   // ellipse pixels scored (the search cost)
};

// Matches templates with reusable scratch buffers: after the first calls with a
// given template size and ellipse size, match() does not allocate. Not
// thread-safe; use one Matcher per thread.
class Matcher {
public:
    // Sizes the scratch for templates up to template_size and ellipse rows of
    // up to max_row_centres pixels (MatchConfig::max_search_pixels bounds every
    // row), so that match() never allocates, not even the first time a larger
    // ellipse comes along.
    void reserve(int template_size, int max_row_centres);

    // The search of matchInEllipse (below) with this matcher's scratch.
    std::optional<Match> match(const cv::Mat& gray, const Patch& patch, const core::Vec2& center_px,
                               const core::Mat2& S, const MatchConfig& cfg);

private:
    // Zero-mean template into tmpl_; false for an invalid or flat template.
    bool prepareTemplate(const Patch& patch, const MatchConfig& cfg);
    // NCC of the template centred on integer pixel (x, y); the window must fit.
    double nccAt(const cv::Mat& gray, int x, int y);
    // NCC of every centre x0..x0+count-1 on row y into ncc_.
    void scoreRow(const cv::Mat& gray, int y, int x0, int count);
    // Sub-pixel offset (each component in [-0.5, 0.5]) of the NCC peak at (x, y),
    // whose score is f0.
    void subpixelOffset(const cv::Mat& gray, int x, int y, double f0, double& off_x, double& off_y);

    int size_ = 0;               // template side of the prepared template
    double tmpl_norm_ = 0;       // sqrt(sum of squared zero-mean template values)
    std::vector<float> tmpl_;    // zero-mean template, row-major
    std::vector<float> window_;  // image rows under one row of centres, as floats
    std::vector<float> acc_;     // per-centre correlation sums of one row
    std::vector<int> col_sum_;   // per-column intensity sums over the template rows
    std::vector<int> col_sq_;    // per-column squared intensity sums
    std::vector<double> ncc_;    // per-centre NCC of one row
};

// Exhaustive NCC of patch.templ at every integer pixel u inside the gate ellipse
// (u - center)^T S^-1 (u - center) <= cfg.chi2_gate (S in pixels^2), restricted to
// the centres where the template fits in the image. nullopt when the image is not
// CV_8UC1, S is not positive definite, the ellipse holds more than
// cfg.max_search_pixels pixels (or spans more rows or columns than that), the
// template is flat or invalid, or the best NCC is below cfg.min_ncc. With
// cfg.subpixel the best pixel is refined by a quadratic fit of the NCC on its 3x3
// neighbourhood: 1-D parabolas in x and y plus the cross term (a Newton step on
// the NCC), which removes the bias separate 1-D fits have on tilted peaks. It falls
// back to the separate 1-D parabolas when the 3x3 fit is not a maximum or leaves
// the image; each offset is clamped to +-0.5 px. Uses a thread-local Matcher.
std::optional<Match> matchInEllipse(const cv::Mat& gray, const Patch& patch,
                                    const core::Vec2& center_px, const core::Mat2& S,
                                    const MatchConfig& cfg);

}  // namespace scaled::drivers::vision
