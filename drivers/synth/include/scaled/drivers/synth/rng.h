#pragma once

// A small, fully specified random generator (SplitMix64). The standard
// library's distributions differ between implementations; these do not, so a
// seed gives the same scene, trajectory and noise everywhere. Used by the
// renderer and by the daemon's sim source and detector (drivers/sim).

#include <cmath>
#include <cstdint>
#include <numbers>

namespace scaled::drivers::synth {

// Bijective 64-bit mix (the SplitMix64 finaliser).
inline std::uint64_t mix64(std::uint64_t z) {
    z = (z ^ (z >> 30U)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27U)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31U);
}

// Combines a seed with a stream index into an independent seed.
inline std::uint64_t combineSeed(std::uint64_t seed, std::uint64_t stream) {
    return mix64(seed ^ mix64(stream + 0x9e3779b97f4a7c15ULL));
}

class SplitMix64 {
public:
    explicit SplitMix64(std::uint64_t seed) : state_(seed) {}

    std::uint64_t next() {
        state_ += 0x9e3779b97f4a7c15ULL;
        return mix64(state_);
    }

    // Uniform in [0, 1), 53 random bits.
    double uniform() { return static_cast<double>(next() >> 11U) * 0x1.0p-53; }

    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }

    // Uniform integer in [0, n), n > 0 (the modulo bias is negligible for small n).
    int uniformInt(int n) { return static_cast<int>(next() % static_cast<std::uint64_t>(n)); }

    // Standard normal by Box-Muller; returns the pair's second value on the next call.
    double gaussian() {
        if (has_spare_) {
            has_spare_ = false;
            return spare_;
        }
        const auto [r, a] = boxMuller();
        spare_ = r * std::sin(a);
        has_spare_ = true;
        return r * std::cos(a);
    }

    // Standard normal by Box-Muller from a fresh pair of uniforms on every call
    // (the pair's second value is dropped), so the stream does not depend on
    // how many values were drawn before.
    double gaussianUnpaired() {
        const auto [r, a] = boxMuller();
        return r * std::cos(a);
    }

private:
    struct Polar {
        double r;
        double a;
    };
    // Radius and angle of a Box-Muller pair.
    Polar boxMuller() {
        double u1 = uniform();
        while (u1 <= 0.0) {
            u1 = uniform();
        }
        const double u2 = uniform();
        return {std::sqrt(-2.0 * std::log(u1)), 2.0 * std::numbers::pi * u2};
    }

    std::uint64_t state_;
    double spare_ = 0.0;
    bool has_spare_ = false;
};

}  // namespace scaled::drivers::synth
