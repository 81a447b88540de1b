#include <cmath>
#include <cstddef>
#include <string>

#include <scaled/drivers/synth/rng.h>
#include <scaled/drivers/synth/scene.h>

#include "raycast.h"
#include "texture.h"

namespace scaled::drivers::synth {

namespace {

constexpr Scalar kMinTexelM = Scalar(0.001);
constexpr Scalar kMaxTexelM = Scalar(0.05);

bool validBox(const Aabb& b) {
    return b.min_m.allFinite() && b.max_m.allFinite() && (b.max_m.array() > b.min_m.array()).all();
}

// The two in-plane axes of a face normal to axis a: columns, rows.
void inPlaneAxes(int a, int* axis_col, int* axis_row) {
    *axis_col = a == 0 ? 1 : 0;
    *axis_row = a == 2 ? 1 : 2;
}

Scene::Face makeFace(const Aabb& box, int axis, double texel_m, std::uint64_t seed,
                     double richness) {
    Scene::Face f;
    f.axis = axis;
    inPlaneAxes(axis, &f.axis_col, &f.axis_row);
    const auto ac = static_cast<Eigen::Index>(f.axis_col);
    const auto ar = static_cast<Eigen::Index>(f.axis_row);
    const double extent_col = static_cast<double>(box.max_m[ac] - box.min_m[ac]);
    const double extent_row = static_cast<double>(box.max_m[ar] - box.min_m[ar]);
    // One texel of margin on each side so bilinear sampling never clamps on the face.
    const int cols = static_cast<int>(std::ceil(extent_col / texel_m)) + 3;
    const int rows = static_cast<int>(std::ceil(extent_row / texel_m)) + 3;
    f.col0_m = static_cast<double>(box.min_m[ac]) - texel_m;
    f.row0_m = static_cast<double>(box.max_m[ar]) + texel_m;
    f.inv_texel = 1.0 / texel_m;
    f.texture = detail::makeTexture(cols, rows, texel_m, seed, richness);
    return f;
}

}  // namespace

bool Aabb::contains(const Vec3& p, Scalar margin_m) const {
    return ((p.array() >= min_m.array() + margin_m) && (p.array() <= max_m.array() - margin_m))
        .all();
}

std::vector<Aabb> defaultFurniture() {
    const auto box = [](Scalar x0, Scalar y0, Scalar z0, Scalar x1, Scalar y1, Scalar z1) {
        return Aabb{Vec3(x0, y0, z0), Vec3(x1, y1, z1)};
    };
    return {
        box(Scalar(1.9), Scalar(-2.4), Scalar(0), Scalar(2.9), Scalar(-1.5),
            Scalar(0.75)),  // table
        box(Scalar(-2.9), Scalar(0.7), Scalar(0), Scalar(-2.35), Scalar(2.3),
            Scalar(1.9)),  // cabinet
        box(Scalar(-0.7), Scalar(1.85), Scalar(0), Scalar(0.3), Scalar(2.4), Scalar(1.0)),  // crate
        box(Scalar(2.2), Scalar(1.2), Scalar(0), Scalar(2.85), Scalar(1.9),
            Scalar(0.5)),  // low box
    };
}

core::Result<Scene> Scene::create(const SceneConfig& config) {
    if (!validBox(config.room)) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth scene: the room needs finite, positive extents");
    }
    if (!std::isfinite(config.texel_m) || config.texel_m < kMinTexelM ||
        config.texel_m > kMaxTexelM) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth scene: texel_m must be in [0.001, 0.05] m (got " +
                                   std::to_string(static_cast<double>(config.texel_m)) + ")");
    }
    if (!std::isfinite(config.texture_richness) || config.texture_richness <= 0 ||
        config.texture_richness > 1) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "synth scene: texture_richness must be in (0, 1] (got " +
                                   std::to_string(static_cast<double>(config.texture_richness)) +
                                   ")");
    }
    for (std::size_t k = 0; k < config.furniture.size(); ++k) {
        const Aabb& b = config.furniture[k];
        if (!validBox(b) || !config.room.contains(b.min_m) || !config.room.contains(b.max_m)) {
            return core::makeError(core::ErrorCode::kInvalidArgument,
                                   "synth scene: furniture box " + std::to_string(k) +
                                       " is empty or not inside the room");
        }
    }
    Scene scene(config);
    const auto texel_m = static_cast<double>(config.texel_m);
    std::uint64_t face_index = 0;
    const auto addBox = [&](const Aabb& box) {
        for (int a = 0; a < 3; ++a) {
            for (int side = 0; side < 2; ++side) {
                scene.faces_.push_back(makeFace(box, a, texel_m,
                                                combineSeed(config.seed, face_index),
                                                static_cast<double>(config.texture_richness)));
                ++face_index;
            }
        }
    };
    addBox(config.room);
    for (const auto& b : config.furniture) {
        addBox(b);
    }
    return scene;
}

