#pragma once

// What the libgpiod v1 and v2 back ends share: finding a chip by path, name or
// label, checking the offsets, and the error messages. Each back end
// (gpio_lines_v1.cpp or gpio_lines_v2.cpp; one of them is built) supplies
// probeChip() and openGpioOutputs().

#include <cstddef>
#include <string>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/gpio/gpio_lines.h>

namespace scaled::drivers::gpio::detail {

// The most lines one request holds (GPIOD_LINE_BULK_MAX_LINES in v1,
// GPIO_V2_LINES_MAX in the kernel's v2 uAPI).
inline constexpr std::size_t kMaxLines = 64;

struct ChipInfo {
    std::string path;   // /dev/gpiochipN
    std::string name;   // gpiochipN
    std::string label;  // e.g. pinctrl-bcm2711
    unsigned num_lines = 0;
};

// Back end: opens `path`, reads its name, label and line count, closes it.
// Returns 0, or the errno of the failure.
int probeChip(const std::string& path, ChipInfo& info);

using base::errnoText;

// /dev/gpiochip*, in numeric order.
std::vector<std::string> listChipPaths();

// The device path of the chip `spec` names: a path (contains '/') as given; a
// name (gpiochipN) when /dev/gpiochipN exists; else the chip whose label is
// `spec` (every chip is probed). kNotFound lists the chips there are.
core::Result<std::string> findChip(const std::string& spec);

// The error for a failed open of `path` (found from `spec`).
core::Error openError(const std::string& spec, const std::string& path, int err);

// "gpiochip1 [scaled-leds]".
std::string chipText(const ChipInfo& chip);

// Offsets present, distinct, at most kMaxLines, each below the chip's count.
core::Status checkOffsets(const GpioOutputOptions& options, const ChipInfo& chip);

// A failed line request. `busy_detail` (for EBUSY): "line 3 is used by 'x'".
core::Error requestError(const ChipInfo& chip, const GpioOutputOptions& options, int err,
                         const std::string& busy_detail);

// A failed set() of line `offset`.
core::Error setError(const ChipInfo& chip, unsigned offset, int err);

// An index past the requested lines.
core::Error indexError(const ChipInfo& chip, std::size_t index, std::size_t count);

// "line 3 is used by 'consumer'" / "line 3 is used (consumer unknown)".
std::string busyText(unsigned offset, const char* consumer);

// "gpiochip1 [scaled-leds] lines 0,1" (plus " active-low").
std::string describeOutputs(const ChipInfo& chip, const GpioOutputOptions& options);

}  // namespace scaled::drivers::gpio::detail
