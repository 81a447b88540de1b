// The GPIO driver and the status LEDs on a real kernel GPIO chip: run inside
// the test VM (tests/vm/run-vm.sh), where a gpio-sim chip labelled
// `scaled-leds` with 8 lines is live and SCALED_VM=1. Elsewhere every test
// skips; in the VM a missing chip fails.
//
// While a program holds a gpio-sim line as an output, the kernel shows the
// level it drives in /sys/devices/platform/gpio-sim.N/gpiochipM/sim_gpioK/value,
// so each set() is checked at the pin. The chip and the lines' owners are
// read with the kernel's GPIO uAPI directly, independent of libgpiod.
//
// Lines: 0 opened by label/name/path; 1,2 active-high; 3,4 active-low; 5 busy;
// 6,7 the status and heartbeat LEDs.

#include <array>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <linux/gpio.h>
#include <memory>
#include <optional>
#include <string>
#include <sys/ioctl.h>
#include <system_error>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/status_lights.h>
#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/base/unique_fd.h>
#include <scaled/drivers/gpio/gpio_lines.h>

namespace scaled {
namespace {

using core::ErrorCode;

constexpr const char* kLabel = "scaled-leds";
constexpr unsigned kLines = 8;
constexpr std::int64_t kMs = 1'000'000;

struct SimChip {
    std::string dev_path;   // /dev/gpiochipM
    std::string name;       // gpiochipM
    std::string sysfs_dir;  // /sys/devices/platform/gpio-sim.N/gpiochipM
    unsigned lines = 0;
};

using Fd = drivers::base::UniqueFd;

// The gpio-sim chip labelled kLabel, found through GPIO_GET_CHIPINFO_IOCTL;
// `why` says what is missing otherwise.
std::optional<SimChip> findSimChip(std::string& why) {
    std::vector<std::string> seen;
    std::error_code ec;
    for (std::filesystem::directory_iterator it("/dev", ec);
         !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (!name.starts_with("gpiochip")) {
            continue;
        }
        const Fd fd(::open(it->path().c_str(), O_RDONLY | O_CLOEXEC));
        gpiochip_info info{};
        if (fd.get() < 0 || ::ioctl(fd.get(), GPIO_GET_CHIPINFO_IOCTL, &info) != 0) {
            seen.push_back(name + " (" + drivers::base::errnoText(errno) + ")");
            continue;
        }
        seen.push_back(name + " [" + info.label + "]");
        if (std::string(info.label) != kLabel) {
            continue;
        }
        SimChip chip;
        chip.dev_path = it->path().string();
        chip.name = info.name;
        chip.lines = info.lines;
        // /sys/bus/gpio/devices/gpiochipM links to the chip's device directory,
        // /sys/devices/platform/gpio-sim.N/gpiochipM.
        const std::filesystem::path bus_dir = "/sys/bus/gpio/devices/" + chip.name;
        if (std::filesystem::exists(bus_dir / "sim_gpio0" / "value", ec)) {
            chip.sysfs_dir = bus_dir.string();
        }
        for (std::filesystem::directory_iterator p("/sys/devices/platform", ec);
             chip.sysfs_dir.empty() && !ec && p != std::filesystem::directory_iterator();
             p.increment(ec)) {
            const std::filesystem::path dir = p->path() / chip.name;
            if (p->path().filename().string().starts_with("gpio-sim.") &&
                std::filesystem::exists(dir / "sim_gpio0" / "value", ec)) {
                chip.sysfs_dir = dir.string();
            }
        }
        if (chip.sysfs_dir.empty()) {
            why = "no sim_gpio0/value under /sys/bus/gpio/devices/" + chip.name +
                  " or /sys/devices/platform/gpio-sim.*/" + chip.name;
            return std::nullopt;
        }
        return chip;
    }
    why = std::string("no GPIO chip labelled '") + kLabel + "'; chips:";
    for (const std::string& s : seen) {
        why += " " + s;
    }
    return std::nullopt;
}

class GpioVmTest : public ::testing::Test {
protected:
    void SetUp() override {
        if (std::getenv("SCALED_VM") == nullptr) {
            GTEST_SKIP() << "needs the test VM's gpio-sim chip (SCALED_VM=1, tests/vm/run-vm.sh)";
        }
        std::string why;
        auto chip = findSimChip(why);
        ASSERT_TRUE(chip.has_value()) << why;
        chip_ = *chip;
        ASSERT_EQ(chip_.lines, kLines);
    }

    // The level the pin is driven to: 0 or 1 (-1 and a failure if unreadable).
    [[nodiscard]] int pin(unsigned offset) const {
        const std::string path = chip_.sysfs_dir + "/sim_gpio" + std::to_string(offset) + "/value";
        std::ifstream in(path);
        int value = -1;
        if (!(in >> value)) {
            ADD_FAILURE() << "cannot read " << path;
            return -1;
        }
        return value;
    }

