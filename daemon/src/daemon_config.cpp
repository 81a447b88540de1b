// The daemon's configuration: the pipeline's sections plus [source] [socket]
// [log] [pipeline], one field registry (config_registry.h), and the command
// line (CLI11; its exceptions stay in parseCommandLine).

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <toml++/toml.h>

#include <scaled/core/geometry/gravity.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/version.h>
#include <scaled/drivers/priors/toml_read.h>

#include "config_registry.h"

namespace scaled::daemon {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;
using drivers::priors::tomlread::show;

namespace {

using config_detail::Bound;
using config_detail::Field;
using config_detail::Locator;

constexpr std::int64_t kMaxInt = std::numeric_limits<std::int64_t>::max();
constexpr unsigned kMaxMode = 0777;
constexpr unsigned kWorldWrite = 0002;
constexpr unsigned kOwnerReadWrite = 0600;
// sockaddr_un::sun_path is 108 bytes with the terminating NUL.
constexpr std::size_t kMaxSocketPathBytes = 107;

// The installed layout (a /usr prefix): config/scaled.toml states the same.
constexpr const char* kDefaultModel = "/usr/share/scaled/models/yolox_nano.onnx";
constexpr const char* kDefaultPriors = "/etc/scaled/priors.toml";

std::string octal(unsigned mode) {
    char buf[8];
    std::snprintf(buf, sizeof buf, "%04o", mode);
    return buf;
}

// socket.mode: "0660" (octal digits) or an integer (0o660 in TOML).
Field socketMode(unsigned* target) {
    return {"socket", "mode",
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                const std::string expected =
                    "must be an octal mode like \"0660\" (a string of octal digits, or an "
                    "integer such as 0o660) in [0000, 0777]";
                std::int64_t mode = -1;
                if (const auto* s = n.as_string()) {
                    const std::string& digits = s->get();
                    if (!digits.empty() && digits.size() <= 4 &&
                        digits.find_first_not_of("01234567") == std::string::npos) {
                        mode = std::stoll(digits, nullptr, 8);
                    }
                } else if (const auto* i = n.as_integer()) {
                    mode = i->get();
                }
                if (mode < 0 || mode > kMaxMode) {
                    return expected + " (got " + show(n) + ")";
                }
                const auto m = static_cast<unsigned>(mode);
                if ((m & kWorldWrite) != 0) {
                    return "must not let others write (no o+w bit, e.g. \"0660\") (got \"" +
                           octal(m) + "\")";
                }
                if ((m & kOwnerReadWrite) != kOwnerReadWrite) {
                    return "must give the owner read and write (0600) (got \"" + octal(m) + "\")";
                }
                *target = m;
                return std::nullopt;
            },
            [=] { return "\"" + octal(*target) + "\""; }};
}

// imu.rotation_imu_to_camera: a proper rotation, by core's test (the one
// estimateGravityDown applies); the message says which part fails.
std::optional<std::string> rotationProblem(const std::array<double, 9>& r) {
    core::Mat3 R;
    for (Eigen::Index i = 0; i < 9; ++i) {
        R(i / 3, i % 3) = static_cast<core::Scalar>(r[static_cast<std::size_t>(i)]);
    }
    const core::RotationDefect d = core::rotationDefect(R);
    if (!(d.orthogonality <= core::kRotationTolerance)) {
        return "must be a rotation, row-major (orthonormal rows: max |R^T R - I| <= " +
               drivers::priors::tomlread::num(core::kRotationTolerance) +
               ") (got max |R^T R - I| = " + drivers::priors::tomlread::num(d.orthogonality) + ")";
    }
    if (!core::isRotation(d)) {
        return "must be a rotation, row-major (determinant +1, not a reflection) (got det = " +
               drivers::priors::tomlread::num(d.determinant) + ")";
    }
    return std::nullopt;
}

// [source]
std::vector<Field> sourceFields(SourceConfig& s) {
    using config_detail::choice;
    using config_detail::integer;
    using config_detail::path;
    using config_detail::real;
    using config_detail::text;
    return {
        choice("source", "kind", &s.kind,
               {{"sim", SourceKind::kSim},
                {"replay", SourceKind::kReplay},
                {"v4l2", SourceKind::kV4l2},
                {"libcamera", SourceKind::kLibcamera}}),
        path("source", "replay", &s.replay_path),
        text("source", "device", &s.device),
        choice("source", "pacing", &s.pacing,
               {{"realtime", drivers::source::PacingMode::kRealTime},
                {"fast", drivers::source::PacingMode::kAsFastAsPossible}}),
        real("source", "speed", &s.speed, 0, 1000, Bound::kOpen),
        choice("source", "at_end", &s.at_end,
               {{"stay", AtEnd::kStay}, {"exit", AtEnd::kExit}, {"loop", AtEnd::kLoop}}),
        integer("source", "max_frames", &s.max_frames, 0, kMaxInt),
        integer("source", "sim_seed", &s.sim_seed, 0, kMaxInt),
        real("source", "sim_fps", &s.sim_fps, 0, 240, Bound::kOpen),
        integer("source", "sim_width_px", &s.sim_width_px, 16, 4096),
        integer("source", "sim_height_px", &s.sim_height_px, 16, 4096),
    };
}

// [camera]
std::vector<Field> cameraFields(CameraConfig& m) {
    using config_detail::boolean;
    using config_detail::choice;
    using config_detail::integer;
    using config_detail::real;
    return {
        integer("camera", "width_px", &m.width_px, 16, 8192),
        integer("camera", "height_px", &m.height_px, 16, 8192),
        real("camera", "fps", &m.fps, 0, 1000, Bound::kOpen),
        choice("camera", "pixel_format", &m.pixel_format,
               {{"auto", drivers::camera::PixelFormat::kAuto},
                {"YUYV", drivers::camera::PixelFormat::kYuyv},
                {"MJPEG", drivers::camera::PixelFormat::kMjpeg},
                {"GREY", drivers::camera::PixelFormat::kGrey},
                {"NV12", drivers::camera::PixelFormat::kNv12}}),
        integer("camera", "buffers", &m.buffers, 2, 32),
        real("camera", "frame_timeout_s", &m.frame_timeout_s, 0, 3600, Bound::kOpen),
        boolean("camera", "drop_repeated_frames", &m.drop_repeated_frames),
        real("camera", "retry_initial_s", &m.retry_initial_s, 0, 3600, Bound::kOpen),
        real("camera", "retry_max_s", &m.retry_max_s, 0, 3600, Bound::kOpen),
        real("camera", "fx_px", &m.fx_px, 0, 1e6),
        real("camera", "fy_px", &m.fy_px, 0, 1e6),
        real("camera", "cx_px", &m.cx_px, 0, 1e6),
        real("camera", "cy_px", &m.cy_px, 0, 1e6),
        real("camera", "k1", &m.k1, -10, 10),
        real("camera", "k2", &m.k2, -10, 10),
    };
}

// [gpio] and [imu]
std::vector<Field> deviceFields(GpioConfig& g, ImuConfig& u) {
    using config_detail::boolean;
    using config_detail::choice;
    using config_detail::integer;
    using config_detail::real;
    using config_detail::text;
    return {
        text("gpio", "chip", &g.chip),
        integer("gpio", "status_line", &g.status_line, -1, 4095),
        integer("gpio", "heartbeat_line", &g.heartbeat_line, -1, 4095),
        boolean("gpio", "active_low", &g.active_low),
        text("gpio", "consumer", &g.consumer),
        text("imu", "device", &u.device),
        choice("imu", "mode", &u.mode, {{"sysfs", ImuMode::kSysfs}, {"buffer", ImuMode::kBuffer}}),
        real("imu", "rate_hz", &u.rate_hz, 1, 10000),
        text("imu", "trigger", &u.trigger),
        integer("imu", "buffer_length", &u.buffer_length, 2, 65536),
        config_detail::realArray("imu", "rotation_imu_to_camera", &u.rotation_imu_to_camera, -1, 1),
        real("imu", "window_s", &u.window_s, 0.05, 10),
    };
}

// [pipeline] queues, [socket] and [log]
std::vector<Field> serviceFields(QueueConfig& q, SocketConfig& k, LogConfig& l) {
    using config_detail::boolean;
    using config_detail::choice;
    using config_detail::integer;
    using config_detail::path;
    using config_detail::real;
    using config_detail::text;
    return {
        integer("pipeline", "capture_queue_frames", &q.capture_queue_frames, 1, 1000),
        integer("pipeline", "status_interval_ms", &q.status_interval_ms, 100, 60000),
        path("socket", "path", &k.path),
        socketMode(&k.mode),
        text("socket", "group", &k.group),
        integer("socket", "max_clients", &k.max_clients, 1, 1024),
        integer("socket", "reserved_query_slots", &k.reserved_query_slots, 0, 1024),
        integer("socket", "max_request_bytes", &k.max_request_bytes, 64, 1 << 20),
        real("socket", "request_timeout_s", &k.request_timeout_s, 0, 3600, Bound::kOpen),
        integer("socket", "client_buffer_bytes", &k.client_buffer_bytes, 4096, 1 << 30),
        real("socket", "stall_timeout_s", &k.stall_timeout_s, 0, 3600, Bound::kOpen),
        real("socket", "pose_rate_hz", &k.pose_rate_hz, 0, 1000),
        boolean("log", "enabled", &l.enabled),
        path("log", "dir", &l.dir),
        integer("log", "frame_every", &l.frame_every, 0, 1000000),
        real("log", "pose_rate_hz", &l.pose_rate_hz, 0, 1000),
        integer("log", "max_file_bytes", &l.max_file_bytes, 4096, std::int64_t{1} << 40),
        integer("log", "max_total_bytes", &l.max_total_bytes, 4096, std::int64_t{1} << 40),
        integer("log", "fsync_interval_ms", &l.fsync_interval_ms, 0, 3600000),
        integer("log", "queue_bytes", &l.queue_bytes, 4096, 1 << 30),
        choice("log", "level", &l.level,
               {{"error", drivers::base::LogLevel::kError},
                {"warning", drivers::base::LogLevel::kWarning},
                {"info", drivers::base::LogLevel::kInfo},
                {"debug", drivers::base::LogLevel::kDebug}}),
    };
}

// Every key of the daemon's file, one table per section (the pipeline's own
// from pipeline_config.cpp), in the order config/scaled.toml documents them.
std::vector<Field> daemonFields(DaemonConfig& c) {
    using config_detail::appendFields;
    std::vector<Field> out = sourceFields(c.source);
    appendFields(out, config_detail::pipelineFields(c.pipeline));
    appendFields(out, cameraFields(c.camera));
    appendFields(out, deviceFields(c.gpio, c.imu));
    appendFields(out, serviceFields(c.queues, c.socket, c.log));
    return out;
}

// The cross-field checks of one part of the configuration; true when the
// check must stop (the first problem, when not collecting them all).
bool checkSourceAndCamera(const DaemonConfig& c, config_detail::Checker& check) {
    const auto& s = c.source;
    if (s.kind == SourceKind::kReplay && s.replay_path.empty() &&
        check.fail({"source.replay", "source.kind"},
                   "required when source.kind = \"replay\" (a dataset directory or video "
                   "file) (got \"\")")) {
        return true;
    }
    if (s.kind == SourceKind::kV4l2 && s.device.empty() &&
        check.fail({"source.device", "source.kind"},
                   "required when source.kind = \"v4l2\" (e.g. \"/dev/video0\") (got \"\")")) {
        return true;
    }
    if (s.kind == SourceKind::kLibcamera && s.device.empty() &&
        check.fail({"source.device", "source.kind"},
                   "required when source.kind = \"libcamera\" (a camera index such as "
                   "\"0\" or a libcamera id) (got \"\")")) {
        return true;
    }
    const bool live = s.kind == SourceKind::kV4l2 || s.kind == SourceKind::kLibcamera;
    const auto& m = c.camera;
    if (live && (m.fx_px <= 0 || m.fy_px <= 0 || m.cx_px <= 0 || m.cy_px <= 0) &&
        check.fail({"camera.fx_px", "source.kind"},
                   std::string("a live source (source.kind = \"") + toString(s.kind) +
                       "\") needs the camera's calibration: camera.fx_px, fy_px, cx_px "
                       "and cy_px must all be > 0 (got fx_px = " +
                       drivers::priors::tomlread::num(m.fx_px) + ")")) {
        return true;
    }
    if (m.drop_repeated_frames && s.kind == SourceKind::kLibcamera &&
        check.fail({"camera.drop_repeated_frames", "source.kind"},
                   "is a V4L2 option (a grabber or loopback device); libcamera's "
                   "sensors never repeat a frame (got true with source.kind = "
                   "\"libcamera\")")) {
        return true;
    }
    if (m.retry_max_s < m.retry_initial_s &&
        check.fail({"camera.retry_max_s", "camera.retry_initial_s"},
                   "must be >= camera.retry_initial_s = " +
                       drivers::priors::tomlread::num(m.retry_initial_s) + " (got " +
                       drivers::priors::tomlread::num(m.retry_max_s) + ")")) {
        return true;
    }
    return false;
}

bool checkGpioAndImu(const DaemonConfig& c, config_detail::Checker& check) {
    const auto& g = c.gpio;
    if (!g.chip.empty() && g.status_line < 0 && g.heartbeat_line < 0 &&
        check.fail({"gpio.status_line", "gpio.chip"},
                   "gpio.chip is set (\"" + g.chip +
                       "\") but no line is: set gpio.status_line and/or "
                       "gpio.heartbeat_line (got -1)")) {
        return true;
    }
    if (g.status_line >= 0 && g.status_line == g.heartbeat_line &&
        check.fail({"gpio.heartbeat_line", "gpio.status_line"},
                   "must differ from gpio.status_line (got " + std::to_string(g.heartbeat_line) +
                       " for both)")) {
        return true;
    }
    if (g.chip.empty() && (g.status_line >= 0 || g.heartbeat_line >= 0) &&
        check.fail({"gpio.chip", "gpio.status_line", "gpio.heartbeat_line"},
                   "required when gpio.status_line or gpio.heartbeat_line is set "
                   "(a path, name or label) (got \"\")")) {
        return true;
    }
    if (auto bad = rotationProblem(c.imu.rotation_imu_to_camera);
        bad && check.fail({"imu.rotation_imu_to_camera"}, *bad)) {
        return true;
    }
    return false;
}

bool checkSocketAndLog(const DaemonConfig& c, config_detail::Checker& check) {
    const std::string socket_path = c.socket.path.string();
    if ((socket_path.empty() || socket_path.size() > kMaxSocketPathBytes) &&
        check.fail({"socket.path"}, "must be a path of 1 to " +
                                        std::to_string(kMaxSocketPathBytes) +
                                        " bytes (a Unix socket) (got \"" + socket_path + "\")")) {
        return true;
    }
    if (c.socket.client_buffer_bytes < c.socket.max_request_bytes &&
        check.fail(
            {"socket.client_buffer_bytes", "socket.max_request_bytes"},
            "must be >= socket.max_request_bytes = " + std::to_string(c.socket.max_request_bytes) +
                " (got " + std::to_string(c.socket.client_buffer_bytes) + ")")) {
        return true;
    }
    if (c.log.enabled && c.log.dir.empty() &&
        check.fail({"log.dir", "log.enabled"},
                   "must not be empty when log.enabled = true (got \"\")")) {
        return true;
    }
    if (c.log.max_total_bytes < c.log.max_file_bytes &&
        check.fail({"log.max_total_bytes", "log.max_file_bytes"},
                   "must be >= log.max_file_bytes = " + std::to_string(c.log.max_file_bytes) +
                       " (got " + std::to_string(c.log.max_total_bytes) + ")")) {
        return true;
    }
    return false;
}

// Cross-field checks of the whole configuration.
Status checkDaemon(const DaemonConfig& c, const Locator& where,
                   config_detail::ProblemList* all = nullptr) {
    config_detail::Checker check(where, all);
    if (check.failed(config_detail::checkPipeline(c.pipeline, where, all))) {
        return check.result();
    }
    if (checkSourceAndCamera(c, check) || checkGpioAndImu(c, check)) {
        return check.result();
    }
    checkSocketAndLog(c, check);
    return check.result();
}

std::filesystem::path fromCommandLine(const std::filesystem::path& p) {
    std::error_code ec;
    const auto abs = std::filesystem::absolute(p, ec);
    return p.empty() || ec ? p : abs.lexically_normal();
}

std::optional<drivers::source::PacingMode> parsePacing(std::string_view text) {
    if (text == "realtime") {
        return drivers::source::PacingMode::kRealTime;
    }
    if (text == "fast") {
        return drivers::source::PacingMode::kAsFastAsPossible;
    }
    return std::nullopt;
}

}  // namespace

