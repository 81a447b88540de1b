#include "measure.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <utility>

namespace scaled::tools::heights {

ClassRule classRule(const std::string& class_name) {
    ClassRule r;
    if (class_name == "chair" || class_name == "potted plant" || class_name == "couch" ||
        class_name == "toilet") {
        r.bottom = BottomRule::kFloor;
        r.group_radius_m = 0.3;
    } else if (class_name == "dining table" || class_name == "bed") {
        // The top of a table is its top plane (cups, books on it are not the
        // table); the visible part of a table moves a lot between views.
        r.bottom = BottomRule::kFloor;
        r.top = TopRule::kPlane;
        r.group_radius_m = 1.0;
    } else if (class_name == "refrigerator" || class_name == "oven") {
        r.bottom = BottomRule::kFloor;
        r.group_radius_m = 0.6;
    }
    return r;
}

core::Vec3 DepthView::world(int u, int v, double z) const {
    const core::Vec3 p_C =
        Eigen::Vector3d((u - static_cast<double>(k.cx)) / static_cast<double>(k.fx) * z,
                        (v - static_cast<double>(k.cy)) / static_cast<double>(k.fy) * z, z)
            .cast<core::Scalar>();
    return T_CtoW.R_CtoW * p_C + T_CtoW.p_CinW;
}

namespace {

bool validDepth(float z) {
    const double d = static_cast<double>(z);
    return d >= kMinDepthM && d <= kMaxDepthM;
}

}  // namespace

void appendHeights(const DepthView& view, int stride, std::vector<float>& heights) {
    for (int v = 0; v < view.depth.rows; v += stride) {
        const auto* row = view.depth.ptr<float>(v);
        for (int u = 0; u < view.depth.cols; u += stride) {
            if (validDepth(row[u])) {
                heights.push_back(
                    static_cast<float>(view.height(view.world(u, v, static_cast<double>(row[u])))));
            }
        }
    }
}

double mad(const std::vector<double>& v) {
    const double m = median(v);
    std::vector<double> d;
    d.reserve(v.size());
    for (const double x : v) {
        d.push_back(std::abs(x - m));
    }
    return 1.4826 * median(d);
}

double percentile(std::span<const float> values, double q) {
    if (values.empty()) {
        return 0;
    }
    // A scratch copy for nth_element, by memcpy once known non-empty: GCC 14
    // at -O3 warns of a null dereference in a vector's copy constructor here.
    std::vector<float> v(values.size());
    std::memcpy(v.data(), values.data(), values.size() * sizeof(float));
    const auto i = static_cast<std::ptrdiff_t>(
        std::lround(std::clamp(q, 0.0, 1.0) * static_cast<double>(v.size() - 1)));
    std::nth_element(v.begin(), v.begin() + i, v.end());
    return static_cast<double>(v[static_cast<std::size_t>(i)]);
}

std::vector<Plane> findPlanes(std::vector<float> heights, double min_fraction) {
    std::vector<Plane> planes;
    if (heights.size() < 100) {
        return planes;
    }
    std::sort(heights.begin(), heights.end());
    // Ignore the extreme 0.1 % on each side (stray readings) for the range.
    const double lo = static_cast<double>(heights[heights.size() / 1000]);
    const double hi = static_cast<double>(heights[heights.size() - 1 - heights.size() / 1000]);
    constexpr double kBin = 0.01;
    const int n = static_cast<int>(std::ceil((hi - lo) / kBin)) + 1;
    std::vector<double> hist(static_cast<std::size_t>(n), 0.0);
    for (const float h : heights) {
        const int b = static_cast<int>(std::floor((static_cast<double>(h) - lo) / kBin));
        if (b >= 0 && b < n) {
            hist[static_cast<std::size_t>(b)] += 1;
        }
    }
    std::vector<double> smooth(hist.size(), 0.0);
    for (int b = 0; b < n; ++b) {
        const auto at = [&](int i) {
            return (i < 0 || i >= n) ? 0.0 : hist[static_cast<std::size_t>(i)];
        };
        smooth[static_cast<std::size_t>(b)] = 0.25 * at(b - 1) + 0.5 * at(b) + 0.25 * at(b + 1);
    }
    const auto total = static_cast<double>(heights.size());
    for (int b = 1; b + 1 < n; ++b) {
        const double c = smooth[static_cast<std::size_t>(b)];
        if (c < smooth[static_cast<std::size_t>(b) - 1] ||
            c <= smooth[static_cast<std::size_t>(b) + 1]) {
            continue;
        }
        const double centre = lo + (b + 0.5) * kBin;
        const auto first = std::lower_bound(heights.begin(), heights.end(), centre - 0.02);
        const auto last = std::upper_bound(heights.begin(), heights.end(), centre + 0.02);
        const auto count = static_cast<double>(last - first);
        if (count < min_fraction * total) {
            continue;
        }
        std::vector<double> near(first, last);
        Plane p;
        p.height_m = median(near);
        p.mad_m = mad(near);
        p.fraction = count / total;
        // Two maxima of one plateau: keep the better supported one.
        if (!planes.empty() && p.height_m - planes.back().height_m < 0.03) {
            if (p.fraction > planes.back().fraction) {
                planes.back() = p;
            }
            continue;
        }
        planes.push_back(p);
    }
    return planes;
}

Shift estimateShift(const cv::Mat& color_bgr, const cv::Mat& depth) {
    Shift s;
    constexpr int kMaxDx = 40;
    constexpr int kMaxDy = 30;
    constexpr float kTrunc = 10.0F;
    cv::Mat gray;
    cv::cvtColor(color_bgr, gray, cv::COLOR_BGR2GRAY);
    cv::GaussianBlur(gray, gray, cv::Size(5, 5), 1.2);
    cv::Mat edges;
    cv::Canny(gray, edges, 40, 120);
    cv::Mat not_edges;
    cv::bitwise_not(edges, not_edges);
    cv::Mat dist;
    cv::distanceTransform(not_edges, dist, cv::DIST_L2, 3);
    cv::min(dist, static_cast<double>(kTrunc), dist);

    // Depth discontinuities, foreground side: a pixel more than 5 % nearer
    // than one of its 4-neighbours.
    std::vector<cv::Point> pts;
    for (int v = kMaxDy + 1; v < depth.rows - kMaxDy - 1; ++v) {
        for (int u = kMaxDx + 1; u < depth.cols - kMaxDx - 1; ++u) {
            const float z = depth.at<float>(v, u);
            if (!validDepth(z)) {
                continue;
            }
            const std::array<float, 4> nb = {depth.at<float>(v, u + 1), depth.at<float>(v, u - 1),
                                             depth.at<float>(v + 1, u), depth.at<float>(v - 1, u)};
            for (const float zn : nb) {
                if (validDepth(zn) && zn - z > 0.05F * z) {
                    pts.emplace_back(u, v);
                    break;
                }
            }
        }
    }
    if (pts.size() < 300) {
        return s;
    }
    const auto score = [&](int dx, int dy) {
        double sum = 0;
        for (const cv::Point& p : pts) {
            sum += static_cast<double>(dist.at<float>(p.y + dy, p.x + dx));
        }
        return sum / static_cast<double>(pts.size());
    };
    s.zero_score = score(0, 0);
    s.score = s.zero_score;
    // Coarse (2 px) then fine search; ties keep the smaller shift.
    for (int dy = -kMaxDy; dy <= kMaxDy; dy += 2) {
        for (int dx = -kMaxDx; dx <= kMaxDx; dx += 2) {
            const double c = score(dx, dy);
            if (c < s.score) {
                s.score = c;
                s.dx = dx;
                s.dy = dy;
            }
        }
    }
    const int cx = s.dx;
    const int cy = s.dy;
    for (int dy = std::max(-kMaxDy, cy - 1); dy <= std::min(kMaxDy, cy + 1); ++dy) {
        for (int dx = std::max(-kMaxDx, cx - 1); dx <= std::min(kMaxDx, cx + 1); ++dx) {
            const double c = score(dx, dy);
            if (c < s.score) {
                s.score = c;
                s.dx = dx;
                s.dy = dy;
            }
        }
    }
    s.ok = s.score < 0.85 * s.zero_score;
    if (!s.ok) {
        s.dx = 0;
        s.dy = 0;
    }
    return s;
}

namespace {

// Bins of the core's depth histogram (metres, from kMinDepthM).
constexpr double kCoreBinM = 0.02;
constexpr int kCoreBins = static_cast<int>((kMaxDepthM - kMinDepthM) / kCoreBinM) + 1;

// A detection box in depth pixels (moved by the colour-to-depth shift).
struct BoxInDepth {
    int width_px = 0;  // the depth image
    int height_px = 0;
    double box_w_px = 0;  // the detection box (colour pixels)
    double box_h_px = 0;
    // The box grown vertically, clamped to the image (inclusive bounds).
    int x0 = 0;
    int x1 = 0;
    int y0 = 0;
    int y1 = 0;
    // The core: the central 50 % x 60 % of the box (inclusive, not clamped).
    int cx0 = 0;
    int cx1 = 0;
    int cy0 = 0;
    int cy1 = 0;

