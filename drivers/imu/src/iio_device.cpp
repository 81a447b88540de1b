#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <poll.h>
#include <string>
#include <system_error>
#include <type_traits>
#include <unistd.h>
#include <utility>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/imu/iio_device.h>

namespace scaled::drivers::imu {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;
namespace fs = std::filesystem;

namespace {

constexpr std::size_t kMaxAttrBytes = 4096;  // a sysfs attribute is at most one page
constexpr std::size_t kMaxScansPerRead = 65536;

struct ClockName {
    const char* name;
    clockid_t id;
};
constexpr std::array<ClockName, 7> kClocks = {{
    {"realtime", CLOCK_REALTIME},
    {"monotonic", CLOCK_MONOTONIC},
    {"monotonic_raw", CLOCK_MONOTONIC_RAW},
    {"realtime_coarse", CLOCK_REALTIME_COARSE},
    {"monotonic_coarse", CLOCK_MONOTONIC_COARSE},
    {"boottime", CLOCK_BOOTTIME},
    {"tai", CLOCK_TAI},
}};

std::optional<clockid_t> clockByName(std::string_view name) {
    for (const ClockName& c : kClocks) {
        if (name == c.name) {
            return c.id;
        }
    }
    return std::nullopt;
}

int64_t nowNs(clockid_t clock) {
    timespec ts{};
    ::clock_gettime(clock, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string quote(std::string_view text) {
    std::string out = "'";
    for (const char c : text.substr(0, 80)) {
        const auto u = static_cast<unsigned char>(c);
        if (u < 0x20 || u >= 0x7f) {
            static constexpr std::array<char, 17> kHex = {"0123456789abcdef"};
            out += "\\x";
            out += kHex[u >> 4U];
            out += kHex[u & 0xfU];
        } else {
            out += c;
        }
    }
    return out + (text.size() > 80 ? "...'" : "'");
}

ErrorCode codeOf(int err) {
    switch (err) {
        case ENOENT:
            return ErrorCode::kNotFound;
        case ENODEV:
        case ENXIO:
        case EBUSY:
        case EAGAIN:
            return ErrorCode::kUnavailable;
        default:
            return ErrorCode::kIo;
    }
}

// A sysfs attribute's text without its trailing newline, NULs and blanks.
Result<std::string> readAttr(const fs::path& path) {
    const base::UniqueFd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
    if (!fd.isValid()) {
        const int err = errno;
        return makeError(codeOf(err),
                         path.string() + ": cannot open: " + drivers::base::errnoText(err));
    }
    std::string text;
    std::array<char, 512> buf{};
    while (text.size() < kMaxAttrBytes) {
        const ssize_t n = ::read(fd.get(), buf.data(), buf.size());
        if (n < 0) {
            if (errno == EINTR) {
                continue;
            }
            const int err = errno;
            return makeError(codeOf(err),
                             path.string() + ": cannot read: " + drivers::base::errnoText(err));
        }
        if (n == 0) {
            break;
        }
        text.append(buf.data(), static_cast<std::size_t>(n));
    }
    // Some attributes end in a NUL as well: the kernel's current_timestamp_clock
    // returns "monotonic\n\0" (6.1, the size of the C string literal).
    while (!text.empty() && (text.back() == '\n' || text.back() == '\0' || text.back() == ' ' ||
                             text.back() == '\t')) {
        text.pop_back();
    }
    return text;
}

Status writeAttr(const fs::path& path, std::string_view value) {
    const base::UniqueFd fd(::open(path.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC));
    if (!fd.isValid()) {
        const int err = errno;
        return makeError(codeOf(err), path.string() + ": cannot open to write " + quote(value) +
                                          ": " + drivers::base::errnoText(err));
    }
    const std::string line = std::string(value) + "\n";
    ssize_t n = 0;
    do {
        n = ::write(fd.get(), line.data(), line.size());
    } while (n < 0 && errno == EINTR);
    if (n != static_cast<ssize_t>(line.size())) {
        const int err = n < 0 ? errno : EIO;
        return makeError(codeOf(err), path.string() + ": cannot write " + quote(value) + ": " +
                                          drivers::base::errnoText(err));
    }
    return {};
}

// A sysfs attribute holding one number of type T (integer, or a finite real).
template <typename T>
Result<T> readNumericAttr(const fs::path& path, const char* what) {
    auto text = readAttr(path);
    if (!text) {
        return text.error();
    }
    T v = 0;
    const char* end = text->data() + text->size();
    const auto [ptr, ec] = std::from_chars(text->data(), end, v);
    bool ok = ec == std::errc() && ptr == end && !text->empty();
    if constexpr (std::is_floating_point_v<T>) {
        ok = ok && std::isfinite(v);
    }
    if (!ok) {
        return makeError(ErrorCode::kParse, path.string() + ": not " + what + ": " + quote(*text));
    }
    return v;
}

Result<int64_t> readIntAttr(const fs::path& path) {
    return readNumericAttr<int64_t>(path, "an integer");
}

Result<double> readNumberAttr(const fs::path& path) {
    return readNumericAttr<double>(path, "a number");
}

bool pathExists(const fs::path& path) {
    std::error_code ec;
    return fs::exists(path, ec) && !ec;
}

// The channel type of a channel name: its leading letters ("accel" of
// "accel_x", "voltage" of "voltage0").
std::string channelType(std::string_view name) {
    std::size_t n = 0;
    while (n < name.size() && name[n] >= 'a' && name[n] <= 'z') {
        ++n;
    }
    return std::string(name.substr(0, n));
}

// in_<ch>_<attr> or the shared in_<type>_<attr>; nullopt when neither exists.
std::optional<fs::path> channelAttr(const fs::path& dir, const std::string& ch,
                                    const std::string& attr) {
    fs::path own = dir / ("in_" + ch + "_" + attr);
    if (pathExists(own)) {
        return own;
    }
    const std::string type = channelType(ch);
    fs::path shared = dir / ("in_" + type + "_" + attr);
    if (!type.empty() && type != ch && pathExists(shared)) {
        return shared;
    }
    return std::nullopt;
}

bool startsWith(std::string_view s, std::string_view prefix) {
    return s.substr(0, prefix.size()) == prefix;
}
bool endsWith(std::string_view s, std::string_view suffix) {
    return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

std::vector<std::string> listDir(const fs::path& dir) {
    std::vector<std::string> out;
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec); !ec && it != fs::directory_iterator();
         it.increment(ec)) {
        out.push_back(it->path().filename().string());
    }
    std::sort(out.begin(), out.end());
    return out;
}

// N of "iio:deviceN", or nullopt.
std::optional<long> deviceNumber(std::string_view entry) {
    constexpr std::string_view kPrefix = "iio:device";
    if (!startsWith(entry, kPrefix) || entry.size() == kPrefix.size()) {
        return std::nullopt;
    }
    long n = 0;
    const char* begin = entry.data() + kPrefix.size();
    const char* end = entry.data() + entry.size();
    const auto [ptr, ec] = std::from_chars(begin, end, n);
    if (ec != std::errc() || ptr != end) {
        return std::nullopt;
    }
    return n;
}

Result<fs::path> findDevice(std::string_view spec, const IioOptions& options) {
    if (spec.empty()) {
        return makeError(ErrorCode::kInvalidArgument, "IIO device: empty name");
    }
    if (spec.find('/') != std::string_view::npos) {
        const fs::path p(spec);
        const std::string base = p.filename().string();
        if (deviceNumber(base)) {
            // /dev/iio:deviceN or /sys/bus/iio/devices/iio:deviceN.
            const fs::path dir = pathExists(p / "name") ? p : options.sysfs_root / base;
            if (!pathExists(dir / "name")) {
                return makeError(ErrorCode::kNotFound, std::string(spec) + ": no IIO device (no " +
                                                           (dir / "name").string() + ")");
            }
            return dir;
        }
        if (pathExists(p / "name")) {
            return p;
        }
        return makeError(ErrorCode::kNotFound,
                         std::string(spec) +
                             ": not an IIO device (neither iio:deviceN nor a directory with a "
                             "`name` file)");
    }
    if (!pathExists(options.sysfs_root)) {
        return makeError(ErrorCode::kNotFound, "no IIO devices: " + options.sysfs_root.string() +
                                                   " does not exist (kernel without IIO?)");
    }
    if (deviceNumber(spec)) {
        const fs::path dir = options.sysfs_root / std::string(spec);
        if (pathExists(dir / "name")) {
            return dir;
        }
    }
    std::optional<long> best;
    fs::path best_dir;
    std::string seen;
    for (const std::string& entry : listDir(options.sysfs_root)) {
        const auto n = deviceNumber(entry);
        if (!n) {
            continue;
        }
        auto name = readAttr(options.sysfs_root / entry / "name");
        const std::string shown = name ? *name : std::string("?");
        seen.append(seen.empty() ? "" : ", ").append(entry).append(" [").append(shown).append("]");
        if (name && *name == spec && (!best || *n < *best)) {
            best = n;
            best_dir = options.sysfs_root / entry;
        }
    }
    if (!best) {
        return makeError(
            ErrorCode::kNotFound,
            "no IIO device named '" + std::string(spec) + "' in " + options.sysfs_root.string() +
                (seen.empty() ? std::string(" (no devices)") : " (devices: " + seen + ")"));
    }
    return best_dir;
}

// The channel names of a device: in_<ch>_raw files and scan elements
// (in_<ch>_en), sorted, each once.
std::vector<std::string> channelNames(const fs::path& dir) {
    std::vector<std::string> names;
    for (const std::string& entry : listDir(dir)) {
        if (startsWith(entry, "in_") && endsWith(entry, "_raw") && entry.size() > 7) {
            names.push_back(entry.substr(3, entry.size() - 7));
        }
    }
    const fs::path scan_dir = dir / "scan_elements";
    for (const std::string& entry : listDir(scan_dir)) {
        if (startsWith(entry, "in_") && endsWith(entry, "_en") && entry.size() > 6) {
            names.push_back(entry.substr(3, entry.size() - 6));
        }
    }
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    return names;
}

// A channel's scale and offset (its own attributes or its type's shared ones).
core::Status readScaleAndOffset(const fs::path& dir, const std::string& ch, IioChannel& c) {
    if (auto p = channelAttr(dir, ch, "scale")) {
        auto v = readNumberAttr(*p);
        if (!v) {
            return v.error();
        }
        c.scale = *v;
        c.has_scale = true;
    }
    if (auto p = channelAttr(dir, ch, "offset")) {
        auto v = readNumberAttr(*p);
        if (!v) {
            return v.error();
        }
        c.offset = *v;
    }
    return {};
}

// A scan element's index and type (scan_elements/in_<ch>_index, _type).
core::Status readScanElement(const fs::path& scan_dir, const std::string& ch, IioChannel& c) {
    const fs::path index_file = scan_dir / ("in_" + ch + "_index");
    auto index = readIntAttr(index_file);
    if (!index) {
        return index.error();
    }
    if (*index < 0 || *index > 1'000'000) {
        return makeError(ErrorCode::kParse, index_file.string() + ": index out of range: " +
                                                quote(std::to_string(*index)));
    }
    const fs::path type_file = scan_dir / ("in_" + ch + "_type");
    auto type_text = readAttr(type_file);
    if (!type_text) {
        return type_text.error();
    }
    auto type = parseIioScanType(*type_text);
    if (!type) {
        return makeError(ErrorCode::kParse, type_file.string() + ": " + type.error().message);
    }
    c.scan_index = static_cast<int>(*index);
    c.scan_type = *type;
    return {};
}

// One channel of the device in `dir`: raw file, scale, offset, scan element.
Result<IioChannel> readChannelInfo(const fs::path& dir, const std::string& ch) {
    IioChannel c;
    c.name = ch;
    c.has_raw = pathExists(dir / ("in_" + ch + "_raw"));
    if (ch != "timestamp") {
        if (auto ok = readScaleAndOffset(dir, ch, c); !ok) {
            return ok.error();
        }
    }
    const fs::path scan_dir = dir / "scan_elements";
    if (pathExists(scan_dir / ("in_" + ch + "_en"))) {
        if (auto ok = readScanElement(scan_dir, ch, c); !ok) {
            return ok.error();
        }
    }
    return c;
}

// Sets current_timestamp_clock to `wanted` (a clock name) unless it already is.
Result<clockid_t> setTimestampClock(const fs::path& clock_file, const std::string& wanted) {
    const auto id = clockByName(wanted);
    if (!id) {
        std::string known;
        for (const ClockName& c : kClocks) {
            known += std::string(known.empty() ? "" : ", ") + c.name;
        }
        return makeError(ErrorCode::kInvalidArgument,
                         "IioOptions::timestamp_clock " + quote(wanted) + ": not one of " + known);
    }
    auto current = readAttr(clock_file);
    if (!current) {
        return current.error();
    }
    if (*current != wanted) {
        auto w = writeAttr(clock_file, wanted);
        if (!w) {
            return w.error();
        }
    }
    return *id;
}

// The clock current_timestamp_clock names.
Result<clockid_t> currentTimestampClock(const fs::path& clock_file) {
    auto current = readAttr(clock_file);
    if (!current) {
        return current.error();
    }
    const auto id = clockByName(*current);
    if (!id) {
        return makeError(ErrorCode::kParse,
                         clock_file.string() + ": unknown clock " + quote(*current));
    }
    return *id;
}

// The clock of the device's timestamps: set from options.timestamp_clock or
// read; CLOCK_REALTIME without a current_timestamp_clock file.
Result<clockid_t> timestampClock(const fs::path& dir, const IioOptions& options) {
    const fs::path clock_file = dir / "current_timestamp_clock";
    if (!pathExists(clock_file)) {
        return CLOCK_REALTIME;
    }
    if (!options.timestamp_clock.empty()) {
        return setTimestampClock(clock_file, options.timestamp_clock);
    }
    return currentTimestampClock(clock_file);
}

std::size_t alignUp(std::size_t v, std::size_t a) {
    return a == 0 ? v : (v + a - 1) / a * a;
}

constexpr std::array<const char*, 3> kAccel = {"accel_x", "accel_y", "accel_z"};
constexpr std::array<const char*, 3> kGyro = {"anglvel_x", "anglvel_y", "anglvel_z"};

}  // namespace

// --- scan types ---------------------------------------------------------------

Result<IioScanType> parseIioScanType(std::string_view text) {
    const auto bad = [&](const std::string& why) {
        return makeError(ErrorCode::kParse, "bad scan type " + quote(text) + " (" + why + ")");
    };
    IioScanType t;
    std::string_view s = text;
    if (startsWith(s, "le:")) {
        t.big_endian = false;
    } else if (startsWith(s, "be:")) {
        t.big_endian = true;
    } else {
        return bad("expected `le:` or `be:` first, as in le:s16/16>>0");
    }
    s.remove_prefix(3);
    if (s.empty() || (s.front() != 's' && s.front() != 'u')) {
        return bad("expected `s` or `u` after the byte order");
    }
    t.is_signed = s.front() == 's';
    s.remove_prefix(1);
    const auto number = [&](unsigned& out) -> bool {
        const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
        if (ec != std::errc() || ptr == s.data()) {
            return false;
        }
        s.remove_prefix(static_cast<std::size_t>(ptr - s.data()));
        return true;
    };
    if (!number(t.real_bits)) {
        return bad("expected the real bits after the sign");
    }
    if (s.empty() || s.front() != '/') {
        return bad("expected `/STORAGE` after the real bits");
    }
    s.remove_prefix(1);
    if (!number(t.storage_bits)) {
        return bad("expected the storage bits after `/`");
    }
    if (!s.empty() && s.front() == 'X') {
        s.remove_prefix(1);
        if (!number(t.repeat) || t.repeat == 0) {
            return bad("expected a repeat count >= 1 after `X`");
        }
    }
    if (!startsWith(s, ">>")) {
        return bad("expected `>>SHIFT` after the storage bits");
    }
    s.remove_prefix(2);
    if (!number(t.shift) || !s.empty()) {
        return bad("expected the shift to end the type");
    }
    if (t.storage_bits != 8 && t.storage_bits != 16 && t.storage_bits != 32 &&
        t.storage_bits != 64) {
        return bad("storage bits must be 8, 16, 32 or 64");
    }
    if (t.real_bits == 0 || t.real_bits + t.shift > t.storage_bits) {
        return bad("real bits + shift exceed the storage bits");
    }
    return t;
}

int64_t decodeIioElement(std::span<const uint8_t> bytes, const IioScanType& type) {
    const std::size_t n = std::min<std::size_t>(bytes.size(), type.storage_bits / 8U);
    uint64_t v = 0;
    for (std::size_t k = 0; k < n; ++k) {
        const uint64_t b = bytes[type.big_endian ? k : n - 1 - k];
        v = (v << 8U) | b;
    }
    v >>= type.shift;
    if (type.real_bits < 64) {
        const uint64_t mask = (uint64_t{1} << type.real_bits) - 1;
        v &= mask;
        if (type.is_signed && (v & (uint64_t{1} << (type.real_bits - 1))) != 0) {
            v |= ~mask;  // sign extension
        }
    }
    // Two's complement reinterpretation (well defined since C++20).
    return static_cast<int64_t>(v);
}

// --- the device -----------------------------------------------------------------

IioDevice::IioDevice(IioDevice&& other) noexcept = default;

IioDevice& IioDevice::operator=(IioDevice&& other) noexcept {
    if (this != &other) {
        (void)stopBuffer();
        name_ = std::move(other.name_);
        sysfs_dir_ = std::move(other.sysfs_dir_);
        dev_path_ = std::move(other.dev_path_);
        channels_ = std::move(other.channels_);
        clock_id_ = other.clock_id_;
        fd_ = std::move(other.fd_);
        elements_ = std::move(other.elements_);
        buffer_names_ = std::move(other.buffer_names_);
        scan_bytes_ = other.scan_bytes_;
        timestamp_element_ = other.timestamp_element_;
        pending_ = std::move(other.pending_);
    }
    return *this;
}

IioDevice::~IioDevice() {
    (void)stopBuffer();
}

Result<IioDevice> IioDevice::open(std::string_view name_or_path, const IioOptions& options) {
    auto dir = findDevice(name_or_path, options);
    if (!dir) {
        return dir.error();
    }
    IioDevice dev;
    dev.sysfs_dir_ = *dir;
    dev.dev_path_ = options.dev_root / dir->filename();
    auto name = readAttr(*dir / "name");
    if (!name) {
        return name.error();
    }
    dev.name_ = *name;

    // The channels: in_<ch>_raw files and scan elements.
    for (const std::string& ch : channelNames(*dir)) {
        auto c = readChannelInfo(*dir, ch);
        if (!c) {
            return c.error();
        }
        dev.channels_.push_back(std::move(*c));
    }

    // The timestamp clock (see the header).
    auto clock = timestampClock(*dir, options);
    if (!clock) {
        return clock.error();
    }
    dev.clock_id_ = *clock;
    return dev;
}

const IioChannel* IioDevice::channel(std::string_view name) const {
    for (const IioChannel& c : channels_) {
        if (c.name == name) {
            return &c;
        }
    }
    return nullptr;
}

bool IioDevice::hasAccel() const {
    return std::all_of(kAccel.begin(), kAccel.end(), [&](const char* n) {
        const IioChannel* c = channel(n);
        return c != nullptr && c->has_raw;
    });
}

bool IioDevice::hasGyro() const {
    return std::all_of(kGyro.begin(), kGyro.end(), [&](const char* n) {
        const IioChannel* c = channel(n);
        return c != nullptr && c->has_raw;
    });
}

std::string IioDevice::describe() const {
    std::string out = sysfs_dir_.filename().string() + " [" + name_ + "]:";
    for (const IioChannel& c : channels_) {
        out += " " + c.name;
    }
    return out;
}

Result<double> IioDevice::readChannel(std::string_view name) const {
    const IioChannel* c = channel(name);
    const fs::path raw_file = sysfs_dir_ / ("in_" + std::string(name) + "_raw");
    if (c == nullptr || !c->has_raw) {
        return makeError(ErrorCode::kNotFound, describe() + ": no channel " + quote(name) +
                                                   " to read (no " + raw_file.string() + ")");
    }
    auto raw = readIntAttr(raw_file);
    if (!raw) {
        return raw.error();
    }
    return (static_cast<double>(*raw) + c->offset) * c->scale;
}

Result<core::ImuSample> IioDevice::readOnce() const {
    if (!hasAccel()) {
        std::string missing;
        for (const char* n : kAccel) {
            const IioChannel* c = channel(n);
            if (c == nullptr || !c->has_raw) {
                missing += (missing.empty() ? "" : ", ") +
                           (sysfs_dir_ / ("in_" + std::string(n) + "_raw")).string();
            }
        }
        return makeError(ErrorCode::kNotFound,
                         describe() + ": not a 3-axis accelerometer: no " + missing);
    }
    core::ImuSample s;
    s.t_ns = nowNs(clock_id_);
    for (std::size_t k = 0; k < 3; ++k) {
        auto v = readChannel(kAccel[k]);
        if (!v) {
            return v.error();
        }
        s.accel_mps2[static_cast<Eigen::Index>(k)] = static_cast<core::Scalar>(*v);
    }
    if (hasGyro()) {
        core::Vec3 w = core::Vec3::Zero();
        for (std::size_t k = 0; k < 3; ++k) {
            auto v = readChannel(kGyro[k]);
            if (!v) {
                return v.error();
            }
            w[static_cast<Eigen::Index>(k)] = static_cast<core::Scalar>(*v);
        }
        s.gyro_radps = w;
    }
    return s;
}

core::Status IioDevice::checkBufferFree(const fs::path& enable_file, unsigned length) const {
    if (bufferRunning()) {
        return makeError(ErrorCode::kInvalidArgument,
                         describe() + ": the buffer is already running");
    }
    if (!pathExists(enable_file)) {
        return makeError(ErrorCode::kNotFound, describe() + ": no buffer (no " +
                                                   enable_file.string() +
                                                   "): read it through sysfs (readOnce)");
    }
    auto enabled = readAttr(enable_file);
    if (!enabled) {
        return enabled.error();
    }
    if (*enabled != "0") {
        return makeError(ErrorCode::kUnavailable, enable_file.string() + " is " + quote(*enabled) +
                                                      ": the buffer is in use (another reader?)");
    }
    if (length == 0) {
        return makeError(ErrorCode::kInvalidArgument, describe() + ": buffer length 0");
    }
    return {};
}

void IioDevice::addDefaultBufferChannels(std::vector<std::string>& wanted) const {
    const auto buffered = [&](const char* n) {
        const IioChannel* c = channel(n);
        return c != nullptr && c->scan_index.has_value();
    };
    for (const char* n : kAccel) {
        wanted.emplace_back(n);
    }
    if (std::all_of(kGyro.begin(), kGyro.end(), buffered)) {
        for (const char* n : kGyro) {
            wanted.emplace_back(n);
        }
    }
    if (buffered("timestamp")) {
        wanted.emplace_back("timestamp");
    }
}

Result<std::vector<std::size_t>> IioDevice::chooseBufferChannels(
    const std::vector<std::string>& wanted) const {
    std::vector<std::size_t> chosen;
    for (const std::string& n : wanted) {
        const IioChannel* c = channel(n);
        if (c == nullptr || !c->scan_index) {
            return makeError(ErrorCode::kNotFound,
                             describe() + ": channel " + quote(n) + " cannot be buffered (no " +
                                 (sysfs_dir_ / "scan_elements" / ("in_" + n + "_en")).string() +
                                 ")");
        }
        const auto idx = static_cast<std::size_t>(c - channels_.data());
        if (std::find(chosen.begin(), chosen.end(), idx) == chosen.end()) {
            chosen.push_back(idx);
        }
        if (c->scan_type->repeat != 1) {
            return makeError(ErrorCode::kInvalidArgument,
                             (sysfs_dir_ / "scan_elements" / ("in_" + n + "_type")).string() +
                                 ": repeated elements (X" + std::to_string(c->scan_type->repeat) +
                                 ") are not supported");
        }
    }
    std::sort(chosen.begin(), chosen.end(), [&](std::size_t a, std::size_t b) {
        return *channels_[a].scan_index < *channels_[b].scan_index;
    });
    return chosen;
}

core::Status IioDevice::enableScanElements(const std::vector<std::size_t>& chosen) const {
    for (std::size_t i = 0; i < channels_.size(); ++i) {
        if (!channels_[i].scan_index) {
            continue;
        }
        const bool on = std::find(chosen.begin(), chosen.end(), i) != chosen.end();
        auto w = writeAttr(sysfs_dir_ / "scan_elements" / ("in_" + channels_[i].name + "_en"),
                           on ? "1" : "0");
        if (!w) {
            return w.error();
        }
    }
    return {};
}

void IioDevice::layOutScan(const std::vector<std::size_t>& chosen) {
    elements_.clear();
    buffer_names_.clear();
    timestamp_element_.reset();
    std::size_t offset = 0;
    std::size_t largest = 1;
    for (const std::size_t i : chosen) {
        const std::size_t bytes = channels_[i].scan_type->storage_bits / 8U;
        offset = alignUp(offset, bytes);
        if (channels_[i].name == "timestamp") {
            timestamp_element_ = elements_.size();
        }
        elements_.push_back(Element{i, offset, bytes});
        buffer_names_.push_back(channels_[i].name);
        offset += bytes;
        largest = std::max(largest, bytes);
    }
    scan_bytes_ = alignUp(offset, largest);
}

core::Status IioDevice::writeTriggerAndLength(const IioBufferOptions& options) const {
    if (!options.trigger.empty()) {
        const fs::path trigger_file = sysfs_dir_ / "trigger" / "current_trigger";
        if (!pathExists(trigger_file)) {
            return makeError(ErrorCode::kInvalidArgument, describe() + ": cannot use trigger " +
                                                              quote(options.trigger) + ": no " +
                                                              trigger_file.string());
        }
        auto w = writeAttr(trigger_file, options.trigger);
        if (!w) {
            return w.error();
        }
    }
    if (auto w = writeAttr(sysfs_dir_ / "buffer" / "length", std::to_string(options.length)); !w) {
        return w.error();
    }
    return {};
}

core::Error IioDevice::explainEnableRefused(core::Error e) const {
    if (e.message.find(drivers::base::errnoText(EINVAL)) != std::string::npos) {
        const fs::path trigger_file = sysfs_dir_ / "trigger" / "current_trigger";
        auto current = readAttr(trigger_file);
        e.message += current && current->empty()
                         ? " (no trigger is set in " + trigger_file.string() +
                               ": name one in IioBufferOptions::trigger)"
                         : std::string(
                               " (the device refused this set of channels or its "
                               "trigger)");
    }
    return e;
}

Status IioDevice::startBuffer(const IioBufferOptions& options) {
    const fs::path enable_file = sysfs_dir_ / "buffer" / "enable";
    if (auto ok = checkBufferFree(enable_file, options.length); !ok) {
        return ok.error();
    }

    // The channels to capture.
    std::vector<std::string> wanted = options.channels;
    if (wanted.empty()) {
        addDefaultBufferChannels(wanted);
    }
    auto chosen = chooseBufferChannels(wanted);
    if (!chosen) {
        return chosen.error();
    }

    // Scan elements on or off.
    if (auto ok = enableScanElements(*chosen); !ok) {
        return ok.error();
    }
    // The layout: each element aligned to its size, the scan to the largest.
    layOutScan(*chosen);

    if (auto ok = writeTriggerAndLength(options); !ok) {
        return ok.error();
    }
    base::UniqueFd fd(::open(dev_path_.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC));
    if (!fd.isValid()) {
        const int err = errno;
        return makeError(codeOf(err),
                         dev_path_.string() + ": cannot open: " + drivers::base::errnoText(err));
    }
    if (auto w = writeAttr(enable_file, "1"); !w) {
        return explainEnableRefused(w.error());
    }
    fd_ = std::move(fd);
    pending_.clear();
    return {};
}

Result<std::vector<IioScan>> IioDevice::readScans(std::size_t max_scans, int timeout_ms) {
    if (!bufferRunning()) {
        return makeError(ErrorCode::kInvalidArgument,
                         describe() + ": the buffer is not running (startBuffer first)");
    }
    std::vector<IioScan> out;
    if (max_scans == 0 || scan_bytes_ == 0) {
        return out;
    }
    max_scans = std::min<std::size_t>(max_scans, kMaxScansPerRead);
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(std::max(timeout_ms, 0));
    std::vector<uint8_t> buf(max_scans * scan_bytes_);
    while (out.empty()) {
        int wait_ms = -1;
        if (timeout_ms >= 0) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                deadline - std::chrono::steady_clock::now());
            wait_ms = static_cast<int>(std::max<int64_t>(left.count(), 0));
        }
        pollfd p{fd_.get(), POLLIN, 0};
        const int rc = ::poll(&p, 1, wait_ms);
        if (rc < 0) {
            if (errno == EINTR) {
                continue;
            }
            const int err = errno;
            return makeError(codeOf(err),
                             dev_path_.string() + ": poll: " + drivers::base::errnoText(err));
        }
        if (rc == 0) {
            return out;  // nothing in time
        }
        if ((p.revents & POLLIN) == 0) {
            return makeError(ErrorCode::kUnavailable,
                             dev_path_.string() + ": the device reported an error or hang-up");
        }
        const std::size_t want = buf.size() - std::min(buf.size(), pending_.size());
        const ssize_t n = ::read(fd_.get(), buf.data(), std::max<std::size_t>(want, 1));
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN) {
                continue;
            }
            const int err = errno;
            return makeError(codeOf(err), dev_path_.string() +
                                              ": cannot read: " + drivers::base::errnoText(err));
        }
        if (n == 0) {
            return makeError(ErrorCode::kUnavailable, dev_path_.string() + ": end of data");
        }
        pending_.insert(pending_.end(), buf.begin(), buf.begin() + n);
        const std::size_t whole = pending_.size() / scan_bytes_;
        const int64_t read_ns = nowNs(clock_id_);
        for (std::size_t s = 0; s < whole; ++s) {
            const std::span<const uint8_t> scan(pending_.data() + s * scan_bytes_, scan_bytes_);
            IioScan d;
            d.raw.reserve(elements_.size());
            d.value.reserve(elements_.size());
            for (const Element& e : elements_) {
                const IioChannel& c = channels_[e.channel];
                const int64_t raw = decodeIioElement(scan.subspan(e.offset, e.bytes), *c.scan_type);
                d.raw.push_back(raw);
                d.value.push_back((static_cast<double>(raw) + c.offset) * c.scale);
            }
            d.t_ns = timestamp_element_ ? d.raw[*timestamp_element_] : read_ns;
            out.push_back(std::move(d));
        }
        pending_.erase(pending_.begin(),
                       pending_.begin() + static_cast<std::ptrdiff_t>(whole * scan_bytes_));
    }
    return out;
}

