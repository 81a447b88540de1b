#pragma once

// Ray casting and texture sampling shared by Scene and Renderer, in double
// precision on plain arrays so the per-pixel loop stays cheap.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include <scaled/drivers/synth/scene.h>

namespace scaled::drivers::synth::detail {

struct BoxD {
    double lo[3] = {0, 0, 0};
    double hi[3] = {0, 0, 0};
};

inline BoxD toBoxD(const Aabb& b) {
    BoxD d;
    for (int a = 0; a < 3; ++a) {
        d.lo[a] = static_cast<double>(b.min_m[a]);
        d.hi[a] = static_cast<double>(b.max_m[a]);
    }
    return d;
}

// The room and the furniture as plain arrays.
struct GeometryD {
    BoxD room;
    std::vector<BoxD> boxes;
};

inline GeometryD toGeometryD(const Scene& scene) {
    GeometryD g;
    g.room = toBoxD(scene.room());
    g.boxes.reserve(scene.furniture().size());
    for (const auto& b : scene.furniture()) {
        g.boxes.push_back(toBoxD(b));
    }
    return g;
}

// Nearest hit of o + t d, t > 0, with the room (seen from inside) and the boxes
// (seen from outside). Returns the surface index (see RayHit) or -1.
inline int intersectScene(const GeometryD& g, const double o[3], const double d[3], double* t_hit) {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    const double inv[3] = {1.0 / d[0], 1.0 / d[1], 1.0 / d[2]};
    double t_best = kInf;
    int face = -1;
    for (int a = 0; a < 3; ++a) {
        if (d[a] > 0) {
            const double t = (g.room.hi[a] - o[a]) * inv[a];
            if (t < t_best) {
                t_best = t;
                face = 2 * a + 1;
            }
        } else if (d[a] < 0) {
            const double t = (g.room.lo[a] - o[a]) * inv[a];
            if (t < t_best) {
                t_best = t;
                face = 2 * a;
            }
        }
    }
    const int n_boxes = static_cast<int>(g.boxes.size());
    for (int k = 0; k < n_boxes; ++k) {
        const BoxD& b = g.boxes[static_cast<std::size_t>(k)];
        double t_near = -kInf;
        double t_far = t_best;
        int near_face = -1;
        bool miss = false;
        for (int a = 0; a < 3 && !miss; ++a) {
            if (d[a] == 0) {
                miss = o[a] < b.lo[a] || o[a] > b.hi[a];
                continue;
            }
            double t0 = (b.lo[a] - o[a]) * inv[a];
            double t1 = (b.hi[a] - o[a]) * inv[a];
            int side = 0;
            if (t0 > t1) {
                std::swap(t0, t1);
                side = 1;
            }
            if (t0 > t_near) {
                t_near = t0;
                near_face = 2 * a + side;
            }
            t_far = std::min(t_far, t1);
            miss = t_near > t_far;
        }
        if (!miss && near_face >= 0 && t_near > 0 && t_near < t_best) {
            t_best = t_near;
            face = 6 + 6 * k + near_face;
        }
    }
    *t_hit = t_best;
    return face;
}

// A face's texture as plain data.
struct FaceView {
    const std::uint8_t* data = nullptr;
    std::size_t step = 0;
    int cols = 0;
    int rows = 0;
    int axis_col = 0;
    int axis_row = 0;
    double col0_m = 0;
    double row0_m = 0;
    double inv_texel = 0;
};

inline FaceView toFaceView(const Scene::Face& f) {
    FaceView v;
    v.data = f.texture.ptr<std::uint8_t>(0);
    v.step = f.texture.step[0];
    v.cols = f.texture.cols;
    v.rows = f.texture.rows;
    v.axis_col = f.axis_col;
    v.axis_row = f.axis_row;
    v.col0_m = f.col0_m;
    v.row0_m = f.row0_m;
    v.inv_texel = f.inv_texel;
    return v;
}

inline std::vector<FaceView> toFaceViews(const Scene& scene) {
    std::vector<FaceView> views;
    views.reserve(scene.faces().size());
    for (const auto& f : scene.faces()) {
        views.push_back(toFaceView(f));
    }
    return views;
}

// Bilinear texture value at the world point p on face f, in [0, 255].
inline float sampleFace(const FaceView& f, const double p[3]) {
    double u = (p[f.axis_col] - f.col0_m) * f.inv_texel;
    double v = (f.row0_m - p[f.axis_row]) * f.inv_texel;
    u = std::clamp(u, 0.0, static_cast<double>(f.cols - 1));
    v = std::clamp(v, 0.0, static_cast<double>(f.rows - 1));
    const int iu = std::min(static_cast<int>(u), f.cols - 2);
    const int iv = std::min(static_cast<int>(v), f.rows - 2);
    const auto fu = static_cast<float>(u - iu);
    const auto fv = static_cast<float>(v - iv);
    const std::uint8_t* r0 =
        f.data + static_cast<std::size_t>(iv) * f.step + static_cast<std::size_t>(iu);
    const std::uint8_t* r1 = r0 + f.step;
    const float top = static_cast<float>(r0[0]) + fu * static_cast<float>(r0[1] - r0[0]);
    const float bottom = static_cast<float>(r1[0]) + fu * static_cast<float>(r1[1] - r1[0]);
    return top + fv * (bottom - top);
}

}  // namespace scaled::drivers::synth::detail
