#pragma once

// The daemon's whole configuration: the pipeline (pipeline_config.h: tracker,
// detector, detection schedule, estimator) plus the source, the socket, the
// field log and the queues. One TOML file (config/scaled.toml documents every
// key, installed as /etc/scaled/scaled.toml); the command line overrides it.
//
// Every key is checked like the pipeline's: a wrong type, a value outside its
// range or an unknown key/section is an Error reading
// `FILE:LINE: section.key: what is wrong (allowed range) (got VALUE)`.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/base/log.h>
#include <scaled/drivers/camera/camera.h>
#include <scaled/drivers/source/paced_source.h>

namespace scaled::daemon {

enum class SourceKind : std::uint8_t { kSim, kReplay, kV4l2, kLibcamera };
const char* toString(SourceKind kind);

// What a replay does at the end of its sequence.
enum class AtEnd : std::uint8_t {
    kStay,  // keep serving the last scale (source_finished in STATUS)
    kExit,  // stop the daemon cleanly (exit code 0): tests, batch runs
    kLoop,  // start over (a new map, a new epoch)
};

// [source]
struct SourceConfig {
    SourceKind kind = SourceKind::kSim;
    std::filesystem::path replay_path;  // kReplay: dataset directory or video file
    std::string device;                 // kV4l2: /dev/videoN or card name; kLibcamera: id/index
    drivers::source::PacingMode pacing = drivers::source::PacingMode::kRealTime;  // replay and sim
    double speed = 1.0;  // real time: playback speed
    AtEnd at_end = AtEnd::kStay;
    std::int64_t max_frames = 0;  // stop the source after this many frames (0: no limit)
    // kSim: the synthetic room (drivers/sim).
    std::uint64_t sim_seed = 1;
    double sim_fps = 30.0;
    int sim_width_px = 320;
    int sim_height_px = 240;
};

// [camera]: the v4l2 and libcamera sources.
struct CameraConfig {
    int width_px = 640;
    int height_px = 480;
    double fps = 30.0;
    drivers::camera::PixelFormat pixel_format = drivers::camera::PixelFormat::kAuto;  // v4l2 only
    int buffers = 4;               // mmap buffers / requests in flight, 2..32
    double frame_timeout_s = 2.0;  // no frame this long: fault, reopen
    // A buffer repeating the previous one's pixels is dropped, not tracked
    // (a grabber or loopback faster than its source); v4l2 only.
    bool drop_repeated_frames = false;
    double retry_initial_s = 0.5;  // first wait before reopening a lost camera
    double retry_max_s = 5.0;      // the wait doubles up to this
    // Calibration of the camera at width_px x height_px (pixels). A live source
    // needs fx_px > 0 (there is no silent guess); k1, k2: radial distortion.
    double fx_px = 0;
    double fy_px = 0;
    double cx_px = 0;
    double cy_px = 0;
    double k1 = 0;
    double k2 = 0;
};

// [gpio]: the status LEDs (status_lights.h).
struct GpioConfig {
    std::string chip;                 // path, name or label; empty: no LEDs
    int status_line = -1;             // line offset of the status LED; -1: none
    int heartbeat_line = -1;          // line offset of the heartbeat LED; -1: none
    bool active_low = false;          // the LEDs light when the line is low
    std::string consumer = "scaled";  // label shown by gpioinfo
};

// [imu]: the accelerometer that gives a new map its vertical (docs/imu.md),
// read through Linux IIO by the daemon's IMU thread (imu_service.h).
enum class ImuMode : std::uint8_t {
    kSysfs,   // one value per channel read (in_accel_*_raw), polled at rate_hz
    kBuffer,  // the buffered character device /dev/iio:deviceN (scan elements)
};

struct ImuConfig {
    std::string device;  // IIO name ("mpu6050"), "iio:deviceN" or a path; empty: no IMU
    ImuMode mode = ImuMode::kSysfs;
    // kSysfs: the polling rate. kBuffer: the rate the device's trigger gives
    // (it sizes the sample ring only).
    double rate_hz = 100;
    std::string trigger;      // kBuffer: written to trigger/current_trigger when not empty
    int buffer_length = 128;  // kBuffer: buffer/length, in scans
    // R_ItoC, row-major: rotates IMU-frame vectors into the camera's optical
    // frame (x right, y down, z forward). A proper rotation (checked).
    std::array<double, 9> rotation_imu_to_camera = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    // The accelerometer average before a map starts (core::estimateGravityDown).
    double window_s = 0.5;
};
const char* toString(ImuMode mode);

// [socket]
struct SocketConfig {
    std::filesystem::path path = "/run/scaled/scaled.sock";
    unsigned mode = 0660;  // file mode of the socket
    std::string group;     // owning group; empty: the process's group
    int max_clients = 16;  // connections at once, and watchers at most
    // Beyond max_clients a connection is still accepted while fewer than this
    // many connected clients do not watch (a status or poll gets in when
    // max_clients watch).
    int reserved_query_slots = 2;
    std::size_t max_request_bytes = 4096;  // a longer line is an ERROR (and discarded)
    double request_timeout_s = 5;          // an incomplete request line this old: ERROR, closed
    // Unsent output per client: reading from it pauses above 1/2 of this and
    // resumes at 1/4; SCALE/POSE lines that would exceed it detach the client.
    std::size_t client_buffer_bytes = 262144;
    double stall_timeout_s = 10;  // output waiting and none of it read this long: detached
    double pose_rate_hz = 30;  // POSE lines to watchers per second of frame time (0: every frame)
};

// [log]
struct LogConfig {
    bool enabled = true;
    std::filesystem::path dir = "/var/log/scaled";
    int frame_every = 30;  // per-frame summary every N tracked frames (0: none)
    // POSE lines per second of frame time (PoseRateLimiter; 0: none).
    double pose_rate_hz = 10;
    std::uint64_t max_file_bytes = 8u << 20;    // rotate after this size
    std::uint64_t max_total_bytes = 64u << 20;  // delete the oldest files above this total
    int fsync_interval_ms = 1000;               // flush + fsync at most this often
    std::size_t queue_bytes = 1u << 20;         // in-memory queue; full: lines dropped and counted
    // The daemon's messages on stderr (the journal under systemd), not the
    // field log: error, warning, info or debug (--verbose).
    drivers::base::LogLevel level = drivers::base::LogLevel::kInfo;
};

// [pipeline]
struct QueueConfig {
    int capture_queue_frames = 4;   // frames between capture and tracking
    int status_interval_ms = 1000;  // STATUS= to systemd, live status line refresh
};

struct DaemonConfig {
    PipelineConfig pipeline = defaultPipelineConfig();
    SourceConfig source;
    CameraConfig camera;
    GpioConfig gpio;
    ImuConfig imu;
    SocketConfig socket;
    LogConfig log;
    QueueConfig queues;
    // The file the configuration came from (empty: built-in defaults); SIGHUP re-reads it.
    std::filesystem::path file;
};

// defaultPipelineConfig() plus the installed paths (a /usr prefix):
// detector.model /usr/share/scaled/models/yolox_nano.onnx, estimator.priors
// /etc/scaled/priors.toml. config/scaled.toml states exactly these values.
DaemonConfig defaultDaemonConfig();

// Applies TOML text / a file (relative paths against the file's directory;
// applyDaemonFile also sets `file` to the file's absolute path). Cross-field
// checks (source.kind "replay" needs source.replay, "v4l2" and "libcamera"
// need source.device, log.max_total_bytes >= log.max_file_bytes, ...) are
// reported at the line of the key or of the key it depends on.
// On error `config` is unchanged.
core::Status applyDaemonToml(std::string_view toml_text, std::string_view source_name,
                             const std::filesystem::path& base_dir, DaemonConfig& config);
core::Status applyDaemonFile(const std::filesystem::path& path, DaemonConfig& config);
// `section.key=value` overrides (the pipeline's and the daemon's sections),
// cross-field checks after all of them; errors name the `--set` to blame.
core::Status applyDaemonOverrides(const std::vector<std::string>& assignments,
                                  DaemonConfig& config);
// Every key as `section.key`, in file order.
std::vector<std::string> daemonConfigKeys();
// The configuration as TOML (every key).
std::string toToml(const DaemonConfig& config);

// `--source` values: sim | replay:DIR | v4l2:DEVICE | libcamera:ID.
core::Status applySourceSpec(std::string_view spec, SourceConfig& source);

// The command line (CLI11). Everything optional overrides the file.
struct CommandLine {
    std::optional<std::filesystem::path> config;   // --config FILE
    std::optional<std::string> source;             // --source SPEC
    std::optional<std::filesystem::path> socket;   // --socket PATH
    std::optional<std::filesystem::path> log_dir;  // --log-dir DIR
    std::optional<std::string> pacing;             // --pacing realtime|fast
    std::vector<std::string> sets;                 // --set section.key=value (repeatable)
    bool no_tty = false;                           // --no-tty: no live status line
    bool verbose = false;                          // -v, --verbose: log.level = debug
    bool check_config = false;                     // --check-config [FILE]: validate and exit
    bool version = false;                          // --version
    bool list_cameras = false;                     // --list-cameras
};

// Outcome of parsing argv: run, or exit at once with `exit_code` after
// printing `output` (help, version) to stdout or `error` to stderr.
struct ParsedCommandLine {
    CommandLine cli;
    bool exit_now = false;
    int exit_code = 0;
    std::string output;
    std::string error;
};
ParsedCommandLine parseCommandLine(int argc, const char* const* argv);

// Builds the configuration: defaults, then the file (--config, else
// default_config_file when it exists), then --set, then the dedicated options.
// Errors name file, line, key and value; the caller exits 78 (EX_CONFIG).
core::Result<DaemonConfig> loadDaemonConfig(const CommandLine& cli,
                                            const std::filesystem::path& default_config_file);

// What `scaled --check-config` starts from: the configuration
// loadDaemonConfig would build, with every problem of the file and the
// command line instead of the first (all of them, each
// `FILE:LINE: section.key: what (got VALUE)`). `error_keys[i]` is the key
// errors[i] is about; `locate` gives where a key was set (`FILE:LINE`,
// `--set ...`, or the file or "built-in defaults" when nothing set it), for
// the checks of files and devices that follow (config_check.h).
struct CheckedConfig {
    DaemonConfig config;
    std::vector<core::Error> errors;
    std::vector<std::string> error_keys;
    std::function<std::string(const std::vector<std::string>& keys)> locate;
};
CheckedConfig checkDaemonConfig(const CommandLine& cli,
                                const std::filesystem::path& default_config_file);

}  // namespace scaled::daemon
