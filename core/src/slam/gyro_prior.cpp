#include <algorithm>
#include <cmath>

#include <scaled/core/slam/gyro_prior.h>
#include <scaled/core/slam/quaternion.h>

namespace scaled::core::slam {

namespace {

// Log of a unit quaternion: the rotation vector (angle in [0, pi]).
Vec3 rotationVectorOf(Vec4 q) {
    if (q(0) < 0) {
        q = -q;
    }
    const Vec3 v = q.tail<3>();
    const Scalar s = v.norm();
    if (s < Scalar(1e-9)) {
        return 2 * v;  // angle = 2 asin(s) ~ 2 s
    }
    return v * (2 * std::atan2(s, q(0)) / s);
}

// Finite, non-negative sigmas (not both zero), a non-negative gap.
bool isValidModel(const GyroModel& model) {
    return model.R_ItoC.allFinite() && model.bias_I_radps.allFinite() && model.noise_density >= 0 &&
           model.bias_sigma_radps >= 0 && (model.noise_density > 0 || model.bias_sigma_radps > 0) &&
           std::isfinite(model.noise_density) && std::isfinite(model.bias_sigma_radps) &&
           model.max_gap_ns >= 0;
}

// q times the rotation of the constant rate w over [a_ns, b_ns].
void integrateConstantRate(Vec4& q, int64_t a_ns, int64_t b_ns, const Vec3& w) {
    const Scalar dt = Scalar(b_ns - a_ns) * Scalar(1e-9);
    q = quatMultiply(q, quatFromRotationVector(w * dt));
}

// The mean rate in the camera frame from the IMU's rotation q over [t0_ns, t1_ns].
GyroRate meanRateOf(const Vec4& q, int64_t t0_ns, int64_t t1_ns, const GyroModel& model, int used) {
    GyroRate rate;
    const Scalar dt = Scalar(t1_ns - t0_ns) * Scalar(1e-9);
    rate.w_C_radps = model.R_ItoC * rotationVectorOf(q) / dt;
    rate.sigma_radps = std::sqrt(model.noise_density * model.noise_density / dt +
                                 model.bias_sigma_radps * model.bias_sigma_radps);
    rate.samples = used;
    return rate;
}

}  // namespace

const char* toString(GyroCoverage coverage) {
    switch (coverage) {
        case GyroCoverage::kOk:
            return "ok";
        case GyroCoverage::kBadInterval:
            return "bad interval or sample";
        case GyroCoverage::kNoSamples:
            return "no gyro samples";
        case GyroCoverage::kGap:
            return "gap in the gyro samples";
    }
    return "?";
}

GyroIntegration integrateGyro(std::span<const ImuSample> samples, int64_t t0_ns, int64_t t1_ns,
                              const GyroModel& model) {
    GyroIntegration out;
    if (!(t1_ns > t0_ns) || !isValidModel(model)) {
        out.coverage = GyroCoverage::kBadInterval;
        return out;
    }
    const int64_t gap = model.max_gap_ns;
    const auto first = std::lower_bound(samples.begin(), samples.end(), t0_ns - gap,
                                        [](const ImuSample& s, int64_t t) { return s.t_ns < t; });

    Vec4 q(1, 0, 0, 0);  // rotation of the IMU frame over [t0, t1], accumulated
    bool have_prev = false;
    int64_t prev_t = 0;
    Vec3 prev_w = Vec3::Zero();
    int used = 0;
    for (auto it = first; it != samples.end() && it->t_ns <= t1_ns + gap; ++it) {
        if (!it->gyro_radps) {
            continue;
        }
        const Vec3 w = *it->gyro_radps - model.bias_I_radps;
        if (!w.allFinite()) {
            out.coverage = GyroCoverage::kBadInterval;
            return out;
        }
        const int64_t t = it->t_ns;
        if (!have_prev) {
            if (t > t0_ns + gap) {
                out.coverage = GyroCoverage::kGap;  // the first sample comes too late
                return out;
            }
            if (t > t0_ns) {
                // constant before the first sample
                integrateConstantRate(q, t0_ns, std::min(t, t1_ns), w);
            }
        } else if (t > t0_ns && prev_t < t1_ns) {
            if (t - prev_t > gap) {
                out.coverage = GyroCoverage::kGap;
                return out;
            }
            // The rate is linear between samples: its value at the piece's
            // midpoint integrates the piece to second order.
            const int64_t a = std::max(prev_t, t0_ns);
            const int64_t b = std::min(t, t1_ns);
            if (b > a) {
                const int64_t mid = a + (b - a) / 2;  // ns: rounding is far below any rate change
                const Scalar f = Scalar(mid - prev_t) / Scalar(t - prev_t);
                integrateConstantRate(q, a, b, prev_w + (w - prev_w) * f);
            }
        }
        have_prev = true;
        prev_t = t;
        prev_w = w;
        // Counted: the last sample at or before t0 and those after it.
        used = t <= t0_ns ? 1 : used + 1;
        if (t >= t1_ns) {
            break;
        }
    }
    if (!have_prev) {
        out.coverage = GyroCoverage::kNoSamples;
        return out;
    }
    if (prev_t < t1_ns) {
        if (t1_ns - prev_t > gap) {
            out.coverage = GyroCoverage::kGap;  // the samples stop short of t1
            return out;
        }
        integrateConstantRate(q, std::max(prev_t, t0_ns), t1_ns,
                              prev_w);  // constant after the last
    }
    out.coverage = GyroCoverage::kOk;
    out.rate = meanRateOf(q, t0_ns, t1_ns, model, used);
    return out;
}

}  // namespace scaled::core::slam
