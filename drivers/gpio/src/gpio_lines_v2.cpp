// libgpiod v2 (2.x) back end. Built when pkg-config's libgpiod is 2 or later;
// the guard keeps the file empty for tools that see it outside that build
// (clang-tidy interpolating a compile command for it in a v1 build).
#if SCALED_GPIOD_API == 2

#include <cerrno>
#include <filesystem>
#include <gpiod.h>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gpio_common.h"

namespace scaled::drivers::gpio {
namespace {

using detail::ChipInfo;

struct ChipCloser {
    void operator()(gpiod_chip* chip) const { ::gpiod_chip_close(chip); }
};
struct ChipInfoFree {
    void operator()(gpiod_chip_info* info) const { ::gpiod_chip_info_free(info); }
};
struct LineInfoFree {
    void operator()(gpiod_line_info* info) const { ::gpiod_line_info_free(info); }
};
struct LineSettingsFree {
    void operator()(gpiod_line_settings* settings) const { ::gpiod_line_settings_free(settings); }
};
struct LineConfigFree {
    void operator()(gpiod_line_config* config) const { ::gpiod_line_config_free(config); }
};
struct RequestConfigFree {
    void operator()(gpiod_request_config* config) const { ::gpiod_request_config_free(config); }
};
struct LineRequestRelease {
    void operator()(gpiod_line_request* request) const { ::gpiod_line_request_release(request); }
};
using ChipPtr = std::unique_ptr<gpiod_chip, ChipCloser>;
using ChipInfoPtr = std::unique_ptr<gpiod_chip_info, ChipInfoFree>;
using LineInfoPtr = std::unique_ptr<gpiod_line_info, LineInfoFree>;
using LineSettingsPtr = std::unique_ptr<gpiod_line_settings, LineSettingsFree>;
using LineConfigPtr = std::unique_ptr<gpiod_line_config, LineConfigFree>;
using RequestConfigPtr = std::unique_ptr<gpiod_request_config, RequestConfigFree>;
using LineRequestPtr = std::unique_ptr<gpiod_line_request, LineRequestRelease>;

int lastErrno() {
    return errno != 0 ? errno : EIO;
}

// Name, label and line count of an open chip; 0 or the errno.
int readChipInfo(gpiod_chip* chip, const std::string& path, ChipInfo& info) {
    errno = 0;
    const ChipInfoPtr chip_info(::gpiod_chip_get_info(chip));
    if (!chip_info) {
        return lastErrno();
    }
    info.path = path;
    info.name = ::gpiod_chip_info_get_name(chip_info.get());
    info.label = ::gpiod_chip_info_get_label(chip_info.get());
    info.num_lines = static_cast<unsigned>(::gpiod_chip_info_get_num_lines(chip_info.get()));
    return 0;
}

class GpiodV2Outputs final : public GpioOutputs {
public:
    GpiodV2Outputs(LineRequestPtr request, ChipInfo info, const GpioOutputOptions& options)
        : request_(std::move(request)),
          info_(std::move(info)),
          offsets_(options.offsets),
          description_(detail::describeOutputs(info_, options)) {}
    GpiodV2Outputs(const GpiodV2Outputs&) = delete;
    GpiodV2Outputs& operator=(const GpiodV2Outputs&) = delete;
    GpiodV2Outputs(GpiodV2Outputs&&) = delete;
    GpiodV2Outputs& operator=(GpiodV2Outputs&&) = delete;
    ~GpiodV2Outputs() override = default;  // request_ releases the lines

    core::Status set(std::size_t index, bool active) override {
        if (index >= offsets_.size()) {
            return detail::indexError(info_, index, offsets_.size());
        }
        // One GPIO_V2_LINE_SET_VALUES_IOCTL with a mask of this line only: the
        // other lines keep their values.
        errno = 0;
        if (::gpiod_line_request_set_value(
                request_.get(), offsets_[index],
                active ? GPIOD_LINE_VALUE_ACTIVE : GPIOD_LINE_VALUE_INACTIVE) != 0) {
            return detail::setError(info_, offsets_[index], lastErrno());
        }
        return {};
    }

