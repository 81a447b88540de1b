// The GPIO driver on a host without GPIO chips: its errors, and the API the
// build picked. Setting lines is tested on a gpio-sim chip in the VM
// (tests/vm/gpio_vm_test.cpp).

#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

#include <gtest/gtest.h>

#include <scaled/drivers/gpio/gpio_lines.h>

#include "temp_dir.h"

namespace scaled::drivers::gpio {
namespace {

using core::ErrorCode;

bool hostHasGpioChips() {
    std::error_code ec;
    for (std::filesystem::directory_iterator it("/dev", ec);
         !ec && it != std::filesystem::directory_iterator(); it.increment(ec)) {
        if (it->path().filename().string().starts_with("gpiochip")) {
            return true;
        }
    }
    return false;
}

// What a kNotFound message says about the chips there are.
std::string expectedChipList() {
    return hostHasGpioChips() ? "chips found: " : "there are no GPIO chips on this system";
}

GpioOutputOptions optionsFor(const std::string& chip) {
    GpioOutputOptions options;
    options.chip = chip;
    options.offsets = {0};
    return options;
}

TEST(GpioLinesTest, ApiVersionIsTheOneOfTheInstalledLibgpiod) {
    const std::string version = SCALED_GPIOD_VERSION_STRING;
    ASSERT_FALSE(version.empty());
    const int expected = version[0] >= '2' && version[0] <= '9' ? 2 : 1;
    EXPECT_EQ(gpiodApiVersion(), expected) << "libgpiod " << version;
    EXPECT_EQ(gpiodApiVersion(), SCALED_GPIOD_API);
}

TEST(GpioLinesTest, UnknownLabelIsNotFoundAndListsTheChips) {
    auto outputs = openGpioOutputs(optionsFor("scaled-no-such-chip"));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kNotFound);
    EXPECT_NE(outputs.error().message.find("'scaled-no-such-chip'"), std::string::npos)
        << outputs.error().message;
    EXPECT_NE(outputs.error().message.find(expectedChipList()), std::string::npos)
        << outputs.error().message;
}

TEST(GpioLinesTest, UnknownNameIsNotFound) {
    auto outputs = openGpioOutputs(optionsFor("gpiochip987"));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kNotFound);
    EXPECT_NE(outputs.error().message.find("gpiochip987"), std::string::npos)
        << outputs.error().message;
    EXPECT_NE(outputs.error().message.find(expectedChipList()), std::string::npos)
        << outputs.error().message;
}

TEST(GpioLinesTest, MissingPathIsNotFound) {
    auto outputs = openGpioOutputs(optionsFor("/dev/gpiochip987"));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kNotFound);
    EXPECT_NE(outputs.error().message.find("/dev/gpiochip987: no such chip"), std::string::npos)
        << outputs.error().message;
    EXPECT_NE(outputs.error().message.find(expectedChipList()), std::string::npos)
        << outputs.error().message;
}

TEST(GpioLinesTest, FileThatIsNotAChipIsRejected) {
    const test::TempDir dir("gpio");
    const std::filesystem::path file = dir.path() / "gpiochip0";
    std::ofstream(file) << "not a device\n";
    auto outputs = openGpioOutputs(optionsFor(file.string()));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kInvalidArgument) << outputs.error().message;
    EXPECT_NE(outputs.error().message.find(file.string() + ": not a GPIO chip"), std::string::npos)
        << outputs.error().message;
}

TEST(GpioLinesTest, CharacterDeviceThatIsNotAChipIsRejected) {
    auto outputs = openGpioOutputs(optionsFor("/dev/null"));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kInvalidArgument) << outputs.error().message;
    EXPECT_NE(outputs.error().message.find("/dev/null: not a GPIO chip"), std::string::npos)
        << outputs.error().message;
}

TEST(GpioLinesTest, EmptyChipIsInvalid) {
    auto outputs = openGpioOutputs(optionsFor(""));
    ASSERT_FALSE(outputs.ok());
    EXPECT_EQ(outputs.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(outputs.error().message.find("GPIO chip"), std::string::npos)
        << outputs.error().message;
}

}  // namespace
}  // namespace scaled::drivers::gpio
