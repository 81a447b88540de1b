// The IIO driver (drivers/imu) on a real kernel IIO device: run inside the
// test VM (tests/vm/run-vm.sh), where guest-init.sh has loaded iio_dummy
// (built with its buffer), iio-trig-sysfs and iio-trig-hrtimer, and
// SCALED_VM=1. Elsewhere every test skips; in the VM a missing module fails.
//
// The device is the kernel's dummy, made here through configfs
// (/sys/kernel/config/iio/devices/dummy/scaled-imu), as fetch-kernel.sh builds
// it with iio_dummy_accel_xyz.patch: a 3-axis accelerometer in sysfs
// (in_accel_{x,y,z}_raw, writable, x = 34 at creation, in_accel_scale
// 0.001) of which only x is buffered (344 in the buffer), a voltage channel
// with offset and scale (in_voltage0_raw 73, _offset 7, _scale 0.001333; 7
// in the buffer, `le:u13/16>>0`), differential voltages and a soft
// timestamp. So readOnce() is checked here with values the test writes, and
// readSamples() for its error (its values on the host, imu_tests); the sysfs
// and buffer mechanics (attributes, scan elements, triggers, poll,
// decoding, timestamps) on the real kernel here.

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <sys/stat.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/imu/iio_device.h>

namespace scaled::drivers::imu {
namespace {

using core::ErrorCode;
namespace fs = std::filesystem;

constexpr const char* kName = "scaled-imu";
const fs::path kIio = "/sys/bus/iio/devices";
const fs::path kConfigfsDummy = "/sys/kernel/config/iio/devices/dummy";
const fs::path kConfigfsHrtimer = "/sys/kernel/config/iio/triggers/hrtimer";

std::string readText(const fs::path& path) {
    std::ifstream in(path);
    std::string s;
    std::getline(in, s);
    return s;
}

bool writeText(const fs::path& path, const std::string& value, std::string& why) {
    std::ofstream out(path);
    out << value << '\n';
    out.flush();
    if (!out.good()) {
        why = "cannot write '" + value + "' to " + path.string() + ": " +
              drivers::base::errnoText(errno);
        return false;
    }
    return true;
}

int64_t monotonicNs() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// The IIO trigger directory (/sys/bus/iio/devices/triggerN) named `name`.
std::optional<fs::path> findTrigger(const std::string& name) {
    std::error_code ec;
    for (fs::directory_iterator it(kIio, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
        if (it->path().filename().string().starts_with("trigger") &&
            readText(it->path() / "name") == name) {
            return it->path();
        }
    }
    return std::nullopt;
}

class ImuVmTest : public ::testing::Test {
protected:
    void SetUp() override {
        if (std::getenv("SCALED_VM") == nullptr) {
            GTEST_SKIP() << "needs the test VM's iio_dummy (SCALED_VM=1, tests/vm/run-vm.sh)";
        }
        ASSERT_TRUE(fs::is_directory(kConfigfsDummy))
            << "no " << kConfigfsDummy << ": iio_dummy (and industrialio-configfs) not loaded";
        // The dummy device, once per VM (mkdir makes it, synchronously).
        const fs::path dir = kConfigfsDummy / kName;
        if (!fs::exists(dir)) {
            ASSERT_EQ(::mkdir(dir.c_str(), 0755), 0)
                << "mkdir " << dir << ": " << drivers::base::errnoText(errno);
        }
        // The sysfs trigger sysfstrig0, once per VM.
        if (!findTrigger("sysfstrig0")) {
            std::string why;
            ASSERT_TRUE(writeText(kIio / "iio_sysfs_trigger" / "add_trigger", "0", why)) << why;
        }
        auto trig = findTrigger("sysfstrig0");
        ASSERT_TRUE(trig.has_value()) << "no trigger sysfstrig0 after add_trigger";
        sysfs_trigger_ = *trig;
    }

    // Fires the sysfs trigger once.
    void fire() {
        std::string why;
        ASSERT_TRUE(writeText(sysfs_trigger_ / "trigger_now", "1", why)) << why;
    }

    fs::path sysfs_trigger_;
};

TEST_F(ImuVmTest, OpensTheDummyByNameAndPath) {
    auto dev = IioDevice::open(kName);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    EXPECT_EQ(dev->name(), kName);
    const std::string node = dev->sysfsDir().filename().string();
    EXPECT_TRUE(node.starts_with("iio:device")) << node;
    EXPECT_EQ(dev->devPath(), fs::path("/dev") / node);
    EXPECT_TRUE(fs::exists(dev->devPath())) << "the character device";
    for (const std::string& spec : {node, dev->sysfsDir().string(), dev->devPath().string()}) {
        auto again = IioDevice::open(spec);
        ASSERT_TRUE(again.ok()) << spec << ": " << again.error().message;
        EXPECT_EQ(again->name(), kName);
    }
    for (const char* ch : {"accel_x", "accel_y", "accel_z", "voltage0", "timestamp"}) {
        EXPECT_NE(dev->channel(ch), nullptr) << dev->describe();
    }
    EXPECT_TRUE(dev->hasAccel()) << "the patched dummy has three accelerometer axes";
    EXPECT_FALSE(dev->hasGyro());
    // open() set the timestamp clock.
    EXPECT_EQ(readText(dev->sysfsDir() / "current_timestamp_clock"), "monotonic");
    auto none = IioDevice::open("no-such-imu");
    ASSERT_FALSE(none.ok());
    EXPECT_EQ(none.error().code, ErrorCode::kNotFound);
    EXPECT_NE(none.error().message.find("[" + std::string(kName) + "]"), std::string::npos)
        << none.error().message;
}

TEST_F(ImuVmTest, SysfsValuesWithOffsetAndScale) {
    auto dev = IioDevice::open(kName);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    // The kernel prints the scale as IIO_VAL_INT_PLUS_MICRO: "0.001333".
    const IioChannel* v = dev->channel("voltage0");
    ASSERT_NE(v, nullptr);
    EXPECT_TRUE(v->has_scale);
    EXPECT_DOUBLE_EQ(v->scale, 0.001333);
    EXPECT_DOUBLE_EQ(v->offset, 7);
    auto volts = dev->readChannel("voltage0");
    ASSERT_TRUE(volts.ok()) << volts.error().message;
    EXPECT_DOUBLE_EQ(*volts, (73 + 7) * 0.001333);
    // The accelerometer's shared scale (in_accel_scale), no offset.
    const IioChannel* a = dev->channel("accel_x");
    ASSERT_NE(a, nullptr);
    EXPECT_TRUE(a->has_scale);
    EXPECT_DOUBLE_EQ(a->scale, 0.001);
    EXPECT_DOUBLE_EQ(a->offset, 0);
    // What the axes read is what the test writes (raw, mm/s^2).
    std::string why;
    ASSERT_TRUE(writeText(dev->sysfsDir() / "in_accel_x_raw", "-120", why)) << why;
    ASSERT_TRUE(writeText(dev->sysfsDir() / "in_accel_y_raw", "4903", why)) << why;
    ASSERT_TRUE(writeText(dev->sysfsDir() / "in_accel_z_raw", "8493", why)) << why;
    auto accel = dev->readChannel("accel_x");
    ASSERT_TRUE(accel.ok()) << accel.error().message;
    EXPECT_DOUBLE_EQ(*accel, -0.12);
    const int64_t before_ns = monotonicNs();
    auto once = dev->readOnce();
    const int64_t after_ns = monotonicNs();
    ASSERT_TRUE(once.ok()) << once.error().message;
    EXPECT_NEAR(once->accel_mps2.x(), -0.120, 1e-6);
    EXPECT_NEAR(once->accel_mps2.y(), 4.903, 1e-6);
    EXPECT_NEAR(once->accel_mps2.z(), 8.493, 1e-6);
    EXPECT_FALSE(once->gyro_radps.has_value());
    EXPECT_GE(once->t_ns, before_ns);
    EXPECT_LE(once->t_ns, after_ns);
    // As created, for the buffer tests.
    ASSERT_TRUE(writeText(dev->sysfsDir() / "in_accel_x_raw", "34", why)) << why;
}

TEST_F(ImuVmTest, BufferWithTheSysfsTrigger) {
    auto dev = IioDevice::open(kName);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    IioBufferOptions opt;
    opt.channels = {"accel_x", "voltage0", "timestamp"};
    opt.trigger = "sysfstrig0";
    opt.length = 16;
    const int64_t before_ns = monotonicNs();
    auto started = dev->startBuffer(opt);
    ASSERT_TRUE(started.ok()) << started.error().message;
    EXPECT_EQ(dev->bufferChannels(),
              (std::vector<std::string>{"voltage0", "accel_x", "timestamp"}));
    EXPECT_EQ(dev->scanBytes(), 16U);  // u16, s16, padding, s64 at 8
    EXPECT_EQ(readText(dev->sysfsDir() / "buffer" / "enable"), "1");
    EXPECT_EQ(readText(dev->sysfsDir() / "trigger" / "current_trigger"), "sysfstrig0");
    // Nothing before the trigger fires.
    auto idle = dev->readScans(4, 0);
    ASSERT_TRUE(idle.ok()) << idle.error().message;
    EXPECT_TRUE(idle->empty());

    // One scan per firing; the next firing only after the scan arrived (a
    // trigger fired while its consumer is busy is dropped by the kernel).
    std::vector<IioScan> got;
    for (int k = 0; k < 3; ++k) {
        fire();
        auto scans = dev->readScans(4, 10'000);
        ASSERT_TRUE(scans.ok()) << scans.error().message;
        ASSERT_EQ(scans->size(), 1U) << "firing " << k;
        got.push_back(scans->front());
    }
    const int64_t after_ns = monotonicNs();
    for (std::size_t k = 0; k < got.size(); ++k) {
        SCOPED_TRACE(k);
        EXPECT_EQ(got[k].raw[0], 7);    // fakedata voltage0
        EXPECT_EQ(got[k].raw[1], 344);  // fakedata accel x
        EXPECT_DOUBLE_EQ(got[k].value[0], (7 + 7) * 0.001333);
        EXPECT_DOUBLE_EQ(got[k].value[1], 344 * 0.001);  // in_accel_scale
        // The kernel's timestamp, on CLOCK_MONOTONIC as open() asked.
        EXPECT_GE(got[k].t_ns, before_ns);
        EXPECT_LE(got[k].t_ns, after_ns);
        if (k > 0) {
            EXPECT_GT(got[k].t_ns, got[k - 1].t_ns);
        }
    }
    // Not an IMU: readSamples says so.
    auto samples = dev->readSamples(1, 0);
    ASSERT_FALSE(samples.ok());
    EXPECT_NE(samples.error().message.find("accel_y is not buffered"), std::string::npos)
        << samples.error().message;

    // A second reader finds the buffer in use.
    auto other = IioDevice::open(kName);
    ASSERT_TRUE(other.ok()) << other.error().message;
    auto busy = other->startBuffer(opt);
    ASSERT_FALSE(busy.ok());
    EXPECT_EQ(busy.error().code, ErrorCode::kUnavailable);
    EXPECT_NE(busy.error().message.find("buffer/enable is '1'"), std::string::npos)
        << busy.error().message;

    auto stopped = dev->stopBuffer();
    ASSERT_TRUE(stopped.ok()) << stopped.error().message;
    EXPECT_EQ(readText(dev->sysfsDir() / "buffer" / "enable"), "0");
}

TEST_F(ImuVmTest, BufferWithoutATriggerIsRefusedWithAHint) {
    auto dev = IioDevice::open(kName);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    std::string why;
    // No trigger: a name that matches none clears current_trigger.
    ASSERT_TRUE(writeText(dev->sysfsDir() / "trigger" / "current_trigger", "", why)) << why;
    ASSERT_EQ(readText(dev->sysfsDir() / "trigger" / "current_trigger"), "");
    IioBufferOptions opt;
    opt.channels = {"accel_x", "timestamp"};
    auto started = dev->startBuffer(opt);
    ASSERT_FALSE(started.ok());
    EXPECT_NE(started.error().message.find("buffer/enable: cannot write '1': Invalid argument"),
              std::string::npos)
        << started.error().message;
    EXPECT_NE(started.error().message.find("name one in IioBufferOptions::trigger"),
              std::string::npos)
        << started.error().message;
    EXPECT_FALSE(dev->bufferRunning());
    EXPECT_EQ(readText(dev->sysfsDir() / "buffer" / "enable"), "0");
}

TEST_F(ImuVmTest, StreamFromTheHrtimerTrigger) {
    ASSERT_TRUE(fs::is_directory(kConfigfsHrtimer))
        << "no " << kConfigfsHrtimer << ": iio-trig-hrtimer not loaded";
    const fs::path hrt = kConfigfsHrtimer / "scaled-hrt";
    if (!fs::exists(hrt)) {
        ASSERT_EQ(::mkdir(hrt.c_str(), 0755), 0)
            << "mkdir " << hrt << ": " << drivers::base::errnoText(errno);
    }
    auto trig = findTrigger("scaled-hrt");
    ASSERT_TRUE(trig.has_value()) << "no IIO trigger scaled-hrt after mkdir " << hrt;
    std::string why;
    ASSERT_TRUE(writeText(*trig / "sampling_frequency", "100", why)) << why;

    auto dev = IioDevice::open(kName);
    ASSERT_TRUE(dev.ok()) << dev.error().message;
    IioBufferOptions opt;
    opt.channels = {"accel_x", "timestamp"};
    opt.trigger = "scaled-hrt";
    auto started = dev->startBuffer(opt);
    ASSERT_TRUE(started.ok()) << started.error().message;
    // 20 scans at 100 Hz; the deadline is generous for an emulated CPU.
    std::vector<IioScan> got;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (got.size() < 20 && std::chrono::steady_clock::now() < deadline) {
        auto scans = dev->readScans(20 - got.size(), 1000);
        ASSERT_TRUE(scans.ok()) << scans.error().message;
        got.insert(got.end(), scans->begin(), scans->end());
    }
    auto stopped = dev->stopBuffer();
    ASSERT_TRUE(stopped.ok()) << stopped.error().message;
    ASSERT_EQ(got.size(), 20U) << "scans within 30 s";
    for (std::size_t k = 0; k < got.size(); ++k) {
        EXPECT_EQ(got[k].raw[0], 344);
        if (k > 0) {
            EXPECT_GT(got[k].t_ns, got[k - 1].t_ns) << k;
        }
    }
    // At 100 Hz the 19 periods take at least 190 ms minus the timer's slack
    // (an emulated CPU may skip periods: more, never much less).
    EXPECT_GE(got.back().t_ns - got.front().t_ns, 150'000'000);
    ::rmdir(hrt.c_str());
}

}  // namespace
}  // namespace scaled::drivers::imu