const char* toString(SourceKind kind) {
    switch (kind) {
        case SourceKind::kSim:
            return "sim";
        case SourceKind::kReplay:
            return "replay";
        case SourceKind::kV4l2:
            return "v4l2";
        case SourceKind::kLibcamera:
            return "libcamera";
    }
    return "?";
}

const char* toString(ImuMode mode) {
    return mode == ImuMode::kBuffer ? "buffer" : "sysfs";
}

DaemonConfig defaultDaemonConfig() {
    DaemonConfig c;
    c.pipeline = defaultPipelineConfig();
    c.pipeline.detector.model_path = kDefaultModel;
    c.pipeline.priors_path = kDefaultPriors;
    return c;
}

Status applyDaemonToml(std::string_view toml_text, std::string_view source_name,
                       const std::filesystem::path& base_dir, DaemonConfig& config) {
    auto root = drivers::priors::tomlread::parse(toml_text, source_name);
    if (!root) {
        return root.error();
    }
    DaemonConfig work = config;
    if (auto ok = config_detail::applyFields(*root, source_name, base_dir, daemonFields(work));
        !ok) {
        return ok;
    }
    if (auto ok = checkDaemon(work, config_detail::documentLocator(*root, source_name)); !ok) {
        return ok;
    }
    config = std::move(work);
    return {};
}

