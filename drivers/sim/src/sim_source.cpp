#include <memory>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>

#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/synth/renderer.h>
#include <scaled/drivers/synth/trajectory.h>

#include "sim_internal.h"

namespace scaled::drivers::sim {

namespace {

class SimSource final : public drivers::source::FrameSource {
public:
    SimSource(const SimConfig& config, drivers::synth::Trajectory trajectory,
              core::PinholeRadialCamera camera, std::unique_ptr<drivers::synth::Scene> scene)
        : config_(config),
          trajectory_(std::move(trajectory)),
          camera_(camera),
          scene_(std::move(scene)),
          renderer_(*scene_, renderOptions(config)) {
        info_.name = "sim";
        info_.intrinsics = camera_.intrinsics();
        info_.has_intrinsics = true;
        info_.gravity_down_W = drivers::synth::gravityDirectionW();
        info_.frame_count =
            config.duration_s > 0.0
                ? static_cast<std::size_t>(std::lround(config.duration_s * config.fps))
                : 0;
        info_.listed_count = info_.frame_count;
        if (info_.frame_count == 0) {
            info_.notes.emplace_back("sim: unbounded (frame_count 0); the camera loops forever");
        }
    }

    [[nodiscard]] const drivers::source::SequenceInfo& info() const override { return info_; }

    core::Result<bool> next(drivers::source::Frame& frame) override {
        if (bounded() && cursor_ >= info_.frame_count) {
            return false;
        }
        const auto id = static_cast<std::int64_t>(cursor_);
        ++cursor_;
        frame.id = id;
        frame.t_ns = detail::frameTimeNs(id, config_.fps);
        const core::CameraPose pose = trajectory_.poseAt(static_cast<double>(frame.t_ns) * 1e-9);
        // A fresh buffer per frame: callers may keep the previous frame's images.
        frame.gray = cv::Mat();
        renderer_.render(camera_, pose, frame.gray, nullptr, static_cast<std::uint64_t>(id));
        frame.color = cv::Mat();
        cv::cvtColor(frame.gray, frame.color, cv::COLOR_GRAY2BGR);
        frame.T_CtoW_gt = pose;
        frame.gravity_down_C = pose.R_CtoW.transpose() * drivers::synth::gravityDirectionW();
        frame.depth_path.reset();
        frame.image_path = "sim:" + std::to_string(id);
        frame.accel_C.reset();
        return true;
    }

    core::Result<bool> seek(std::size_t index) override {
        if (bounded() && index > info_.frame_count) {
            return core::makeError(core::ErrorCode::kInvalidArgument,
                                   "sim: cannot seek to frame " + std::to_string(index) +
                                       ": the sequence has " + std::to_string(info_.frame_count) +
                                       " frames");
        }
        cursor_ = index;
        return !bounded() || index < info_.frame_count;
    }

private:
    static drivers::synth::RenderOptions renderOptions(const SimConfig& config) {
        drivers::synth::RenderOptions o;
        o.antialias = config.antialias;
        o.noise_sigma = config.pixel_noise;
        o.noise_seed = drivers::synth::combineSeed(config.seed, 0x72656e64ULL);
        return o;
    }
    [[nodiscard]] bool bounded() const { return info_.frame_count > 0; }

    SimConfig config_;
    drivers::synth::Trajectory trajectory_;
    core::PinholeRadialCamera camera_;
    std::unique_ptr<drivers::synth::Scene> scene_;  // stable address: the renderer points to it
    drivers::synth::Renderer renderer_;
    drivers::source::SequenceInfo info_;
    std::size_t cursor_ = 0;
};

}  // namespace

core::Result<std::unique_ptr<drivers::source::FrameSource>> openSimSource(const SimConfig& config) {
    auto rig = detail::makeSimRig(config, simSceneConfig(config));
    if (!rig) {
        return rig.error();
    }
    return std::unique_ptr<drivers::source::FrameSource>(std::make_unique<SimSource>(
        config, std::move(rig->trajectory), rig->camera,
        std::make_unique<drivers::synth::Scene>(std::move(rig->scene))));
}

}  // namespace scaled::drivers::sim
