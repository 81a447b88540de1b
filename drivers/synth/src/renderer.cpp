#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>

#include <Eigen/Core>

#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/rng.h>

#include "raycast.h"

namespace scaled::drivers::synth {

namespace {

// Four rays at once: one pixel's 2x2 samples, or four pixels. Single precision
// in camera-centred coordinates (the room is a few metres across: micrometres).
using Arr = Eigen::Array4f;
using Mask = Eigen::Array<bool, 4, 1>;  // evaluated: Eigen comparisons are lazy

constexpr std::size_t kGroup = 4;
constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
// Texture coordinates stay below size - kEdge, so bilinear reads stay inside.
constexpr float kEdge = 1.001f;

bool sameIntrinsics(const core::CameraIntrinsics& a, const core::CameraIntrinsics& b) {
    return a.fx == b.fx && a.fy == b.fy && a.cx == b.cx && a.cy == b.cy && a.k1 == b.k1 &&
           a.k2 == b.k2 && a.width_px == b.width_px && a.height_px == b.height_px;
}

std::array<float, 2> rayAt(const core::PinholeRadialCamera& cam, double u, double v) {
    const auto ray = cam.unproject(Vec2(static_cast<Scalar>(u), static_cast<Scalar>(v)));
    if (!ray) {
        return {kNan, kNan};
    }
    return {static_cast<float>(ray->x()), static_cast<float>(ray->y())};
}

// A box relative to the camera centre.
struct BoxF {
    float lo[3];
    float hi[3];
    float first_face;  // surface index of its face 0
};

// Per-frame data: the pose, the room and the possibly visible boxes relative
// to the camera centre, and each face's texture offsets.
struct FrameData {
    float r[9];  // R_CtoW, row-major
    BoxF room;
    std::vector<BoxF> boxes;
    std::vector<detail::FaceView> faces;
    std::vector<float> col_off;  // texture column / row coordinate offsets, metres
    std::vector<float> row_off;
    std::vector<float> inv_texel;
};

// Whether a box can be seen by rays with x_u in [b[0], b[1]] and y_u in [b[2], b[3]]:
// false when all its corners lie outside one plane of that frustum.
bool maybeVisible(const detail::BoxD& box, const Eigen::Matrix3d& R_WtoC, const Eigen::Vector3d& o,
                  const float* b) {
    int out[5] = {0, 0, 0, 0, 0};
    for (int c = 0; c < 8; ++c) {
        const Eigen::Vector3d p_W((c & 1) != 0 ? box.hi[0] : box.lo[0],
                                  (c & 2) != 0 ? box.hi[1] : box.lo[1],
                                  (c & 4) != 0 ? box.hi[2] : box.lo[2]);
        const Eigen::Vector3d p = R_WtoC * (p_W - o);
        out[0] += p.z() <= 0 ? 1 : 0;
        out[1] += p.x() < static_cast<double>(b[0]) * p.z() ? 1 : 0;
        out[2] += p.x() > static_cast<double>(b[1]) * p.z() ? 1 : 0;
        out[3] += p.y() < static_cast<double>(b[2]) * p.z() ? 1 : 0;
        out[4] += p.y() > static_cast<double>(b[3]) * p.z() ? 1 : 0;
    }
    return std::none_of(std::begin(out), std::end(out), [](int n) { return n == 8; });
}

BoxF relativeBox(const detail::BoxD& b, const Eigen::Vector3d& o, int first_face) {
    BoxF r{};
    for (int a = 0; a < 3; ++a) {
        r.lo[a] = static_cast<float>(b.lo[a] - o[a]);
        r.hi[a] = static_cast<float>(b.hi[a] - o[a]);
    }
    r.first_face = static_cast<float>(first_face);
    return r;
}

FrameData makeFrame(const Scene& scene, const core::CameraPose& pose, const float* ray_bounds) {
    FrameData f{};
    const Eigen::Matrix3d R = pose.R_CtoW.cast<double>();
    const Eigen::Vector3d o = pose.p_CinW.cast<double>();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
            f.r[3 * i + j] = static_cast<float>(R(i, j));
        }
    }
    const detail::GeometryD g = detail::toGeometryD(scene);
    f.room = relativeBox(g.room, o, 0);
    const Eigen::Matrix3d R_WtoC = R.transpose();
    for (std::size_t k = 0; k < g.boxes.size(); ++k) {
        if (maybeVisible(g.boxes[k], R_WtoC, o, ray_bounds)) {
            f.boxes.push_back(relativeBox(g.boxes[k], o, 6 + 6 * static_cast<int>(k)));
        }
    }
    f.faces = detail::toFaceViews(scene);
    for (const auto& v : f.faces) {
        f.col_off.push_back(static_cast<float>(v.col0_m - o[v.axis_col]));
        f.row_off.push_back(static_cast<float>(v.row0_m - o[v.axis_row]));
        f.inv_texel.push_back(static_cast<float>(v.inv_texel));
    }
    return f;
}

