// libgpiod v1 (1.6) back end. Built when pkg-config's libgpiod is 1.x; the
// guard keeps the file empty for tools that see it outside that build
// (clang-tidy interpolating a compile command for it in a v2 build).
#if SCALED_GPIOD_API == 1

#include <array>
#include <cerrno>
#include <gpiod.h>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gpio_common.h"

namespace scaled::drivers::gpio {
namespace detail {

int probeChip(const std::string& path, ChipInfo& info) {
    errno = 0;
    gpiod_chip* chip = ::gpiod_chip_open(path.c_str());
    if (chip == nullptr) {
        return errno != 0 ? errno : EIO;
    }
    info.path = path;
    info.name = ::gpiod_chip_name(chip);
    info.label = ::gpiod_chip_label(chip);
    info.num_lines = ::gpiod_chip_num_lines(chip);
    ::gpiod_chip_close(chip);
    return 0;
}

}  // namespace detail

namespace {

using detail::ChipInfo;

static_assert(detail::kMaxLines == GPIOD_LINE_BULK_MAX_LINES);

struct ChipCloser {
    void operator()(gpiod_chip* chip) const { ::gpiod_chip_close(chip); }
};
using ChipPtr = std::unique_ptr<gpiod_chip, ChipCloser>;

class GpiodV1Outputs final : public GpioOutputs {
public:
    // `bulk` holds the requested lines of `chip` (owned by it).
    GpiodV1Outputs(ChipPtr chip, ChipInfo info, const GpioOutputOptions& options,
                   const gpiod_line_bulk& bulk)
        : chip_(std::move(chip)),
          info_(std::move(info)),
          offsets_(options.offsets),
          description_(detail::describeOutputs(info_, options)),
          bulk_(bulk) {}
    GpiodV1Outputs(const GpiodV1Outputs&) = delete;
    GpiodV1Outputs& operator=(const GpiodV1Outputs&) = delete;
    GpiodV1Outputs(GpiodV1Outputs&&) = delete;
    GpiodV1Outputs& operator=(GpiodV1Outputs&&) = delete;
    // Releases the lines, then chip_ closes the chip (the lines belong to it).
    ~GpiodV1Outputs() override { ::gpiod_line_release_bulk(&bulk_); }

    core::Status set(std::size_t index, bool active) override {
        if (index >= offsets_.size()) {
            return detail::indexError(info_, index, offsets_.size());
        }
        // All lines at once, from the values kept here: in 1.6,
        // gpiod_line_set_value() on one line of a bulk request sends a single
        // value to the request's handle, which the kernel applies to the
        // handle's FIRST line and zeroes the others.
        const int previous = values_[index];
        values_[index] = active ? 1 : 0;
        errno = 0;
        if (::gpiod_line_set_value_bulk(&bulk_, values_.data()) != 0) {
            const int err = errno != 0 ? errno : EIO;
            values_[index] = previous;
            return detail::setError(info_, offsets_[index], err);
        }
        return {};
    }

    [[nodiscard]] std::string describe() const override { return description_; }

private:
    ChipPtr chip_;
    ChipInfo info_;
    std::vector<unsigned> offsets_;
    std::string description_;
    gpiod_line_bulk bulk_;
    std::array<int, GPIOD_LINE_BULK_MAX_LINES> values_{};  // logical, as requested: inactive
};

// Who holds the lines of a request that failed with EBUSY.
std::string busyDetail(gpiod_line_bulk& bulk) {
    std::string detail;
    for (unsigned i = 0; i < gpiod_line_bulk_num_lines(&bulk); ++i) {
        gpiod_line* line = gpiod_line_bulk_get_line(&bulk, i);
        if (::gpiod_line_update(line) != 0 || !::gpiod_line_is_used(line)) {
            continue;
        }
        if (!detail.empty()) {
            detail += "; ";
        }
        detail += detail::busyText(::gpiod_line_offset(line), ::gpiod_line_consumer(line));
    }
    return detail;
}

}  // namespace

core::Result<std::unique_ptr<GpioOutputs>> openGpioOutputs(const GpioOutputOptions& options) {
    auto path = detail::findChip(options.chip);
    if (!path) {
        return path.error();
    }
    errno = 0;
    ChipPtr chip(::gpiod_chip_open(path->c_str()));
    if (!chip) {
        return detail::openError(options.chip, *path, errno != 0 ? errno : EIO);
    }
    ChipInfo info;
    info.path = *path;
    info.name = ::gpiod_chip_name(chip.get());
    info.label = ::gpiod_chip_label(chip.get());
    info.num_lines = ::gpiod_chip_num_lines(chip.get());
    if (auto ok = detail::checkOffsets(options, info); !ok) {
        return ok.error();
    }

    // gpiod_chip_get_lines() takes a non-const array.
    std::vector<unsigned> offsets = options.offsets;
    gpiod_line_bulk bulk{};
    gpiod_line_bulk_init(&bulk);
    errno = 0;
    if (::gpiod_chip_get_lines(chip.get(), offsets.data(), static_cast<unsigned>(offsets.size()),
                               &bulk) != 0) {
        const int err = errno != 0 ? errno : EIO;
        return core::makeError(core::ErrorCode::kIo, detail::chipText(info) +
                                                         ": cannot get the lines' information: " +
                                                         detail::errnoText(err));
    }
    const int flags = options.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    const std::array<int, GPIOD_LINE_BULK_MAX_LINES> inactive{};
    errno = 0;
    if (::gpiod_line_request_bulk_output_flags(&bulk, options.consumer.c_str(), flags,
                                               inactive.data()) != 0) {
        const int err = errno != 0 ? errno : EIO;
        return detail::requestError(info, options, err,
                                    err == EBUSY ? busyDetail(bulk) : std::string());
    }
    return std::unique_ptr<GpioOutputs>(
        std::make_unique<GpiodV1Outputs>(std::move(chip), std::move(info), options, bulk));
}

}  // namespace scaled::drivers::gpio

#endif  // SCALED_GPIOD_API == 1