    // The consumer holding line `offset`, or nullopt when it is free.
    [[nodiscard]] std::optional<std::string> holder(unsigned offset) const {
        const Fd fd(::open(chip_.dev_path.c_str(), O_RDONLY | O_CLOEXEC));
        gpio_v2_line_info info{};
        info.offset = offset;
        if (fd.get() < 0 || ::ioctl(fd.get(), GPIO_V2_GET_LINEINFO_IOCTL, &info) != 0) {
            ADD_FAILURE() << chip_.dev_path << ": cannot read line " << offset
                          << " info: " << drivers::base::errnoText(errno);
            return std::nullopt;
        }
        if ((info.flags & GPIO_V2_LINE_FLAG_USED) == 0) {
            return std::nullopt;
        }
        return std::string(info.consumer);
    }

    [[nodiscard]] drivers::gpio::GpioOutputOptions options(const std::string& chip,
                                                           std::vector<unsigned> offsets,
                                                           bool active_low = false) const {
        drivers::gpio::GpioOutputOptions o;
        o.chip = chip;
        o.offsets = std::move(offsets);
        o.active_low = active_low;
        o.consumer = "scaled-vm-test";
        return o;
    }

    SimChip chip_;
};

TEST_F(GpioVmTest, OpensByLabelNameAndPath) {
    // Which libgpiod API these tests drive (the trixie stage of CI runs them
    // with libgpiod 2: docs/vm-tests.md); in the log and the XML report.
    std::cout << "libgpiod API v" << drivers::gpio::gpiodApiVersion() << "\n";
    RecordProperty("libgpiod_api", drivers::gpio::gpiodApiVersion());
    for (const std::string& spec : {std::string(kLabel), chip_.name, chip_.dev_path}) {
        SCOPED_TRACE(spec);
        auto outputs = drivers::gpio::openGpioOutputs(options(spec, {0}));
        ASSERT_TRUE(outputs.ok()) << outputs.error().message;
        EXPECT_EQ((*outputs)->describe(), chip_.name + " [" + kLabel + "] lines 0");
        EXPECT_EQ(holder(0), "scaled-vm-test");
        EXPECT_EQ(pin(0), 0);  // requested inactive
        ASSERT_TRUE((*outputs)->set(0, true).ok());
        EXPECT_EQ(pin(0), 1);
        ASSERT_TRUE((*outputs)->set(0, false).ok());
        EXPECT_EQ(pin(0), 0);
        outputs->reset();
        EXPECT_EQ(holder(0), std::nullopt) << "released on destruction";
    }
}

TEST_F(GpioVmTest, ActiveHighLinesAreSetOneAtATime) {
    auto outputs = drivers::gpio::openGpioOutputs(options(kLabel, {1, 2}));
    ASSERT_TRUE(outputs.ok()) << outputs.error().message;
    auto& out = **outputs;
    EXPECT_EQ(pin(1), 0);
    EXPECT_EQ(pin(2), 0);
    ASSERT_TRUE(out.set(1, true).ok());  // the second line only
    EXPECT_EQ(pin(1), 0);
    EXPECT_EQ(pin(2), 1);
    ASSERT_TRUE(out.set(0, true).ok());
    EXPECT_EQ(pin(1), 1);
    EXPECT_EQ(pin(2), 1);
    ASSERT_TRUE(out.set(1, false).ok());
    EXPECT_EQ(pin(1), 1);
    EXPECT_EQ(pin(2), 0);
    ASSERT_TRUE(out.set(0, false).ok());
    EXPECT_EQ(pin(1), 0);
    EXPECT_EQ(pin(2), 0);
    auto bad = out.set(2, true);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
}

TEST_F(GpioVmTest, ActiveLowLinesAreHighWhenInactive) {
    auto outputs = drivers::gpio::openGpioOutputs(options(kLabel, {3, 4}, true));
    ASSERT_TRUE(outputs.ok()) << outputs.error().message;
    auto& out = **outputs;
    EXPECT_NE(out.describe().find("active-low"), std::string::npos) << out.describe();
    EXPECT_EQ(pin(3), 1);  // requested inactive: high
    EXPECT_EQ(pin(4), 1);
    ASSERT_TRUE(out.set(0, true).ok());
    EXPECT_EQ(pin(3), 0);
    EXPECT_EQ(pin(4), 1);
    ASSERT_TRUE(out.set(1, true).ok());
    EXPECT_EQ(pin(3), 0);
    EXPECT_EQ(pin(4), 0);
    ASSERT_TRUE(out.set(0, false).ok());
    EXPECT_EQ(pin(3), 1);
    EXPECT_EQ(pin(4), 0);
}

TEST_F(GpioVmTest, OffsetOutOfRangeNamesTheLineCount) {
    auto outputs = drivers::gpio::openGpioOutputs(options(kLabel, {2, kLines}));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(outputs.error().message.find(chip_.name + " [" + kLabel + "]"), std::string::npos)
        << outputs.error().message;
    EXPECT_NE(outputs.error().message.find("line 8 out of range: the chip has 8 lines"),
              std::string::npos)
        << outputs.error().message;
    EXPECT_EQ(holder(2), std::nullopt) << "nothing requested";
}

TEST_F(GpioVmTest, BusyLineNamesItsConsumer) {
    auto first_options = options(kLabel, {5});
    first_options.consumer = "scaled-vm-first";
    auto first = drivers::gpio::openGpioOutputs(first_options);
    ASSERT_TRUE(first.ok()) << first.error().message;
    EXPECT_EQ(holder(5), "scaled-vm-first");

    auto second = drivers::gpio::openGpioOutputs(options(chip_.dev_path, {4, 5}));
    ASSERT_FALSE(second.ok());
    EXPECT_EQ(second.error().code, ErrorCode::kUnavailable);
    EXPECT_NE(second.error().message.find("line 5 is used by 'scaled-vm-first'"), std::string::npos)
        << second.error().message;
    EXPECT_EQ(holder(4), std::nullopt) << "a failed request holds nothing";
}

// --- StatusLights ---------------------------------------------------------------

constexpr unsigned kStatusLine = 6;
constexpr unsigned kHeartbeatLine = 7;

class StatusLightsVmTest : public GpioVmTest, public ::testing::WithParamInterface<bool> {};

TEST_P(StatusLightsVmTest, EveryPatternAtThePins) {
    const bool active_low = GetParam();
    daemon::GpioConfig config;
    config.chip = kLabel;
    config.status_line = static_cast<int>(kStatusLine);
    config.heartbeat_line = static_cast<int>(kHeartbeatLine);
    config.active_low = active_low;
    config.consumer = "scaled-vm-leds";
    auto opened = daemon::StatusLights::open(config);
    ASSERT_TRUE(opened.ok()) << opened.error().message;
    std::unique_ptr<daemon::StatusLights> lights = std::move(*opened);
    ASSERT_NE(lights, nullptr);
    EXPECT_EQ(holder(kStatusLine), "scaled-vm-leds");
    EXPECT_EQ(holder(kHeartbeatLine), "scaled-vm-leds");
    const auto pinFor = [&](bool active) { return active != active_low ? 1 : 0; };

    // Times far from the clock's present, so nothing here depends on it.
    const std::int64_t alive_since = kMs * 1000 * 1000;
    lights->setAliveAt(true, alive_since);
    // Phase points and both sides of every edge of every pattern.
    const std::array<std::int64_t, 18> offsets = {
        0,         50 * kMs,       100 * kMs - 1, 100 * kMs,  150 * kMs,     200 * kMs - 1,
        200 * kMs, 250 * kMs,      300 * kMs - 1, 300 * kMs,  500 * kMs - 1, 500 * kMs,
        700 * kMs, 1000 * kMs - 1, 1000 * kMs,    1100 * kMs, 1250 * kMs,    1500 * kMs};
    std::int64_t start = alive_since + 250 * kMs;  // the heartbeat's phase differs
    // kOff first: the lights begin as kStarting, and setting the pattern they
    // show would not restart its phase.
    for (const daemon::LightPattern p :
         {daemon::LightPattern::kOff, daemon::LightPattern::kStarting,
          daemon::LightPattern::kInitialising, daemon::LightPattern::kConverging,
          daemon::LightPattern::kConverged, daemon::LightPattern::kLost}) {
        SCOPED_TRACE(daemon::toString(p));
        lights->setPatternAt(p, start);
        for (const std::int64_t t : offsets) {
            SCOPED_TRACE(t);
            ASSERT_TRUE(lights->render(start + t).ok());
            EXPECT_EQ(pin(kStatusLine), pinFor(daemon::patternLevel(p, t)));
            // The heartbeat is a 500/500 ms blink from alive_since, as converging is.
            const bool beat =
                daemon::patternLevel(daemon::LightPattern::kConverging, start + t - alive_since);
            EXPECT_EQ(pin(kHeartbeatLine), pinFor(beat));
        }
        start += 10'000 * kMs;
    }
    lights->setAliveAt(false, start);
    ASSERT_TRUE(lights->render(start).ok());
    EXPECT_EQ(pin(kHeartbeatLine), pinFor(false));

    // Driven on, then destroyed: the lines are set inactive and released.
    lights->setPatternAt(daemon::LightPattern::kConverged, start);
    lights->setAliveAt(true, start);
    ASSERT_TRUE(lights->render(start).ok());
    EXPECT_EQ(pin(kStatusLine), pinFor(true));
    EXPECT_EQ(pin(kHeartbeatLine), pinFor(true));
    EXPECT_FALSE(lights->takeError().has_value());
    lights.reset();
    EXPECT_EQ(holder(kStatusLine), std::nullopt);
    EXPECT_EQ(holder(kHeartbeatLine), std::nullopt);
    // Free again: another request gets them.
    auto again = drivers::gpio::openGpioOutputs(options(kLabel, {kStatusLine, kHeartbeatLine}));
    EXPECT_TRUE(again.ok()) << again.error().message;
}

INSTANTIATE_TEST_SUITE_P(Polarity, StatusLightsVmTest, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& param) {
                             return param.param ? std::string("ActiveLow")
                                                : std::string("ActiveHigh");
                         });

}  // namespace
}  // namespace scaled