// Ray parameters (= depths: the rays have z = 1) and surfaces hit by four rays;
// d receives the world directions. A NaN ray gives face -1.
void castGroup(const FrameData& f, const Arr& rx, const Arr& ry, Arr d[3], Arr* t_out,
               Arr* face_out) {
    const float* r = f.r;
    d[0] = r[0] * rx + r[1] * ry + r[2];
    d[1] = r[3] * rx + r[4] * ry + r[5];
    d[2] = r[6] * rx + r[7] * ry + r[8];
    const Arr inv[3] = {d[0].inverse(), d[1].inverse(), d[2].inverse()};
    const Arr zero = Arr::Zero();
    // The room, from inside: the nearest of the three exit planes.
    Arr t = (d[0] > zero).select(Arr::Constant(f.room.hi[0]), Arr::Constant(f.room.lo[0])) * inv[0];
    Arr face = (d[0] > zero).select(Arr::Constant(1.0f), Arr::Constant(0.0f));
    for (int a = 1; a < 3; ++a) {
        const Mask up = d[a] > zero;
        const Arr ta = up.select(Arr::Constant(f.room.hi[a]), Arr::Constant(f.room.lo[a])) * inv[a];
        const Mask nearer = ta < t;
        face = nearer.select(up.select(Arr::Constant(static_cast<float>(2 * a + 1)),
                                       Arr::Constant(static_cast<float>(2 * a))),
                             face);
        t = nearer.select(ta, t);
    }
    // The boxes, from outside (slab test).
    for (const BoxF& b : f.boxes) {
        Arr t_min[3];
        Arr t_near = Arr::Constant(-std::numeric_limits<float>::infinity());
        Arr t_far = t;
        for (int a = 0; a < 3; ++a) {
            const Arr t0 = b.lo[a] * inv[a];
            const Arr t1 = b.hi[a] * inv[a];
            t_min[a] = t0.min(t1);
            t_near = t_near.max(t_min[a]);
            t_far = t_far.min(t0.max(t1));
        }
        const Mask hit = (t_near <= t_far) && (t_near > zero) && (t_near < t);
        if (!hit.any()) {
            continue;
        }
        // Entry face: the axis whose slab is entered last, at its min side when moving up.
        Arr entry = (d[2] > zero).select(Arr::Constant(4.0f), Arr::Constant(5.0f));
        entry = (t_min[1] == t_near)
                    .select((d[1] > zero).select(Arr::Constant(2.0f), Arr::Constant(3.0f)), entry);
        entry = (t_min[0] == t_near)
                    .select((d[0] > zero).select(Arr::Constant(0.0f), Arr::Constant(1.0f)), entry);
        face = hit.select(entry + b.first_face, face);
        t = hit.select(t_near, t);
    }
    const Mask valid = !(rx.isNaN() || ry.isNaN()) && t > zero;  // false on NaN
    *t_out = t;
    *face_out = valid.select(face, Arr::Constant(-1.0f));
}

