#pragma once

// Accelerometers and gyroscopes through Linux IIO (Industrial I/O), the
// kernel's interface to most MEMS IMUs on ARM boards (MPU-6050, LSM6DS*, BMI*,
// ADXL345, ...). Two ways to read, both supported:
//
//   sysfs     one value per read: in_accel_{x,y,z}_raw, in_anglvel_{x,y,z}_raw
//             in the device's directory, converted as (raw + offset) * scale
//             with in_<ch>_scale or the shared in_<type>_scale (accel, anglvel:
//             the kernel's units are m/s^2 and rad/s) and in_<ch>_offset or
//             in_<type>_offset; a missing scale is 1 and a missing offset 0
//             (IioChannel says which were present). readOnce(), readChannel().
//   buffer    a stream of scans from the character device /dev/iio:deviceN:
//             startBuffer() enables the scan elements (scan_elements/in_*_en,
//             their _type such as `le:s16/16>>0` and _index), sets
//             trigger/current_trigger (when a trigger is named), buffer/length
//             and buffer/enable; readSamples() / readScans() poll and decode
//             (sign, real and storage bits, shift, endianness, the kernel's
//             alignment of each element to its own size); stopBuffer() (also
//             the destructor) disables it. Repeated elements (`X2`) are
//             refused.
//
// Triggers: the scans come when the device's trigger fires. Devices with a
// data-ready interrupt register their own trigger (e.g. `mpu6050-dev0`), to
// name in IioBufferOptions::trigger; otherwise a software trigger made by the
// user (iio-trig-hrtimer through configfs, iio-trig-sysfs) is named the same
// way. With no trigger named, current_trigger is left as it is: devices with
// a hardware FIFO need none, and a device that needs one refuses
// buffer/enable (the error says to name a trigger).
//
// Timestamps: open() sets current_timestamp_clock to IioOptions::timestamp_clock
// ("monotonic" by default) when the device has the attribute, so buffered
// timestamps (the `timestamp` scan element) and readOnce() (which takes the
// time just before reading) use the same clock. Without a timestamp element a
// buffered scan is stamped when read.
//
// The device: open("mpu6050") by its name (/sys/bus/iio/devices/iio:deviceN/name;
// the lowest N when several match), open("iio:device0"), or by path
// ("/sys/bus/iio/devices/iio:device2", "/dev/iio:device2").
//
// Errors name the sysfs file or device and the value, e.g.
//   `/sys/bus/iio/devices/iio:device0/in_accel_scale: not a number: 'abc'`,
//   `/sys/bus/iio/devices/iio:device0/scan_elements/in_accel_x_type: bad scan
//    type 'le:s16/8>>0' (real bits + shift exceed the storage bits)`.
// kNotFound: no such device or channel; kUnavailable: the buffer is in use or
// the device went away; kParse: an attribute that does not parse; kIo: other
// read/write failures; kInvalidArgument: a request the device cannot do.
//
// Not thread-safe: one thread uses one IioDevice.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/imu_sample.h>
#include <scaled/core/result.h>
#include <scaled/drivers/base/unique_fd.h>

namespace scaled::drivers::imu {

// How one element is stored in a scan (scan_elements/in_<ch>_type), e.g.
// "le:s16/16>>0" or "be:u12/16>>4".
struct IioScanType {
    bool big_endian = false;
    bool is_signed = false;
    unsigned real_bits = 0;     // significant bits
    unsigned storage_bits = 0;  // 8, 16, 32 or 64
    unsigned shift = 0;         // right shift before masking to real_bits
    unsigned repeat = 1;        // "X<n>": n elements (parsed; buffers with n > 1 are refused)
};

// Parses `[be|le]:[s|u]REAL/STORAGE[Xn]>>SHIFT`. The message says what is
// wrong, without a location.
[[nodiscard]] core::Result<IioScanType> parseIioScanType(std::string_view text);

// The integer in `bytes` (storage_bits / 8 of them) as `type` describes it:
// byte order, shift, mask to real_bits, sign extension.
[[nodiscard]] int64_t decodeIioElement(std::span<const uint8_t> bytes, const IioScanType& type);

struct IioChannel {
    std::string name;      // "accel_x", "anglvel_z", "voltage0", "timestamp": the <ch> of in_<ch>_*
    bool has_raw = false;  // in_<ch>_raw exists: readable one value at a time
    double scale = 1;      // value = (raw + offset) * scale
    double offset = 0;
    bool has_scale = false;  // a scale attribute exists (else scale = 1)
    // Buffered: scan_elements/in_<ch>_index and _type, when the channel has them.
    std::optional<int> scan_index;
    std::optional<IioScanType> scan_type;
};

struct IioOptions {
    // Where the devices are; the tests point these at a directory tree.
    std::filesystem::path sysfs_root = "/sys/bus/iio/devices";
    std::filesystem::path dev_root = "/dev";
    // Written to current_timestamp_clock when the device has that attribute:
    // realtime, monotonic, monotonic_raw, realtime_coarse, monotonic_coarse,
    // boottime or tai. Empty: leave the device's clock (read, realtime if absent).
    std::string timestamp_clock = "monotonic";
};

struct IioBufferOptions {
    // The channels to capture, by IioChannel::name. Empty: accel_x/y/z (which
    // must exist), anglvel_x/y/z when all three can be buffered, and
    // timestamp when it can.
    std::vector<std::string> channels;
    // Written to trigger/current_trigger when not empty (see the top).
    std::string trigger;
    unsigned length = 128;  // buffer/length, in scans
};

// One decoded scan (readScans()).
struct IioScan {
    // Per buffered channel, in bufferChannels() order: the raw integer and
    // (raw + offset) * scale.
    std::vector<int64_t> raw;
    std::vector<double> value;
    // The timestamp element when buffered, else the clock when it was read.
    int64_t t_ns = 0;
};

class IioDevice {
public:
    [[nodiscard]] static core::Result<IioDevice> open(std::string_view name_or_path,
                                                      const IioOptions& options = {});

