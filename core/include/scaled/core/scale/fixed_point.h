#pragma once

// Fixed-point arithmetic for the integer scale posterior (fixed_posterior.h):
// Q formats, and exp / log / log-sum-exp from two small tables with linear
// interpolation. Everything here is integer arithmetic; the tables are built at
// compile time (constexpr series), so they cost no start-up time, no heap and
// no floating point at run time.
//
// Formats (value = integer * 2^-frac_bits):
//   log-probabilities  int32 (LogQ16)  Q16 nats: 1.5e-5 nats resolution,
//                                      range +-32768 nats
//   log2 quantities    int64           Q24 log2 units (variances, sigmas)
//   probabilities,     int64           Q30 (1.0 = 2^30)
//   mantissas
//   lengths            int64           Q32 metres (2.3e-10 m, up to 2^30 m)
//
// Table accuracy (measured over every input in tests/unit/core/
// fixed_posterior_test.cpp; the interpolation bound is h^2/8 max|f''| with
// h = 2^-10):
//   2^-u, u in [0, 1]      1025 x uint32 Q30, relative error <= 6e-8
//   log2(1 + t), t in [0,1] 1025 x uint32 Q30, absolute error <= 2e-7 log2 units
// so expNegQ30 is within 1e-7 relative (+1 unit of Q30), lnQ16 within 1 unit
// of Q16 (1.5e-5 nats) and logAddExpQ16 within 2 units of Q16.

#include <array>
#include <bit>
#include <cstdint>
#include <limits>

