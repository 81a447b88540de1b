#include <bit>
#include <cmath>

#include <scaled/drivers/vision/brief.h>

namespace scaled::drivers::vision {

namespace {

struct Pair {
    std::int8_t ax, ay, bx, by;
};

// 256 pairs of offsets in [-12, 12] (the 5x5 boxes then stay within +-14),
// drawn once from a fixed xorshift sequence: the same pattern on every
// platform and in every build.
constexpr std::array<Pair, 256> makePattern() {
    std::array<Pair, 256> p{};
    std::uint64_t s = 0x9E3779B97F4A7C15ULL;
    auto next = [&s]() {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        // Sum of two uniforms in [-6, 6]: a triangular spread, denser near the centre.
        const int u = static_cast<int>(s % 13) - 6;
        const int v = static_cast<int>((s >> 16) % 13) - 6;
        return static_cast<std::int8_t>(u + v);
    };
    for (auto& q : p) {
        q.ax = next();
        q.ay = next();
        q.bx = next();
        q.by = next();
    }
    return p;
}

constexpr std::array<Pair, 256> kPattern = makePattern();

// Sum of the 5x5 box centred on (x, y).
int boxSum(const cv::Mat& g, int x, int y) {
    int s = 0;
    for (int r = -2; r <= 2; ++r) {
        const uchar* row = g.ptr<uchar>(y + r) + x;
        s += row[-2] + row[-1] + row[0] + row[1] + row[2];
    }
    return s;
}

}  // namespace

bool computeBrief(const cv::Mat& gray, const core::Vec2& px, BriefDescriptor& out) {
    if (gray.empty() || gray.type() != CV_8UC1 || !px.allFinite()) {
        return false;
    }
    const double fx = std::round(static_cast<double>(px.x()));
    const double fy = std::round(static_cast<double>(px.y()));
    if (fx < kBriefRadiusPx || fy < kBriefRadiusPx || fx > gray.cols - 1 - kBriefRadiusPx ||
        fy > gray.rows - 1 - kBriefRadiusPx) {
        return false;
    }
    const int x = static_cast<int>(fx);
    const int y = static_cast<int>(fy);
    out = {};
    for (std::size_t i = 0; i < kPattern.size(); ++i) {
        const Pair& q = kPattern[i];
        if (boxSum(gray, x + q.ax, y + q.ay) < boxSum(gray, x + q.bx, y + q.by)) {
            out[i / 64] |= std::uint64_t{1} << (i % 64);
        }
    }
    return true;
}

int briefDistance(const BriefDescriptor& a, const BriefDescriptor& b) {
    int d = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        d += std::popcount(a[i] ^ b[i]);
    }
    return d;
}

}  // namespace scaled::drivers::vision
