#pragma once

// Which frames of a recording a replay reads: every stride-th frame (a 30 Hz
// sequence replayed at 10 Hz is stride 3) and ranges of frames replaced by
// black images (a covered lens, a dark corridor: the tracker sees nothing but
// time goes on). Used by slam-run and scale-eval (--stride, --blank) so that
// both read the same frames the same way.

#include <cstddef>
#include <span>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/source/frame_source.h>

namespace scaled::drivers::source {

// Frames [first, end) of the source's numbering.
struct FrameRange {
    std::size_t first = 0;
    std::size_t end = 0;
};

struct FrameSelection {
    std::size_t stride = 1;         // read every stride-th frame (>= 1)
    std::vector<FrameRange> blank;  // frames delivered black
    [[nodiscard]] bool blanked(std::int64_t index) const;
};

// "A:B" with A < B, both given: the frames A to B-1. An error names the text.
core::Result<FrameRange> parseBlankRange(std::string_view text);

// Reads the frame at `index` of the source (seeking to it first when the
// selection skips frames, so index must follow the previous one by stride)
// and blanks it when the selection says so: gray and colour images of the same
// size and type, all zero; everything else of the frame (time, ground truth)
// is kept. Same return as FrameSource::next.
core::Result<bool> readSelected(FrameSource& source, const FrameSelection& selection,
                                std::size_t index, Frame& frame);

}  // namespace scaled::drivers::source
