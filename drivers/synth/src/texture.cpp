#include "texture.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <vector>

#include <scaled/drivers/synth/rng.h>

namespace scaled::drivers::synth::detail {

namespace {

// Shape sizes s have density proportional to 1 / s^2 in [kMinShapeM, kMaxShapeM]:
// many small shapes, few large ones, every scale covering a similar share.
constexpr double kShapesPerSquareMetre = 350.0;
constexpr double kMinShapeM = 0.015;
constexpr double kMaxShapeM = 0.4;
constexpr int kSubpixelShift = 4;  // cv drawing: coordinates in 1/16 texel
constexpr double kSubpixelScale = 16.0;

double smoothstep(double x) {
    return x * x * (3.0 - 2.0 * x);
}

// Adds amplitude * (value noise with lattice spacing cell texels) to acc.
void addValueNoise(std::vector<float>& acc, int cols, int rows, double cell, float amplitude,
                   SplitMix64& rng) {
    const int nx = static_cast<int>(std::ceil(cols / cell)) + 2;
    const int ny = static_cast<int>(std::ceil(rows / cell)) + 2;
    std::vector<float> lattice(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny));
    for (auto& v : lattice) {
        v = static_cast<float>(rng.uniform(-1.0, 1.0));
    }
    // A random offset so octaves do not share lattice lines.
    const double off_x = rng.uniform(0.0, cell);
    const double off_y = rng.uniform(0.0, cell);
    std::vector<int> ix(static_cast<std::size_t>(cols));
    std::vector<float> wx(static_cast<std::size_t>(cols));
    for (int c = 0; c < cols; ++c) {
        const double x = (c + off_x) / cell;
        const double fl = std::floor(x);
        ix[static_cast<std::size_t>(c)] = static_cast<int>(fl);
        wx[static_cast<std::size_t>(c)] = static_cast<float>(smoothstep(x - fl));
    }
    for (int r = 0; r < rows; ++r) {
        const double y = (r + off_y) / cell;
        const double fl = std::floor(y);
        const auto iy = static_cast<std::size_t>(fl);
        const auto wy = static_cast<float>(smoothstep(y - fl));
        const float* l0 = lattice.data() + iy * static_cast<std::size_t>(nx);
        const float* l1 = l0 + nx;
        float* out = acc.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(cols);
        for (int c = 0; c < cols; ++c) {
            const auto i = static_cast<std::size_t>(ix[static_cast<std::size_t>(c)]);
            const float w = wx[static_cast<std::size_t>(c)];
            const float top = l0[i] + w * (l0[i + 1] - l0[i]);
            const float bottom = l1[i] + w * (l1[i + 1] - l1[i]);
            out[c] += amplitude * (top + wy * (bottom - top));
        }
    }
}

cv::Point toFixed(double x, double y) {
    return {static_cast<int>(std::lround(x * kSubpixelScale)),
            static_cast<int>(std::lround(y * kSubpixelScale))};
}

// One random shape of size size_px (texels) at a random place.
void drawShape(cv::Mat& layer, double size_px, SplitMix64& rng) {
    const double cx = rng.uniform(-size_px, layer.cols + size_px);
    const double cy = rng.uniform(-size_px, layer.rows + size_px);
    const cv::Scalar colour(static_cast<double>(rng.uniformInt(256)));
    const int kind = rng.uniformInt(10);
    if (kind < 4) {  // axis-aligned rectangle
        const double w = size_px;
        const double h = size_px * rng.uniform(0.3, 1.0);
        const bool swap = rng.uniformInt(2) == 1;
        const double hx = 0.5 * (swap ? h : w);
        const double hy = 0.5 * (swap ? w : h);
        const cv::Point pts[4] = {toFixed(cx - hx, cy - hy), toFixed(cx + hx, cy - hy),
                                  toFixed(cx + hx, cy + hy), toFixed(cx - hx, cy + hy)};
        cv::fillConvexPoly(layer, pts, 4, colour, cv::LINE_AA, kSubpixelShift);
    } else if (kind < 6) {  // rotated rectangle
        const double hw = 0.5 * size_px;
        const double hh = 0.5 * size_px * rng.uniform(0.2, 1.0);
        const double a = rng.uniform(0.0, std::numbers::pi);
        const double ca = std::cos(a);
        const double sa = std::sin(a);
        cv::Point pts[4];
        const double corners[4][2] = {{-hw, -hh}, {hw, -hh}, {hw, hh}, {-hw, hh}};
        for (int i = 0; i < 4; ++i) {
            const double x = corners[i][0];
            const double y = corners[i][1];
            pts[i] = toFixed(cx + ca * x - sa * y, cy + sa * x + ca * y);
        }
        cv::fillConvexPoly(layer, pts, 4, colour, cv::LINE_AA, kSubpixelShift);
    } else if (kind < 8) {  // triangle
        cv::Point pts[3];
        const double a0 = rng.uniform(0.0, 2.0 * std::numbers::pi);
        for (int i = 0; i < 3; ++i) {
            const double a = a0 + 2.0 * std::numbers::pi * (i + rng.uniform(-0.25, 0.25)) / 3.0;
            const double r = 0.5 * size_px * rng.uniform(0.6, 1.0);
            pts[i] = toFixed(cx + r * std::cos(a), cy + r * std::sin(a));
        }
        cv::fillConvexPoly(layer, pts, 3, colour, cv::LINE_AA, kSubpixelShift);
    } else {  // ellipse
        const double ax = 0.5 * size_px;
        const double ay = ax * rng.uniform(0.4, 1.0);
        const double angle_deg = rng.uniform(0.0, 180.0);
        const cv::Size axes(static_cast<int>(std::lround(ax * kSubpixelScale)),
                            static_cast<int>(std::lround(ay * kSubpixelScale)));
        cv::ellipse(layer, toFixed(cx, cy), axes, angle_deg, 0.0, 360.0, colour, cv::FILLED,
                    cv::LINE_AA, kSubpixelShift);
    }
}

}  // namespace

