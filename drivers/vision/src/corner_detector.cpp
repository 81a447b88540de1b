#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <scaled/vision/corner_detector.h>

namespace scaled::vision {

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
    const int block_size = std::max(cfg.block_size, 1);

    // The response is computed on the region inside the border; as a view into the
    // image, its derivatives still see the real pixels around it. Its outermost
    // ring only serves the 3x3 local-maximum test.
    const cv::Rect roi(border, border, gray.cols - 2 * border, gray.rows - 2 * border);
    thread_local cv::Mat response;
    try {
        if (cfg.use_harris) {
            cv::cornerHarris(gray(roi), response, block_size, 3, 0.04);
        } else {
            cv::cornerMinEigenVal(gray(roi), response, block_size, 3);
        }
    } catch (const cv::Exception&) {
        return;  // inputs are validated above; this is a last line of defence
    }
    const cv::Mat roi_mask = mask.empty() ? cv::Mat() : mask(roi);
    double max_response = 0;
    cv::minMaxLoc(response, nullptr, &max_response, nullptr, nullptr, roi_mask);
    if (!(max_response > 0)) {
        return;
    }
    const auto threshold = static_cast<float>(max_response * quality);

    // Local maxima (3x3) above the threshold where the mask allows, as
    // goodFeaturesToTrack does, then a greedy pick in order of strength that keeps
    // min_distance_px between corners. Only as many candidates as needed are
    // taken from the heap, so a rich image does not pay for a full sort.
    thread_local cv::Mat dilated;
    thread_local std::vector<Candidate> candidates;
    candidates.clear();
    try {
        cv::dilate(response, dilated, cv::Mat());  // 3x3 maximum (vectorised)
    } catch (const cv::Exception&) {
        return;
    }
    for (int y = 1; y < response.rows - 1; ++y) {
        const auto* row = response.ptr<float>(y);
        const auto* row_max = dilated.ptr<float>(y);
        const uchar* m = roi_mask.empty() ? nullptr : roi_mask.ptr<uchar>(y);
        for (int x = 1; x < response.cols - 1; ++x) {
            const float v = row[x];
            // Local maxima are rare: test that first, it branches predictably.
            if (v < row_max[x] || !(v > threshold) || (m != nullptr && m[x] == 0)) {
                continue;
            }
            candidates.push_back({v, x, y});
        }
    }
    std::make_heap(candidates.begin(), candidates.end(), weaker);
    const double min_d2 = min_distance * min_distance;
    const auto wanted = static_cast<std::size_t>(cfg.max_corners);
    auto heap_end = candidates.end();
    std::vector<cv::Point> picked;
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
    mask.setTo(cv::Scalar(255));
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
        const cv::Point c(static_cast<int>(std::lround(x)), static_cast<int>(std::lround(y)));
        cv::circle(mask, c, radius, cv::Scalar(0), cv::FILLED, cv::LINE_8);
    }
}

}  // namespace scaled::vision
