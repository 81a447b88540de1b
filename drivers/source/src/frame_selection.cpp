#include <charconv>
#include <string>

#include <scaled/drivers/source/frame_selection.h>

namespace scaled::drivers::source {

namespace {

bool parseIndex(std::string_view s, std::size_t& out) {
    const auto* end = s.data() + s.size();
    const auto r = std::from_chars(s.data(), end, out);
    return !s.empty() && r.ec == std::errc() && r.ptr == end;
}

}  // namespace

bool FrameSelection::blanked(std::int64_t index) const {
    if (index < 0) {
        return false;
    }
    const auto i = static_cast<std::size_t>(index);
    for (const FrameRange& r : blank) {
        if (i >= r.first && i < r.end) {
            return true;
        }
    }
    return false;
}

core::Result<FrameRange> parseBlankRange(std::string_view text) {
    const auto colon = text.find(':');
    FrameRange r;
    if (colon == std::string_view::npos || !parseIndex(text.substr(0, colon), r.first) ||
        !parseIndex(text.substr(colon + 1), r.end) || r.end <= r.first) {
        return core::makeError(
            core::ErrorCode::kInvalidArgument,
            "blank range '" + std::string(text) + "': expected A:B, frame numbers with A < B");
    }
    return r;
}

core::Result<bool> readSelected(FrameSource& source, const FrameSelection& selection,
                                std::size_t index, Frame& frame) {
    if (selection.stride > 1) {
        auto s = source.seek(index);
        if (!s || !*s) {
            return s;
        }
    }
    auto got = source.next(frame);
    if (!got || !*got) {
        return got;
    }
    if (selection.blanked(frame.id)) {
        frame.gray = cv::Mat::zeros(frame.gray.size(), frame.gray.type());
        frame.color = cv::Mat::zeros(frame.color.size(), frame.color.type());
    }
    return got;
}

}  // namespace scaled::drivers::source