Status applyDaemonFile(const std::filesystem::path& path, DaemonConfig& config) {
    auto text = config_detail::readConfigFile(path);
    if (!text) {
        return text.error();
    }
    const auto absolute = fromCommandLine(path);
    if (auto ok = applyDaemonToml(*text, path.string(), absolute.parent_path(), config); !ok) {
        return ok;
    }
    config.file = absolute;
    return {};
}

Status applyDaemonOverrides(const std::vector<std::string>& assignments, DaemonConfig& config) {
    DaemonConfig work = config;
    std::vector<std::pair<std::string, std::string>> set_by;
    if (auto ok = config_detail::applyAssignments(assignments, daemonFields(work), set_by); !ok) {
        return ok;
    }
    if (auto ok = checkDaemon(work, config_detail::assignmentLocator(std::move(set_by), "--set"));
        !ok) {
        return ok;
    }
    config = std::move(work);
    return {};
}

std::vector<std::string> daemonConfigKeys() {
    DaemonConfig c;
    return config_detail::fieldKeys(daemonFields(c));
}

std::string toToml(const DaemonConfig& config) {
    DaemonConfig copy = config;
    return config_detail::fieldsToToml(daemonFields(copy));
}

Status applySourceSpec(std::string_view spec, SourceConfig& source) {
    const std::string where = "--source " + std::string(spec);
    const auto colon = spec.find(':');
    const std::string_view kind = spec.substr(0, colon);
    const std::string_view arg =
        colon == std::string_view::npos ? std::string_view() : spec.substr(colon + 1);
    const auto fail = [&](const std::string& what) {
        return makeError(ErrorCode::kInvalidArgument, where + ": " + what);
    };
    if (kind == "sim") {
        if (colon != std::string_view::npos) {
            return fail("sim takes no argument (expected sim)");
        }
        source.kind = SourceKind::kSim;
        return {};
    }
    const bool known = kind == "replay" || kind == "v4l2" || kind == "libcamera";
    if (!known) {
        return fail("unknown source \"" + std::string(kind) +
                    "\" (expected sim, replay:DIR, v4l2:DEVICE or libcamera:ID)");
    }
    if (arg.empty()) {
        const char* what = kind == "replay" ? "replay:DIR (a dataset directory or video file)"
                           : kind == "v4l2" ? "v4l2:DEVICE (e.g. v4l2:/dev/video0)"
                                            : "libcamera:ID (e.g. libcamera:0)";
        return fail(std::string("missing argument: expected ") + what);
    }
    if (kind == "replay") {
        source.kind = SourceKind::kReplay;
        source.replay_path = fromCommandLine(std::filesystem::path(arg));
    } else {
        source.kind = kind == "v4l2" ? SourceKind::kV4l2 : SourceKind::kLibcamera;
        source.device = std::string(arg);
    }
    return {};
}

