#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <string>
#include <utility>

#include <scaled/drivers/sim/sim_source.h>

#include "sim_internal.h"

namespace scaled::drivers::sim {

namespace {

using core::Scalar;
using core::Vec3;

constexpr double kMaxFps = 240.0;
constexpr int kMinWidth = 64;
constexpr int kMaxWidth = 1920;
constexpr int kMinHeight = 48;
constexpr int kMaxHeight = 1080;
constexpr double kMaxDurationS = 1e7;  // t_ns stays far inside int64
constexpr double kMinHfovDeg = 30.0;
constexpr double kMaxHfovDeg = 120.0;
constexpr double kMaxPixelNoise = 50.0;
constexpr double kMaxJitterPx = 50.0;
// Texture resolution of the rendered room: about one texel per pixel at 3 m
// for the default camera, finer for closer surfaces.
constexpr Scalar kTexelM = Scalar(0.006);

std::string num(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

core::Error bad(const std::string& field, const std::string& range, const std::string& got) {
    return core::makeError(core::ErrorCode::kInvalidArgument,
                           "sim: " + field + " must be in " + range + " (got " + got + ")");
}

bool inRange(double v, double lo, double hi) {
    return std::isfinite(v) && v >= lo && v <= hi;
}

drivers::synth::Aabb floorBox(double x0, double y0, double x1, double y1, double height_m) {
    return drivers::synth::Aabb{Vec3(Scalar(x0), Scalar(y0), Scalar(0)),
                                Vec3(Scalar(x1), Scalar(y1), Scalar(height_m))};
}

}  // namespace

core::Status validate(const SimConfig& c) {
    if (!std::isfinite(c.fps) || !(c.fps > 0.0) || c.fps > kMaxFps) {
        return bad("fps", "(0, 240]", num(c.fps));
    }
    if (c.width_px < kMinWidth || c.width_px > kMaxWidth) {
        return bad("width_px", "[64, 1920]", std::to_string(c.width_px));
    }
    if (c.height_px < kMinHeight || c.height_px > kMaxHeight) {
        return bad("height_px", "[48, 1080]", std::to_string(c.height_px));
    }
    if (!inRange(c.duration_s, 0.0, kMaxDurationS)) {
        return bad("duration_s", "[0, 1e7] (0: unbounded)", num(c.duration_s));
    }
    if (c.duration_s > 0.0 && std::lround(c.duration_s * c.fps) < 1) {
        return bad("duration_s", "a range giving at least one frame at fps", num(c.duration_s));
    }
    if (!inRange(c.hfov_deg, kMinHfovDeg, kMaxHfovDeg)) {
        return bad("hfov_deg", "[30, 120]", num(c.hfov_deg));
    }
    if (!inRange(c.pixel_noise, 0.0, kMaxPixelNoise)) {
        return bad("pixel_noise", "[0, 50]", num(c.pixel_noise));
    }
    if (!inRange(c.box_jitter_px, 0.0, kMaxJitterPx)) {
        return bad("box_jitter_px", "[0, 50]", num(c.box_jitter_px));
    }
    if (!inRange(c.miss_probability, 0.0, 1.0)) {
        return bad("miss_probability", "[0, 1]", num(c.miss_probability));
    }
    if (!std::isfinite(c.score) || !(c.score > 0.0f) || c.score > 1.0f) {
        return bad("score", "(0, 1]", num(static_cast<double>(c.score)));
    }
    if (!std::isfinite(c.min_inside_fraction) || !(c.min_inside_fraction > 0.0) ||
        c.min_inside_fraction > 1.0) {
        return bad("min_inside_fraction", "(0, 1]", num(c.min_inside_fraction));
    }
    if (!std::isfinite(c.min_visible_fraction) || !(c.min_visible_fraction > 0.0) ||
        c.min_visible_fraction > 1.0) {
        return bad("min_visible_fraction", "(0, 1]", num(c.min_visible_fraction));
    }
    return {};
}

std::vector<SimObject> simObjects(const SimConfig& /*config*/) {
    // Heights: the means in config/priors.toml. Placed along the walls of the
    // 9 m x 8 m room, 2.3-3.5 m from the camera loop (which stays within 1.3 m
    // of the centre), so whole objects fit the default view.
    return {
        {"refrigerator", 1.75, floorBox(3.75, -1.2, 4.45, -0.45, 1.75)},
        {"couch", 0.85, floorBox(-0.6, 3.6, 1.4, 3.95, 0.85)},
        {"chair", 0.90, floorBox(-4.0, 0.6, -3.7, 1.1, 0.90)},
        {"suitcase", 0.62, floorBox(-1.6, -3.95, -1.15, -3.7, 0.62)},
        {"dining table", 0.75, floorBox(1.0, -3.9, 2.4, -3.0, 0.75)},
    };
}

core::CameraIntrinsics simIntrinsics(const SimConfig& config) {
    core::CameraIntrinsics k;
    const double half = 0.5 * config.hfov_deg * std::numbers::pi / 180.0;
    const double f = 0.5 * static_cast<double>(config.width_px) / std::tan(half);
    k.fx = Scalar(f);
    k.fy = Scalar(f);
    // Pixel centres are at integer coordinates: the image centre is (w - 1) / 2.
    k.cx = Scalar(0.5 * static_cast<double>(config.width_px - 1));
    k.cy = Scalar(0.5 * static_cast<double>(config.height_px - 1));
    k.width_px = config.width_px;
    k.height_px = config.height_px;
    return k;
}

drivers::synth::SceneConfig simSceneConfig(const SimConfig& config) {
    drivers::synth::SceneConfig s;
    s.room = drivers::synth::Aabb{Vec3(Scalar(-4.5), Scalar(-4), Scalar(0)),
                                  Vec3(Scalar(4.5), Scalar(4), Scalar(3))};
    s.furniture.clear();
    for (const auto& o : simObjects(config)) {
        s.furniture.push_back(o.box);
    }
    s.texel_m = kTexelM;
    s.seed = config.seed;
    return s;
}

core::Result<core::CameraPose> simPoseAt(const SimConfig& config, std::int64_t t_ns) {
    auto traj = detail::makeTrajectory(config);
    if (!traj) {
        return traj.error();
    }
    return traj->poseAt(static_cast<double>(t_ns) * 1e-9);
}

namespace detail {

core::Result<drivers::synth::Trajectory> makeTrajectory(const SimConfig& config) {
    if (auto v = validate(config); !v) {
        return v.error();
    }
    drivers::synth::TrajectoryConfig t;
    t.seed = config.seed;
    // Only frameCount() reads the duration; poses are defined for any time.
    t.duration_s = config.duration_s > 0.0 ? config.duration_s : 60.0;
    return drivers::synth::Trajectory::create(t);
}

core::Result<SimRig> makeSimRig(const SimConfig& config,
                                const drivers::synth::SceneConfig& scene_config) {
    auto trajectory = makeTrajectory(config);
    if (!trajectory) {
        return trajectory.error();
    }
    auto camera = core::PinholeRadialCamera::create(simIntrinsics(config));
    if (!camera) {
        return camera.error();
    }
    auto scene = drivers::synth::Scene::create(scene_config);
    if (!scene) {
        return scene.error();
    }
    return SimRig{std::move(*trajectory), *camera, std::move(*scene)};
}

std::int64_t frameTimeNs(std::int64_t index, double fps) {
    return std::llround(static_cast<double>(index) * 1e9 / fps);
}

}  // namespace detail

}  // namespace scaled::drivers::sim
