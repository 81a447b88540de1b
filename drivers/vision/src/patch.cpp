#include <algorithm>
#include <cmath>

#include <scaled/drivers/vision/patch.h>

namespace scaled::drivers::vision {

using core::Mat2;
using core::Vec2;

std::optional<Patch> extractPatch(const cv::Mat& gray, const Vec2& px, int size, int source_size) {
    Patch patch;
    if (!extractPatchInto(gray, px, size, source_size, patch)) {
        return std::nullopt;
    }
    return patch;
}

bool extractPatchInto(const cv::Mat& gray, const Vec2& px, int size, int source_size,
                      Patch& patch) {
    if (gray.empty() || gray.type() != CV_8UC1) {
        return false;
    }
    if (size < 1 || size % 2 == 0 || source_size < size || source_size % 2 == 0) {
        return false;
    }
    const double x = static_cast<double>(px.x());
    const double y = static_cast<double>(px.y());
    if (!std::isfinite(x) || !std::isfinite(y)) {
        return false;
    }
    const int half = source_size / 2;
    const double left = x - half;
    const double top = y - half;
    // Top-left source sample and the bilinear weights (the same for every sample).
    const double x0f = std::floor(left);
    const double y0f = std::floor(top);
    const double ax = left - x0f;
    const double ay = top - y0f;
    // The template square must lie in the image; the rest of the source may
    // leave it and takes the nearest border pixel there (it feeds warped and
    // coarse-level templates only). A zero weight needs no neighbour, so
    // integer positions may touch the border.
    const int off = half - size / 2;
    const double t_last_x = x0f + off + (size - 1) + (ax > 0 ? 1 : 0);
    const double t_last_y = y0f + off + (size - 1) + (ay > 0 ? 1 : 0);
    if (x0f + off < 0 || y0f + off < 0 || t_last_x > gray.cols - 1 || t_last_y > gray.rows - 1) {
        return false;
    }
    const int x0 = static_cast<int>(x0f);
    const int y0 = static_cast<int>(y0f);
    const auto wx = static_cast<float>(ax);
    const auto wy = static_cast<float>(ay);
    const int last_col = gray.cols - 1;
    const int last_row = gray.rows - 1;
    const bool inside =
        x0 >= 0 && y0 >= 0 && x0 + source_size <= last_col && y0 + source_size <= last_row;

    patch.size = size;
    // A template that views the source (a shallow copy) must not alias the
    // pixels written below; give it its own buffer.
    if (patch.templ.datastart != nullptr && patch.templ.datastart == patch.source.datastart) {
        patch.templ.release();
    }
    patch.source.create(source_size, source_size, CV_32FC1);
    for (int i = 0; i < source_size; ++i) {
        const int ya = std::clamp(y0 + i, 0, last_row);
        const int yb = std::clamp(y0 + i + 1, 0, last_row);
        const uchar* r0 = gray.ptr<uchar>(ya);
        const uchar* r1 = gray.ptr<uchar>(yb);
        auto* dst = patch.source.ptr<float>(i);
        for (int j = 0; j < source_size; ++j) {
            int xa = x0 + j;
            int xb = xa + 1;
            if (!inside) {
                xa = std::clamp(xa, 0, last_col);
                xb = std::clamp(xb, 0, last_col);
            }
            const float top_v =
                (1.0F - wx) * static_cast<float>(r0[xa]) + wx * static_cast<float>(r0[xb]);
            const float bottom_v =
                (1.0F - wx) * static_cast<float>(r1[xa]) + wx * static_cast<float>(r1[xb]);
            dst[j] = (1.0F - wy) * top_v + wy * bottom_v;
        }
    }
    patch.source(cv::Rect(off, off, size, size)).copyTo(patch.templ);
    return true;
}

void warpTemplate(Patch& patch, const Mat2& A) {
    const cv::Mat& src = patch.source;
    if (src.empty() || src.type() != CV_32FC1 || src.rows != src.cols || src.cols % 2 == 0) {
        return;
    }
    const int size = patch.size;
    if (size < 1 || size % 2 == 0 || size > src.cols || !A.allFinite()) {
        return;
    }
    const auto a00 = static_cast<float>(A(0, 0));
    const auto a01 = static_cast<float>(A(0, 1));
    const auto a10 = static_cast<float>(A(1, 0));
    const auto a11 = static_cast<float>(A(1, 1));
    const int half_t = size / 2;
    const int centre_px = src.cols / 2;
    const auto centre = static_cast<float>(centre_px);
    const auto max_coord = static_cast<float>(src.cols - 1);
    const int last = src.cols - 1;

    if (patch.templ.datastart != nullptr && patch.templ.datastart == src.datastart) {
        patch.templ.release();  // a view into the source: never overwrite the source
    }
    patch.templ.create(size, size, CV_32FC1);
    for (int i = 0; i < size; ++i) {
        const auto d_y = static_cast<float>(i - half_t);
        auto* dst = patch.templ.ptr<float>(i);
        for (int j = 0; j < size; ++j) {
            const auto d_x = static_cast<float>(j - half_t);
            // Clamping the coordinate gives the nearest border value outside.
            const float sx = std::clamp(centre + a00 * d_x + a01 * d_y, 0.0F, max_coord);
            const float sy = std::clamp(centre + a10 * d_x + a11 * d_y, 0.0F, max_coord);
            const int x0 = std::min(static_cast<int>(sx), last - 1 < 0 ? 0 : last - 1);
            const int y0 = std::min(static_cast<int>(sy), last - 1 < 0 ? 0 : last - 1);
            const int x1 = std::min(x0 + 1, last);
            const int y1 = std::min(y0 + 1, last);
            const float wx = sx - static_cast<float>(x0);
            const float wy = sy - static_cast<float>(y0);
            const auto* r0 = src.ptr<float>(y0);
            const auto* r1 = src.ptr<float>(y1);
            const float top_v = (1.0F - wx) * r0[x0] + wx * r0[x1];
            const float bottom_v = (1.0F - wx) * r1[x0] + wx * r1[x1];
            dst[j] = (1.0F - wy) * top_v + wy * bottom_v;
        }
    }
}

}  // namespace scaled::drivers::vision