    [[nodiscard]] bool inCore(int u, int v) const {
        return u >= cx0 && u <= cx1 && v >= cy0 && v <= cy1;
    }
};

// The box in depth pixels, grown vertically by 8 % + 4 px on each side so
// that the residual misregistration cannot cut the object's top or
// bottom off (depth segmentation removes the background this adds), and its core.
BoxInDepth boxInDepth(const DepthView& view, const core::BoundingBox& box, const Shift& shift,
                      double bw, double bh) {
    BoxInDepth b;
    const int w = view.depth.cols;
    const int h = view.depth.rows;
    b.width_px = w;
    b.height_px = h;
    b.box_w_px = bw;
    b.box_h_px = bh;
    const double grow = 0.08 * bh + 4;
    b.x0 = std::clamp(static_cast<int>(std::lround(static_cast<double>(box.x_min_px) - shift.dx)),
                      0, w - 1);
    b.x1 = std::clamp(static_cast<int>(std::lround(static_cast<double>(box.x_max_px) - shift.dx)),
                      0, w - 1);
    b.y0 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.y_min_px) - shift.dy - grow)), 0,
        h - 1);
    b.y1 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.y_max_px) - shift.dy + grow)), 0,
        h - 1);
    b.cx0 = static_cast<int>(std::lround(static_cast<double>(box.x_min_px) - shift.dx + 0.25 * bw));
    b.cx1 = static_cast<int>(std::lround(static_cast<double>(box.x_max_px) - shift.dx - 0.25 * bw));
    b.cy0 = static_cast<int>(std::lround(static_cast<double>(box.y_min_px) - shift.dy + 0.2 * bh));
    b.cy1 = static_cast<int>(std::lround(static_cast<double>(box.y_max_px) - shift.dy - 0.2 * bh));
    return b;
}