Result<std::vector<core::ImuSample>> IioDevice::readSamples(std::size_t max_samples,
                                                            int timeout_ms) {
    const auto position = [&](const char* n) -> std::optional<std::size_t> {
        const auto it = std::find(buffer_names_.begin(), buffer_names_.end(), n);
        if (it == buffer_names_.end()) {
            return std::nullopt;
        }
        return static_cast<std::size_t>(it - buffer_names_.begin());
    };
    std::array<std::size_t, 3> accel{};
    for (std::size_t k = 0; k < 3; ++k) {
        const auto p = position(kAccel[k]);
        if (!p) {
            return makeError(ErrorCode::kInvalidArgument, describe() + ": " + kAccel[k] +
                                                              " is not buffered (startBuffer with "
                                                              "accel_x, accel_y and accel_z)");
        }
        accel[k] = *p;
    }
    std::array<std::optional<std::size_t>, 3> gyro = {position(kGyro[0]), position(kGyro[1]),
                                                      position(kGyro[2])};
    const bool has_gyro = gyro[0] && gyro[1] && gyro[2];
    auto scans = readScans(max_samples, timeout_ms);
    if (!scans) {
        return scans.error();
    }
    std::vector<core::ImuSample> out;
    out.reserve(scans->size());
    for (const IioScan& scan : *scans) {
        core::ImuSample s;
        s.t_ns = scan.t_ns;
        for (std::size_t k = 0; k < 3; ++k) {
            s.accel_mps2[static_cast<Eigen::Index>(k)] =
                static_cast<core::Scalar>(scan.value[accel[k]]);
        }
        if (has_gyro) {
            core::Vec3 w = core::Vec3::Zero();
            for (std::size_t k = 0; k < 3; ++k) {
                w[static_cast<Eigen::Index>(k)] = static_cast<core::Scalar>(scan.value[*gyro[k]]);
            }
            s.gyro_radps = w;
        }
        out.push_back(s);
    }
    return out;
}

Result<bool> IioDevice::stopBuffer() {
    if (!bufferRunning()) {
        return false;
    }
    auto w = writeAttr(sysfs_dir_ / "buffer" / "enable", "0");
    fd_.reset();
    pending_.clear();
    if (!w) {
        return w.error();
    }
    return true;
}

}  // namespace scaled::drivers::imu