cv::Mat makeTexture(int cols, int rows, double texel_m, std::uint64_t seed, double richness) {
    SplitMix64 rng(seed);
    const auto n_texels = static_cast<std::size_t>(cols) * static_cast<std::size_t>(rows);

    // Value noise, octaves of lattice spacing 32 cm down to 1 cm (at least 2 texels).
    std::vector<float> noise(n_texels, 0.0f);
    constexpr double kCellsM[] = {0.32, 0.16, 0.08, 0.04, 0.02, 0.01};
    constexpr float kAmplitudes[] = {0.6f, 0.6f, 0.6f, 0.7f, 0.8f, 0.8f};
    float power = 0.0f;
    for (std::size_t o = 0; o < std::size(kCellsM); ++o) {
        const double cell = std::max(2.0, kCellsM[o] / texel_m);
        addValueNoise(noise, cols, rows, cell, kAmplitudes[o], rng);
        power += kAmplitudes[o] * kAmplitudes[o];
    }
    // The interpolated lattice has a standard deviation of roughly 0.45.
    const float noise_gain = static_cast<float>(richness) * 32.0f / (0.45f * std::sqrt(power));
    // Each surface gets its own brightness, as if lit differently.
    const auto brightness = static_cast<float>(rng.uniform(-25.0, 25.0));

    // Shapes, largest first so small ones stay on top.
    cv::Mat layer(rows, cols, CV_8UC1, cv::Scalar(128));
    const double area_m2 = static_cast<double>(n_texels) * texel_m * texel_m;
    const auto n_shapes =
        static_cast<std::size_t>(std::lround(richness * kShapesPerSquareMetre * area_m2));
    std::vector<double> sizes_px(n_shapes);
    // Inverse CDF of p(s) ~ 1 / s^2: 1 / s uniform between 1 / max and 1 / min.
    for (auto& s : sizes_px) {
        s = 1.0 / (rng.uniform(1.0 / kMaxShapeM, 1.0 / kMinShapeM) * texel_m);
    }
    std::sort(sizes_px.begin(), sizes_px.end(), [](double a, double b) { return a > b; });
    for (const double s : sizes_px) {
        drawShape(layer, s, rng);
    }

    cv::Mat out(rows, cols, CV_8UC1);
    for (int r = 0; r < rows; ++r) {
        const auto* l = layer.ptr<std::uint8_t>(r);
        const float* n =
            noise.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(cols);
        auto* o = out.ptr<std::uint8_t>(r);
        for (int c = 0; c < cols; ++c) {
            const float v = 128.0f + brightness + 0.8f * (static_cast<float>(l[c]) - 128.0f) +
                            noise_gain * n[c];
            o[c] = static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 255.0f)));
        }
    }
    return out;
}

}  // namespace scaled::drivers::synth::detail