// The histogram (kCoreBinM bins) of the valid depths of the core.
struct CoreDepths {
    std::vector<int> hist;
    int count = 0;  // valid pixels
};

CoreDepths coreDepthHistogram(const DepthView& view, const BoxInDepth& b) {
    CoreDepths c;
    c.hist.assign(static_cast<std::size_t>(kCoreBins), 0);
    for (int v = std::max(b.cy0, 0); v <= std::min(b.cy1, b.height_px - 1); ++v) {
        for (int u = std::max(b.cx0, 0); u <= std::min(b.cx1, b.width_px - 1); ++u) {
            const float z = view.depth.at<float>(v, u);
            if (validDepth(z)) {
                ++c.hist[static_cast<std::size_t>((static_cast<double>(z) - kMinDepthM) /
                                                  kCoreBinM)];
                ++c.count;
            }
        }
    }
    return c;
}

// Runs of bins holding >= 0.5 % of the core each, gaps of at most one
// bin; the nearest run with >= 15 % of the core is the object. Its first
// and last bins, or nothing.
std::optional<std::pair<int, int>> nearestDominantRun(const CoreDepths& c) {
    const int min_bin = std::max(2, c.count / 200);
    for (int b = 0; b < kCoreBins;) {
        if (c.hist[static_cast<std::size_t>(b)] < min_bin) {
            ++b;
            continue;
        }
        int e = b;
        int sum = 0;
        int gap = 0;
        for (int i = b; i < kCoreBins; ++i) {
            if (c.hist[static_cast<std::size_t>(i)] >= min_bin) {
                e = i;
                gap = 0;
            } else if (++gap > 1) {
                break;
            }
            sum += c.hist[static_cast<std::size_t>(i)];
        }
        if (sum >= 0.15 * c.count) {
            return std::pair{b, e};
        }
        b = e + 1;
    }
    return std::nullopt;
}

