#pragma once

// The daemon's `sim` source: a synthetic room (drivers/synth) seen by a
// handheld camera walking a loop, as a FrameSource, plus an ObjectDetector
// that reports the room's furniture from the ground truth. With both, the
// daemon and its clients run on any machine without a camera, a model or data.
//
// The room (9 m x 8 m x 3 m, z up, floor at z = 0) holds axis-aligned boxes
// standing on the floor whose heights are the means of COCO classes in
// config/priors.toml (simObjects() lists them); the camera follows
// drivers::synth::Trajectory (a loop around the room centre at about 1.45 m, looking
// outwards). Frames are rendered from the textured scene, deterministically:
// the same SimConfig gives the same bytes, and the detector's boxes depend
// only on (config, frame_id, t_ns). docs/sim.md has the numbers.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/result.h>
#include <scaled/drivers/detector/object_detector.h>
#include <scaled/drivers/source/frame_source.h>
#include <scaled/drivers/synth/scene.h>

namespace scaled::drivers::sim {

struct SimConfig {
    std::uint64_t seed = 1;    // textures, trajectory phases, pixel and detection noise
    double fps = 30.0;         // (0, 240]
    int width_px = 320;        // [64, 1920]
    int height_px = 240;       // [48, 1080]
    double duration_s = 0;     // >= 0; 0: unbounded (the trajectory loops forever)
    double hfov_deg = 66.0;    // horizontal field of view of the pinhole camera, [30, 120]
    double pixel_noise = 2.0;  // additive Gaussian pixel noise, grey levels std, [0, 50]
    bool antialias = false;    // 2x2 supersampling (about twice the rendering cost)

    // Detection noise. Each box edge moves by an independent Gaussian of this
    // std (pixels, [0, 50]); an object that would be reported is dropped with
    // miss_probability ([0, 1]) per frame.
    double box_jitter_px = 1.5;
    double miss_probability = 0.05;
    float score = 0.9f;  // reported score, (0, 1]
    // An object is reported when at least this fraction of its projected box
    // lies inside the image ((0, 1]) and at least min_visible_fraction of the
    // sample points on its faces turned to the camera (those inside the image)
    // are seen unoccluded ((0, 1]).
    double min_inside_fraction = 0.8;
    double min_visible_fraction = 0.6;
};

// Checks every field; the error message names the field and its value.
core::Status validate(const SimConfig& config);

// The objects in the sim room: COCO class name, true height (the class's prior
// mean in config/priors.toml) and the box (world frame, metres, on the floor).
struct SimObject {
    std::string class_name;
    double height_m = 0;
    drivers::synth::Aabb box;
};
std::vector<SimObject> simObjects(const SimConfig& config);

// The camera of the sim source: pinhole, no distortion, principal point at
// the image centre, square pixels, the configured horizontal field of view.
core::CameraIntrinsics simIntrinsics(const SimConfig& config);

// The room's scene configuration (room, furniture = simObjects' boxes, texel
// size, seed).
drivers::synth::SceneConfig simSceneConfig(const SimConfig& config);

// Ground-truth camera-to-world pose of the sim camera at time t_ns (world: z
// up, metres), as the source renders it and the detector reads it.
core::Result<core::CameraPose> simPoseAt(const SimConfig& config, std::int64_t t_ns);

// Frame i has t_ns = round(i * 1e9 / fps), the ground-truth pose and gravity.
// SequenceInfo: name "sim", intrinsics simIntrinsics(), frame_count =
// round(duration_s * fps), or 0 when duration_s is 0, which means unbounded:
// next() never ends and seek() accepts any index.
core::Result<std::unique_ptr<drivers::source::FrameSource>> openSimSource(const SimConfig& config);

// An ObjectDetector reporting the sim objects visible at t_ns (pose from the
// trajectory, not from the image), with box jitter and misses drawn from
// (seed, frame_id). The image must have the configured size (any of the
// ObjectDetector image types). classNames() are the objects' classes.
core::Result<std::unique_ptr<drivers::detector::ObjectDetector>> createSimDetector(
    const SimConfig& config);

}  // namespace scaled::drivers::sim
