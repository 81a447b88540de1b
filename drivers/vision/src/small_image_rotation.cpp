#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <scaled/drivers/vision/small_image_rotation.h>

namespace scaled::drivers::vision {

using Vec3f = Eigen::Vector3f;
using Mat3f = Eigen::Matrix3f;

namespace {

// The previous image and its gradients at (x, y), bilinear, from the
// interleaved (value, d/dx, d/dy) buffer.
struct Sample {
    float value;
    float gx;
    float gy;
};

inline Sample bilinear3(const float* data, int stride, float x, float y) {
    const int x0 = static_cast<int>(x);
    const int y0 = static_cast<int>(y);
    const float fx = x - static_cast<float>(x0);
    const float fy = y - static_cast<float>(y0);
    const float w00 = (1 - fx) * (1 - fy);
    const float w01 = fx * (1 - fy);
    const float w10 = (1 - fx) * fy;
    const float w11 = fx * fy;
    const float* p =
        data + (static_cast<std::ptrdiff_t>(y0) * stride) + (static_cast<std::ptrdiff_t>(3) * x0);
    const float* q = p + stride;
    return {w00 * p[0] + w01 * p[3] + w10 * q[0] + w11 * q[3],
            w00 * p[1] + w01 * p[4] + w10 * q[1] + w11 * q[4],
            w00 * p[2] + w01 * p[5] + w10 * q[2] + w11 * q[5]};
}

constexpr int kBorder = 2;         // small pixels left out at the border
constexpr int kPixelStep = 2;      // every second small pixel of every second row
constexpr float kHuber = 0.5F;     // in normalised intensity
constexpr float kMinStep = 1e-4F;  // rad (0.007 small pixels): converged
constexpr float kMinDepthRatio = 0.1F;
constexpr int kMinPixels = 50;             // compared, at the least
constexpr float kMaxStep = 0.05F;          // rad (3 small pixels at f 65) per step
constexpr float kSettledStep = 2e-3F;      // rad (0.13 small pixels): a last step this small
constexpr float kMinConditioning = 1e-4F;  // smallest over largest eigenvalue of H
constexpr float kMaxRms = 0.5F;            // two unrelated images give about 1.4

}  // namespace

void SmallImageRotation::create(int width, int height) {
    const cv::Size small(width / kShrink, height / kShrink);
    shrunk_.create(small, CV_32F);
    blurred_.create(small, CV_32F);
    previous_.create(small, CV_32F);
    current_.create(small, CV_32F);
    previous3_.create(small, CV_32FC3);
    has_previous_ = false;
}

// Loops of their own rather than cv::resize, GaussianBlur and Sobel, which
// build filter engines and tables on every call (allocations).
void SmallImageRotation::makeSmall(const cv::Mat& gray, cv::Mat& out) {
    const int w = gray.cols / kShrink;
    const int h = gray.rows / kShrink;
    if (shrunk_.cols != w || shrunk_.rows != h) {
        create(gray.cols, gray.rows);
    }
    // The mean of each kShrink x kShrink block.
    for (int v = 0; v < h; ++v) {
        float* row = shrunk_.ptr<float>(v);
        std::fill(row, row + w, 0.0F);
        for (int dy = 0; dy < kShrink; ++dy) {
            const std::uint8_t* src = gray.ptr<std::uint8_t>(v * kShrink + dy);
            for (int u = 0; u < w; ++u) {
                int sum = 0;
                for (int dx = 0; dx < kShrink; ++dx) {
                    sum += src[u * kShrink + dx];
                }
                row[u] += static_cast<float>(sum);
            }
        }
        for (int u = 0; u < w; ++u) {
            row[u] *= 1.0F / (kShrink * kShrink);
        }
    }
    // Binomial blur [1 4 6 4 1] / 16, rows then columns, the border replicated.
    constexpr float kTaps[5] = {1.0F / 16, 4.0F / 16, 6.0F / 16, 4.0F / 16, 1.0F / 16};
    for (int v = 0; v < h; ++v) {
        const float* src = shrunk_.ptr<float>(v);
        float* dst = blurred_.ptr<float>(v);
        for (int u = 0; u < w; ++u) {
            float acc = 0;
            for (int k = -2; k <= 2; ++k) {
                acc += kTaps[k + 2] * src[std::clamp(u + k, 0, w - 1)];
            }
            dst[u] = acc;
        }
    }
    double sum = 0;
    double sum_sq = 0;
    for (int v = 0; v < h; ++v) {
        float* dst = out.ptr<float>(v);
        for (int u = 0; u < w; ++u) {
            float acc = 0;
            for (int k = -2; k <= 2; ++k) {
                acc += kTaps[k + 2] * blurred_.ptr<float>(std::clamp(v + k, 0, h - 1))[u];
            }
            dst[u] = acc;
            sum += double(acc);
            sum_sq += double(acc) * double(acc);
        }
    }
    // Zero mean, unit spread: a change of exposure is not a rotation.
    const double n = double(w) * h;
    const double mean = sum / n;
    const double spread = std::sqrt(std::max(sum_sq / n - mean * mean, 0.0));
    const auto scale = static_cast<float>(1.0 / std::max(spread, 1.0));
    const auto offset = static_cast<float>(mean);
    for (int v = 0; v < h; ++v) {
        float* dst = out.ptr<float>(v);
        for (int u = 0; u < w; ++u) {
            dst[u] = (dst[u] - offset) * scale;
        }
    }
}

void SmallImageRotation::gradients() {
    const int w = previous_.cols;
    const int h = previous_.rows;
    for (int v = 0; v < h; ++v) {
        const float* up = previous_.ptr<float>(std::max(v - 1, 0));
        const float* row = previous_.ptr<float>(v);
        const float* down = previous_.ptr<float>(std::min(v + 1, h - 1));
        auto* out = previous3_.ptr<cv::Vec3f>(v);
        for (int u = 0; u < w; ++u) {
            out[u] =
                cv::Vec3f(row[u], 0.5F * (row[std::min(u + 1, w - 1)] - row[std::max(u - 1, 0)]),
                          0.5F * (down[u] - up[u]));
        }
    }
}

SmallImageRotation::Normal SmallImageRotation::normalEquations(const Intrinsics& k, const Mat3f& R,
                                                               const Vec3f& t) const {
    Normal n;
    const int w = current_.cols;
    const int h = current_.rows;
    const auto* prev3 = previous3_.ptr<float>(0);
    const auto stride3 = static_cast<int>(previous3_.step1());
    const auto xmax = static_cast<float>(w - 2);
    const auto ymax = static_cast<float>(h - 2);
    const float inv_f = 1.0F / k.f;
    for (int v = kBorder; v < h - kBorder; v += kPixelStep) {
        const float* cur = current_.ptr<float>(v);
        const float ry = (static_cast<float>(v) - k.cy) * inv_f;
        for (int u = kBorder; u < w - kBorder; u += kPixelStep) {
            // The pixel's scene point, at unit depth in the current camera,
            // seen from the previous one: rp = R ray + t.
            const Vec3f ray((static_cast<float>(u) - k.cx) * inv_f, ry, 1.0F);
            const Vec3f rp = R * ray + t;
            if (rp.z() <= kMinDepthRatio) {
                continue;
            }
            const float iz = 1.0F / rp.z();
            const float xp = k.f * rp.x() * iz + k.cx;
            const float yp = k.f * rp.y() * iz + k.cy;
            if (!(xp >= 1 && yp >= 1 && xp <= xmax && yp <= ymax)) {
                continue;
            }
            const Sample smp = bilinear3(prev3, stride3, xp, yp);
            const float e = smp.value - cur[u];
            // c: the gradient through d pixel / d rp; d rp / d delta for
            // R Exp(delta) is -R [ray]x, so J = -(R^T c) x ray.
            const Vec3f c(k.f * iz * smp.gx, k.f * iz * smp.gy,
                          -iz * iz * k.f * (rp.x() * smp.gx + rp.y() * smp.gy));
            const Vec3f J = -(R.transpose() * c).cross(ray);
            const float ae = std::abs(e);
            const float wgt = ae <= kHuber ? 1.0F : kHuber / ae;
            n.H.noalias() += (wgt * J) * J.transpose();
            n.b.noalias() += (wgt * e) * J;
            n.sq += e * e;
            ++n.used;
        }
    }
    return n;
}

std::optional<SmallImageRotation::Result> SmallImageRotation::align(
    const core::PinholeRadialCamera& camera, const core::Mat3& R0_CinP,
    const core::Vec3& t_CinP_per_depth) const {
    const auto& intr = camera.intrinsics();
    constexpr float kS = 1.0F / kShrink;
    Intrinsics k;
    k.f = 0.5F * static_cast<float>(intr.fx + intr.fy) * kS;
    k.cx = (static_cast<float>(intr.cx) + 0.5F) * kS - 0.5F;
    k.cy = (static_cast<float>(intr.cy) + 0.5F) * kS - 0.5F;
    const Vec3f t = t_CinP_per_depth.cast<float>();
    const int min_used =
        std::max(kMinPixels, (current_.cols * current_.rows) / (4 * kPixelStep * kPixelStep));
    Mat3f R = R0_CinP.cast<float>();
    Result res;
    bool converged = false;
    bool settled = false;  // the last step small enough to trust its R
    for (int it = 0; it < kMaxIterations && !converged; ++it) {
        const Normal n = normalEquations(k, R, t);
        if (n.used < min_used) {
            return std::nullopt;  // too little overlap where the last step took it
        }
        // A direction the image cannot see (texture along one line): no answer.
        const Eigen::SelfAdjointEigenSolver<Mat3f> eig(n.H, Eigen::EigenvaluesOnly);
        if (!(eig.eigenvalues()(0) > kMinConditioning * eig.eigenvalues()(2))) {
            return std::nullopt;
        }
        Vec3f d = -n.H.ldlt().solve(n.b);
        if (!d.allFinite()) {
            return std::nullopt;
        }
        res.rms = std::sqrt(n.sq / static_cast<float>(n.used));
        res.pixels = n.used;
        res.iterations = it + 1;
        const float angle = d.norm();
        if (angle > kMaxStep) {
            d *= kMaxStep / angle;  // Gauss-Newton far from the minimum: a bounded step
        }
        if (angle > 0) {
            R = R * Eigen::AngleAxisf(d.norm(), d.normalized()).toRotationMatrix();
        }
        // A step this small leaves the residual where it was measured: the
        // overlap and rms above are the answer's.
        converged = angle < kMinStep;
        settled = angle < kSettledStep;
    }
    // Still moving after kMaxIterations (its last step above kSettledStep), or
    // the images do not agree under any rotation (a scene that moved, a blank
    // frame): no answer.
    if (!settled || !R.allFinite() || res.rms > kMaxRms) {
        return std::nullopt;
    }
    res.R_CinP = R.cast<core::Scalar>();
    return res;
}

std::optional<SmallImageRotation::Result> SmallImageRotation::push(
    const cv::Mat& gray, const core::PinholeRadialCamera& camera, const core::Mat3& R0_CinP,
    const core::Vec3& t_CinP_per_depth, bool align_now) {
    makeSmall(gray, current_);
    std::optional<Result> out;
    if (align_now && has_previous_ && previous_.size() == current_.size()) {
        out = align(camera, R0_CinP, t_CinP_per_depth);
    }
    std::swap(previous_, current_);
    gradients();
    has_previous_ = true;
    return out;
}

}  // namespace scaled::drivers::vision
