#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <scaled/drivers/vision/corner_detector.h>

namespace scaled::drivers::vision {

using core::Scalar;
using core::Vec2;

namespace {

struct Candidate {
    float response;
    int x;
    int y;
};

// Strongest first; ties in raster order, so the result is deterministic.
bool weaker(const Candidate& a, const Candidate& b) {
    if (a.response != b.response) {
        return a.response < b.response;
    }
    return a.y != b.y ? a.y > b.y : a.x > b.x;
}

// OpenCV's BORDER_REFLECT_101 (its BORDER_DEFAULT): ... 2 1 | 0 1 2 ... n-1 | n-2 ...
inline int reflect101(int i, int n) {
    if (i >= 0 && i < n) {
        return i;  // every pixel but the border ones: keep the per-pixel loops cheap
    }
    if (n == 1) {
        return 0;
    }
    while (i < 0 || i >= n) {
        i = i < 0 ? -i : 2 * n - 2 - i;
    }
    return i;
}

// Per-thread scratch of detectCorners, grown to the largest region seen and
// never shrunk: after the first call at a given image size, detection does not
// allocate (the tracker adds features in steady state). cv::cornerMinEigenVal
// and cv::dilate, which this replaces, allocate their temporaries every call.
struct CornerScratch {
    std::vector<float> products;  // dx^2, dx dy, dy^2 of one row (3 x cols)
    // Products summed along rows over the block, for the last `block` region
    // rows (a ring: region row r in slot r mod block, 3 x cols per slot).
    std::vector<float> row_sums;
    std::vector<float> column;    // row sums summed down the block, for one output row (3 x cols)
    std::vector<float> response;  // rows x cols
    std::vector<Candidate> candidates;
    std::vector<cv::Point> picked;