// The depths (metres) taken as the object's.
struct DepthBand {
    double near_m = 0;  // the run's nearest depth
    double lo_m = 0;
    double hi_m = 0;

    [[nodiscard]] bool contains(double z) const {
        return z >= kMinDepthM && z <= kMaxDepthM && z >= lo_m && z <= hi_m;
    }
};

// The band: the run of bins [run_lo, run_hi], at most ~1.2 box widths deep
// (an object is about as deep as it is wide), plus 3 cm of depth noise on
// each side.
DepthBand objectBand(const DepthView& view, const BoxInDepth& b, int run_lo, int run_hi) {
    DepthBand band;
    band.near_m = kMinDepthM + run_lo * kCoreBinM;
    const double width_m = b.box_w_px * band.near_m / static_cast<double>(view.k.fx);
    band.lo_m = band.near_m - 0.03;
    band.hi_m = std::min(kMinDepthM + (run_hi + 1) * kCoreBinM,
                         band.near_m + std::max(0.10, 1.2 * width_m)) +
                0.03;
    return band;
}

// The box pixels in the band, back-projected.
struct BandPixels {
    std::vector<float> heights;  // world up, metres
    std::vector<int> rows;       // their image rows
    // World coordinates of those in the core.
    std::vector<double> xs;
    std::vector<double> ys;
    std::vector<double> zs;
};

BandPixels collectBandPixels(const DepthView& view, const BoxInDepth& b, const DepthBand& band) {
    BandPixels px;
    for (int v = b.y0; v <= b.y1; ++v) {
        for (int u = b.x0; u <= b.x1; ++u) {
            const double z = view.depthAt(u, v);
            if (!band.contains(z)) {
                continue;
            }
            const core::Vec3 p = view.world(u, v, z);
            px.heights.push_back(static_cast<float>(view.height(p)));
            px.rows.push_back(v);
            if (b.inCore(u, v)) {
                px.xs.push_back(p.x());
                px.ys.push_back(p.y());
                px.zs.push_back(p.z());
            }
        }
    }
    return px;
}

// The best supported horizontal plane of the object pixels (a table's
// top dominates its box; cups, books and chair backs on or behind it
// make smaller peaks): its height, or nothing.
std::optional<double> topPlaneHeight(const std::vector<float>& heights) {
    const std::vector<Plane> planes = findPlanes(heights, 0.10);
    if (planes.empty()) {
        return std::nullopt;
    }
    const auto best =
        std::max_element(planes.begin(), planes.end(),
                         [](const Plane& a, const Plane& b) { return a.fraction < b.fraction; });
    return best->height_m;
}

// Occlusion check: the object's top must be seen near the box's top
// (else the nearest mode was something in front, e.g. a table edge
// before a chair). Tolerance: the residual misregistration.
bool topOccluded(const BandPixels& px, double top_m, const core::BoundingBox& box,
                 const Shift& shift, double bh) {
    std::vector<float> top_rows;
    for (std::size_t i = 0; i < px.heights.size(); ++i) {
        if (static_cast<double>(px.heights[i]) >= top_m - 0.03) {
            top_rows.push_back(static_cast<float>(px.rows[i]));
        }
    }
    const double top_row = percentile(top_rows, 0.05);
    return top_row - (static_cast<double>(box.y_min_px) - shift.dy) > std::max(0.2 * bh, 30.0);
}