    [[nodiscard]] std::string describe() const override { return description_; }

private:
    LineRequestPtr request_;  // independent of the chip, which is closed after the request
    ChipInfo info_;
    std::vector<unsigned> offsets_;
    std::string description_;
};

// Who holds the lines of a request that failed with EBUSY.
std::string busyDetail(gpiod_chip* chip, const std::vector<unsigned>& offsets) {
    std::string detail;
    for (const unsigned offset : offsets) {
        const LineInfoPtr info(::gpiod_chip_get_line_info(chip, offset));
        if (!info || !::gpiod_line_info_is_used(info.get())) {
            continue;
        }
        if (!detail.empty()) {
            detail += "; ";
        }
        detail += detail::busyText(offset, ::gpiod_line_info_get_consumer(info.get()));
    }
    return detail;
}

core::Error setupError(const ChipInfo& info, const char* what, int err) {
    return core::makeError(core::ErrorCode::kIo,
                           detail::chipText(info) + ": " + what + ": " + detail::errnoText(err));
}

}  // namespace

namespace detail {

int probeChip(const std::string& path, ChipInfo& info) {
    errno = 0;
    const ChipPtr chip(::gpiod_chip_open(path.c_str()));
    if (!chip) {
        return lastErrno();
    }
    return readChipInfo(chip.get(), path, info);
}

}  // namespace detail

core::Result<std::unique_ptr<GpioOutputs>> openGpioOutputs(const GpioOutputOptions& options) {
    auto path = detail::findChip(options.chip);
    if (!path) {
        return path.error();
    }
    errno = 0;
    const ChipPtr chip(::gpiod_chip_open(path->c_str()));
    if (!chip) {
        return detail::openError(options.chip, *path, lastErrno());
    }
    ChipInfo info;
    info.path = *path;
    info.name = std::filesystem::path(*path).filename().string();
    if (const int err = readChipInfo(chip.get(), *path, info); err != 0) {
        return setupError(info, "cannot read the chip's information", err);
    }
    if (auto ok = detail::checkOffsets(options, info); !ok) {
        return ok.error();
    }

    errno = 0;
    const LineSettingsPtr settings(::gpiod_line_settings_new());
    if (!settings) {
        return setupError(info, "cannot make line settings", lastErrno());
    }
    if (::gpiod_line_settings_set_direction(settings.get(), GPIOD_LINE_DIRECTION_OUTPUT) != 0 ||
        ::gpiod_line_settings_set_output_value(settings.get(), GPIOD_LINE_VALUE_INACTIVE) != 0) {
        return setupError(info, "cannot set up output line settings", lastErrno());
    }
    ::gpiod_line_settings_set_active_low(settings.get(), options.active_low);

    errno = 0;
    const LineConfigPtr line_config(::gpiod_line_config_new());
    if (!line_config) {
        return setupError(info, "cannot make a line config", lastErrno());
    }
    if (::gpiod_line_config_add_line_settings(line_config.get(), options.offsets.data(),
                                              options.offsets.size(), settings.get()) != 0) {
        return setupError(info, "cannot configure the lines", lastErrno());
    }

    errno = 0;
    const RequestConfigPtr request_config(::gpiod_request_config_new());
    if (!request_config) {
        return setupError(info, "cannot make a request config", lastErrno());
    }
    ::gpiod_request_config_set_consumer(request_config.get(), options.consumer.c_str());

    errno = 0;
    LineRequestPtr request(
        ::gpiod_chip_request_lines(chip.get(), request_config.get(), line_config.get()));
    if (!request) {
        const int err = lastErrno();
        return detail::requestError(info, options, err,
                                    err == EBUSY ? busyDetail(chip.get(), options.offsets) : "");
    }
    return std::unique_ptr<GpioOutputs>(
        std::make_unique<GpiodV2Outputs>(std::move(request), std::move(info), options));
}

}  // namespace scaled::drivers::gpio

#endif  // SCALED_GPIOD_API == 2