    void reserve(std::size_t rows, std::size_t cols, std::size_t block) {
        const std::size_t n = rows * cols;
        if (products.size() < 3 * cols) {
            products.resize(3 * cols);
        }
        if (row_sums.size() < 3 * block * cols) {
            row_sums.resize(3 * block * cols);
        }
        if (column.size() < 3 * cols) {
            column.resize(3 * cols);
        }
        if (response.size() < n) {
            response.resize(n);
        }
        // Every pixel may be a (non-strict) local maximum on a plateau: the
        // bound that keeps push_back from ever growing.
        if (candidates.capacity() < n) {
            candidates.reserve(n);
        }
    }
};

// Sobel derivative products (scaled) of the pixels j in [first, last) of the
// region row whose image rows above, at and below are up, mid and down; the
// column of region pixel j is x0 + j, its neighbours l(j) and r(j).
template <typename Left, typename Right>
inline void sobelProducts(const uchar* __restrict up, const uchar* __restrict mid,
                          const uchar* __restrict down, int x0, int first, int last, Left l,
                          Right r, float scale, float* __restrict xx, float* __restrict xy,
                          float* __restrict yy) {
    for (int j = first; j < last; ++j) {
        const int x = x0 + j;
        const int xl = l(x);
        const int xr = r(x);
        const int gx = (up[xr] - up[xl]) + 2 * (mid[xr] - mid[xl]) + (down[xr] - down[xl]);
        const int gy = (down[xl] + 2 * down[x] + down[xr]) - (up[xl] + 2 * up[x] + up[xr]);
        const float dx = static_cast<float>(gx) * scale;
        const float dy = static_cast<float>(gy) * scale;
        xx[j] = dx * dx;
        xy[j] = dx * dy;
        yy[j] = dy * dy;
    }
}

// Row i of the region: its Sobel products summed along the row over the
// block (BORDER_REFLECT_101 at the region's border), into `out` (3 x cols).
void rowSums(const cv::Mat& gray, const cv::Rect& roi, int i, int block_size, CornerScratch& s,
             float* __restrict out) {
    const int cols = roi.width;
    const auto ucols = static_cast<std::size_t>(cols);
    const float scale = static_cast<float>(1.0 / (4.0 * block_size * 255.0));
    const int anchor = block_size / 2;
    const int y = roi.y + i;
    const uchar* up = gray.ptr<uchar>(reflect101(y - 1, gray.rows));
    const uchar* mid = gray.ptr<uchar>(y);
    const uchar* down = gray.ptr<uchar>(reflect101(y + 1, gray.rows));
    float* xx = s.products.data();
    float* xy = xx + ucols;
    float* yy = xy + ucols;
    // Columns whose Sobel neighbours are inside the image need no reflection.
    const int sobel_lo = std::clamp(1 - roi.x, 0, cols);
    const int sobel_hi = std::clamp(gray.cols - 1 - roi.x, sobel_lo, cols);
    const auto left = [&](int x) { return reflect101(x - 1, gray.cols); };
    const auto right = [&](int x) { return reflect101(x + 1, gray.cols); };
    sobelProducts(up, mid, down, roi.x, 0, sobel_lo, left, right, scale, xx, xy, yy);
    const auto before = [](int x) { return x - 1; };
    const auto after = [](int x) { return x + 1; };
    sobelProducts(up, mid, down, roi.x, sobel_lo, sobel_hi, before, after, scale, xx, xy, yy);
    sobelProducts(up, mid, down, roi.x, sobel_hi, cols, left, right, scale, xx, xy, yy);
    // Columns whose window stays inside the region need no reflection.
    const int sum_lo = std::min(anchor, cols);
    const int sum_hi = std::max(sum_lo, cols - (block_size - 1 - anchor));
    for (std::size_t c = 0; c < 3; ++c) {
        const float* __restrict src = s.products.data() + c * ucols;
        float* __restrict dst = out + c * ucols;
        std::fill(dst, dst + ucols, 0.0F);
        for (int k = 0; k < block_size; ++k) {
            for (int j = 0; j < sum_lo; ++j) {
                dst[j] += src[reflect101(j - anchor + k, cols)];
            }
            for (int j = sum_lo; j < sum_hi; ++j) {
                dst[j] += src[j - anchor + k];
            }
            for (int j = sum_hi; j < cols; ++j) {
                dst[j] += src[reflect101(j - anchor + k, cols)];
            }
        }
    }
}

// The structure-tensor response of cv::cornerMinEigenVal / cv::cornerHarris
// (aperture 3) of the region `roi` of `gray`, computed as OpenCV does: Sobel
// derivatives scaled by 1 / (4 block 255), seeing the image's real pixels
// around the region (BORDER_REFLECT_101 at the image border), their products
// summed over block x block windows with BORDER_REFLECT_101 at the region's
// border, then the smaller eigenvalue (or the Harris measure, k = 0.04) in
// float. Into s.response, row-major, roi.width per row.
//
// Every window sum is 0 + t_0 + t_1 + ... + t_(block-1) in that order, for
// every pixel: the loops run over the block outside and over the pixels
// inside, so that the compiler vectorises them across pixels without
// reassociating any sum (the result does not depend on the vector width).
// Row sums are made as the output rows come to need them, into a ring of
// `block` rows that stays in cache.
void structureResponse(const cv::Mat& gray, const cv::Rect& roi, int block_size, bool harris,
                       CornerScratch& s) {
    const int rows = roi.height;
    const auto ucols = static_cast<std::size_t>(roi.width);
    const int anchor = block_size / 2;
    const auto slot = [&](int row) {
        return s.row_sums.data() + 3 * static_cast<std::size_t>(row % block_size) * ucols;
    };
    // The rows a window needs (reflected at the region's border) lie within
    // `block` consecutive rows, and the highest is the last one made: a ring
    // of `block` slots never drops a row still needed.
    int made = -1;  // highest region row whose sums are in the ring
    // The three window sums of a row: a, b, c (one buffer, so not restrict).
    float* a = s.column.data();
    float* b = a + ucols;
    float* c = b + ucols;
    for (int i = 0; i < rows; ++i) {
        int highest = 0;
        for (int k = 0; k < block_size; ++k) {
            highest = std::max(highest, reflect101(i - anchor + k, rows));
        }
        for (; made < highest; ++made) {
            rowSums(gray, roi, made + 1, block_size, s, slot(made + 1));
        }
        float* __restrict acc = s.column.data();
        std::fill(acc, acc + 3 * ucols, 0.0F);
        for (int k = 0; k < block_size; ++k) {
            const float* __restrict sums = slot(reflect101(i - anchor + k, rows));
            for (std::size_t j = 0; j < 3 * ucols; ++j) {
                acc[j] += sums[j];
            }
        }
        float* __restrict resp = s.response.data() + static_cast<std::size_t>(i) * ucols;
        if (harris) {
            constexpr float kHarrisK = 0.04F;
            for (std::size_t j = 0; j < ucols; ++j) {
                resp[j] = a[j] * c[j] - b[j] * b[j] - kHarrisK * (a[j] + c[j]) * (a[j] + c[j]);
            }
        } else {
            for (std::size_t j = 0; j < ucols; ++j) {
                const float ha = a[j] * 0.5F;
                const float hc = c[j] * 0.5F;
                resp[j] = (ha + hc) - std::sqrt((ha - hc) * (ha - hc) + b[j] * b[j]);
            }
        }
    }
}

// The response of the region inside the border (row-major, `cols` per row)
// and the mask over that region (none when the mask is empty).
struct ResponseView {
    const float* response = nullptr;
    std::size_t cols = 0;
    int rows = 0;   // the region's height
    int width = 0;  // the region's width
    const cv::Mat* mask = nullptr;
    int border = 0;

