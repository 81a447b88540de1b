#include <cmath>
#include <cstdio>
#include <numbers>

#include <Eigen/Geometry>

#include <scaled/drivers/imu/simulated_gyro.h>

namespace scaled::drivers::imu {

namespace {

std::uint64_t splitmix64(std::uint64_t& s) {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30U)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27U)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31U);
}

// A standard normal draw (Box-Muller), the same on every platform.
double gaussian(std::uint64_t& s) {
    const double u1 = (double(splitmix64(s) >> 11U) + 0.5) * 0x1.0p-53;
    const double u2 = double(splitmix64(s) >> 11U) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

}  // namespace

core::Result<SimulatedGyro> SimulatedGyro::create(const SimulatedGyroOptions& o) {
    const auto bad = [](const char* what, double v, const char* range) {
        char text[160];
        std::snprintf(text, sizeof text, "simulated gyro: %s = %g: must be in %s", what, v, range);
        return core::makeError(core::ErrorCode::kInvalidArgument, text);
    };
    if (!(o.rate_hz >= 10 && o.rate_hz <= 10000)) {
        return bad("rate_hz", o.rate_hz, "[10, 10000]");
    }
    if (!(o.noise_density >= 0 && o.noise_density <= 1)) {
        return bad("noise_density", o.noise_density, "[0, 1] rad/s/sqrt(Hz)");
    }
    if (!(o.bias_sigma_radps >= 0 && o.bias_sigma_radps <= 10)) {
        return bad("bias_sigma_radps", o.bias_sigma_radps, "[0, 10] rad/s");
    }
    std::uint64_t s = o.seed * 0x2545F4914F6CDD1DULL + 1;
    core::Vec3 bias;
    for (int a = 0; a < 3; ++a) {
        bias(a) = static_cast<core::Scalar>(o.bias_sigma_radps * gaussian(s));
    }
    return SimulatedGyro(o, bias);
}

SimulatedGyro::SimulatedGyro(const SimulatedGyroOptions& options, const core::Vec3& bias)
    : options_(options), bias_(bias), state_(options.seed * 0x9E3779B97F4A7C15ULL + 7) {}

std::span<const core::ImuSample> SimulatedGyro::between(std::int64_t t0_ns,
                                                        const core::Mat3& R0_CtoW,
                                                        std::int64_t t1_ns,
                                                        const core::Mat3& R1_CtoW) {
    samples_.clear();
    constexpr std::int64_t kMaxIntervalNs = 10'000'000'000;  // no frame gap a tracker keeps
    if (t1_ns <= t0_ns || t1_ns - t0_ns > kMaxIntervalNs) {
        return samples_;
    }
    const double dt = double(t1_ns - t0_ns) * 1e-9;
    const Eigen::AngleAxisd aa((R0_CtoW.transpose() * R1_CtoW).cast<double>());
    const Eigen::Vector3d w = aa.axis() * (aa.angle() / dt);
    const double sigma = options_.noise_density * std::sqrt(options_.rate_hz);
    const auto n = static_cast<std::int64_t>(std::ceil(dt * options_.rate_hz));
    for (std::int64_t k = 0; k <= n; ++k) {
        core::ImuSample s;
        s.t_ns = k == n ? t1_ns
                        : t0_ns + static_cast<std::int64_t>(
                                      std::llround(double(t1_ns - t0_ns) * double(k) / double(n)));
        s.accel_mps2 = core::Vec3::Zero();
        core::Vec3 g;
        for (int a = 0; a < 3; ++a) {
            g(a) = static_cast<core::Scalar>(w(a) + sigma * gaussian(state_)) + bias_(a);
        }
        s.gyro_radps = g;
        samples_.push_back(s);
    }
    return samples_;
}

std::string SimulatedGyro::describe() const {
    char text[200];
    std::snprintf(text, sizeof text,
                  "simulated gyro from ground truth (%g Hz, %g rad/s/sqrt(Hz), bias (%.4f, "
                  "%.4f, %.4f) rad/s)",
                  options_.rate_hz, options_.noise_density, double(bias_.x()), double(bias_.y()),
                  double(bias_.z()));
    return text;
}

}  // namespace scaled::drivers::imu