namespace {

constexpr const char* kCommandLineFooter =
    "Configuration: defaults, then the file (--config, else " SCALED_SYSCONFDIR
    "/scaled/scaled.toml when it exists), then --set, then "
    "--source/--socket/--log-dir/--pacing/--verbose. Every key, its "
    "default, unit and allowed range is documented in config/scaled.toml (installed as "
    "/etc/scaled/scaled.toml).\n"
    "Exit codes (sysexits.h): 0 success; 64 usage; 66 an input that does not exist "
    "(dataset, model, camera device); 69 a camera or model that is there but cannot be "
    "used; 70 internal error; 71 the system refused a lookup; "
    "73 cannot create the socket (path in use by a live daemon, directory missing or not "
    "writable); 74 the source failed while running; 78 configuration error (also: an "
    "unknown socket.group, a priors file that is missing or does not parse; --check-config "
    "reports every such problem).";

// The options' text as given, before they are checked.
struct RawOptions {
    std::string config;
    std::string check_file;
    std::string source;
    std::string socket;
    std::string log_dir;
    std::string pacing;
    CLI::Option* config_opt = nullptr;
    CLI::Option* source_opt = nullptr;
    CLI::Option* socket_opt = nullptr;
    CLI::Option* log_opt = nullptr;
    CLI::Option* pacing_opt = nullptr;
    CLI::Option* check_opt = nullptr;
};

void addOptions(CLI::App& app, RawOptions& raw, CommandLine& cli) {
    raw.config_opt =
        app.add_option("--config", raw.config, "configuration file (TOML)")->type_name("FILE");
    raw.source_opt = app.add_option("--source", raw.source,
                                    "frame source: sim, replay:DIR, v4l2:DEVICE or "
                                    "libcamera:ID (overrides [source] kind)")
                         ->type_name("SPEC");
    raw.socket_opt =
        app.add_option("--socket", raw.socket, "Unix socket path (overrides socket.path)")
            ->type_name("PATH");
    raw.log_opt =
        app.add_option("--log-dir", raw.log_dir, "field log directory (overrides log.dir)")
            ->type_name("DIR");
    raw.pacing_opt =
        app.add_option("--pacing", raw.pacing, "realtime or fast (overrides source.pacing)")
            ->type_name("realtime|fast");
    app.add_option("--set", cli.sets,
                   "override one key, e.g. --set detection.every_frames=5 (repeatable)")
        ->type_name("SECTION.KEY=VALUE")
        ->allow_extra_args(false)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
    app.add_flag("-v,--verbose", cli.verbose,
                 "debug messages too (overrides log.level; messages go to stderr, the journal "
                 "under systemd)");
    app.add_flag("--no-tty", cli.no_tty, "no live status line on the terminal");
    raw.check_opt = app.add_option("--check-config", raw.check_file,
                                   "check the configuration (FILE, else the file that "
                                   "would be used), print the result and exit")
                        ->type_name("[FILE]")
                        ->expected(0, 1);
    app.add_flag("--version", cli.version, "print the version and exit");
    app.add_flag("--list-cameras", cli.list_cameras,
                 "list the V4L2 and libcamera cameras with their formats and exit");
}

// --config and --check-config; nullopt when they agree, else the usage error.
std::optional<std::string> takeConfigOptions(const RawOptions& raw, CommandLine& cli) {
    if (raw.config_opt->count() > 0) {
        cli.config = std::filesystem::path(raw.config);
    }
    if (raw.check_opt->count() > 0) {
        cli.check_config = true;
        if (!raw.check_file.empty()) {
            if (cli.config && *cli.config != raw.check_file) {
                return "--check-config " + raw.check_file + " and --config " + raw.config +
                       " name different files";
            }
            cli.config = std::filesystem::path(raw.check_file);
        }
    }
    return std::nullopt;
}

// The dedicated options and --set, checked for form (their values are
// checked with the configuration); nullopt when fine, else the usage error.
std::optional<std::string> takeOverrides(const RawOptions& raw, CommandLine& cli) {
    if (raw.source_opt->count() > 0) {
        SourceConfig scratch;
        if (auto ok = applySourceSpec(raw.source, scratch); !ok) {
            return ok.error().message;
        }
        cli.source = raw.source;
    }
    if (raw.socket_opt->count() > 0) {
        if (raw.socket.empty()) {
            return std::string("--socket needs a non-empty path");
        }
        cli.socket = std::filesystem::path(raw.socket);
    }
    if (raw.log_opt->count() > 0) {
        if (raw.log_dir.empty()) {
            return std::string("--log-dir needs a non-empty directory");
        }
        cli.log_dir = std::filesystem::path(raw.log_dir);
    }
    if (raw.pacing_opt->count() > 0) {
        if (!parsePacing(raw.pacing)) {
            return "--pacing " + raw.pacing + ": expected realtime or fast";
        }
        cli.pacing = raw.pacing;
    }
    for (const auto& a : cli.sets) {
        const auto eq = a.find('=');
        const auto dot = a.find('.');
        if (eq == std::string::npos || dot == std::string::npos || dot > eq || dot == 0 ||
            eq == dot + 1) {
            return "--set " + a + ": expected section.key=value (e.g. detection.every_frames=5)";
        }
    }
    return std::nullopt;
}

}  // namespace