    IioDevice(IioDevice&& other) noexcept;
    IioDevice& operator=(IioDevice&& other) noexcept;
    IioDevice(const IioDevice&) = delete;
    IioDevice& operator=(const IioDevice&) = delete;
    ~IioDevice();  // stops the buffer when running

    [[nodiscard]] const std::string& name() const { return name_; }
    [[nodiscard]] const std::filesystem::path& sysfsDir() const { return sysfs_dir_; }
    [[nodiscard]] const std::filesystem::path& devPath() const { return dev_path_; }
    // Every channel the device shows (in_<ch>_raw or a scan element), by name.
    [[nodiscard]] const std::vector<IioChannel>& channels() const { return channels_; }
    [[nodiscard]] const IioChannel* channel(std::string_view name) const;
    // The clock of the samples' t_ns (CLOCK_MONOTONIC, CLOCK_REALTIME, ...):
    // current_timestamp_clock as open() left it; CLOCK_REALTIME without one.
    [[nodiscard]] int clockId() const { return clock_id_; }
    [[nodiscard]] bool hasAccel() const;  // accel_x, accel_y and accel_z readable
    [[nodiscard]] bool hasGyro() const;   // anglvel_x, anglvel_y and anglvel_z readable
    // "iio:device0 [mpu6050]: accel_x accel_y accel_z anglvel_x ... timestamp".
    [[nodiscard]] std::string describe() const;

    // --- sysfs ---
    // One channel, (raw + offset) * scale.
    [[nodiscard]] core::Result<double> readChannel(std::string_view name) const;
    // The accelerometer (and gyro, when hasGyro()), stamped just before reading.
    [[nodiscard]] core::Result<core::ImuSample> readOnce() const;

    // --- buffer ---
    [[nodiscard]] core::Status startBuffer(const IioBufferOptions& options = {});
    [[nodiscard]] bool bufferRunning() const { return fd_.isValid(); }
    // The buffered channels in scan order (their scan_index).
    [[nodiscard]] const std::vector<std::string>& bufferChannels() const { return buffer_names_; }
    [[nodiscard]] std::size_t scanBytes() const { return scan_bytes_; }
    // Up to `max_scans` scans (at most 65536 a call): waits at most
    // `timeout_ms` for the first (0: does not wait; negative: no limit), then
    // returns what is there (an empty vector when nothing came in time).
    // kUnavailable when the device ended (read returned 0: a regular file at
    // its end, a device gone).
    [[nodiscard]] core::Result<std::vector<IioScan>> readScans(std::size_t max_scans,
                                                               int timeout_ms);
    // readScans() as IMU samples; needs accel_x/y/z buffered (gyro when
    // anglvel_x/y/z are).
    [[nodiscard]] core::Result<std::vector<core::ImuSample>> readSamples(std::size_t max_samples,
                                                                         int timeout_ms);
    // Disables the buffer and closes the device; true when it was running.
    [[nodiscard]] core::Result<bool> stopBuffer();

private:
    IioDevice() = default;

    struct Element {
        std::size_t channel = 0;  // index into channels_
        std::size_t offset = 0;   // bytes into the scan
        std::size_t bytes = 0;
    };

    // The steps of startBuffer().
    // The buffer is not running, exists, is not enabled by another reader, and
    // `length` scans is not 0.
    [[nodiscard]] core::Status checkBufferFree(const std::filesystem::path& enable_file,
                                               unsigned length) const;
    // Appends accel_x/y/z, anglvel_x/y/z when all three can be buffered, and
    // timestamp when it can.
    void addDefaultBufferChannels(std::vector<std::string>& wanted) const;
    // Indices into channels_ of `wanted`, each once, in scan_index order.
    [[nodiscard]] core::Result<std::vector<std::size_t>> chooseBufferChannels(
        const std::vector<std::string>& wanted) const;
    // Each scan element on when chosen, off otherwise.
    [[nodiscard]] core::Status enableScanElements(const std::vector<std::size_t>& chosen) const;
    // elements_, buffer_names_, timestamp_element_ and scan_bytes_ for `chosen`.
    void layOutScan(const std::vector<std::size_t>& chosen);
    [[nodiscard]] core::Status writeTriggerAndLength(const IioBufferOptions& options) const;
    // The error of writing 1 to buffer/enable, with the likely reason on EINVAL.
    [[nodiscard]] core::Error explainEnableRefused(core::Error e) const;

    std::string name_;
    std::filesystem::path sysfs_dir_;
    std::filesystem::path dev_path_;
    std::vector<IioChannel> channels_;
    int clock_id_ = 0;  // CLOCK_REALTIME

    base::UniqueFd fd_;  // the character device while the buffer runs
    std::vector<Element> elements_;
    std::vector<std::string> buffer_names_;
    std::size_t scan_bytes_ = 0;
    std::optional<std::size_t> timestamp_element_;
    std::vector<uint8_t> pending_;  // bytes of a scan read only in part
};

}  // namespace scaled::drivers::imu
