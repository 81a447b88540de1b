#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/synth/trajectory.h>

#include "sim_internal.h"

namespace scaled::drivers::sim {

namespace {

using core::Scalar;
using core::Vec2;
using core::Vec3;

constexpr int kFaceSamples = 5;              // per side of the grid of points on each face
constexpr Scalar kMinDepthM = Scalar(0.05);  // every corner must be this far in front
// The geometry is all the detector needs of the scene: coarse textures are cheap.
constexpr Scalar kDetectorTexelM = Scalar(0.05);

class SimDetector final : public drivers::detector::ObjectDetector {
public:
    SimDetector(const SimConfig& config, drivers::synth::Trajectory trajectory,
                core::PinholeRadialCamera camera, drivers::synth::Scene scene)
        : config_(config),
          trajectory_(std::move(trajectory)),
          camera_(camera),
          scene_(std::move(scene)),
          objects_(simObjects(config)),
          noise_seed_(drivers::synth::combineSeed(config.seed, 0x646574ULL)) {
        for (const auto& o : objects_) {
            if (std::find(names_.begin(), names_.end(), o.class_name) == names_.end()) {
                names_.push_back(o.class_name);
            }
        }
        for (const auto& o : objects_) {
            class_ids_.push_back(static_cast<int>(
                std::find(names_.begin(), names_.end(), o.class_name) - names_.begin()));
        }
    }

    core::Status detect(const cv::Mat& image, std::int64_t frame_id, std::int64_t t_ns,
                        drivers::detector::DetectionResult& out) override {
        const auto t0 = std::chrono::steady_clock::now();
        if (image.empty()) {
            return core::makeError(core::ErrorCode::kInvalidArgument, "sim detector: empty image");
        }
        if (image.type() != CV_8UC1 && image.type() != CV_8UC3 && image.type() != CV_8UC4) {
            return core::makeError(core::ErrorCode::kInvalidArgument,
                                   "sim detector: unsupported image type (want 8-bit gray, BGR "
                                   "or BGRA)");
        }
        if (image.cols != config_.width_px || image.rows != config_.height_px) {
            return core::makeError(core::ErrorCode::kInvalidArgument,
                                   "sim detector: image is " + std::to_string(image.cols) + "x" +
                                       std::to_string(image.rows) + ", the sim camera " +
                                       std::to_string(config_.width_px) + "x" +
                                       std::to_string(config_.height_px));
        }
        out.frame_id = frame_id;
        out.t_ns = t_ns;
        out.width_px = image.cols;
        out.height_px = image.rows;
        out.detections.clear();
        const core::CameraPose pose = trajectory_.poseAt(static_cast<double>(t_ns) * 1e-9);
        const std::uint64_t frame_seed =
            drivers::synth::combineSeed(noise_seed_, static_cast<std::uint64_t>(frame_id));
        for (std::size_t k = 0; k < objects_.size(); ++k) {
            // Draws in a fixed order per object, whatever is visible.
            drivers::synth::SplitMix64 rng(drivers::synth::combineSeed(frame_seed, k));
            const bool miss = rng.uniform() < config_.miss_probability;
            std::array<double, 4> jitter{};
            for (auto& j : jitter) {
                j = config_.box_jitter_px * rng.gaussianUnpaired();
            }
            core::BoundingBox box;
            if (miss || !seen(k, pose, box)) {
                continue;
            }
            box.x_min_px += Scalar(jitter[0]);
            box.y_min_px += Scalar(jitter[1]);
            box.x_max_px += Scalar(jitter[2]);
            box.y_max_px += Scalar(jitter[3]);
            if (box.x_min_px > box.x_max_px) {
                std::swap(box.x_min_px, box.x_max_px);
            }
            if (box.y_min_px > box.y_max_px) {
                std::swap(box.y_min_px, box.y_max_px);
            }
            clip(box);
            drivers::detector::ObjectDetection d;
            d.box = box;
            d.class_id = class_ids_[k];
            d.class_name = names_[static_cast<std::size_t>(d.class_id)];
            d.score = config_.score;
            out.detections.push_back(d);
        }
        // All scores are equal: the order (by decreasing score) is the objects' order.
        out.timing = {};
        out.timing.forward_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        return {};
    }

    [[nodiscard]] std::span<const std::string> classNames() const override { return names_; }

private:
    void clip(core::BoundingBox& b) const {
        const auto w1 = static_cast<Scalar>(config_.width_px - 1);
        const auto h1 = static_cast<Scalar>(config_.height_px - 1);
        b.x_min_px = std::clamp(b.x_min_px, Scalar(0), w1);
        b.x_max_px = std::clamp(b.x_max_px, Scalar(0), w1);
        b.y_min_px = std::clamp(b.y_min_px, Scalar(0), h1);
        b.y_max_px = std::clamp(b.y_max_px, Scalar(0), h1);
    }

    [[nodiscard]] bool inImage(const Vec2& px) const {
        return px.x() >= 0 && px.y() >= 0 && px.x() <= Scalar(config_.width_px - 1) &&
               px.y() <= Scalar(config_.height_px - 1);
    }