    [[nodiscard]] const float* at(int y, int x) const {
        return response + static_cast<std::size_t>(y) * cols + static_cast<std::size_t>(x);
    }
    [[nodiscard]] const uchar* maskRow(int y) const {
        return mask->empty() ? nullptr : mask->ptr<uchar>(y + border) + border;
    }
};

// The strongest response where the mask allows (as cv::minMaxLoc would);
// false when the mask allows no pixel.
bool strongestResponse(const ResponseView& view, float& max_response) {
    bool any = false;
    for (int y = 0; y < view.rows; ++y) {
        const float* row = view.at(y, 0);
        const uchar* m = view.maskRow(y);
        for (int x = 0; x < view.width; ++x) {
            if (m == nullptr || m[x] != 0) {
                max_response = any ? std::max(max_response, row[x]) : row[x];
                any = true;
            }
        }
    }
    return any;
}

// The local maxima (3x3) above the threshold where the mask allows, in raster order.
void collectLocalMaxima(const ResponseView& view, float threshold,
                        std::vector<Candidate>& candidates) {
    candidates.clear();
    for (int y = 1; y < view.rows - 1; ++y) {
        const float* above = view.at(y - 1, 0);
        const float* row = view.at(y, 0);
        const float* below = view.at(y + 1, 0);
        const uchar* m = view.maskRow(y);
        for (int x = 1; x < view.width - 1; ++x) {
            const float v = row[x];
            if (!(v > threshold) || (m != nullptr && m[x] == 0)) {
                continue;
            }
            // v equals the maximum of its 3x3 neighbourhood (cv::dilate's test).
            if (v < row[x - 1] || v < row[x + 1] || v < above[x - 1] || v < above[x] ||
                v < above[x + 1] || v < below[x - 1] || v < below[x] || v < below[x + 1]) {
                continue;
            }
            candidates.push_back({v, x, y});
        }
    }
}

// Up to `wanted` candidates, strongest first, each at least min_distance from
// those picked before it (region coordinates); reorders `candidates` (a heap).
void pickSpreadCorners(std::vector<Candidate>& candidates, double min_distance, std::size_t wanted,
                       std::vector<cv::Point>& picked) {
    std::make_heap(candidates.begin(), candidates.end(), weaker);
    const double min_d2 = min_distance * min_distance;
    auto heap_end = candidates.end();
    picked.clear();
    picked.reserve(std::min(wanted, candidates.capacity()));  // once per size of request
    while (heap_end != candidates.begin() && picked.size() < wanted) {
        std::pop_heap(candidates.begin(), heap_end, weaker);
        --heap_end;
        const cv::Point p(heap_end->x, heap_end->y);
        const bool crowded = std::any_of(picked.begin(), picked.end(), [&](const cv::Point& q) {
            const double dx = p.x - q.x;
            const double dy = p.y - q.y;
            return dx * dx + dy * dy < min_d2;
        });
        if (!crowded) {
            picked.push_back(p);
        }
    }
}

}  // namespace

void detectCorners(const cv::Mat& gray, const cv::Mat& mask, const CornerConfig& cfg,
                   std::vector<Vec2>& out) {
    out.clear();
    if (gray.empty() || gray.type() != CV_8UC1 || cfg.max_corners <= 0) {
        return;
    }
    if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != gray.size())) {
        return;
    }
    const int border = std::max(cfg.border_px, 0);
    if (border > (gray.cols - 3) / 2 || border > (gray.rows - 3) / 2) {
        return;  // no pixel with a full 3x3 neighbourhood inside the border
    }
    const double quality =
        std::isfinite(cfg.quality_level) ? std::clamp(cfg.quality_level, 0.0, 1.0) : 0.01;
    const double min_distance = std::max(cfg.min_distance_px, 0);
    // Bounded by the image (OpenCV's box filter would reflect a larger block
    // more than once; no detector setting comes near this).
    const int block_size = std::clamp(cfg.block_size, 1, std::min(gray.rows, gray.cols));

    // The response is computed on the region inside the border; its
    // derivatives still see the real pixels around it. Its outermost ring only
    // serves the 3x3 local-maximum test.
    const cv::Rect roi(border, border, gray.cols - 2 * border, gray.rows - 2 * border);
    thread_local CornerScratch scratch;
    scratch.reserve(static_cast<std::size_t>(roi.height), static_cast<std::size_t>(roi.width),
                    static_cast<std::size_t>(block_size));
    structureResponse(gray, roi, block_size, cfg.use_harris, scratch);
    const ResponseView view{scratch.response.data(),
                            static_cast<std::size_t>(roi.width),
                            roi.height,
                            roi.width,
                            &mask,
                            border};

    float max_response = 0;
    const bool any = strongestResponse(view, max_response);
    if (!any || !(max_response > 0)) {
        return;
    }
    const auto threshold = static_cast<float>(static_cast<double>(max_response) * quality);

    // Local maxima (3x3) above the threshold where the mask allows, as
    // goodFeaturesToTrack does, then a greedy pick in order of strength that
    // keeps min_distance_px between corners. Only as many candidates as needed
    // are taken from the heap, so a rich image does not pay for a full sort.
    collectLocalMaxima(view, threshold, scratch.candidates);
    std::vector<cv::Point>& picked = scratch.picked;
    pickSpreadCorners(scratch.candidates, min_distance, static_cast<std::size_t>(cfg.max_corners),
                      picked);
    out.reserve(picked.size());
    for (const cv::Point& p : picked) {
        out.emplace_back(static_cast<Scalar>(p.x + border), static_cast<Scalar>(p.y + border));
    }
}

