#pragma once

// Synthetic images for the scaled_vision tests, all from fixed seeds.

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace scaled::drivers::vision::test {

// Smooth random texture: uniform noise blurred with sigma_px, rescaled to mean
// 128 and standard deviation 40 (CV_8UC1).
inline cv::Mat smoothTexture(cv::Size size, double sigma_px, std::uint64_t seed) {
    cv::Mat noise(size, CV_32FC1);
    cv::RNG rng(seed);
    rng.fill(noise, cv::RNG::UNIFORM, 0.0, 255.0);
    cv::GaussianBlur(noise, noise, cv::Size(0, 0), sigma_px);
    cv::Scalar mean;
    cv::Scalar stddev;
    cv::meanStdDev(noise, mean, stddev);
    cv::Mat out;
    noise.convertTo(out, CV_8UC1, 40.0 / stddev[0], 128.0 - 40.0 * mean[0] / stddev[0]);
    return out;
}

// Checkerboard of square_px squares whose first square starts at offset_px.
inline cv::Mat checkerboard(cv::Size size, int square_px, int offset_px) {
    cv::Mat img(size, CV_8UC1);
    for (int y = 0; y < size.height; ++y) {
        for (int x = 0; x < size.width; ++x) {
            const int cx = (x + square_px - offset_px) / square_px;
            const int cy = (y + square_px - offset_px) / square_px;
            img.at<uchar>(y, x) = ((cx + cy) % 2 == 0) ? 40 : 210;
        }
    }
    return img;
}

}  // namespace scaled::drivers::vision::test
