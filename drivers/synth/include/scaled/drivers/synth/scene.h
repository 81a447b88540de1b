#pragma once

// A textured box room for synthetic image sequences with exact ground truth.
//
// World frame: z up, metres. The room is an axis-aligned box (floor, ceiling
// and four walls, seen from inside); "furniture" are axis-aligned boxes inside
// it (seen from outside). Every face carries its own procedural grayscale
// texture (multi-octave value noise under random rectangles, triangles and
// discs at several scales), generated from the seed, stored as an 8-bit image
// with a known size per texel and sampled bilinearly.

#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <utility>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/core/types.h>

namespace scaled::drivers::synth {

using core::Scalar;
using core::Vec2;
using core::Vec3;

// Axis-aligned box, metres.
struct Aabb {
    Vec3 min_m = Vec3::Zero();
    Vec3 max_m = Vec3::Zero();

    // True when p lies inside the box shrunk by margin_m on every side.
    [[nodiscard]] bool contains(const Vec3& p, Scalar margin_m = 0) const;
};

// The furniture of the default room: a table, a tall cabinet, a crate and a
// low box, all standing on the floor at least 5 cm from the walls and clear
// of the default trajectory.
std::vector<Aabb> defaultFurniture();

struct SceneConfig {
    // Default: 6 m x 5 m x 3 m, centred on the world origin in x and y, floor at z = 0.
    Aabb room{Vec3(Scalar(-3), Scalar(-2.5), Scalar(0)), Vec3(Scalar(3), Scalar(2.5), Scalar(3))};
    std::vector<Aabb> furniture = defaultFurniture();  // clear it for an empty room
    Scalar texel_m = Scalar(0.005);                    // texture resolution, in [1 mm, 5 cm]
    std::uint64_t seed = 1;                            // textures
    // Shapes per square metre and noise contrast of every texture, relative to
    // the rich default, in (0, 1]: 0.1 leaves mostly plain surfaces with a few
    // marks, closer to a kitchen's cabinet fronts than the default.
    Scalar texture_richness = 1;
};

// Surface index: the room's faces are 0..5, box k's faces 6 + 6k .. 11 + 6k.
// Within a box, face 2 a + s is the face normal to axis a (0 x, 1 y, 2 z) at
// its minimum (s = 0) or maximum (s = 1) coordinate.
struct RayHit {
    Scalar t = 0;  // ray parameter: p_W = origin + t dir
    Vec3 p_W = Vec3::Zero();
    int surface = -1;
};

class Scene {
public:
    // Validates the configuration (room with positive extents, furniture inside
    // the room, texel size in range) and generates the textures.
    static core::Result<Scene> create(const SceneConfig& config = {});

    [[nodiscard]] const SceneConfig& config() const { return config_; }
    [[nodiscard]] const Aabb& room() const { return config_.room; }
    [[nodiscard]] const std::vector<Aabb>& furniture() const { return config_.furniture; }
    [[nodiscard]] Scalar texelSize() const { return config_.texel_m; }

    [[nodiscard]] int surfaceCount() const { return static_cast<int>(faces_.size()); }
    // CV_8UC1 texture of a surface: column along the first in-plane axis
    // (x, or y on x-walls), row along the second (top row at its maximum).
    [[nodiscard]] const cv::Mat& texture(int surface) const;

    // Nearest surface hit by the ray origin + t dir, t > 0 (dir need not be unit).
    // The origin must be inside the room; nullopt when nothing is hit.
    [[nodiscard]] std::optional<RayHit> castRay(const Vec3& origin_W, const Vec3& dir_W) const;

    // Texture value at a hit, bilinear, in [0, 255].
    [[nodiscard]] float intensityAt(const RayHit& hit) const;

    // True when p is inside the room and outside every piece of furniture, with
    // at least margin_m to every surface.
    [[nodiscard]] bool isFree(const Vec3& p_W, Scalar margin_m = 0) const;

    // The world point seen at pixel px (distorted pixel coordinates, integers
    // at pixel centres), by casting the camera's unprojected ray.
    [[nodiscard]] std::optional<Vec3> pointAt(const core::PinholeRadialCamera& cam,
                                              const core::CameraPose& pose, const Vec2& px) const;

    // Exact metric depth (along the optical axis z, metres) of the surface seen at px.
    [[nodiscard]] std::optional<Scalar> depthAt(const core::PinholeRadialCamera& cam,
                                                const core::CameraPose& pose, const Vec2& px) const;

    // Low-level description used by the renderer: one entry per surface.
    struct Face {
        int axis = 0;       // normal axis (0 x, 1 y, 2 z)
        int axis_col = 1;   // world axis along texture columns
        int axis_row = 2;   // world axis along texture rows (decreasing)
        double col0_m = 0;  // world coordinate of texel column 0
        double row0_m = 0;  // world coordinate of texel row 0
        double inv_texel = 0;
        cv::Mat texture;  // CV_8UC1
    };
    [[nodiscard]] const std::vector<Face>& faces() const { return faces_; }

private:
    explicit Scene(SceneConfig config) : config_(std::move(config)) {}
    // The surface hit by the camera ray through px (ray (x_u, y_u, 1), so the
    // hit's t is the depth along z).
    [[nodiscard]] std::optional<RayHit> hitAt(const core::PinholeRadialCamera& cam,
                                              const core::CameraPose& pose, const Vec2& px) const;

    SceneConfig config_;
    std::vector<Face> faces_;
};

}  // namespace scaled::drivers::synth
