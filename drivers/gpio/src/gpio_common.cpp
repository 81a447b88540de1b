#include "gpio_common.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <filesystem>
#include <string_view>
#include <system_error>
#include <utility>

#include <scaled/drivers/base/errno_text.h>

#ifndef SCALED_GPIOD_API
#error "SCALED_GPIOD_API (1 or 2) comes from drivers/gpio/CMakeLists.txt"
#endif

namespace scaled::drivers::gpio {
namespace detail {
namespace {

using core::ErrorCode;
using core::makeError;

constexpr std::string_view kChipPrefix = "gpiochip";

// Most boards give access through a group rather than running as root:
// Raspberry Pi OS ships the `gpio` group and a udev rule for /dev/gpiochip*.
constexpr std::string_view kPermissionHint =
    "the user needs read-write access to /dev/gpiochip* (add it to the `gpio` group, or "
    "give a group the chips with a udev rule)";

bool isPermissionError(int err) {
    return err == EACCES || err == EPERM;
}

// N of "gpiochipN"; false for other names.
bool chipNumber(std::string_view name, unsigned& number) {
    if (!name.starts_with(kChipPrefix) || name.size() == kChipPrefix.size()) {
        return false;
    }
    const std::string_view digits = name.substr(kChipPrefix.size());
    const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), number);
    return ec == std::errc() && ptr == digits.data() + digits.size();
}

struct Probe {
    ChipInfo info;
    int err = 0;
};

std::vector<Probe> probeAll() {
    std::vector<Probe> probes;
    for (const std::string& path : listChipPaths()) {
        Probe probe;
        probe.info.path = path;
        probe.info.name = std::filesystem::path(path).filename().string();
        probe.err = probeChip(path, probe.info);
        probes.push_back(std::move(probe));
    }
    return probes;
}

// "chips found: gpiochip0 [pinctrl-bcm2711] (58 lines), gpiochip1 (cannot
// open: Permission denied)", or that there are none.
std::string chipsText(const std::vector<Probe>& probes) {
    if (probes.empty()) {
        return "there are no GPIO chips on this system (no /dev/gpiochip*)";
    }
    std::string text = "chips found: ";
    bool permission_denied = false;
    for (std::size_t i = 0; i < probes.size(); ++i) {
        const Probe& probe = probes[i];
        if (i > 0) {
            text += ", ";
        }
        if (probe.err == 0) {
            text += chipText(probe.info) + " (" + std::to_string(probe.info.num_lines) + " lines)";
        } else {
            text += probe.info.name + " (cannot open: " + errnoText(probe.err) + ")";
            permission_denied = permission_denied || isPermissionError(probe.err);
        }
    }
    if (permission_denied) {
        text += "; ";
        text += kPermissionHint;
    }
    return text;
}

std::string offsetsText(const std::vector<unsigned>& offsets) {
    std::string text;
    for (std::size_t i = 0; i < offsets.size(); ++i) {
        if (i > 0) {
            text += ',';
        }
        text += std::to_string(offsets[i]);
    }
    return text;
}

}  // namespace

std::vector<std::string> listChipPaths() {
    std::vector<std::pair<unsigned, std::string>> chips;
    std::error_code ec;
    std::filesystem::directory_iterator it("/dev", ec);
    for (; !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string();
        unsigned number = 0;
        if (chipNumber(name, number)) {
            chips.emplace_back(number, it->path().string());
        }
    }
    std::sort(chips.begin(), chips.end());
    std::vector<std::string> paths;
    paths.reserve(chips.size());
    for (auto& chip : chips) {
        paths.push_back(std::move(chip.second));
    }
    return paths;
}

core::Result<std::string> findChip(const std::string& spec) {
    if (spec.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         "GPIO chip: none given (a path, name or label is needed)");
    }
    if (spec.find('/') != std::string::npos) {
        return spec;
    }
    unsigned number = 0;
    if (chipNumber(spec, number)) {
        std::string path = "/dev/" + spec;
        std::error_code ec;
        if (std::filesystem::exists(path, ec)) {
            return path;
        }
    }
    const std::vector<Probe> probes = probeAll();
    for (const Probe& probe : probes) {
        if (probe.err == 0 && probe.info.label == spec) {
            return probe.info.path;
        }
    }
    return makeError(
        ErrorCode::kNotFound,
        "GPIO chip '" + spec + "': no chip has that path, name or label; " + chipsText(probes));
}

