#pragma once

// Shared by the sim source and the sim detector: the trajectory, the camera
// and the room of a config. Their random draws use scaled_synth's fully
// specified generator (<scaled/synth/rng.h>).

#include <cstdint>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/synth/rng.h>
#include <scaled/drivers/synth/scene.h>
#include <scaled/drivers/synth/trajectory.h>

namespace scaled::drivers::sim::detail {

// The sim camera's trajectory (validated config).
core::Result<drivers::synth::Trajectory> makeTrajectory(const SimConfig& config);

// What the source and the detector are built from.
struct SimRig {
    drivers::synth::Trajectory trajectory;
    core::PinholeRadialCamera camera;
    drivers::synth::Scene scene;
};

// The trajectory, the camera (simIntrinsics) and the room (`scene_config`,
// simSceneConfig(config) or a variant of it) of `config`.
core::Result<SimRig> makeSimRig(const SimConfig& config,
                                const drivers::synth::SceneConfig& scene_config);

// Timestamp of frame i.
std::int64_t frameTimeNs(std::int64_t index, double fps);

}  // namespace scaled::drivers::sim::detail