// The plane an object on a counter stands on: the highest scene plane
// below the middle of the seed pixels (the core's pixels in the band), or null.
const Plane* supportingPlane(const DepthView& view, const BoxInDepth& b, const DepthBand& band,
                             const std::vector<Plane>& scene_planes) {
    std::vector<float> seed_heights;
    for (int v = std::max(b.cy0, 0); v <= std::min(b.cy1, b.height_px - 1); ++v) {
        for (int u = std::max(b.cx0, 0); u <= std::min(b.cx1, b.width_px - 1); ++u) {
            const double z = view.depthAt(u, v);
            if (band.contains(z)) {
                seed_heights.push_back(static_cast<float>(view.height(view.world(u, v, z))));
            }
        }
    }
    const double seed_mid = percentile(seed_heights, 0.5);
    const Plane* support = nullptr;
    for (const Plane& p : scene_planes) {
        if (p.height_m < seed_mid - 0.005) {
            support = &p;
        }
    }
    return support;
}

// Where an object on a counter is grown: the box widened by 30 px + 20 %
// (residual misregistration), clamped to the image.
cv::Rect searchWindow(const BoxInDepth& b, const core::BoundingBox& box, const Shift& shift) {
    const double bw = b.box_w_px;
    const double bh = b.box_h_px;
    const int gx = static_cast<int>(30 + 0.2 * bw);
    const int gy = static_cast<int>(30 + 0.2 * bh);
    return cv::Rect(static_cast<int>(static_cast<double>(box.x_min_px) - shift.dx) - gx,
                    static_cast<int>(static_cast<double>(box.y_min_px) - shift.dy) - gy,
                    static_cast<int>(bw) + 2 * gx, static_cast<int>(bh) + 2 * gy) &
           cv::Rect(0, 0, b.width_px, b.height_px);
}

// The plane as this frame sees it (the scene plane is pooled over all
// frames; pose and depth errors move it by ~1 cm between frames): the
// median of the window's pixels within 1.5 cm of it (narrow, so that
// the object's own lowest pixels barely pull it up).
double localPlaneHeight(const DepthView& view, const cv::Rect& win, const Plane& support) {
    std::vector<double> local;
    for (int v = win.y; v < win.y + win.height; ++v) {
        for (int u = win.x; u < win.x + win.width; ++u) {
            const double z = view.depthAt(u, v);
            if (z >= kMinDepthM && z <= kMaxDepthM) {
                const double hp = view.height(view.world(u, v, z));
                if (std::abs(hp - support.height_m) < 0.015) {
                    local.push_back(hp);
                }
            }
        }
    }
    return local.size() >= 50 ? median(local) : support.height_m;
}

// The depth-connected region above a plane, grown inside a window.
struct Region {
    cv::Mat seen;                // CV_8UC1, depth-image size: the region
    std::vector<float> heights;  // of its pixels
    int on_window_top_edge = 0;  // its pixels on the window's top row
};

