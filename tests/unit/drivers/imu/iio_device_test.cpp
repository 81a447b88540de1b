// The IIO driver (drivers/imu/iio_device.h) against a directory tree of real
// files laid out like /sys/bus/iio/devices/iio:deviceN (an MPU-6050-like
// accelerometer and gyroscope), with a regular file of binary scans standing
// in for the character device /dev/iio:deviceN. The real device (poll,
// triggers, the kernel's own attribute formats) is tested in the VM against
// the kernel's iio_dummy driver (tests/vm/imu_vm_test.cpp).

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/imu/iio_device.h>

#include "fake_iio.h"
#include "temp_dir.h"

namespace scaled::drivers::imu {
namespace {

using core::ErrorCode;
using test::putFile;
using test::TempDir;
namespace fs = std::filesystem;

std::string get(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

constexpr double kAccelScale = 0.000598;    // m/s^2 per LSB (+-2 g)
constexpr double kGyroScale = 0.001064724;  // rad/s per LSB

// A fake sysfs tree: ROOT/sys/iio:device0 (name "mpu6050"), iio:device1
// (a 2-axis accelerometer), trigger0; ROOT/dev/iio:device0 the scans.
class FakeIio : public ::testing::Test {
protected:
    void SetUp() override {
        options_.sysfs_root = tmp_.path() / "sys";
        options_.dev_root = tmp_.path() / "dev";
        const fs::path d = dev0();
        putFile(d / "name", "mpu6050\n");
        putFile(d / "current_timestamp_clock", "realtime\n");
        putFile(d / "in_accel_x_raw", "100\n");
        putFile(d / "in_accel_y_raw", "-200\n");
        putFile(d / "in_accel_z_raw", "16384\n");
        putFile(d / "in_accel_scale", "0.000598\n");
        putFile(d / "in_accel_x_offset", "-10\n");  // own offset of x; y and z have none
        putFile(d / "in_anglvel_x_raw", "5\n");
        putFile(d / "in_anglvel_y_raw", "-3\n");
        putFile(d / "in_anglvel_z_raw", "0\n");
        putFile(d / "in_anglvel_scale", "0.001064724\n");
        putFile(d / "in_temp_raw", "-521\n");
        putFile(d / "in_temp_offset", "12420\n");
        putFile(d / "in_temp_scale", "2.941176\n");
        putFile(d / "in_accel_scale_available", "0.000598 0.001196 0.002392 0.004785\n");
        // Scan elements: accel big-endian 16 bits (as the MPU-6050), temp,
        // gyro little-endian 12 bits shifted by 4, the timestamp last.
        const std::array<std::pair<const char*, const char*>, 8> elements = {{
            {"accel_x", "be:s16/16>>0"},
            {"accel_y", "be:s16/16>>0"},
            {"accel_z", "be:s16/16>>0"},
            {"temp", "be:s16/16>>0"},
            {"anglvel_x", "le:s12/16>>4"},
            {"anglvel_y", "le:s12/16>>4"},
            {"anglvel_z", "le:s12/16>>4"},
            {"timestamp", "le:s64/64>>0"},
        }};
        for (std::size_t k = 0; k < elements.size(); ++k) {
            const std::string ch = elements[k].first;
            putFile(d / "scan_elements" / ("in_" + ch + "_en"), "0\n");
            putFile(d / "scan_elements" / ("in_" + ch + "_index"), std::to_string(k) + "\n");
            putFile(d / "scan_elements" / ("in_" + ch + "_type"),
                    std::string(elements[k].second) + "\n");
        }
        putFile(d / "buffer" / "enable", "0\n");
        putFile(d / "buffer" / "length", "0\n");
        putFile(d / "trigger" / "current_trigger", "\n");

        const fs::path d1 = options_.sysfs_root / "iio:device1";
        putFile(d1 / "name", "adxl-2axis\n");
        putFile(d1 / "in_accel_x_raw", "1\n");
        putFile(d1 / "in_accel_y_raw", "2\n");
        putFile(options_.sysfs_root / "trigger0" / "name", "mpu6050-dev0\n");
        putFile(options_.dev_root / "iio:device0", "");
    }

    [[nodiscard]] fs::path dev0() const { return options_.sysfs_root / "iio:device0"; }

    TempDir tmp_{"imu_iio"};
    IioOptions options_;
};

// --- scan types -------------------------------------------------------------------

TEST(IioScanType, Parses) {
    auto t = parseIioScanType("le:s16/16>>0");
    ASSERT_TRUE(t.ok()) << t.error().message;
    EXPECT_FALSE(t->big_endian);
    EXPECT_TRUE(t->is_signed);
    EXPECT_EQ(t->real_bits, 16U);
    EXPECT_EQ(t->storage_bits, 16U);
    EXPECT_EQ(t->shift, 0U);
    EXPECT_EQ(t->repeat, 1U);
    auto u = parseIioScanType("be:u12/16X3>>4");
    ASSERT_TRUE(u.ok()) << u.error().message;
    EXPECT_TRUE(u->big_endian);
    EXPECT_FALSE(u->is_signed);
    EXPECT_EQ(u->real_bits, 12U);
    EXPECT_EQ(u->repeat, 3U);
    EXPECT_EQ(u->shift, 4U);
}

TEST(IioScanType, RefusesWithTheReason) {
    const std::array<std::pair<const char*, const char*>, 8> bad = {{
        {"xe:s16/16>>0", "expected `le:` or `be:`"},
        {"le:x16/16>>0", "expected `s` or `u`"},
        {"le:s16>>0", "expected `/STORAGE`"},
        {"le:s16/24>>0", "storage bits must be 8, 16, 32 or 64"},
        {"le:s16/8>>0", "real bits + shift exceed the storage bits"},
        {"le:s12/16>>8", "real bits + shift exceed the storage bits"},
        {"le:s16/16", "expected `>>SHIFT`"},
        {"le:s16/16>>0 ", "expected the shift to end the type"},
    }};
    for (const auto& [text, why] : bad) {
        SCOPED_TRACE(text);
        auto t = parseIioScanType(text);
        ASSERT_FALSE(t.ok());
        EXPECT_EQ(t.error().code, ErrorCode::kParse);
        EXPECT_NE(t.error().message.find(std::string("bad scan type '") + text + "'"),
                  std::string::npos)
            << t.error().message;
        EXPECT_NE(t.error().message.find(why), std::string::npos) << t.error().message;
    }
}

TEST(IioScanType, DecodesSignShiftAndByteOrder) {
    const auto type = [](const char* text) {
        auto t = parseIioScanType(text);
        EXPECT_TRUE(t.ok()) << text;
        return t.ok() ? *t : IioScanType{};
    };
    const std::array<uint8_t, 2> be_m2 = {0xff, 0xfe};
    EXPECT_EQ(decodeIioElement(be_m2, type("be:s16/16>>0")), -2);
    EXPECT_EQ(decodeIioElement(be_m2, type("be:u16/16>>0")), 65534);
    EXPECT_EQ(decodeIioElement(be_m2, type("le:s16/16>>0")), -257);  // 0xfeff
    // 12 bits of -3 (0xffd) shifted left by 4 in a little-endian word: 0xffd0.
    const std::array<uint8_t, 2> le_shifted = {0xd0, 0xff};
    EXPECT_EQ(decodeIioElement(le_shifted, type("le:s12/16>>4")), -3);
    EXPECT_EQ(decodeIioElement(le_shifted, type("le:u12/16>>4")), 0xffd);
    // 13 significant bits in 16 with junk above them: 0xffe7 -> 0x1fe7,
    // which as a 13-bit signed number is 0x1fe7 - 0x2000 = -25.
    const std::array<uint8_t, 2> junk = {0xff, 0xe7};
    EXPECT_EQ(decodeIioElement(junk, type("be:u13/16>>0")), 0x1fe7);
    EXPECT_EQ(decodeIioElement(junk, type("be:s13/16>>0")), -25);
    const std::array<uint8_t, 2> positive = {0x0f, 0xe7};
    EXPECT_EQ(decodeIioElement(positive, type("be:s13/16>>0")), 0x0fe7);
    const std::array<uint8_t, 1> byte = {0x80};
    EXPECT_EQ(decodeIioElement(byte, type("le:s8/8>>0")), -128);
    const std::array<uint8_t, 4> be24 = {0x00, 0x80, 0x00, 0x01};  // 24 bits in 32
    EXPECT_EQ(decodeIioElement(be24, type("be:s24/32>>0")), -8388607);
    const std::array<uint8_t, 8> ts = {0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x88};
    EXPECT_EQ(decodeIioElement(ts, type("le:s64/64>>0")), static_cast<int64_t>(0x8807060504030201));
    EXPECT_EQ(decodeIioElement(ts, type("le:u64/64>>0")), static_cast<int64_t>(0x8807060504030201));
}

// --- opening, sysfs -----------------------------------------------------------------

TEST_F(FakeIio, OpensByNameNumberAndPath) {
    for (const std::string& spec :
         {std::string("mpu6050"), std::string("iio:device0"), dev0().string(),
          (options_.dev_root / "iio:device0").string()}) {
        SCOPED_TRACE(spec);
        auto dev = IioDevice::open(spec, options_);
        ASSERT_TRUE(dev.ok()) << dev.error().message;
        EXPECT_EQ(dev->name(), "mpu6050");
        EXPECT_EQ(dev->sysfsDir(), dev0());
        EXPECT_EQ(dev->devPath(), options_.dev_root / "iio:device0");
        EXPECT_TRUE(dev->hasAccel());
        EXPECT_TRUE(dev->hasGyro());
    }
    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok());
    EXPECT_EQ(dev->describe(),
              "iio:device0 [mpu6050]: accel_x accel_y accel_z anglvel_x anglvel_y anglvel_z "
              "temp timestamp");
    // The timestamp clock was set, so buffered and sysfs times agree.
    EXPECT_EQ(get(dev0() / "current_timestamp_clock"), "monotonic\n");
    // Already that clock, as the kernel prints it (with a NUL: 6.1's
    // iio_show_timestamp_clock): not written again, since the kernel refuses
    // the write (EBUSY) while another reader runs the buffer.
    putFile(dev0() / "current_timestamp_clock", std::string("monotonic\n\0", 11));
    auto again = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(again.ok()) << again.error().message;
    EXPECT_EQ(get(dev0() / "current_timestamp_clock"), std::string("monotonic\n\0", 11));
    const IioChannel* x = dev->channel("accel_x");
    ASSERT_NE(x, nullptr);
    EXPECT_DOUBLE_EQ(x->scale, kAccelScale);
    EXPECT_DOUBLE_EQ(x->offset, -10);
    EXPECT_TRUE(x->has_scale);
    ASSERT_TRUE(x->scan_type.has_value());
    EXPECT_TRUE(x->scan_type->big_endian);
    EXPECT_EQ(dev->channel("accel_y")->offset, 0);
    EXPECT_FALSE(dev->channel("timestamp")->has_raw);
}

TEST_F(FakeIio, UnknownNameListsTheDevices) {
    auto dev = IioDevice::open("bmi160", options_);
    ASSERT_FALSE(dev.ok());
    EXPECT_EQ(dev.error().code, ErrorCode::kNotFound);
    EXPECT_EQ(dev.error().message,
              "no IIO device named 'bmi160' in " + options_.sysfs_root.string() +
                  " (devices: iio:device0 [mpu6050], iio:device1 [adxl-2axis])");
    auto path = IioDevice::open((options_.dev_root / "iio:device7").string(), options_);
    ASSERT_FALSE(path.ok());
    EXPECT_EQ(path.error().code, ErrorCode::kNotFound);
    EXPECT_NE(path.error().message.find("iio:device7/name"), std::string::npos);
    IioOptions nowhere = options_;
    nowhere.sysfs_root = tmp_.path() / "no-sys";
    auto none = IioDevice::open("mpu6050", nowhere);
    ASSERT_FALSE(none.ok());
    EXPECT_NE(none.error().message.find("does not exist (kernel without IIO?)"), std::string::npos);
}

TEST_F(FakeIio, ReadOnceAppliesOffsetAndScale) {
    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    auto s = dev->readOnce();
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_DOUBLE_EQ(s->accel_mps2.x(), (100 - 10) * kAccelScale);
    EXPECT_DOUBLE_EQ(s->accel_mps2.y(), -200 * kAccelScale);
    EXPECT_DOUBLE_EQ(s->accel_mps2.z(), 16384 * kAccelScale);
    ASSERT_TRUE(s->gyro_radps.has_value());
    EXPECT_DOUBLE_EQ(s->gyro_radps->x(), 5 * kGyroScale);
    EXPECT_DOUBLE_EQ(s->gyro_radps->y(), -3 * kGyroScale);
    EXPECT_GT(s->t_ns, 0);
    // Any channel: in_temp_{raw,offset,scale}.
    auto t = dev->readChannel("temp");
    ASSERT_TRUE(t.ok()) << t.error().message;
    EXPECT_DOUBLE_EQ(*t, (-521 + 12420) * 2.941176);
    auto missing = dev->readChannel("magn_x");
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().code, ErrorCode::kNotFound);
    EXPECT_NE(missing.error().message.find("in_magn_x_raw"), std::string::npos);
}

TEST_F(FakeIio, BadAttributesAreNamedWithTheirValue) {
    putFile(dev0() / "in_accel_scale", "abc\n");
    auto scale = IioDevice::open("mpu6050", options_);
    ASSERT_FALSE(scale.ok());
    EXPECT_EQ(scale.error().code, ErrorCode::kParse);
    EXPECT_EQ(scale.error().message,
              (dev0() / "in_accel_scale").string() + ": not a number: 'abc'");

    putFile(dev0() / "in_accel_scale", "0.000598\n");
    putFile(dev0() / "scan_elements" / "in_anglvel_y_type", "le:s16/8>>0\n");
    auto type = IioDevice::open("mpu6050", options_);
    ASSERT_FALSE(type.ok());
    EXPECT_EQ(type.error().message,
              (dev0() / "scan_elements" / "in_anglvel_y_type").string() +
                  ": bad scan type 'le:s16/8>>0' (real bits + shift exceed the storage bits)");

    putFile(dev0() / "scan_elements" / "in_anglvel_y_type", "le:s12/16>>4\n");
    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    putFile(dev0() / "in_accel_z_raw", "12.5\n");
    auto raw = dev->readOnce();
    ASSERT_FALSE(raw.ok());
    EXPECT_EQ(raw.error().message,
              (dev0() / "in_accel_z_raw").string() + ": not an integer: '12.5'");

    IioOptions bad_clock = options_;
    bad_clock.timestamp_clock = "sundial";
    auto clock = IioDevice::open("mpu6050", bad_clock);
    ASSERT_FALSE(clock.ok());
    EXPECT_EQ(clock.error().code, ErrorCode::kInvalidArgument);
    EXPECT_NE(clock.error().message.find("'sundial': not one of realtime, monotonic"),
              std::string::npos);
}

TEST_F(FakeIio, TwoAxisDeviceIsNotAnAccelerometer) {
    auto dev = IioDevice::open("adxl-2axis", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    EXPECT_FALSE(dev->hasAccel());
    auto s = dev->readOnce();
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kNotFound);
    EXPECT_EQ(s.error().message,
              "iio:device1 [adxl-2axis]: accel_x accel_y: not a 3-axis accelerometer: no " +
                  (options_.sysfs_root / "iio:device1" / "in_accel_z_raw").string());
    auto buffer = dev->startBuffer();
    ASSERT_FALSE(buffer.ok());
    EXPECT_NE(buffer.error().message.find("no buffer"), std::string::npos);
}

// --- the buffer -----------------------------------------------------------------------

void appendLe(std::string& out, uint64_t v, int bytes) {
    for (int k = 0; k < bytes; ++k) {
        out += static_cast<char>((v >> (8U * static_cast<unsigned>(k))) & 0xffU);
    }
}
void appendBe16(std::string& out, int16_t v) {
    const auto u = static_cast<uint16_t>(v);
    out += static_cast<char>(u >> 8U);
    out += static_cast<char>(u & 0xffU);
}
void appendGyro(std::string& out, int v) {  // le:s12/16>>4
    appendLe(out, (static_cast<uint64_t>(v) & 0xfffU) << 4U, 2);
}

TEST_F(FakeIio, BufferedSamplesAreDecoded) {
    // The default channels: accel, gyro, timestamp (temp left out). Layout:
    // accel_x 0, y 2, z 4 (be16); anglvel_x 6, y 8, z 10 (le12<<4); 4 bytes
    // of padding; timestamp 16 (le64, aligned to 8); 24 bytes a scan.
    std::string scans;
    const std::array<std::array<int, 7>, 3> rows = {{
        {110, -200, 16384, 5, -3, 0, 0},
        {-32768, 32767, 16000, -2048, 2047, -1, 1},
        {0, 1, -1, 1, -1, 100, 2},
    }};
    for (const auto& r : rows) {
        for (int k = 0; k < 3; ++k) {
            appendBe16(scans, static_cast<int16_t>(r[static_cast<std::size_t>(k)]));
        }
        for (int k = 3; k < 6; ++k) {
            appendGyro(scans, r[static_cast<std::size_t>(k)]);
        }
        scans += std::string(4, '\xaa');  // padding, ignored
        appendLe(scans, 1'700'000'000'000'000'000ULL + static_cast<uint64_t>(r[6]) * 5'000'000, 8);
    }
    putFile(options_.dev_root / "iio:device0", scans);

    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    IioBufferOptions opt;
    opt.trigger = "mpu6050-dev0";
    auto started = dev->startBuffer(opt);
    ASSERT_TRUE(started.ok()) << started.error().message;
    EXPECT_TRUE(dev->bufferRunning());
    EXPECT_EQ(dev->scanBytes(), 24U);
    EXPECT_EQ(dev->bufferChannels(),
              (std::vector<std::string>{"accel_x", "accel_y", "accel_z", "anglvel_x", "anglvel_y",
                                        "anglvel_z", "timestamp"}));
    // What the driver wrote to sysfs.
    EXPECT_EQ(get(dev0() / "buffer" / "enable"), "1\n");
    EXPECT_EQ(get(dev0() / "buffer" / "length"), "128\n");
    EXPECT_EQ(get(dev0() / "trigger" / "current_trigger"), "mpu6050-dev0\n");
    EXPECT_EQ(get(dev0() / "scan_elements" / "in_accel_z_en"), "1\n");
    EXPECT_EQ(get(dev0() / "scan_elements" / "in_timestamp_en"), "1\n");
    EXPECT_EQ(get(dev0() / "scan_elements" / "in_temp_en"), "0\n");

    auto first = dev->readSamples(2, 1000);
    ASSERT_TRUE(first.ok()) << first.error().message;
    ASSERT_EQ(first->size(), 2U);
    const auto& a = (*first)[0];
    EXPECT_EQ(a.t_ns, 1'700'000'000'000'000'000);
    EXPECT_DOUBLE_EQ(a.accel_mps2.x(), (110 - 10) * kAccelScale);
    EXPECT_DOUBLE_EQ(a.accel_mps2.y(), -200 * kAccelScale);
    EXPECT_DOUBLE_EQ(a.accel_mps2.z(), 16384 * kAccelScale);
    ASSERT_TRUE(a.gyro_radps.has_value());
    EXPECT_DOUBLE_EQ(a.gyro_radps->x(), 5 * kGyroScale);
    EXPECT_DOUBLE_EQ(a.gyro_radps->y(), -3 * kGyroScale);
    const auto& b = (*first)[1];
    EXPECT_EQ(b.t_ns, 1'700'000'000'005'000'000);
    EXPECT_DOUBLE_EQ(b.accel_mps2.x(), (-32768 - 10) * kAccelScale);
    EXPECT_DOUBLE_EQ(b.accel_mps2.y(), 32767 * kAccelScale);
    EXPECT_DOUBLE_EQ(b.gyro_radps->x(), -2048 * kGyroScale);
    EXPECT_DOUBLE_EQ(b.gyro_radps->y(), 2047 * kGyroScale);
    EXPECT_DOUBLE_EQ(b.gyro_radps->z(), -1 * kGyroScale);

    auto rest = dev->readSamples(10, 1000);
    ASSERT_TRUE(rest.ok()) << rest.error().message;
    ASSERT_EQ(rest->size(), 1U);
    EXPECT_DOUBLE_EQ((*rest)[0].gyro_radps->z(), 100 * kGyroScale);
    // The regular file ends; a real device would wait (poll) instead.
    auto end = dev->readSamples(10, 1000);
    ASSERT_FALSE(end.ok());
    EXPECT_EQ(end.error().code, ErrorCode::kUnavailable);
    EXPECT_EQ(end.error().message, (options_.dev_root / "iio:device0").string() + ": end of data");

    auto stopped = dev->stopBuffer();
    ASSERT_TRUE(stopped.ok()) << stopped.error().message;
    EXPECT_TRUE(*stopped);
    EXPECT_FALSE(dev->bufferRunning());
    EXPECT_EQ(get(dev0() / "buffer" / "enable"), "0\n");
}

TEST_F(FakeIio, ChosenChannelsAndThePartialScan) {
    // accel_z (be16) at 0, temp (be16) at 2, timestamp at 8: 16 bytes a scan.
    std::string scans;
    for (int k = 0; k < 2; ++k) {
        appendBe16(scans, static_cast<int16_t>(1000 + k));
        appendBe16(scans, static_cast<int16_t>(-521));
        scans += std::string(4, '\0');
        appendLe(scans, 1000U + static_cast<uint64_t>(k), 8);
    }
    scans += std::string(5, '\x01');  // a scan cut short
    putFile(options_.dev_root / "iio:device0", scans);
    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    IioBufferOptions opt;
    opt.channels = {"timestamp", "temp", "accel_z"};
    opt.length = 16;
    auto started = dev->startBuffer(opt);
    ASSERT_TRUE(started.ok()) << started.error().message;
    EXPECT_EQ(dev->bufferChannels(), (std::vector<std::string>{"accel_z", "temp", "timestamp"}));
    EXPECT_EQ(dev->scanBytes(), 16U);
    EXPECT_EQ(get(dev0() / "buffer" / "length"), "16\n");
    EXPECT_EQ(get(dev0() / "trigger" / "current_trigger"), "\n") << "no trigger named: left";
    EXPECT_EQ(get(dev0() / "scan_elements" / "in_accel_x_en"), "0\n");

    auto samples = dev->readSamples(4, 100);
    ASSERT_FALSE(samples.ok()) << "accel_x and accel_y are not buffered";
    EXPECT_NE(samples.error().message.find("accel_x is not buffered"), std::string::npos);

    auto scans_read = dev->readScans(8, 1000);
    ASSERT_TRUE(scans_read.ok()) << scans_read.error().message;
    ASSERT_EQ(scans_read->size(), 2U);
    EXPECT_EQ((*scans_read)[1].raw, (std::vector<int64_t>{1001, -521, 1001}));
    EXPECT_EQ((*scans_read)[1].t_ns, 1001);
    EXPECT_DOUBLE_EQ((*scans_read)[1].value[0], 1001 * kAccelScale);
    EXPECT_DOUBLE_EQ((*scans_read)[1].value[1], (-521 + 12420) * 2.941176);
    auto end = dev->readScans(8, 1000);  // 5 bytes left, then the end
    ASSERT_FALSE(end.ok());
    EXPECT_EQ(end.error().code, ErrorCode::kUnavailable);
}

TEST_F(FakeIio, BufferErrors) {
    auto dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    auto not_running = dev->readScans(1, 0);
    ASSERT_FALSE(not_running.ok());
    EXPECT_NE(not_running.error().message.find("not running"), std::string::npos);

    IioBufferOptions unknown;
    unknown.channels = {"accel_x", "magn_x"};
    auto bad_channel = dev->startBuffer(unknown);
    ASSERT_FALSE(bad_channel.ok());
    EXPECT_EQ(bad_channel.error().code, ErrorCode::kNotFound);
    EXPECT_NE(bad_channel.error().message.find(
                  "channel 'magn_x' cannot be buffered (no " +
                  (dev0() / "scan_elements" / "in_magn_x_en").string() + ")"),
              std::string::npos)
        << bad_channel.error().message;

    putFile(dev0() / "buffer" / "enable", "1\n");
    auto busy = dev->startBuffer();
    ASSERT_FALSE(busy.ok());
    EXPECT_EQ(busy.error().code, ErrorCode::kUnavailable);
    EXPECT_EQ(busy.error().message, (dev0() / "buffer" / "enable").string() +
                                        " is '1': the buffer is in use (another reader?)");

    putFile(dev0() / "buffer" / "enable", "0\n");
    fs::remove(options_.dev_root / "iio:device0");
    auto no_dev = dev->startBuffer();
    ASSERT_FALSE(no_dev.ok());
    EXPECT_EQ(no_dev.error().code, ErrorCode::kNotFound);
    EXPECT_EQ(no_dev.error().message, (options_.dev_root / "iio:device0").string() +
                                          ": cannot open: No such file or directory");
    EXPECT_EQ(get(dev0() / "buffer" / "enable"), "0\n") << "never enabled";

    putFile(dev0() / "scan_elements" / "in_accel_y_type", "le:s16/16X2>>0\n");
    putFile(options_.dev_root / "iio:device0", "");
    auto repeat_dev = IioDevice::open("mpu6050", options_);
    ASSERT_TRUE(repeat_dev.ok()) << repeat_dev.error().message;
    auto repeat = repeat_dev->startBuffer();
    ASSERT_FALSE(repeat.ok());
    EXPECT_NE(repeat.error().message.find("repeated elements (X2) are not supported"),
              std::string::npos)
        << repeat.error().message;
}

TEST_F(FakeIio, DestructionStopsTheBuffer) {
    {
        auto dev = IioDevice::open("mpu6050", options_);
        ASSERT_TRUE(dev.ok()) << dev.error().message;
        ASSERT_TRUE(dev->startBuffer().ok());
        IioDevice moved = std::move(*dev);
        EXPECT_TRUE(moved.bufferRunning());
        EXPECT_EQ(get(dev0() / "buffer" / "enable"), "1\n");
    }
    EXPECT_EQ(get(dev0() / "buffer" / "enable"), "0\n");
}

}  // namespace
}  // namespace scaled::drivers::imu
