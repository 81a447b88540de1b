#pragma once

// PacedFrameSource: replays any FrameSource either as fast as the consumer
// reads it or at the pace it was recorded, like a live camera.
//
// Real time: the first frame read after creation or seek() sets the origin
// (its timestamp t_0 and the clock's time start). Frame i is released at
//
//     start + (t_i - t_0) / speed          on the injected clock
//
// next() sleeps until then when the consumer is early; when it is already late
// it never sleeps and counts the frame as late. With drop_late, a frame more
// than one frame period late (period = (t_i - t_{i-1}) / speed, the gap to the
// frame read before it) is skipped and counted as dropped, as a live camera
// drops the frames a slow consumer misses; the next frame is read instead.
//
// The clock is an interface so that tests use a fake one and never sleep;
// SteadyPacingClock is std::chrono::steady_clock + std::this_thread::sleep_until.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>

#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::source {

class PacingClock {
public:
    PacingClock() = default;
    PacingClock(const PacingClock&) = delete;
    PacingClock& operator=(const PacingClock&) = delete;
    PacingClock(PacingClock&&) = delete;
    PacingClock& operator=(PacingClock&&) = delete;
    virtual ~PacingClock() = default;

    // Monotonic time in nanoseconds (any origin).
    virtual int64_t nowNs() = 0;
    // Returns at or after nowNs() == t_ns.
    virtual void sleepUntil(int64_t t_ns) = 0;
};

class SteadyPacingClock final : public PacingClock {
public:
    int64_t nowNs() override;
    void sleepUntil(int64_t t_ns) override;
};

enum class PacingMode { kAsFastAsPossible, kRealTime };

struct PacingOptions {
    PacingMode mode = PacingMode::kAsFastAsPossible;
    // Real time: playback speed (2.0 = twice as fast as recorded). Finite, > 0.
    double speed = 1.0;
    // Real time: skip frames more than one frame period late.
    bool drop_late = false;
};

struct PacingStats {
    std::size_t released = 0;  // frames next() returned
    std::size_t late = 0;      // released frames the consumer asked for after their time
    std::size_t dropped = 0;   // frames skipped by drop_late
    std::size_t slept = 0;     // times next() slept
    int64_t max_late_ns = 0;   // largest lateness of a released frame
};

class PacedFrameSource final : public FrameSource {
public:
    // Takes ownership of `inner`. `clock` defaults to a SteadyPacingClock.
    // Errors: a null source, a bad speed (kInvalidArgument).
    static core::Result<std::unique_ptr<PacedFrameSource>> create(
        std::unique_ptr<FrameSource> inner, const PacingOptions& options,
        std::shared_ptr<PacingClock> clock = nullptr);

    [[nodiscard]] const SequenceInfo& info() const override { return inner_->info(); }
    core::Result<bool> next(Frame& frame) override;
    // Seeks the inner source and resets the pacing origin (not the counters).
    core::Result<bool> seek(std::size_t index) override;

    [[nodiscard]] const PacingStats& stats() const { return stats_; }
    [[nodiscard]] const PacingOptions& options() const { return options_; }

private:
    PacedFrameSource(std::unique_ptr<FrameSource> inner, const PacingOptions& options,
                     std::shared_ptr<PacingClock> clock);

    // When the frame at t_ns is due on the clock (sets the origin on first use).
    int64_t dueNs(int64_t t_ns, int64_t now_ns);

    std::unique_ptr<FrameSource> inner_;
    PacingOptions options_;
    std::shared_ptr<PacingClock> clock_;
    PacingStats stats_;
    std::optional<int64_t> origin_t_ns_;    // t_0
    int64_t origin_clock_ns_ = 0;           // start
    std::optional<int64_t> previous_t_ns_;  // timestamp of the last frame read
};

}  // namespace scaled::drivers::source