// Texture value of sample s of a group cast by castGroup.
float shadeOne(const FrameData& f, const Arr d[3], const Arr& t, const Arr& face, Eigen::Index s) {
    const float fs = face[s];
    if (fs < 0.0f) {
        return 0.0f;
    }
    const auto i = static_cast<std::size_t>(fs);
    const detail::FaceView& v = f.faces[i];
    const float ts = t[s];
    float u = (ts * d[v.axis_col][s] - f.col_off[i]) * f.inv_texel[i];
    float w = (f.row_off[i] - ts * d[v.axis_row][s]) * f.inv_texel[i];
    u = std::clamp(u, 0.0f, static_cast<float>(v.cols) - kEdge);
    w = std::clamp(w, 0.0f, static_cast<float>(v.rows) - kEdge);
    const int iu = static_cast<int>(u);
    const int iw = static_cast<int>(w);
    const float fu = u - static_cast<float>(iu);
    const float fw = w - static_cast<float>(iw);
    const std::uint8_t* r0 =
        v.data + static_cast<std::size_t>(iw) * v.step + static_cast<std::size_t>(iu);
    const std::uint8_t* r1 = r0 + v.step;
    const float top = static_cast<float>(r0[0]) + fu * static_cast<float>(r0[1] - r0[0]);
    const float bottom = static_cast<float>(r1[0]) + fu * static_cast<float>(r1[1] - r1[0]);
    return top + fw * (bottom - top);
}

// Texture values of the four samples of a group (bilinear, as shadeOne), four
// at a time when they hit the same surface (the common case).
Arr shadeGroup(const FrameData& f, const Arr d[3], const Arr& t, const Arr& face) {
    const float f0 = face[0];
    if (!(f0 >= 0.0f) || !(face == f0).all()) {
        return {shadeOne(f, d, t, face, 0), shadeOne(f, d, t, face, 1), shadeOne(f, d, t, face, 2),
                shadeOne(f, d, t, face, 3)};
    }
    const auto i = static_cast<std::size_t>(f0);
    const detail::FaceView& v = f.faces[i];
    const Arr u = ((t * d[v.axis_col] - f.col_off[i]) * f.inv_texel[i])
                      .max(0.0f)
                      .min(static_cast<float>(v.cols) - kEdge);
    const Arr w = ((f.row_off[i] - t * d[v.axis_row]) * f.inv_texel[i])
                      .max(0.0f)
                      .min(static_cast<float>(v.rows) - kEdge);
    const Eigen::Array4i iu = u.cast<int>();
    const Eigen::Array4i iw = w.cast<int>();
    const Arr fu = u - iu.cast<float>();
    const Arr fw = w - iw.cast<float>();
    Eigen::Array4i i00;
    Eigen::Array4i i01;
    Eigen::Array4i i10;
    Eigen::Array4i i11;
    for (Eigen::Index s = 0; s < 4; ++s) {
        const std::uint8_t* r0 =
            v.data + static_cast<std::size_t>(iw[s]) * v.step + static_cast<std::size_t>(iu[s]);
        const std::uint8_t* r1 = r0 + v.step;
        i00[s] = r0[0];
        i01[s] = r0[1];
        i10[s] = r1[0];
        i11[s] = r1[1];
    }
    const Arr c00 = i00.cast<float>();
    const Arr c01 = i01.cast<float>();
    const Arr c10 = i10.cast<float>();
    const Arr c11 = i11.cast<float>();
    const Arr top = c00 + fu * (c01 - c00);
    const Arr bottom = c10 + fu * (c11 - c10);
    return top + fw * (bottom - top);
}

std::uint8_t toGrey(double v) {
    return static_cast<std::uint8_t>(std::lrint(std::clamp(v, 0.0, 255.0)));
}

}  // namespace

