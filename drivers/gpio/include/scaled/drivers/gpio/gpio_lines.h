#pragma once

// Output lines on a GPIO chip through libgpiod, v1 (1.6: Debian and Raspberry
// Pi OS bookworm) or v2 (Debian trixie) API, chosen at build time
// (SCALED_GPIOD_API = 1 or 2, from pkg-config's libgpiod version).
//
// The chip is found by path (/dev/gpiochip0), name (gpiochip0) or label
// ("pinctrl-bcm2711", "gpio-sim.0-node0"), in that order. Lines are requested
// as outputs, initially inactive, with the consumer name given; active_low
// makes set(true) drive the line low. Released on destruction.
// Errors name the chip and the cause: no such chip (kNotFound, listing the
// chips found with their labels, or saying there are none), offset out of
// range (kInvalidArgument, naming the line count), line busy (kUnavailable,
// naming its consumer when known), permission denied (kIo, naming the `gpio`
// group).

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <scaled/core/result.h>

namespace scaled::drivers::gpio {

struct GpioOutputOptions {
    std::string chip;                 // path, name or label
    std::vector<unsigned> offsets;    // lines to drive, in this order (1 to 64, distinct)
    bool active_low = false;          // for every line
    std::string consumer = "scaled";  // shown by gpioinfo (the kernel keeps 31 characters)
};

// One request of output lines. Not thread-safe: one thread at a time calls
// set() (StatusLights serialises its calls with its own mutex).
class GpioOutputs {
public:
    GpioOutputs() = default;
    GpioOutputs(const GpioOutputs&) = delete;
    GpioOutputs& operator=(const GpioOutputs&) = delete;
    GpioOutputs(GpioOutputs&&) = delete;
    GpioOutputs& operator=(GpioOutputs&&) = delete;
    virtual ~GpioOutputs() = default;

    // Sets line `index` (into options.offsets) active (true) or inactive; the
    // other lines keep their values. One ioctl; no allocation (except for the
    // message of an error).
    virtual core::Status set(std::size_t index, bool active) = 0;
    // "gpiochip1 [gpio-sim.0-node0] lines 0,1" (plus " active-low"): for the log.
    [[nodiscard]] virtual std::string describe() const = 0;
};

core::Result<std::unique_ptr<GpioOutputs>> openGpioOutputs(const GpioOutputOptions& options);

// The libgpiod API this build uses: 1 or 2.
int gpiodApiVersion();

}  // namespace scaled::drivers::gpio
