#include "measure.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <opencv2/imgproc.hpp>

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

ViewMeasurement measureView(const DepthView& view, const core::BoundingBox& box, const Shift& shift,
                            const ClassRule& rule, const std::vector<Plane>& scene_planes,
                            bool keep_mask) {
    ViewMeasurement m;
    const int w = view.depth.cols;
    const int h = view.depth.rows;
    const double bw = box.x_max_px - box.x_min_px;
    const double bh = box.y_max_px - box.y_min_px;
    if (bw < 8 || bh < 8) {
        m.reject = "box too small";
        return m;
    }
    // The box in depth pixels, grown vertically by 8 % + 4 px on each side so
    // that the residual misregistration cannot cut the object's top or
    // bottom off (depth segmentation removes the background this adds).
    const double grow = 0.08 * bh + 4;
    const int x0 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.x_min_px) - shift.dx)), 0, w - 1);
    const int x1 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.x_max_px) - shift.dx)), 0, w - 1);
    const int y0 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.y_min_px) - shift.dy - grow)), 0,
        h - 1);
    const int y1 = std::clamp(
        static_cast<int>(std::lround(static_cast<double>(box.y_max_px) - shift.dy + grow)), 0,
        h - 1);
    m.depth_box = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);

    // 1. The core (central 50 % x 60 % of the box): its nearest dominant depth mode.
    const int cx0 =
        static_cast<int>(std::lround(static_cast<double>(box.x_min_px) - shift.dx + 0.25 * bw));
    const int cx1 =
        static_cast<int>(std::lround(static_cast<double>(box.x_max_px) - shift.dx - 0.25 * bw));
    const int cy0 =
        static_cast<int>(std::lround(static_cast<double>(box.y_min_px) - shift.dy + 0.2 * bh));
    const int cy1 =
        static_cast<int>(std::lround(static_cast<double>(box.y_max_px) - shift.dy - 0.2 * bh));
    constexpr double kBin = 0.02;
    const int nbins = static_cast<int>((kMaxDepthM - kMinDepthM) / kBin) + 1;
    std::vector<int> hist(static_cast<std::size_t>(nbins), 0);
    int core_n = 0;
    for (int v = std::max(cy0, 0); v <= std::min(cy1, h - 1); ++v) {
        for (int u = std::max(cx0, 0); u <= std::min(cx1, w - 1); ++u) {
            const float z = view.depth.at<float>(v, u);
            if (validDepth(z)) {
                ++hist[static_cast<std::size_t>((static_cast<double>(z) - kMinDepthM) / kBin)];
                ++core_n;
            }
        }
    }
    if (core_n < 50) {
        m.reject = "no depth in the box centre";
        return m;
    }
    // Runs of bins holding >= 0.5 % of the core each, gaps of at most one
    // bin; the nearest run with >= 15 % of the core is the object.
    const int min_bin = std::max(2, core_n / 200);
    int run_lo = -1;
    int run_hi = -1;
    for (int b = 0; b < nbins;) {
        if (hist[static_cast<std::size_t>(b)] < min_bin) {
            ++b;
            continue;
        }
        int e = b;
        int sum = 0;
        int gap = 0;
        for (int i = b; i < nbins; ++i) {
            if (hist[static_cast<std::size_t>(i)] >= min_bin) {
                e = i;
                gap = 0;
            } else if (++gap > 1) {
                break;
            }
            sum += hist[static_cast<std::size_t>(i)];
        }
        if (sum >= 0.15 * core_n) {
            run_lo = b;
            run_hi = e;
            break;
        }
        b = e + 1;
    }
    if (run_lo < 0) {
        m.reject = "no dominant depth mode";
        return m;
    }
    m.near_m = kMinDepthM + run_lo * kBin;
    // The band: the run, at most ~1.2 box widths deep (an object is about as
    // deep as it is wide), plus 3 cm of depth noise on each side.
    const double width_m = bw * m.near_m / static_cast<double>(view.k.fx);
    const double band_lo = m.near_m - 0.03;
    const double band_hi =
        std::min(kMinDepthM + (run_hi + 1) * kBin, m.near_m + std::max(0.10, 1.2 * width_m)) + 0.03;

    // 2. Every box pixel in the band is the object; back-project them.
    std::vector<float> heights;
    std::vector<int> rows;
    std::vector<double> xs;
    std::vector<double> ys;
    std::vector<double> zs;
    const auto inCore = [&](int u, int v) { return u >= cx0 && u <= cx1 && v >= cy0 && v <= cy1; };
    const auto inBand = [&](double z) {
        return z >= kMinDepthM && z <= kMaxDepthM && z >= band_lo && z <= band_hi;
    };
    for (int v = y0; v <= y1; ++v) {
        for (int u = x0; u <= x1; ++u) {
            const double z = view.depthAt(u, v);
            if (!inBand(z)) {
                continue;
            }
            const core::Vec3 p = view.world(u, v, z);
            heights.push_back(static_cast<float>(view.height(p)));
            rows.push_back(v);
            if (inCore(u, v)) {
                xs.push_back(p.x());
                ys.push_back(p.y());
                zs.push_back(p.z());
            }
        }
    }
    m.pixels = static_cast<int>(heights.size());
    if (m.pixels < 100 || xs.size() < 20) {
        m.reject = "too few object pixels";
        return m;
    }
    m.centroid_W = Eigen::Vector3d(median(xs), median(ys), median(zs)).cast<core::Scalar>();
    // 3. Top and bottom: 1st / 99th percentiles (flying pixels and noise).
    m.bottom_m = percentile(heights, 0.01);
    m.top_m = percentile(heights, 0.99);
    if (rule.top == TopRule::kPlane) {
        // The best supported horizontal plane of the object pixels (a table's
        // top dominates its box; cups, books and chair backs on or behind it
        // make smaller peaks).
        const std::vector<Plane> planes = findPlanes(heights, 0.10);
        if (planes.empty()) {
            m.reject = "no horizontal top plane";
            return m;
        }
        const auto best = std::max_element(
            planes.begin(), planes.end(),
            [](const Plane& a, const Plane& b) { return a.fraction < b.fraction; });
        m.top_m = best->height_m;
    }
    if (rule.bottom == BottomRule::kFloor && rule.top == TopRule::kHighest) {
        // Occlusion check: the object's top must be seen near the box's top
        // (else the nearest mode was something in front, e.g. a table edge
        // before a chair). Tolerance: the residual misregistration.
        std::vector<float> top_rows;
        for (std::size_t i = 0; i < heights.size(); ++i) {
            if (static_cast<double>(heights[i]) >= m.top_m - 0.03) {
                top_rows.push_back(static_cast<float>(rows[i]));
            }
        }
        const double top_row = percentile(top_rows, 0.05);
        if (top_row - (static_cast<double>(box.y_min_px) - shift.dy) > std::max(0.2 * bh, 30.0)) {
            m.reject = "object top not at the box top (occluded?)";
            return m;
        }
    }
    if (rule.bottom == BottomRule::kObject) {
        // Objects on counters: the plane they stand on is the highest scene
        // plane below the middle of the seed pixels; the object is the
        // depth-connected region above it (1 cm) grown from the seeds inside
        // the box widened by 30 px + 20 % (residual misregistration), so a
        // box that does not sit exactly on the object in the depth image
        // neither cuts its top off nor takes in the counter.
        std::vector<float> seed_heights;
        for (int v = std::max(cy0, 0); v <= std::min(cy1, h - 1); ++v) {
            for (int u = std::max(cx0, 0); u <= std::min(cx1, w - 1); ++u) {
                const double z = view.depthAt(u, v);
                if (inBand(z)) {
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
        if (support == nullptr) {
            m.reject = "no supporting plane";
            return m;
        }
        const int gx = static_cast<int>(30 + 0.2 * bw);
        const int gy = static_cast<int>(30 + 0.2 * bh);
        const cv::Rect win =
            cv::Rect(static_cast<int>(static_cast<double>(box.x_min_px) - shift.dx) - gx,
                     static_cast<int>(static_cast<double>(box.y_min_px) - shift.dy) - gy,
                     static_cast<int>(bw) + 2 * gx, static_cast<int>(bh) + 2 * gy) &
            cv::Rect(0, 0, w, h);
        // The plane as this frame sees it (the scene plane is pooled over all
        // frames; pose and depth errors move it by ~1 cm between frames): the
        // median of the window's pixels within 1.5 cm of it (narrow, so that
        // the object's own lowest pixels barely pull it up).
        std::vector<double> local;
        for (int v = win.y; v < win.y + win.height; ++v) {
            for (int u = win.x; u < win.x + win.width; ++u) {
                const double z = view.depthAt(u, v);
                if (z >= kMinDepthM && z <= kMaxDepthM) {
                    const double hp = view.height(view.world(u, v, z));
                    if (std::abs(hp - support->height_m) < 0.015) {
                        local.push_back(hp);
                    }
                }
            }
        }
        const double support_h = local.size() >= 50 ? median(local) : support->height_m;
        // Object pixels: 2 cm above the plane (its depth noise and roughness).
        const double floor_h = support_h + 0.02;
        cv::Mat seen = cv::Mat::zeros(h, w, CV_8UC1);
        std::vector<cv::Point> stack;
        std::vector<float> comp;
        int on_top_edge = 0;
        const auto above = [&](int u, int v, double z) {
            return view.height(view.world(u, v, z)) > floor_h;
        };
        for (int v = std::max(cy0, 0); v <= std::min(cy1, h - 1); ++v) {
            for (int u = std::max(cx0, 0); u <= std::min(cx1, w - 1); ++u) {
                const double z = view.depthAt(u, v);
                if (inBand(z) && above(u, v, z)) {
                    seen.at<std::uint8_t>(v, u) = 255;
                    stack.emplace_back(u, v);
                }
            }
        }
        while (!stack.empty()) {
            const cv::Point p = stack.back();
            stack.pop_back();
            const double z = view.depthAt(p.x, p.y);
            comp.push_back(static_cast<float>(view.height(view.world(p.x, p.y, z))));
            if (p.y == win.y) {
                ++on_top_edge;
            }
            const std::array<cv::Point, 4> nb = {cv::Point(p.x + 1, p.y), cv::Point(p.x - 1, p.y),
                                                 cv::Point(p.x, p.y + 1), cv::Point(p.x, p.y - 1)};
            for (const cv::Point& q : nb) {
                if (!win.contains(q) || seen.at<std::uint8_t>(q.y, q.x) != 0) {
                    continue;
                }
                const double zq = view.depthAt(q.x, q.y);
                if (zq < kMinDepthM || zq > kMaxDepthM || std::abs(zq - z) > 0.01 + 0.02 * z ||
                    !above(q.x, q.y, zq)) {
                    continue;
                }
                seen.at<std::uint8_t>(q.y, q.x) = 255;
                stack.push_back(q);
            }
        }
        if (comp.size() < 50) {
            m.reject = "too few object pixels above the supporting plane";
            return m;
        }
        if (on_top_edge > 3) {
            m.reject = "object region leaves the search window at the top";
            return m;
        }
        const double lowest = percentile(comp, 0.01);
        if (lowest > support_h + 0.05) {
            m.reject = "object does not reach the supporting plane (occluded?)";
            return m;
        }
        m.pixels = static_cast<int>(comp.size());
        m.top_m = percentile(comp, 0.99);
        m.bottom_m = support_h;
        if (keep_mask) {
            m.mask = seen;
        }
    } else if (keep_mask) {
        m.mask = cv::Mat::zeros(h, w, CV_8UC1);
        for (int v = y0; v <= y1; ++v) {
            for (int u = x0; u <= x1; ++u) {
                if (inBand(view.depthAt(u, v))) {
                    m.mask.at<std::uint8_t>(v, u) = 255;
                }
            }
        }
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