ParsedCommandLine parseCommandLine(int argc, const char* const* argv) {
    ParsedCommandLine out;
    const auto usage = [&](const std::string& message) {
        out.exit_now = true;
        out.exit_code = 64;  // EX_USAGE
        out.error = "scaled: " + message + "\nRun 'scaled --help' for the options.\n";
        return out;
    };
    try {
        CLI::App app(
            "scaled: gives a monocular SLAM map a metric scale from the objects a detector "
            "finds.",
            "scaled");
        app.footer(kCommandLineFooter);
        RawOptions raw;
        addOptions(app, raw, out.cli);
        try {
            app.parse(argc, argv);
        } catch (const CLI::ParseError& e) {
            if (e.get_exit_code() != 0) {
                return usage(e.what());
            }
            out.exit_now = true;  // --help
            out.output = app.help();
            return out;
        }
        if (out.cli.version) {
            out.exit_now = true;
            out.output = std::string("scaled ") + version() + "\n";
            return out;
        }
        if (out.cli.list_cameras) {
            return out;  // runMain lists them (the drivers are not part of parsing)
        }
        if (auto bad = takeConfigOptions(raw, out.cli)) {
            return usage(*bad);
        }
        if (auto bad = takeOverrides(raw, out.cli)) {
            return usage(*bad);
        }
        return out;
    } catch (const std::exception& e) {  // CLI11's construction errors, allocation
        return usage(e.what());
    }
}

