#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <opencv2/core/hal/intrin.hpp>

#include <scaled/drivers/vision/matcher.h>

namespace scaled::drivers::vision {

using core::Mat2;
using core::Scalar;
using core::Vec2;

namespace {

// Centres farther out than this are treated as invalid input (keeps every
// pixel coordinate comfortably inside int).
constexpr double kMaxCoordinatePx = 1e7;

// The gate ellipse (u - c)^T S^-1 (u - c) <= gate, walked row by row: on row y
// the ellipse spans x in [mid - half, mid + half] (conditional Gaussian).
struct Ellipse {
    double cx = 0;
    double cy = 0;
    double s00 = 0;
    double s01 = 0;
    double s11 = 0;
    double gate = 0;

    [[nodiscard]] double halfHeight() const { return std::sqrt(gate * s11); }
    [[nodiscard]] double halfWidth() const { return std::sqrt(gate * s00); }

    // Integer x range of row y; false when the row misses the ellipse.
    bool rowSpan(int y, int& x_first, int& x_last) const {
        const double dy = y - cy;
        const double rem = gate - dy * dy / s11;
        if (rem < 0) {
            return false;
        }
        const double half = std::sqrt(rem * (s00 - s01 * s01 / s11));
        const double mid = cx + s01 / s11 * dy;
        x_first = static_cast<int>(std::ceil(mid - half));
        x_last = static_cast<int>(std::floor(mid + half));
        return x_first <= x_last;
    }
};

// The gate ellipse of a prediction at center_px with innovation covariance
// S; false when the centre is absurdly far out or S is not positive definite.
bool makeGateEllipse(const Vec2& center_px, const Mat2& S, double chi2_gate, Ellipse& e) {
    e.cx = static_cast<double>(center_px.x());
    e.cy = static_cast<double>(center_px.y());
    e.s00 = static_cast<double>(S(0, 0));
    e.s11 = static_cast<double>(S(1, 1));
    e.s01 = 0.5 * (static_cast<double>(S(0, 1)) + static_cast<double>(S(1, 0)));
    e.gate = chi2_gate;
    if (!(std::abs(e.cx) < kMaxCoordinatePx) || !(std::abs(e.cy) < kMaxCoordinatePx)) {
        return false;
    }
    const double det = e.s00 * e.s11 - e.s01 * e.s01;
    return std::isfinite(det) && e.s00 > 0 && e.s11 > 0 && det > 0;
}

// The ellipse's rows [y_first, y_last]; false when it is too uncertain to
// search: an extent beyond the pixel budget, then the exact count.
bool fitsSearchBudget(const Ellipse& e, const MatchConfig& cfg, int& y_first, int& y_last) {
    const double max_pixels = cfg.max_search_pixels;
    if (2 * e.halfHeight() + 1 > max_pixels || 2 * e.halfWidth() + 1 > max_pixels) {
        return false;
    }
    y_first = static_cast<int>(std::ceil(e.cy - e.halfHeight()));
    y_last = static_cast<int>(std::floor(e.cy + e.halfHeight()));
    std::int64_t inside = 0;
    for (int y = y_first; y <= y_last; ++y) {
        int xa = 0;
        int xb = 0;
        if (e.rowSpan(y, xa, xb)) {
            inside += xb - xa + 1;
        }
    }
    return inside <= cfg.max_search_pixels;
}

// Centres scored together: two 4-float registers of accumulators.
constexpr std::size_t kBlock = 8;

#if CV_SIMD128
// OpenCV 4.8 and later name the vector arithmetic (v_add, v_mul) and drop the
// operators on NEON (aarch64: trixie's 4.10); 4.6 (bookworm) has only the
// operators. The headers with the functions define CV_SIMD_SCALABLE. Both
// spellings are the same multiply then add (no fused multiply-add).
inline cv::v_float32x4 plus(const cv::v_float32x4& a, const cv::v_float32x4& b) {
#ifdef CV_SIMD_SCALABLE
    return cv::v_add(a, b);
#else
    return a + b;
#endif
}

// acc + a * b
inline cv::v_float32x4 plusProduct(const cv::v_float32x4& acc, const cv::v_float32x4& a,
                                   const cv::v_float32x4& b) {
#ifdef CV_SIMD_SCALABLE
    return cv::v_add(acc, cv::v_mul(a, b));
#else
    return acc + a * b;
#endif
}
#endif

// out[m] = sum_ij t[i][j] * window[i][m + j] for B (4 or 8) consecutive centres,
// the accumulators kept in registers.
template <std::size_t B>
void correlateBlock(const float* window, std::size_t stride, const float* t, int size, float* out) {
    static_assert(B == 4 || B == 8);
    const auto n = static_cast<std::size_t>(size);
#if CV_SIMD128
    // Even and odd template rows in separate accumulators: four independent
    // dependency chains keep the adder busy.
    cv::v_float32x4 a0 = cv::v_setzero_f32();
    cv::v_float32x4 a1 = cv::v_setzero_f32();
    cv::v_float32x4 b0 = cv::v_setzero_f32();
    cv::v_float32x4 b1 = cv::v_setzero_f32();
    std::size_t i = 0;
    for (; i + 1 < n; i += 2) {
        const float* w = window + i * stride;
        const float* v = w + stride;
        const float* ti = t + i * n;
        const float* ui = ti + n;
        for (std::size_t j = 0; j < n; ++j) {
            const cv::v_float32x4 tv = cv::v_setall_f32(ti[j]);
            const cv::v_float32x4 uv = cv::v_setall_f32(ui[j]);
            a0 = plusProduct(a0, tv, cv::v_load(w + j));
            b0 = plusProduct(b0, uv, cv::v_load(v + j));
            if constexpr (B == 8) {
                a1 = plusProduct(a1, tv, cv::v_load(w + j + 4));
                b1 = plusProduct(b1, uv, cv::v_load(v + j + 4));
            }
        }
    }
    if (i < n) {
        const float* w = window + i * stride;
        const float* ti = t + i * n;
        for (std::size_t j = 0; j < n; ++j) {
            const cv::v_float32x4 tv = cv::v_setall_f32(ti[j]);
            a0 = plusProduct(a0, tv, cv::v_load(w + j));
            if constexpr (B == 8) {
                a1 = plusProduct(a1, tv, cv::v_load(w + j + 4));
            }
        }
    }
    cv::v_store(out, plus(a0, b0));
    if constexpr (B == 8) {
        cv::v_store(out + 4, plus(a1, b1));
    }
#else
    std::array<float, B> a{};
    std::array<float, B> b{};
    for (std::size_t i = 0; i < n; ++i) {
        const float* w = window + i * stride;
        const float* ti = t + i * n;
        auto& acc = (i % 2 == 0) ? a : b;
        for (std::size_t j = 0; j < n; ++j) {
            for (std::size_t m = 0; m < B; ++m) {
                acc[m] += ti[j] * w[j + m];
            }
        }
    }
    for (std::size_t m = 0; m < B; ++m) {
        out[m] = a[m] + b[m];
    }
#endif
}

// Vertex offset of the parabola through (-1, fm), (0, f0), (1, fp), clamped to
// +-0.5; 0 when the three points do not bend down.
double parabolaPeak(double fm, double f0, double fp) {
    const double curvature = fm - 2 * f0 + fp;
    if (!(curvature < 0)) {
        return 0;
    }
    return std::clamp(0.5 * (fm - fp) / curvature, -0.5, 0.5);
}

}  // namespace

void Matcher::reserve(int template_size, int max_row_centres) {
    if (template_size < 1 || max_row_centres < 1) {
        return;
    }
    const auto size = static_cast<std::size_t>(template_size);
    const auto count = static_cast<std::size_t>(max_row_centres);
    // The sizes scoreRow() and prepareTemplate() ask for; resize() within the
    // capacity reserved here does not allocate.
    const std::size_t width = count + size - 1;
    tmpl_.reserve(size * size);
    acc_.reserve(count + kBlock);
    ncc_.reserve(count + kBlock);
    col_sum_.reserve(width);
    col_sq_.reserve(width);
    window_.reserve(size * (width + kBlock));
}

bool Matcher::prepareTemplate(const Patch& patch, const MatchConfig& cfg) {
    const cv::Mat& t = patch.templ;
    const int size = patch.size;
    if (size < 1 || size % 2 == 0 || t.type() != CV_32FC1 || t.rows != size || t.cols != size) {
        return false;
    }
    const auto n = static_cast<std::size_t>(size) * static_cast<std::size_t>(size);
    tmpl_.resize(n);
    double sum = 0;
    for (int i = 0; i < size; ++i) {
        const auto* row = t.ptr<float>(i);
        for (int j = 0; j < size; ++j) {
            sum += static_cast<double>(row[j]);
        }
    }
    const double mean = sum / static_cast<double>(n);
    if (!std::isfinite(mean)) {
        return false;
    }
    double sq = 0;
    for (int i = 0; i < size; ++i) {
        const auto* row = t.ptr<float>(i);
        for (int j = 0; j < size; ++j) {
            const auto v = static_cast<float>(static_cast<double>(row[j]) - mean);
            tmpl_[static_cast<std::size_t>(i) * static_cast<std::size_t>(size) +
                  static_cast<std::size_t>(j)] = v;
            sq += static_cast<double>(v) * static_cast<double>(v);
        }
    }
    const double stddev = std::sqrt(sq / static_cast<double>(n));
    if (!(stddev >= cfg.min_template_stddev) || !(sq > 0)) {
        return false;
    }
    size_ = size;
    tmpl_norm_ = std::sqrt(sq);
    return true;
}

void Matcher::scoreRow(const cv::Mat& gray, int y, int x0, int count) {
    const int size = size_;
    const int r = size / 2;
    const auto n_count = static_cast<std::size_t>(count);
    const auto width = static_cast<std::size_t>(count + size - 1);
    // Window rows padded with zeros so the last block may run past the row end.
    const std::size_t stride = width + kBlock;
    const std::size_t n_rows = static_cast<std::size_t>(size);
    if (acc_.size() < n_count + kBlock) {
        acc_.resize(n_count + kBlock);
        ncc_.resize(n_count + kBlock);
    }
    if (col_sum_.size() < width) {
        col_sum_.resize(width);
        col_sq_.resize(width);
    }
    if (window_.size() < n_rows * stride) {
        window_.resize(n_rows * stride);
    }
    int* __restrict col_sum = col_sum_.data();
    int* __restrict col_sq = col_sq_.data();
    std::fill_n(col_sum, width, 0);
    std::fill_n(col_sq, width, 0);

    // The image rows under this row of centres, as floats, and their column
    // sums for the window means and variances.
    for (std::size_t i = 0; i < n_rows; ++i) {
        const uchar* __restrict src = gray.ptr<uchar>(y - r + static_cast<int>(i)) + (x0 - r);
        float* __restrict dst = window_.data() + i * stride;
        for (std::size_t k = 0; k < width; ++k) {
            const int v = src[k];
            dst[k] = static_cast<float>(v);
            col_sum[k] += v;
            col_sq[k] += v * v;
        }
        std::fill_n(dst + width, kBlock, 0.0F);
    }
    // Correlation with the zero-mean template, kBlock centres at a time.
    for (std::size_t k = 0; k < n_count; k += kBlock) {
        if (n_count - k > kBlock / 2) {
            correlateBlock<kBlock>(window_.data() + k, stride, tmpl_.data(), size, acc_.data() + k);
        } else {
            correlateBlock<kBlock / 2>(window_.data() + k, stride, tmpl_.data(), size,
                                       acc_.data() + k);
        }
    }
    const float* acc = acc_.data();

    const std::int64_t n = static_cast<std::int64_t>(size) * size;
    const double n_d = static_cast<double>(n);
    const auto s_size = static_cast<std::size_t>(size);
    std::int64_t s = 0;
    std::int64_t s2 = 0;
    for (std::size_t k = 0; k < s_size; ++k) {
        s += col_sum[k];
        s2 += col_sq[k];
    }
    for (std::size_t c = 0; c < n_count; ++c) {
        if (c > 0) {
            s += col_sum[c + s_size - 1] - col_sum[c - 1];
            s2 += col_sq[c + s_size - 1] - col_sq[c - 1];
        }
        // n * sum(I - mean)^2, exact in integers.
        const std::int64_t var_n = n * s2 - s * s;
        ncc_[c] = var_n > 0 ? static_cast<double>(acc[c]) /
                                  (tmpl_norm_ * std::sqrt(static_cast<double>(var_n) / n_d))
                            : 0.0;
    }
}

double Matcher::nccAt(const cv::Mat& gray, int x, int y) {
    // Through scoreRow, so that neighbouring scores share the same arithmetic.
    scoreRow(gray, y, x, 1);
    return ncc_[0];
}

void Matcher::subpixelOffset(const cv::Mat& gray, int x, int y, double f0, double& off_x,
                             double& off_y) {
    const int r = size_ / 2;
    const bool has_x = x - 1 >= r && x + 1 <= gray.cols - 1 - r;
    const bool has_y = y - 1 >= r && y + 1 <= gray.rows - 1 - r;
    off_x = 0;
    off_y = 0;
    if (has_x && has_y) {
        // The 3x3 neighbourhood, one row of three centres at a time.
        std::array<std::array<double, 3>, 3> f{};
        for (std::size_t row = 0; row < 3; ++row) {
            scoreRow(gray, y - 1 + static_cast<int>(row), x - 1, 3);
            std::copy_n(ncc_.begin(), 3, f[row].begin());
        }
        const double fc = f[1][1];
        off_x = parabolaPeak(f[1][0], fc, f[1][2]);
        off_y = parabolaPeak(f[0][1], fc, f[2][1]);
        // The 2-D quadratic through the neighbourhood (a Newton step on the NCC):
        // its cross term removes the bias of separate 1-D fits on tilted peaks.
        const double fxx = f[1][0] - 2 * fc + f[1][2];
        const double fyy = f[0][1] - 2 * fc + f[2][1];
        const double fxy = 0.25 * (f[2][2] - f[0][2] - f[2][0] + f[0][0]);
        const double det = fxx * fyy - fxy * fxy;
        if (!(fxx < 0) || !(fyy < 0) || !(det > 0)) {
            return;  // not a proper maximum: keep the 1-D fits
        }
        const double gx = 0.5 * (f[1][2] - f[1][0]);
        const double gy = 0.5 * (f[2][1] - f[0][1]);
        off_x = std::clamp(-(fyy * gx - fxy * gy) / det, -0.5, 0.5);
        off_y = std::clamp(-(fxx * gy - fxy * gx) / det, -0.5, 0.5);
    } else if (has_x) {
        scoreRow(gray, y, x - 1, 3);
        off_x = parabolaPeak(ncc_[0], f0, ncc_[2]);
    } else if (has_y) {
        off_y = parabolaPeak(nccAt(gray, x, y - 1), f0, nccAt(gray, x, y + 1));
    }
}

std::optional<Match> Matcher::match(const cv::Mat& gray, const Patch& patch, const Vec2& center_px,
                                    const Mat2& S, const MatchConfig& cfg) {
    if (gray.empty() || gray.type() != CV_8UC1) {
        return std::nullopt;
    }
    if (!(cfg.chi2_gate > 0) || !std::isfinite(cfg.chi2_gate) || cfg.max_search_pixels <= 0) {
        return std::nullopt;
    }
    Ellipse e;
    if (!makeGateEllipse(center_px, S, cfg.chi2_gate, e)) {
        return std::nullopt;
    }
    int y_first = 0;
    int y_last = 0;
    if (!fitsSearchBudget(e, cfg, y_first, y_last)) {
        return std::nullopt;
    }
    if (!prepareTemplate(patch, cfg)) {
        return std::nullopt;
    }

    // Centres where the template fits in the image.
    const int r = size_ / 2;
    const int x_min = r;
    const int x_max = gray.cols - 1 - r;
    const int y_min = r;
    const int y_max = gray.rows - 1 - r;
    if (x_min > x_max || y_min > y_max) {
        return std::nullopt;
    }

    Match best;
    double best_ncc = -2;
    int best_x = 0;
    int best_y = 0;
    for (int y = std::max(y_first, y_min); y <= std::min(y_last, y_max); ++y) {
        int xa = 0;
        int xb = 0;
        if (!e.rowSpan(y, xa, xb)) {
            continue;
        }
        xa = std::max(xa, x_min);
        xb = std::min(xb, x_max);
        if (xa > xb) {
            continue;
        }
        const int count = xb - xa + 1;
        scoreRow(gray, y, xa, count);
        best.evaluated += count;
        for (int c = 0; c < count; ++c) {
            const double v = ncc_[static_cast<std::size_t>(c)];
            if (v > best_ncc) {
                best_ncc = v;
                best_x = xa + c;
                best_y = y;
            }
        }
    }
    if (best.evaluated == 0 || !(best_ncc >= cfg.min_ncc)) {
        return std::nullopt;
    }

    double off_x = 0;
    double off_y = 0;
    if (cfg.subpixel) {
        subpixelOffset(gray, best_x, best_y, best_ncc, off_x, off_y);
    }
    best.px = Vec2(static_cast<Scalar>(best_x + off_x), static_cast<Scalar>(best_y + off_y));
    best.ncc = best_ncc;
    return best;
}

std::optional<Match> matchInEllipse(const cv::Mat& gray, const Patch& patch, const Vec2& center_px,
                                    const Mat2& S, const MatchConfig& cfg) {
    thread_local Matcher matcher;
    return matcher.match(gray, patch, center_px, S, cfg);
}

}  // namespace scaled::drivers::vision