const cv::Mat& Scene::texture(int surface) const {
    static const cv::Mat kEmpty;
    if (surface < 0 || surface >= surfaceCount()) {
        return kEmpty;
    }
    return faces_[static_cast<std::size_t>(surface)].texture;
}

std::optional<RayHit> Scene::castRay(const Vec3& origin_W, const Vec3& dir_W) const {
    if (!origin_W.allFinite() || !dir_W.allFinite() || dir_W.isZero(0)) {
        return std::nullopt;
    }
    const detail::GeometryD g = detail::toGeometryD(*this);
    const double o[3] = {static_cast<double>(origin_W.x()), static_cast<double>(origin_W.y()),
                         static_cast<double>(origin_W.z())};
    const double d[3] = {static_cast<double>(dir_W.x()), static_cast<double>(dir_W.y()),
                         static_cast<double>(dir_W.z())};
    double t = 0;
    const int face = detail::intersectScene(g, o, d, &t);
    if (face < 0 || !(t > 0) || !std::isfinite(t)) {
        return std::nullopt;
    }
    RayHit hit;
    hit.t = static_cast<Scalar>(t);
    hit.p_W = Vec3(static_cast<Scalar>(o[0] + t * d[0]), static_cast<Scalar>(o[1] + t * d[1]),
                   static_cast<Scalar>(o[2] + t * d[2]));
    hit.surface = face;
    return hit;
}

float Scene::intensityAt(const RayHit& hit) const {
    if (hit.surface < 0 || hit.surface >= surfaceCount()) {
        return 0.0f;
    }
    const double p[3] = {static_cast<double>(hit.p_W.x()), static_cast<double>(hit.p_W.y()),
                         static_cast<double>(hit.p_W.z())};
    return detail::sampleFace(detail::toFaceView(faces_[static_cast<std::size_t>(hit.surface)]), p);
}

bool Scene::isFree(const Vec3& p_W, Scalar margin_m) const {
    if (!room().contains(p_W, margin_m)) {
        return false;
    }
    for (const auto& b : furniture()) {
        if (b.contains(p_W, -margin_m)) {
            return false;
        }
    }
    return true;
}

std::optional<RayHit> Scene::hitAt(const core::PinholeRadialCamera& cam,
                                   const core::CameraPose& pose, const Vec2& px) const {
    const auto ray_C = cam.unproject(px);
    if (!ray_C) {
        return std::nullopt;
    }
    return castRay(pose.p_CinW, pose.R_CtoW * *ray_C);
}

std::optional<Vec3> Scene::pointAt(const core::PinholeRadialCamera& cam,
                                   const core::CameraPose& pose, const Vec2& px) const {
    const auto hit = hitAt(cam, pose, px);
    return hit ? std::optional<Vec3>(hit->p_W) : std::nullopt;
}

std::optional<Scalar> Scene::depthAt(const core::PinholeRadialCamera& cam,
                                     const core::CameraPose& pose, const Vec2& px) const {
    const auto hit = hitAt(cam, pose, px);
    return hit ? std::optional<Scalar>(hit->t) : std::nullopt;
}

}  // namespace scaled::drivers::synth