namespace {

// The file loadDaemonConfig reads: --config, else the default file when it exists.
std::filesystem::path configFileFor(const CommandLine& cli,
                                    const std::filesystem::path& default_config_file) {
    std::error_code ec;
    if (cli.config) {
        return *cli.config;
    }
    if (!default_config_file.empty() && std::filesystem::exists(default_config_file, ec)) {
        return default_config_file;
    }
    return {};
}

// --source, --socket, --log-dir and --pacing onto `config`, each recorded in
// `set_by` for a Locator. Without `all` the first problem ends it.
Status applyDedicatedOptions(const CommandLine& cli, DaemonConfig& config,
                             std::vector<std::pair<std::string, std::string>>& set_by,
                             config_detail::ProblemList* all) {
    const Locator nowhere = [](const std::vector<std::string>&) { return std::string(); };
    config_detail::Checker check(nowhere, all);
    if (cli.source) {
        if (auto ok = applySourceSpec(*cli.source, config.source);
            !ok && check.fail(ok.error(), "source.kind")) {
            return check.result();
        }
        for (const char* key : {"source.kind", "source.replay", "source.device"}) {
            set_by.emplace_back(key, "--source " + *cli.source);
        }
    }
    if (cli.socket) {
        config.socket.path = fromCommandLine(*cli.socket);
        set_by.emplace_back("socket.path", "--socket " + cli.socket->string());
    }
    if (cli.log_dir) {
        config.log.dir = fromCommandLine(*cli.log_dir);
        set_by.emplace_back("log.dir", "--log-dir " + cli.log_dir->string());
    }
    if (cli.verbose) {
        config.log.level = drivers::base::LogLevel::kDebug;
        set_by.emplace_back("log.level", "--verbose");
    }
    if (cli.pacing) {
        if (const auto mode = parsePacing(*cli.pacing)) {
            config.source.pacing = *mode;
        } else if (check.fail(makeError(ErrorCode::kInvalidArgument,
                                        "--pacing " + *cli.pacing + ": expected realtime or fast"),
                              "source.pacing")) {
            return check.result();
        }
    }
    return check.result();
}

}  // namespace