void makeFreeMask(cv::Size size, std::span<const Vec2> occupied_px, int radius_px, cv::Mat& mask) {
    if (size.width <= 0 || size.height <= 0) {
        mask.release();
        return;
    }
    mask.create(size, CV_8UC1);
    // Row by row: cv::Mat::setTo allocates a scratch buffer every call.
    for (int row = 0; row < size.height; ++row) {
        uchar* dst = mask.ptr<uchar>(row);
        std::fill(dst, dst + size.width, uchar{255});
    }
    if (radius_px < 0) {
        return;
    }
    // Bounded so that every coordinate below stays well inside int.
    constexpr int kMaxRadiusPx = 1 << 20;
    const int radius = std::min(radius_px, kMaxRadiusPx);
    const double r = radius;
    for (const Vec2& p : occupied_px) {
        const double x = static_cast<double>(p.x());
        const double y = static_cast<double>(p.y());
        if (!std::isfinite(x) || !std::isfinite(y) || x < -r - 1 || y < -r - 1 ||
            x > size.width + r || y > size.height + r) {
            continue;
        }
        // A filled disc, row by row: the pixels cv::circle(FILLED) zeroes
        // (d^2 <= r^2), without the outline polygon it allocates every call
        // (the tracker builds this mask whenever it adds features).
        const auto cx = static_cast<std::int64_t>(std::lround(x));
        const auto cy = static_cast<std::int64_t>(std::lround(y));
        const auto r64 = static_cast<std::int64_t>(radius);
        const std::int64_t r2 = r64 * r64;
        const std::int64_t y_first = std::max<std::int64_t>(cy - r64, 0);
        const std::int64_t y_last = std::min<std::int64_t>(cy + r64, size.height - 1);
        for (std::int64_t row = y_first; row <= y_last; ++row) {
            const std::int64_t dy = row - cy;
            // Largest dx with dx^2 <= r2 - dy^2.
            auto half = static_cast<std::int64_t>(std::sqrt(static_cast<double>(r2 - dy * dy)));
            while (half * half > r2 - dy * dy) {
                --half;
            }
            while ((half + 1) * (half + 1) <= r2 - dy * dy) {
                ++half;
            }
            const std::int64_t x_first = std::max<std::int64_t>(cx - half, 0);
            const std::int64_t x_last = std::min<std::int64_t>(cx + half, size.width - 1);
            if (x_first > x_last) {
                continue;
            }
            uchar* dst = mask.ptr<uchar>(static_cast<int>(row));
            std::fill(dst + x_first, dst + x_last + 1, uchar{0});
        }
    }
}

}  // namespace scaled::drivers::vision