core::Error openError(const std::string& spec, const std::string& path, int err) {
    const std::string who =
        spec == path ? "GPIO chip " + path : "GPIO chip '" + spec + "' (" + path + ")";
    if (err == ENOENT) {
        // libgpiod 2 checks a character device against sysfs
        // (/sys/dev/char/MAJ:MIN/subsystem) and passes on ENOENT when sysfs
        // does not know it (no /sys in a container or chroot): the path
        // exists, so the chip is not missing, the file is not one.
        std::error_code ec;
        if (std::filesystem::exists(path, ec)) {
            return makeError(ErrorCode::kInvalidArgument,
                             who + ": not a GPIO chip (sysfs does not list it as a GPIO device)");
        }
        return makeError(ErrorCode::kNotFound, who + ": no such chip; " + chipsText(probeAll()));
    }
    if (isPermissionError(err)) {
        return makeError(ErrorCode::kIo, who + ": cannot open: " + errnoText(err) + "; " +
                                             std::string(kPermissionHint));
    }
    if (err == ENOTTY || err == ENODEV) {
        return makeError(ErrorCode::kInvalidArgument,
                         who + ": not a GPIO chip (" + errnoText(err) + ")");
    }
    return makeError(ErrorCode::kIo, who + ": cannot open: " + errnoText(err));
}

std::string chipText(const ChipInfo& chip) {
    return chip.name + " [" + chip.label + "]";
}

core::Status checkOffsets(const GpioOutputOptions& options, const ChipInfo& chip) {
    const std::vector<unsigned>& offsets = options.offsets;
    if (offsets.empty()) {
        return makeError(ErrorCode::kInvalidArgument, chipText(chip) + ": no lines to request");
    }
    if (offsets.size() > kMaxLines) {
        return makeError(ErrorCode::kInvalidArgument,
                         chipText(chip) + ": at most " + std::to_string(kMaxLines) +
                             " lines per request (got " + std::to_string(offsets.size()) + ")");
    }
    for (std::size_t i = 0; i < offsets.size(); ++i) {
        if (offsets[i] >= chip.num_lines) {
            const std::string range =
                chip.num_lines == 0 ? "" : " (0.." + std::to_string(chip.num_lines - 1) + ")";
            return makeError(ErrorCode::kInvalidArgument,
                             chipText(chip) + ": line " + std::to_string(offsets[i]) +
                                 " out of range: the chip has " + std::to_string(chip.num_lines) +
                                 " lines" + range);
        }
        if (std::find(offsets.begin(), offsets.begin() + static_cast<std::ptrdiff_t>(i),
                      offsets[i]) != offsets.begin() + static_cast<std::ptrdiff_t>(i)) {
            return makeError(
                ErrorCode::kInvalidArgument,
                chipText(chip) + ": line " + std::to_string(offsets[i]) + " given twice");
        }
    }
    return {};
}

core::Error requestError(const ChipInfo& chip, const GpioOutputOptions& options, int err,
                         const std::string& busy_detail) {
    const std::string what =
        chipText(chip) + ": cannot request lines " + offsetsText(options.offsets) + " as outputs: ";
    if (err == EBUSY) {
        return makeError(
            ErrorCode::kUnavailable,
            what + "busy: " + (busy_detail.empty() ? "in use by another consumer" : busy_detail));
    }
    if (isPermissionError(err)) {
        return makeError(ErrorCode::kIo,
                         what + errnoText(err) + "; " + std::string(kPermissionHint));
    }
    return makeError(ErrorCode::kIo, what + errnoText(err));
}

core::Error setError(const ChipInfo& chip, unsigned offset, int err) {
    return makeError(ErrorCode::kIo, chipText(chip) + " line " + std::to_string(offset) +
                                         ": cannot set the value: " + errnoText(err));
}

core::Error indexError(const ChipInfo& chip, std::size_t index, std::size_t count) {
    return makeError(ErrorCode::kInvalidArgument, chipText(chip) + ": no output " +
                                                      std::to_string(index) + " (" +
                                                      std::to_string(count) + " lines requested)");
}

std::string busyText(unsigned offset, const char* consumer) {
    const std::string line = "line " + std::to_string(offset) + " is used";
    if (consumer == nullptr || *consumer == '\0') {
        return line + " (consumer unknown)";
    }
    return line + " by '" + consumer + "'";
}

std::string describeOutputs(const ChipInfo& chip, const GpioOutputOptions& options) {
    return chipText(chip) + " lines " + offsetsText(options.offsets) +
           (options.active_low ? " active-low" : "");
}

}  // namespace detail

int gpiodApiVersion() {
    return SCALED_GPIOD_API;
}

}  // namespace scaled::drivers::gpio
