#pragma once

// A Linux IIO device's sysfs directory made of plain files, for host tests of
// the IIO driver (drivers/imu) and of what reads through it (the daemon's
// [imu]). sysfs mode reads plain attribute files, so such a tree is the
// driver's real input; the kernel's own device is tested in the VM.

#include <array>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include <gtest/gtest.h>

namespace scaled::test {

// Writes `content` to `path`, making its directories.
inline void putFile(const std::filesystem::path& path, std::string_view content) {
    std::filesystem::create_directories(path.parent_path());
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << content;
    ASSERT_TRUE(out.good()) << "cannot write " << path;
}

// A 3-axis accelerometer named `name` in `dir` (laid out like
// /sys/bus/iio/devices/iio:deviceN): in_accel_{x,y,z}_raw, in_accel_scale,
// and current_timestamp_clock "realtime" (IioDevice::open sets monotonic).
inline void writeFakeAccelerometer(const std::filesystem::path& dir, std::string_view name,
                                   const std::array<long, 3>& raw, std::string_view scale) {
    putFile(dir / "name", std::string(name) + "\n");
    putFile(dir / "current_timestamp_clock", "realtime\n");
    const std::array<const char*, 3> axes = {"x", "y", "z"};
    for (std::size_t i = 0; i < 3; ++i) {
        putFile(dir / ("in_accel_" + std::string(axes[i]) + "_raw"), std::to_string(raw[i]) + "\n");
    }
    putFile(dir / "in_accel_scale", std::string(scale) + "\n");
}

}  // namespace scaled::test