Result<DaemonConfig> loadDaemonConfig(const CommandLine& cli,
                                      const std::filesystem::path& default_config_file) {
    DaemonConfig config = defaultDaemonConfig();
    const std::filesystem::path file = configFileFor(cli, default_config_file);
    if (!file.empty()) {
        if (auto ok = applyDaemonFile(file, config); !ok) {
            return ok.error();
        }
    }

    // The command line: --set, then the dedicated options, checked together.
    DaemonConfig work = config;
    std::vector<std::pair<std::string, std::string>> set_by;
    if (auto ok = config_detail::applyAssignments(cli.sets, daemonFields(work), set_by); !ok) {
        return ok.error();
    }
    if (auto ok = applyDedicatedOptions(cli, work, set_by, nullptr); !ok) {
        return ok.error();
    }
    if (auto ok =
            checkDaemon(work, config_detail::assignmentLocator(std::move(set_by), "command line"));
        !ok) {
        return ok.error();
    }
    return work;
}

namespace {

// Keeps the problems of `from` whose key has no problem in `into` yet (a key
// with a wrong value is not also blamed for what follows from its default),
// and no message twice.
void mergeProblems(config_detail::ProblemList& into, const config_detail::ProblemList& from) {
    for (std::size_t i = 0; i < from.errors.size(); ++i) {
        const bool seen = std::any_of(into.errors.begin(), into.errors.end(), [&](const auto& e) {
            return e.message == from.errors[i].message;
        });
        if (!seen && !into.about(from.keys[i])) {
            into.add(from.errors[i], from.keys[i]);
        }
    }
}

}  // namespace