namespace scaled::core::fixed {

using LogQ16 = std::int32_t;

inline constexpr int kLogFracBits = 16;
inline constexpr std::int64_t kLogOne = std::int64_t{1} << kLogFracBits;  // 1 nat
inline constexpr int kLog2FracBits = 24;
inline constexpr std::int64_t kLog2One = std::int64_t{1} << kLog2FracBits;
inline constexpr int kProbFracBits = 30;
inline constexpr std::int64_t kProbOne = std::int64_t{1} << kProbFracBits;
inline constexpr int kLengthFracBits = 32;

inline constexpr int kTableBits = 10;
inline constexpr int kTableSize = (1 << kTableBits) + 1;

// ln 2 and 1 / ln 2 in Q32 (rounded).
inline constexpr std::int64_t kLn2Q32 = 2977044472;     // 0.693147180559945 * 2^32
inline constexpr std::int64_t kInvLn2Q32 = 6196328019;  // 1.442695040888963 * 2^32

namespace detail {

// Compile-time series: only for building the tables (double, evaluated by the
// compiler, never at run time).
constexpr double expSeries(double x) {  // |x| <= 1
    double term = 1;
    double sum = 1;
    for (int k = 1; k < 30; ++k) {
        term *= x / k;
        sum += term;
    }
    return sum;
}

constexpr double log1pSeries(double t) {  // t in [0, 1]: ln(1 + t) = 2 atanh(t / (2 + t))
    const double s = t / (2 + t);
    const double s2 = s * s;
    double power = s;
    double sum = 0;
    for (int k = 0; k < 40; ++k) {
        sum += power / (2 * k + 1);
        power *= s2;
    }
    return 2 * sum;
}

constexpr std::uint32_t roundQ30(double v) {
    // std::lround is not constexpr (C++20); v >= 0 here, so truncating v + 0.5
    // rounds to nearest.
    const double shifted = v * static_cast<double>(kProbOne) + 0.5;
    // NOLINTNEXTLINE(bugprone-incorrect-roundings): see above
    return static_cast<std::uint32_t>(shifted);
}

struct Tables {
    std::array<std::uint32_t, kTableSize> exp2_neg{};  // 2^-(i / 1024), Q30
    std::array<std::uint32_t, kTableSize> log2_1p{};   // log2(1 + i / 1024), Q30
};

constexpr Tables makeTables() {
    constexpr double kLn2 = 0.693147180559945309417;
    Tables t;
    for (int i = 0; i < kTableSize; ++i) {
        const double u = static_cast<double>(i) / (1 << kTableBits);
        const auto slot = static_cast<std::size_t>(i);
        t.exp2_neg[slot] = roundQ30(expSeries(-u * kLn2));
        t.log2_1p[slot] = roundQ30(log1pSeries(u) / kLn2);
    }
    return t;
}

inline constexpr Tables kTables = makeTables();

// Linear interpolation in a table at a Q30 position in [0, 1].
constexpr std::int64_t interpolate(const std::array<std::uint32_t, kTableSize>& table,
                                   std::int64_t pos_q30) {
    constexpr int kFracBits = kProbFracBits - kTableBits;
    std::int64_t idx = pos_q30 >> kFracBits;
    if (idx >= (1 << kTableBits)) {
        idx = (1 << kTableBits) - 1;
    }
    const std::int64_t frac = pos_q30 - (idx << kFracBits);
    const auto a = static_cast<std::int64_t>(table[static_cast<std::size_t>(idx)]);
    const auto b = static_cast<std::int64_t>(table[static_cast<std::size_t>(idx + 1)]);
    return a + (((b - a) * frac + (std::int64_t{1} << (kFracBits - 1))) >> kFracBits);
}

}  // namespace detail

// Rounding arithmetic shift right by s >= 0; s <= 0 shifts left, saturating
// at +-2^61 (2^29 m in Q32 metres: far beyond any physical length, and the sum
// of two saturated values still fits int64).
constexpr std::int64_t shiftRound(std::int64_t v, int s) {
    constexpr std::int64_t kSat = std::int64_t{1} << 61;
    if (s > 0) {
        if (s >= 63) {
            return 0;
        }
        return (v + (std::int64_t{1} << (s - 1))) >> s;
    }
    if (v >= kSat || v <= -kSat) {
        return v > 0 ? kSat : -kSat;
    }
    if (v == 0 || s == 0) {
        return v;
    }
    const int left = -s;
    if (left >= 61 || v >= (kSat >> left) || v <= -(kSat >> left)) {
        return v > 0 ? kSat : -kSat;
    }
    return v * (std::int64_t{1} << left);
}

// 2^-u for u >= 0 in Q24 log2 units, as Q30 (0 once below half a unit of Q30).
constexpr std::int64_t exp2NegQ30(std::int64_t u_q24) {
    if (u_q24 <= 0) {
        return kProbOne;
    }
    const std::int64_t n = u_q24 >> kLog2FracBits;
    if (n > kProbFracBits) {
        return 0;
    }
    const std::int64_t f = u_q24 & (kLog2One - 1);
    const std::int64_t m =
        detail::interpolate(detail::kTables.exp2_neg, f << (kProbFracBits - kLog2FracBits));
    return shiftRound(m, static_cast<int>(n));
}

// 2^y for y in Q24 log2 units, split as mantissa * 2^(exponent - 30) with the
// mantissa (Q30) in (2^29, 2^30].
struct Exp2Split {
    std::int64_t mantissa = kProbOne;
    int exponent = 0;
};
constexpr Exp2Split exp2Split(std::int64_t y_q24) {
    // exponent = ceil(y), u = exponent - y in [0, 1).
    const std::int64_t e = -((-y_q24) >> kLog2FracBits);
    const std::int64_t u = (e << kLog2FracBits) - y_q24;
    return {detail::interpolate(detail::kTables.exp2_neg, u << (kProbFracBits - kLog2FracBits)),
            static_cast<int>(e)};
}

// log2(v) of the integer v > 0, Q24 log2 units (v = 0 gives the value of v = 1).
constexpr std::int64_t log2Q24(std::uint64_t v) {
    if (v == 0) {
        v = 1;
    }
    const int k = 63 - std::countl_zero(v);
    const std::uint64_t normalised =
        k >= kProbFracBits ? v >> (k - kProbFracBits) : v << (kProbFracBits - k);
    const auto t = static_cast<std::int64_t>(normalised) - kProbOne;  // Q30 in [0, 1)
    const std::int64_t l = detail::interpolate(detail::kTables.log2_1p, t);
    constexpr int kDrop = kProbFracBits - kLog2FracBits;
    return (std::int64_t{k} << kLog2FracBits) + ((l + (std::int64_t{1} << (kDrop - 1))) >> kDrop);
}

// ln(v * 2^-frac_bits) for v > 0, Q16 nats.
constexpr std::int64_t lnQ16(std::uint64_t v, int frac_bits) {
    const std::int64_t l2 = log2Q24(v) - (std::int64_t{frac_bits} << kLog2FracBits);
    constexpr int kShift = kLog2FracBits + 32 - kLogFracBits;
    return (l2 * kLn2Q32 + (std::int64_t{1} << (kShift - 1))) >> kShift;
}

// exp(-x) for x >= 0 in Q16 nats, as Q30 (0 beyond ~21 nats).
constexpr std::int64_t expNegQ30(std::int64_t x_q16) {
    if (x_q16 <= 0) {
        return kProbOne;
    }
    if (x_q16 >= (std::int64_t{32} << kLogFracBits)) {
        return 0;  // e^-32 < 2^-46: far below a unit of Q30
    }
    constexpr int kShift = kLogFracBits + 32 - kLog2FracBits;
    return exp2NegQ30((x_q16 * kInvLn2Q32 + (std::int64_t{1} << (kShift - 1))) >> kShift);
}

// ln(1 + t) for t in [0, 1] (Q30), Q16 nats.
constexpr std::int64_t log1pQ16(std::int64_t t_q30) {
    const std::int64_t l2 = detail::interpolate(detail::kTables.log2_1p, t_q30);
    constexpr int kShift = kProbFracBits + 32 - kLogFracBits;
    return (l2 * kLn2Q32 + (std::int64_t{1} << (kShift - 1))) >> kShift;
}

// log(e^a + e^b) in Q16 nats: max + ln(1 + e^-|a - b|).
constexpr std::int64_t logAddExpQ16(std::int64_t a, std::int64_t b) {
    const std::int64_t hi = a > b ? a : b;
    const std::int64_t lo = a > b ? b : a;
    return hi + log1pQ16(expNegQ30(hi - lo));
}

// log2(2^a + 2^b), Q24 log2 units.
constexpr std::int64_t log2AddExp2Q24(std::int64_t a, std::int64_t b) {
    const std::int64_t hi = a > b ? a : b;
    const std::int64_t lo = a > b ? b : a;
    const std::int64_t t = exp2NegQ30(hi - lo);
    constexpr int kDrop = kProbFracBits - kLog2FracBits;
    return hi +
           ((detail::interpolate(detail::kTables.log2_1p, t) + (std::int64_t{1} << (kDrop - 1))) >>
            kDrop);
}

constexpr LogQ16 saturateLog(std::int64_t v) {
    constexpr std::int64_t kMax = std::numeric_limits<LogQ16>::max();
    constexpr std::int64_t kMin = std::numeric_limits<LogQ16>::min();
    return static_cast<LogQ16>(v > kMax ? kMax : (v < kMin ? kMin : v));
}

}  // namespace scaled::core::fixed
