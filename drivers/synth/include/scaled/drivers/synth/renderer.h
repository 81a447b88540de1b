#pragma once

// Renders grayscale images of a Scene through a PinholeRadialCamera by casting
// one ray per (sub)pixel. Pixel (col, row) is centred on the distorted pixel
// coordinates (col, row), the convention of PinholeRadialCamera::project and
// of OpenCV; rays go through the camera's unproject, so radial distortion is
// honoured exactly.

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/scale/vertical_extent.h>
#include <scaled/drivers/synth/scene.h>

namespace scaled::drivers::synth {

struct RenderOptions {
    bool antialias = true;         // 2x2 supersampling per pixel
    double noise_sigma = 0.0;      // additive Gaussian pixel noise, grey levels (0: none)
    std::uint64_t noise_seed = 0;  // with render's noise_stream, selects the noise pattern
};

class Renderer {
public:
    // The scene must outlive the renderer. A renderer caches the rays of the last
    // camera: use one renderer per thread.
    explicit Renderer(const Scene& scene, RenderOptions options = {});

    [[nodiscard]] const RenderOptions& options() const { return options_; }
    void setOptions(const RenderOptions& options);

    // Renders the view of a camera at pose (camera-to-world) into out_gray
    // (CV_8UC1, cam.width() x cam.height()). out_depth_m, when given, receives
    // the depth along the optical axis of the surface at each pixel centre
    // (CV_32FC1, metres; NaN where the pixel has no ray). noise_stream selects
    // an independent noise pattern (e.g. the frame index). Deterministic: the
    // same inputs give the same bytes. Rays are computed once per intrinsics.
    void render(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                cv::Mat& out_gray, cv::Mat* out_depth_m = nullptr, std::uint64_t noise_stream = 0);

    // A rolling shutter: image row r seen from row_poses[r] (one pose per row of
    // the camera's image), the rest as render() without depth. False (nothing
    // rendered) when row_poses does not have one pose per row.
    bool renderRows(const core::PinholeRadialCamera& cam,
                    const std::vector<core::CameraPose>& row_poses, cv::Mat& out_gray,
                    std::uint64_t noise_stream = 0);

    // Only the depth render() gives (CV_32FC1, metres along the optical axis,
    // NaN without a surface), without the image.
    void renderDepth(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                     cv::Mat& out_depth_m);

private:
    void prepareRays(const core::PinholeRadialCamera& cam);
    void renderImage(const core::PinholeRadialCamera& cam, const core::CameraPose& pose,
                     const core::CameraPose* row_poses, cv::Mat& out_gray,
                     std::uint64_t noise_stream);

    const Scene* scene_;
    RenderOptions options_;
    // Camera-frame rays (x_u, y_u) with z = 1, NaN when a sample has no ray, in
    // groups of four (structure of arrays: 4 x, then 4 y): one group per pixel
    // with antialiasing (its 2x2 samples), else four consecutive pixels.
    bool rays_valid_ = false;
    bool rays_antialias_ = false;
    core::CameraIntrinsics rays_intrinsics_;
    std::vector<float> group_rays_;
    std::vector<float> centre_rays_;      // x, y per pixel centre, for the depth output
    float ray_bounds_[4] = {0, 0, 0, 0};  // min x_u, max x_u, min y_u, max y_u over the rays
};

}  // namespace scaled::drivers::synth