namespace {

// The LINE of a "SOURCE:LINE: ..." message about source_name; else the
// largest number (the command line's problems come after the file's).
std::size_t lineOf(const core::Error& e, const std::string& source_name) {
    const std::string prefix = source_name + ":";
    std::size_t n = 0;
    if (e.message.rfind(prefix, 0) == 0) {
        std::size_t i = prefix.size();
        while (i < e.message.size() && e.message[i] >= '0' && e.message[i] <= '9') {
            n = n * 10 + static_cast<std::size_t>(e.message[i] - '0');
            ++i;
        }
        if (n > 0) {
            return n;
        }
    }
    return std::numeric_limits<std::size_t>::max();
}

// The problems into `out` in file order (a TOML table iterates its keys by
// name), then the command line's in its order.
void takeProblemsInOrder(const config_detail::ProblemList& problems, const std::string& source_name,
                         CheckedConfig& out) {
    std::vector<std::size_t> order(problems.errors.size());
    for (std::size_t i = 0; i < order.size(); ++i) {
        order[i] = i;
    }
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return lineOf(problems.errors[a], source_name) < lineOf(problems.errors[b], source_name);
    });
    for (const std::size_t i : order) {
        out.errors.push_back(problems.errors[i]);
        out.error_keys.push_back(problems.keys[i]);
    }
}

}  // namespace

CheckedConfig checkDaemonConfig(const CommandLine& cli,
                                const std::filesystem::path& default_config_file) {
    CheckedConfig out;
    out.config = defaultDaemonConfig();
    config_detail::ProblemList problems;
    std::string source_name = "built-in defaults";
    const auto finish = [&] {
        takeProblemsInOrder(problems, source_name, out);
        return std::move(out);
    };
    const std::filesystem::path file = configFileFor(cli, default_config_file);
    // The document outlives this call inside `locate`.
    auto root = std::make_shared<toml::table>();
    if (!file.empty()) {
        auto text = config_detail::readConfigFile(file);
        if (!text) {
            problems.add(text.error(), "");
            out.locate = [file](const std::vector<std::string>&) { return file.string(); };
            return finish();
        }
        auto parsed = drivers::priors::tomlread::parse(*text, file.string());
        if (!parsed) {
            problems.add(parsed.error(), "");
            out.locate = [file](const std::vector<std::string>&) { return file.string(); };
            return finish();
        }
        *root = std::move(*parsed);
        source_name = file.string();
        const auto absolute = fromCommandLine(file);
        // Every problem goes to `problems` (the result says only whether there was one).
        static_cast<void>(config_detail::applyFields(*root, source_name, absolute.parent_path(),
                                                     daemonFields(out.config), &problems));
        config_detail::ProblemList cross;
        static_cast<void>(
            checkDaemon(out.config, config_detail::documentLocator(*root, source_name), &cross));
        mergeProblems(problems, cross);
        out.config.file = absolute;
    }

    // The command line, as loadDaemonConfig applies it.
    std::vector<std::pair<std::string, std::string>> set_by;
    static_cast<void>(
        config_detail::applyAssignments(cli.sets, daemonFields(out.config), set_by, &problems));
    static_cast<void>(applyDedicatedOptions(cli, out.config, set_by, &problems));
    const auto by_file = file.empty() ? config_detail::Locator([](const std::vector<std::string>&) {
        return std::string("built-in defaults");
    })
                                      : config_detail::documentLocator(*root, source_name);
    out.locate = [root, by_file, set_by](const std::vector<std::string>& keys) {
        for (const auto& key : keys) {
            for (auto it = set_by.rbegin(); it != set_by.rend(); ++it) {
                if (it->first == key) {
                    return it->second;
                }
            }
        }
        return by_file(keys);
    };
    if (!set_by.empty() || cli.pacing) {
        config_detail::ProblemList cross;
        static_cast<void>(checkDaemon(out.config, out.locate, &cross));
        mergeProblems(problems, cross);
    }
    return finish();
}

}  // namespace scaled::daemon