// The region above `floor_h` (metres) grown from the core's pixels in
// the band inside `win`: 4-neighbours whose depth differs by at most
// 1 cm + 2 %.
Region growAbovePlane(const DepthView& view, const BoxInDepth& b, const DepthBand& band,
                      const cv::Rect& win, double floor_h) {
    Region r;
    r.seen = cv::Mat::zeros(b.height_px, b.width_px, CV_8UC1);
    std::vector<cv::Point> stack;
    const auto above = [&](int u, int v, double z) {
        return view.height(view.world(u, v, z)) > floor_h;
    };
    for (int v = std::max(b.cy0, 0); v <= std::min(b.cy1, b.height_px - 1); ++v) {
        for (int u = std::max(b.cx0, 0); u <= std::min(b.cx1, b.width_px - 1); ++u) {
            const double z = view.depthAt(u, v);
            if (band.contains(z) && above(u, v, z)) {
                r.seen.at<std::uint8_t>(v, u) = 255;
                stack.emplace_back(u, v);
            }
        }
    }
    while (!stack.empty()) {
        const cv::Point p = stack.back();
        stack.pop_back();
        const double z = view.depthAt(p.x, p.y);
        r.heights.push_back(static_cast<float>(view.height(view.world(p.x, p.y, z))));
        if (p.y == win.y) {
            ++r.on_window_top_edge;
        }
        const std::array<cv::Point, 4> nb = {cv::Point(p.x + 1, p.y), cv::Point(p.x - 1, p.y),
                                             cv::Point(p.x, p.y + 1), cv::Point(p.x, p.y - 1)};
        for (const cv::Point& q : nb) {
            if (!win.contains(q) || r.seen.at<std::uint8_t>(q.y, q.x) != 0) {
                continue;
            }
            const double zq = view.depthAt(q.x, q.y);
            if (zq < kMinDepthM || zq > kMaxDepthM || std::abs(zq - z) > 0.01 + 0.02 * z ||
                !above(q.x, q.y, zq)) {
                continue;
            }
            r.seen.at<std::uint8_t>(q.y, q.x) = 255;
            stack.push_back(q);
        }
    }
    return r;
}

// Objects on counters: the plane they stand on is the highest scene
// plane below the middle of the seed pixels; the object is the
// depth-connected region above it (1 cm) grown from the seeds inside
// the box widened by 30 px + 20 % (residual misregistration), so a
// box that does not sit exactly on the object in the depth image
// neither cuts its top off nor takes in the counter. Sets m's pixels,
// top and bottom (and mask); false with m.reject set when it cannot.
bool measureOnSupport(const DepthView& view, const BoxInDepth& b, const DepthBand& band,
                      const core::BoundingBox& box, const Shift& shift,
                      const std::vector<Plane>& scene_planes, bool keep_mask, ViewMeasurement& m) {
    const Plane* support = supportingPlane(view, b, band, scene_planes);
    if (support == nullptr) {
        m.reject = "no supporting plane";
        return false;
    }
    const cv::Rect win = searchWindow(b, box, shift);
    const double support_h = localPlaneHeight(view, win, *support);
    // Object pixels: 2 cm above the plane (its depth noise and roughness).
    const double floor_h = support_h + 0.02;
    const Region region = growAbovePlane(view, b, band, win, floor_h);
    if (region.heights.size() < 50) {
        m.reject = "too few object pixels above the supporting plane";
        return false;
    }
    if (region.on_window_top_edge > 3) {
        m.reject = "object region leaves the search window at the top";
        return false;
    }
    const double lowest = percentile(region.heights, 0.01);
    if (lowest > support_h + 0.05) {
        m.reject = "object does not reach the supporting plane (occluded?)";
        return false;
    }
    m.pixels = static_cast<int>(region.heights.size());
    m.top_m = percentile(region.heights, 0.99);
    m.bottom_m = support_h;
    if (keep_mask) {
        m.mask = region.seen;
    }
    return true;
}

// The mask of the box pixels in the band.
cv::Mat bandMask(const DepthView& view, const BoxInDepth& b, const DepthBand& band) {
    cv::Mat mask = cv::Mat::zeros(b.height_px, b.width_px, CV_8UC1);
    for (int v = b.y0; v <= b.y1; ++v) {
        for (int u = b.x0; u <= b.x1; ++u) {
            if (band.contains(view.depthAt(u, v))) {
                mask.at<std::uint8_t>(v, u) = 255;
            }
        }
    }
    return mask;
}

}  // namespace

