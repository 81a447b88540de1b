#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <thread>
#include <utility>

#include <scaled/drivers/source/paced_source.h>

namespace scaled::drivers::source {

using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

constexpr double kMaxSpeed = 1e6;
constexpr double kMaxOffsetNs = 9.0e18;  // below INT64_MAX

// (later - earlier) / speed in nanoseconds, 0 when later <= earlier, saturated.
int64_t scaledGapNs(int64_t earlier, int64_t later, double speed) {
    if (later <= earlier) {
        return 0;
    }
    // The difference of two int64 fits in uint64.
    const uint64_t gap = static_cast<uint64_t>(later) - static_cast<uint64_t>(earlier);
    const double scaled = static_cast<double>(gap) / speed;
    return scaled >= kMaxOffsetNs ? static_cast<int64_t>(kMaxOffsetNs)
                                  : static_cast<int64_t>(std::llround(scaled));
}

int64_t saturatingAdd(int64_t a, int64_t b) {
    if (b > 0 && a > std::numeric_limits<int64_t>::max() - b) {
        return std::numeric_limits<int64_t>::max();
    }
    return a + b;
}

}  // namespace

int64_t SteadyPacingClock::nowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

void SteadyPacingClock::sleepUntil(int64_t t_ns) {
    const auto at = std::chrono::steady_clock::time_point(
        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
            std::chrono::nanoseconds(t_ns)));
    std::this_thread::sleep_until(at);
}

Result<std::unique_ptr<PacedFrameSource>> PacedFrameSource::create(
    std::unique_ptr<FrameSource> inner, const PacingOptions& options,
    std::shared_ptr<PacingClock> clock) {
    if (!inner) {
        return makeError(ErrorCode::kInvalidArgument, "PacedFrameSource: no frame source");
    }
    if (!(std::isfinite(options.speed) && options.speed > 0 && options.speed <= kMaxSpeed)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "PacingOptions.speed must be finite and in (0, 1e6] (got " +
                             std::to_string(options.speed) + ")");
    }
    if (!clock) {
        clock = std::make_shared<SteadyPacingClock>();
    }
    return std::unique_ptr<PacedFrameSource>(
        new PacedFrameSource(std::move(inner), options, std::move(clock)));
}

PacedFrameSource::PacedFrameSource(std::unique_ptr<FrameSource> inner, const PacingOptions& options,
                                   std::shared_ptr<PacingClock> clock)
    : inner_(std::move(inner)), options_(options), clock_(std::move(clock)) {}

int64_t PacedFrameSource::dueNs(int64_t t_ns, int64_t now_ns) {
    if (!origin_t_ns_) {
        origin_t_ns_ = t_ns;
        origin_clock_ns_ = now_ns;
    }
    return saturatingAdd(origin_clock_ns_, scaledGapNs(*origin_t_ns_, t_ns, options_.speed));
}

Result<bool> PacedFrameSource::next(Frame& frame) {
    if (options_.mode == PacingMode::kAsFastAsPossible) {
        auto r = inner_->next(frame);
        if (r && *r) {
            ++stats_.released;
        }
        return r;
    }
    while (true) {
        Frame f;
        auto r = inner_->next(f);
        if (!r || !*r) {
            return r;
        }
        const int64_t now_ns = clock_->nowNs();
        const int64_t due_ns = dueNs(f.t_ns, now_ns);
        const std::optional<int64_t> previous_t_ns = previous_t_ns_;
        previous_t_ns_ = f.t_ns;
        if (now_ns < due_ns) {
            clock_->sleepUntil(due_ns);
            ++stats_.slept;
        } else if (now_ns > due_ns) {
            const int64_t late_ns = now_ns - due_ns;
            if (options_.drop_late && previous_t_ns &&
                late_ns > scaledGapNs(*previous_t_ns, f.t_ns, options_.speed)) {
                ++stats_.dropped;
                continue;
            }
            ++stats_.late;
            stats_.max_late_ns = std::max(stats_.max_late_ns, late_ns);
        }
        ++stats_.released;
        frame = std::move(f);
        return true;
    }
}

Result<bool> PacedFrameSource::seek(std::size_t index) {
    origin_t_ns_.reset();
    previous_t_ns_.reset();
    return inner_->seek(index);
}

}  // namespace scaled::drivers::source
