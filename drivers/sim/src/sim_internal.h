#pragma once

// Shared by the sim source and the sim detector: the trajectory and a small
// fully specified random generator (the standard distributions differ
// between standard libraries; these do not).

#include <cmath>
#include <cstdint>
#include <numbers>

#include <scaled/core/result.h>
#include <scaled/sim/sim_source.h>
#include <scaled/synth/trajectory.h>

namespace scaled::sim::detail {

inline std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30U)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27U)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31U);
}

inline std::uint64_t combineSeed(std::uint64_t seed, std::uint64_t stream) {
    return mix64(seed ^ mix64(stream + 0x9e3779b97f4a7c15ULL));
}

class Rng {
public:
    explicit Rng(std::uint64_t seed) : state_(seed) {}

    std::uint64_t next() {
        state_ += 0x9e3779b97f4a7c15ULL;
        return mix64(state_);
    }
    // Uniform in [0, 1).
    double uniform() { return static_cast<double>(next() >> 11U) * 0x1.0p-53; }
    // Standard normal (Box-Muller, one value per call).
    double gaussian() {
        double u1 = uniform();
        while (u1 <= 0.0) {
            u1 = uniform();
        }
        const double u2 = uniform();
        return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
    }

private:
    std::uint64_t state_;
};

// The sim camera's trajectory (validated config).
core::Result<synth::Trajectory> makeTrajectory(const SimConfig& config);

// Timestamp of frame i.
std::int64_t frameTimeNs(std::int64_t index, double fps);

}  // namespace scaled::sim::detail