ViewMeasurement measureView(const DepthView& view, const core::BoundingBox& box, const Shift& shift,
                            const ClassRule& rule, const std::vector<Plane>& scene_planes,
                            bool keep_mask) {
    ViewMeasurement m;
    const double bw = box.x_max_px - box.x_min_px;
    const double bh = box.y_max_px - box.y_min_px;
    if (bw < 8 || bh < 8) {
        m.reject = "box too small";
        return m;
    }
    const BoxInDepth b = boxInDepth(view, box, shift, bw, bh);
    m.depth_box = cv::Rect(b.x0, b.y0, b.x1 - b.x0 + 1, b.y1 - b.y0 + 1);

    // 1. The core (central 50 % x 60 % of the box): its nearest dominant depth mode.
    const CoreDepths core_depths = coreDepthHistogram(view, b);
    if (core_depths.count < 50) {
        m.reject = "no depth in the box centre";
        return m;
    }
    const auto run = nearestDominantRun(core_depths);
    if (!run) {
        m.reject = "no dominant depth mode";
        return m;
    }
    const DepthBand band = objectBand(view, b, run->first, run->second);
    m.near_m = band.near_m;

    // 2. Every box pixel in the band is the object; back-project them.
    const BandPixels px = collectBandPixels(view, b, band);
    m.pixels = static_cast<int>(px.heights.size());
    if (m.pixels < 100 || px.xs.size() < 20) {
        m.reject = "too few object pixels";
        return m;
    }
    m.centroid_W =
        Eigen::Vector3d(median(px.xs), median(px.ys), median(px.zs)).cast<core::Scalar>();
    // 3. Top and bottom: 1st / 99th percentiles (flying pixels and noise).
    m.bottom_m = percentile(px.heights, 0.01);
    m.top_m = percentile(px.heights, 0.99);
    if (rule.top == TopRule::kPlane) {
        const std::optional<double> top_m = topPlaneHeight(px.heights);
        if (!top_m) {
            m.reject = "no horizontal top plane";
            return m;
        }
        m.top_m = *top_m;
    }
    if (rule.bottom == BottomRule::kFloor && rule.top == TopRule::kHighest &&
        topOccluded(px, m.top_m, box, shift, bh)) {
        m.reject = "object top not at the box top (occluded?)";
        return m;
    }
    if (rule.bottom == BottomRule::kObject) {
        if (!measureOnSupport(view, b, band, box, shift, scene_planes, keep_mask, m)) {
            return m;
        }
    } else if (keep_mask) {
        m.mask = bandMask(view, b, band);
    }
    m.ok = true;
    return m;
}

std::vector<int> groupInstances(const std::vector<core::Vec3>& centroids, const core::Vec3& up_W,
                                double radius_m) {
    const auto horizontal = [&](const core::Vec3& p) { return core::Vec3(p - up_W.dot(p) * up_W); };
    std::vector<std::vector<core::Vec3>> members;
    std::vector<core::Vec3> centres;
    const auto centreOf = [](const std::vector<core::Vec3>& ps) {
        std::vector<double> x;
        std::vector<double> y;
        std::vector<double> z;
        for (const core::Vec3& p : ps) {
            x.push_back(p.x());
            y.push_back(p.y());
            z.push_back(p.z());
        }
        return Eigen::Vector3d(median(x), median(y), median(z)).cast<core::Scalar>();
    };
    const auto nearest = [&](const core::Vec3& p) {
        int best = -1;
        double best_d = radius_m;
        for (std::size_t i = 0; i < centres.size(); ++i) {
            const double d = (horizontal(p) - horizontal(centres[i])).norm();
            if (d < best_d) {
                best_d = d;
                best = static_cast<int>(i);
            }
        }
        return best;
    };
    for (const core::Vec3& p : centroids) {
        const int i = nearest(p);
        if (i < 0) {
            members.push_back({p});
            centres.push_back(p);
        } else {
            members[static_cast<std::size_t>(i)].push_back(p);
            centres[static_cast<std::size_t>(i)] = centreOf(members[static_cast<std::size_t>(i)]);
        }
    }
    std::vector<int> out;
    out.reserve(centroids.size());
    for (const core::Vec3& p : centroids) {
        int i = nearest(p);
        if (i < 0) {  // its centre moved away: the nearest at any distance
            double best_d = 1e300;
            for (std::size_t j = 0; j < centres.size(); ++j) {
                const double d = (horizontal(p) - horizontal(centres[j])).norm();
                if (d < best_d) {
                    best_d = d;
                    i = static_cast<int>(j);
                }
            }
        }
        out.push_back(i);
    }
    return out;
}

}  // namespace scaled::tools::heights