Renderer::Renderer(const Scene& scene, RenderOptions options) : scene_(&scene), options_(options) {}

void Renderer::setOptions(const RenderOptions& options) {
    options_ = options;
}

void Renderer::prepareRays(const core::PinholeRadialCamera& cam) {
    const auto& k = cam.intrinsics();
    if (rays_valid_ && rays_antialias_ == options_.antialias &&
        sameIntrinsics(k, rays_intrinsics_)) {
        return;
    }
    const int w = cam.width();
    const int h = cam.height();
    const std::size_t n_px = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    centre_rays_.assign(2 * n_px, 0.0f);
    std::size_t i = 0;
    for (int row = 0; row < h; ++row) {
        for (int col = 0; col < w; ++col, ++i) {
            const auto ray = rayAt(cam, col, row);
            centre_rays_[2 * i] = ray[0];
            centre_rays_[2 * i + 1] = ray[1];
        }
    }
    if (options_.antialias) {
        // 2x2 samples on a regular grid at +-1/4 pixel around the centre.
        constexpr double kOffsets[kGroup][2] = {
            {-0.25, -0.25}, {0.25, -0.25}, {-0.25, 0.25}, {0.25, 0.25}};
        group_rays_.assign(2 * kGroup * n_px, 0.0f);
        i = 0;
        for (int row = 0; row < h; ++row) {
            for (int col = 0; col < w; ++col, ++i) {
                for (std::size_t s = 0; s < kGroup; ++s) {
                    const auto ray = rayAt(cam, col + kOffsets[s][0], row + kOffsets[s][1]);
                    group_rays_[2 * kGroup * i + s] = ray[0];
                    group_rays_[2 * kGroup * i + kGroup + s] = ray[1];
                }
            }
        }
    } else {
        // Four consecutive pixels per group; the last group is padded with NaN rays.
        const std::size_t n_groups = (n_px + kGroup - 1) / kGroup;
        group_rays_.assign(2 * kGroup * n_groups, kNan);
        for (i = 0; i < n_px; ++i) {
            const std::size_t g = i / kGroup;
            const std::size_t s = i % kGroup;
            group_rays_[2 * kGroup * g + s] = centre_rays_[2 * i];
            group_rays_[2 * kGroup * g + kGroup + s] = centre_rays_[2 * i + 1];
        }
    }
    // Bounds of the undistorted field of view, for culling boxes.
    float bounds[4] = {
        std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
        std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
    for (std::size_t j = 0; j < group_rays_.size(); j += 2 * kGroup) {
        for (std::size_t s = 0; s < kGroup; ++s) {
            const float x = group_rays_[j + s];
            const float y = group_rays_[j + kGroup + s];
            if (!std::isnan(x) && !std::isnan(y)) {
                bounds[0] = std::min(bounds[0], x);
                bounds[1] = std::max(bounds[1], x);
                bounds[2] = std::min(bounds[2], y);
                bounds[3] = std::max(bounds[3], y);
            }
        }
    }
    std::copy(std::begin(bounds), std::end(bounds), std::begin(ray_bounds_));
    rays_intrinsics_ = k;
    rays_antialias_ = options_.antialias;
    rays_valid_ = true;
}

void Renderer::render(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                      cv::Mat& out_gray, cv::Mat* out_depth_m, std::uint64_t noise_stream) {
    renderImage(cam, pose, nullptr, out_gray, noise_stream);
    if (out_depth_m != nullptr) {
        renderDepth(cam, pose, *out_depth_m);
    }
}

bool Renderer::renderRows(const core::PinholeRadialCamera& cam,
                          const std::vector<core::CameraPose>& row_poses, cv::Mat& out_gray,
                          std::uint64_t noise_stream) {
    if (row_poses.size() != static_cast<std::size_t>(cam.height())) {
        return false;
    }
    renderImage(cam, row_poses.front(), row_poses.data(), out_gray, noise_stream);
    return true;
}

void Renderer::renderImage(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                           const core::CameraPose* row_poses, cv::Mat& out_gray,
                           std::uint64_t noise_stream) {
    prepareRays(cam);
    const int w = cam.width();
    const int h = cam.height();
    out_gray.create(h, w, CV_8UC1);
    FrameData frame = makeFrame(*scene_, pose, ray_bounds_);
    int frame_row = 0;
    // With a pose per row (a rolling shutter), the row's own view.
    const auto frameForRow = [&](int row) -> const FrameData& {
        if (row_poses != nullptr && row != frame_row) {
            frame = makeFrame(*scene_, row_poses[row], ray_bounds_);
            frame_row = row;
        }
        return frame;
    };
    const bool noisy = options_.noise_sigma > 0.0;
    SplitMix64 rng(combineSeed(options_.noise_seed, noise_stream));
    const auto noisyGrey = [&](float v) {
        double x = static_cast<double>(v);
        if (noisy) {
            x += options_.noise_sigma * rng.gaussian();
        }
        return toGrey(x);
    };

    Arr d[3];
    Arr t;
    Arr face;
    const float* rays = group_rays_.data();
    if (options_.antialias) {
        for (int row = 0; row < h; ++row) {
            auto* out = out_gray.ptr<std::uint8_t>(row);
            const FrameData& f = frameForRow(row);
            for (int col = 0; col < w; ++col, rays += 2 * kGroup) {
                castGroup(f, Eigen::Map<const Arr>(rays), Eigen::Map<const Arr>(rays + kGroup), d,
                          &t, &face);
                out[col] = noisyGrey(0.25f * shadeGroup(f, d, t, face).sum());
            }
        }
    } else {
        const std::size_t n_px = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
        const auto uw = static_cast<std::size_t>(w);
        for (std::size_t i = 0; i < n_px; i += kGroup, rays += 2 * kGroup) {
            // A group of four may end a row and begin the next: its first pixel's row.
            const FrameData& f = frameForRow(static_cast<int>(i / uw));
            castGroup(f, Eigen::Map<const Arr>(rays), Eigen::Map<const Arr>(rays + kGroup), d, &t,
                      &face);
            const Arr values = shadeGroup(f, d, t, face);
            for (std::size_t s = 0; s < kGroup && i + s < n_px; ++s) {
                const float v = values[static_cast<Eigen::Index>(s)];
                out_gray.ptr<std::uint8_t>(static_cast<int>((i + s) / uw))[(i + s) % uw] =
                    noisyGrey(v);
            }
        }
    }
}

void Renderer::renderDepth(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                           cv::Mat& out_depth_m) {
    // Exact depths, in double precision, at the pixel centres.
    prepareRays(cam);
    const int w = cam.width();
    const int h = cam.height();
    out_depth_m.create(h, w, CV_32FC1);
    const detail::GeometryD g = detail::toGeometryD(*scene_);
    const double o[3] = {static_cast<double>(pose.p_CinW.x()), static_cast<double>(pose.p_CinW.y()),
                         static_cast<double>(pose.p_CinW.z())};
    const Eigen::Matrix3d R = pose.R_CtoW.cast<double>();
    std::size_t i = 0;
    for (int row = 0; row < h; ++row) {
        auto* depth = out_depth_m.ptr<float>(row);
        for (int col = 0; col < w; ++col, ++i) {
            const auto x = static_cast<double>(centre_rays_[2 * i]);
            const auto y = static_cast<double>(centre_rays_[2 * i + 1]);
            const Eigen::Vector3d dir = R * Eigen::Vector3d(x, y, 1.0);
            double t_hit = 0;
            const int f = std::isnan(x) ? -1 : detail::intersectScene(g, o, dir.data(), &t_hit);
            depth[col] = f >= 0 ? static_cast<float>(t_hit) : kNan;
        }
    }
}

}  // namespace scaled::drivers::synth