    // Whether object k is mostly inside the image and mostly unoccluded; box:
    // its exact projected bounding box, clipped.
    bool seen(std::size_t k, const core::CameraPose& pose, core::BoundingBox& box) const {
        const drivers::synth::Aabb& b = objects_[k].box;
        const core::Mat3 R_WtoC = pose.R_CtoW.transpose();
        Scalar x0 = std::numeric_limits<Scalar>::infinity();
        Scalar y0 = x0;
        Scalar x1 = -x0;
        Scalar y1 = -x0;
        for (int c = 0; c < 8; ++c) {
            const Vec3 p_W((c & 1) != 0 ? b.max_m.x() : b.min_m.x(),
                           (c & 2) != 0 ? b.max_m.y() : b.min_m.y(),
                           (c & 4) != 0 ? b.max_m.z() : b.min_m.z());
            const Vec3 p_C = R_WtoC * (p_W - pose.p_CinW);
            if (p_C.z() < kMinDepthM) {
                return false;
            }
            const auto px = camera_.project(p_C);
            if (!px) {
                return false;
            }
            x0 = std::min(x0, px->x());
            y0 = std::min(y0, px->y());
            x1 = std::max(x1, px->x());
            y1 = std::max(y1, px->y());
        }
        const Scalar area = (x1 - x0) * (y1 - y0);
        box = {x0, y0, x1, y1};
        clip(box);
        const Scalar inside = (box.x_max_px - box.x_min_px) * (box.y_max_px - box.y_min_px);
        if (!(area > 0) || inside < Scalar(config_.min_inside_fraction) * area) {
            return false;
        }
        return visibleFraction(k, pose) >= config_.min_visible_fraction;
    }

    // Fraction of the sample points on the faces of object k turned towards
    // the camera, among those inside the image, that are the first surface
    // their camera ray hits (0 when none is inside the image).
    [[nodiscard]] double visibleFraction(std::size_t k, const core::CameraPose& pose) const {
        const drivers::synth::Aabb& b = objects_[k].box;
        const Vec3& o = pose.p_CinW;
        const core::Mat3 R_WtoC = pose.R_CtoW.transpose();
        const int first_surface = 6 + 6 * static_cast<int>(k);
        int in_image = 0;
        int visible = 0;
        for (int axis = 0; axis < 3; ++axis) {
            for (int side = 0; side < 2; ++side) {
                const Scalar plane = side == 0 ? b.min_m[axis] : b.max_m[axis];
                if (side == 0 ? !(o[axis] < plane) : !(o[axis] > plane)) {
                    continue;  // the face is turned away (or edge-on)
                }
                const int a1 = (axis + 1) % 3;
                const int a2 = (axis + 2) % 3;
                for (int i = 0; i < kFaceSamples; ++i) {
                    for (int j = 0; j < kFaceSamples; ++j) {
                        Vec3 p = Vec3::Zero();
                        p[axis] = plane;
                        const Scalar s = (Scalar(i) + Scalar(0.5)) / Scalar(kFaceSamples);
                        const Scalar t = (Scalar(j) + Scalar(0.5)) / Scalar(kFaceSamples);
                        p[a1] = b.min_m[a1] + s * (b.max_m[a1] - b.min_m[a1]);
                        p[a2] = b.min_m[a2] + t * (b.max_m[a2] - b.min_m[a2]);
                        const Vec3 p_C = R_WtoC * (p - o);
                        if (p_C.z() <= 0) {
                            continue;
                        }
                        const auto px = camera_.project(p_C);
                        if (!px || !inImage(*px)) {
                            continue;
                        }
                        ++in_image;
                        const auto hit = scene_.castRay(o, p - o);
                        if (hit && hit->surface >= first_surface &&
                            hit->surface < first_surface + 6) {
                            ++visible;
                        }
                    }
                }
            }
        }
        return in_image > 0 ? static_cast<double>(visible) / in_image : 0.0;
    }

    SimConfig config_;
    drivers::synth::Trajectory trajectory_;
    core::PinholeRadialCamera camera_;
    drivers::synth::Scene scene_;
    std::vector<SimObject> objects_;
    std::vector<std::string> names_;  // distinct classes, in object order
    std::vector<int> class_ids_;      // per object, into names_
    std::uint64_t noise_seed_;
};

}  // namespace

core::Result<std::unique_ptr<drivers::detector::ObjectDetector>> createSimDetector(
    const SimConfig& config) {
    drivers::synth::SceneConfig scene_config = simSceneConfig(config);
    scene_config.texel_m = kDetectorTexelM;
    auto rig = detail::makeSimRig(config, scene_config);
    if (!rig) {
        return rig.error();
    }
    return std::unique_ptr<drivers::detector::ObjectDetector>(std::make_unique<SimDetector>(
        config, std::move(rig->trajectory), rig->camera, std::move(rig->scene)));
}

}  // namespace scaled::drivers::sim
