#pragma once

// The rotation between consecutive frames from their small blurred images
// (the "small blurry image" alignment of Klein and Murray's PTAM): each frame
// shrunk kShrink times and blurred, its intensities normalised, and the
// rotation of the current camera in the previous one found by Gauss-Newton
// over SO(3) on the photometric error (Huber), every pixel's scene point on a
// fronto-parallel plane moved by a given translation per unit of depth (the
// motion model's, over the scene's median depth). Translation the model does
// not know enters as rotation error, some 0.1-0.2 rad/s on handheld real
// images (docs/slam.md "The rotation check"): a check of the motion model's
// guess against the images, not a gyro.
//
// Every buffer is sized by create() (or the first frame of another size);
// frames of that size do not allocate. Image sides that are not multiples of
// kShrink lose their last few pixels.

#include <opencv2/core.hpp>
#include <optional>

#include <Eigen/Core>

#include <scaled/core/camera/pinhole_radial.h>
#include <scaled/core/types.h>

namespace scaled::drivers::vision {

struct SmallImageRotation {
    static constexpr int kShrink = 8;
    static constexpr int kMaxIterations = 10;

    struct Result {
        core::Mat3 R_CinP = core::Mat3::Identity();  // current camera's axes in the previous one
        float rms = 0;   // normalised intensity residual at the end (1 = the images' spread)
        int pixels = 0;  // pixels compared in the last iteration
        int iterations = 0;
    };

    // Sizes the buffers for frames of width x height.
    void create(int width, int height);

    // Forgets the previous frame (a new map, a lost camera).
    void reset() { has_previous_ = false; }

    // Makes gray's small image the current one and, when a previous one
    // exists and align_now, aligns the two starting from R0_CinP, the scene
    // translated by t_CinP_per_depth (the current camera's position in the
    // previous camera's frame over the scene's depth; zero: a distant scene).
    // nullopt without a previous frame, without align_now, or when the
    // alignment has no trustworthy answer: fewer than a quarter of the pixels
    // overlap, a rotation the texture cannot see (H near singular), no
    // convergence in kMaxIterations (steps of at most 0.05 rad), or a
    // residual too large for the two images to show one scene. The current
    // frame becomes the previous one either way.
    std::optional<Result> push(const cv::Mat& gray, const core::PinholeRadialCamera& camera,
                               const core::Mat3& R0_CinP, const core::Vec3& t_CinP_per_depth,
                               bool align_now = true);

private:
    struct Intrinsics {  // of the small image (one focal length)
        float f = 1;
        float cx = 0;
        float cy = 0;
    };
    struct Normal {  // Gauss-Newton's normal equations, H delta = -b
        Eigen::Matrix3f H = Eigen::Matrix3f::Zero();
        Eigen::Vector3f b = Eigen::Vector3f::Zero();
        float sq = 0;  // sum of squared residuals
        int used = 0;  // pixels compared
    };

    [[nodiscard]] Normal normalEquations(const Intrinsics& k, const Eigen::Matrix3f& R_CinP,
                                         const Eigen::Vector3f& t_CinP_per_depth) const;
    [[nodiscard]] std::optional<Result> align(const core::PinholeRadialCamera& camera,
                                              const core::Mat3& R0_CinP,
                                              const core::Vec3& t_CinP_per_depth) const;
    void makeSmall(const cv::Mat& gray, cv::Mat& out);
    void gradients();  // previous_ and its gradients into previous3_

    cv::Mat shrunk_;    // CV_32F, block means
    cv::Mat blurred_;   // CV_32F, blurred along rows
    cv::Mat previous_;  // CV_32F, zero mean, unit spread
    cv::Mat current_;
    cv::Mat previous3_;  // CV_32FC3: previous_ and its x and y gradients, interleaved
    bool has_previous_ = false;
};

}  // namespace scaled::drivers::vision
