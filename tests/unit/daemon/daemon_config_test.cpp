// The daemon configuration: the shipped config/scaled.toml is the defaults and
// names every key; every daemon key checked with errors naming file, line,
// key, range and value; cross-field checks; overrides; --source specs; the
// command line; the order defaults < file < --set < dedicated options.

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/daemon_config.h>

#include "temp_dir.h"

namespace scaled::daemon {
namespace {

const std::filesystem::path kShipped =
    std::filesystem::path(SCALED_SOURCE_DIR) / "config" / "scaled.toml";

std::string applyError(const std::string& text, DaemonConfig& c) {
    auto r = applyDaemonToml(text, "scaled.toml", "/etc/scaled", c);
    EXPECT_FALSE(r.ok()) << "accepted: " << text;
    return r.ok() ? std::string() : r.error().message;
}

ParsedCommandLine parse(const std::vector<std::string>& args) {
    std::vector<const char*> argv = {"scaled"};
    for (const auto& a : args) {
        argv.push_back(a.c_str());
    }
    return parseCommandLine(static_cast<int>(argv.size()), argv.data());
}

TEST(DaemonConfig, Defaults) {
    const DaemonConfig c = defaultDaemonConfig();
    EXPECT_EQ(c.source.kind, SourceKind::kSim);
    EXPECT_EQ(c.socket.path, std::filesystem::path("/run/scaled/scaled.sock"));
    EXPECT_EQ(c.socket.mode, 0660U);
    EXPECT_DOUBLE_EQ(c.socket.pose_rate_hz, 30.0);
    EXPECT_EQ(c.socket.max_clients, 16);
    EXPECT_EQ(c.socket.reserved_query_slots, 2);
    EXPECT_DOUBLE_EQ(c.socket.request_timeout_s, 5.0);
    EXPECT_DOUBLE_EQ(c.socket.stall_timeout_s, 10.0);
    EXPECT_DOUBLE_EQ(c.log.pose_rate_hz, 10.0);
    EXPECT_EQ(c.log.dir, std::filesystem::path("/var/log/scaled"));
    EXPECT_EQ(c.pipeline.detector.model_path,
              std::filesystem::path("/usr/share/scaled/models/yolox_nano.onnx"));
    EXPECT_EQ(c.pipeline.priors_path, std::filesystem::path("/etc/scaled/priors.toml"));
    EXPECT_DOUBLE_EQ(c.pipeline.detection.period_s, 0.0);
    EXPECT_TRUE(c.file.empty());
    // The pipeline part is the pipeline's defaults but for the installed paths.
    PipelineConfig p = c.pipeline;
    p.detector.model_path.clear();
    p.priors_path.clear();
    EXPECT_EQ(toToml(p), toToml(defaultPipelineConfig()));
    EXPECT_STREQ(toString(SourceKind::kReplay), "replay");
    EXPECT_STREQ(toString(SourceKind::kLibcamera), "libcamera");
}

TEST(DaemonConfig, ShippedFileIsTheDefaults) {
    DaemonConfig c = defaultDaemonConfig();
    auto r = applyDaemonFile(kShipped, c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    // The one relative path resolves against the file's directory.
    EXPECT_EQ(c.pipeline.priors_path, kShipped.parent_path().lexically_normal() / "priors.toml");
    EXPECT_TRUE(std::filesystem::exists(c.pipeline.priors_path));
    EXPECT_EQ(c.file, std::filesystem::absolute(kShipped).lexically_normal());
    c.pipeline.priors_path = defaultDaemonConfig().pipeline.priors_path;
    EXPECT_EQ(toToml(c), toToml(defaultDaemonConfig()));
}

TEST(DaemonConfig, ShippedFileNamesAndDocumentsEveryKey) {
    std::ifstream in(kShipped);
    ASSERT_TRUE(in) << kShipped;
    std::vector<std::string> found;
    std::string section;
    std::string line;
    std::string previous;
    while (std::getline(in, line)) {
        if (line.rfind('[', 0) == 0) {
            section = line.substr(1, line.find(']') - 1);
            EXPECT_EQ(previous.rfind('#', 0), 0U) << "[" << section << "] has no comment above";
        } else if (!line.empty() && line[0] != '#' && line.find(" = ") != std::string::npos) {
            found.push_back(section + "." + line.substr(0, line.find(" = ")));
            // Each key has its comment right above (or shares one with the key before).
            EXPECT_TRUE(previous.rfind('#', 0) == 0 || previous.find(" = ") != std::string::npos)
                << found.back() << " has no comment";
        }
        previous = line;
    }
    EXPECT_EQ(found, daemonConfigKeys());
}

TEST(DaemonConfig, KeysAreThePipelinesAndTheDaemons) {
    const auto keys = daemonConfigKeys();
    const std::set<std::string> unique(keys.begin(), keys.end());
    EXPECT_EQ(unique.size(), keys.size());
    for (const auto& k : pipelineConfigKeys()) {
        EXPECT_EQ(unique.count(k), 1U) << k;
    }
    for (const char* k : {"source.kind",
                          "source.replay",
                          "source.device",
                          "source.pacing",
                          "source.speed",
                          "source.at_end",
                          "source.max_frames",
                          "source.sim_seed",
                          "source.sim_fps",
                          "source.sim_width_px",
                          "source.sim_height_px",
                          "socket.path",
                          "socket.mode",
                          "socket.group",
                          "socket.max_clients",
                          "socket.reserved_query_slots",
                          "socket.max_request_bytes",
                          "socket.request_timeout_s",
                          "socket.client_buffer_bytes",
                          "socket.stall_timeout_s",
                          "socket.pose_rate_hz",
                          "log.enabled",
                          "log.dir",
                          "log.frame_every",
                          "log.pose_rate_hz",
                          "log.max_file_bytes",
                          "log.max_total_bytes",
                          "log.fsync_interval_ms",
                          "log.queue_bytes",
                          "log.level",
                          "pipeline.capture_queue_frames",
                          "pipeline.status_interval_ms",
                          "camera.width_px",
                          "camera.height_px",
                          "camera.fps",
                          "camera.pixel_format",
                          "camera.buffers",
                          "camera.frame_timeout_s",
                          "camera.retry_initial_s",
                          "camera.retry_max_s",
                          "camera.fx_px",
                          "camera.fy_px",
                          "camera.cx_px",
                          "camera.cy_px",
                          "camera.k1",
                          "camera.k2",
                          "gpio.chip",
                          "gpio.status_line",
                          "gpio.heartbeat_line",
                          "gpio.active_low",
                          "gpio.consumer",
                          "detection.period_s"}) {
        EXPECT_EQ(unique.count(k), 1U) << k;
    }
    EXPECT_EQ(keys.front(), "source.kind");
}

TEST(DaemonConfig, AppliesDaemonKeys) {
    DaemonConfig c = defaultDaemonConfig();
    const std::string text = R"([source]
kind = "replay"
replay = "data/rk"
pacing = "fast"
speed = 2.5
at_end = "exit"
max_frames = 300
sim_seed = 9
[socket]
path = "run/s.sock"
mode = 0o640
group = "scaled"
max_clients = 1024
reserved_query_slots = 0
request_timeout_s = 0.25
stall_timeout_s = 3600
pose_rate_hz = 12.5
[log]
enabled = false
dir = ""
pose_rate_hz = 0
max_file_bytes = 4096
max_total_bytes = 4096
[pipeline]
capture_queue_frames = 2
[detection]
period_s = 0.5
)";
    auto r = applyDaemonToml(text, "scaled.toml", "/etc/scaled", c);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(c.source.kind, SourceKind::kReplay);
    EXPECT_EQ(c.source.replay_path, std::filesystem::path("/etc/scaled/data/rk"));
    EXPECT_EQ(c.source.pacing, drivers::source::PacingMode::kAsFastAsPossible);
    EXPECT_DOUBLE_EQ(c.source.speed, 2.5);
    EXPECT_EQ(c.source.at_end, AtEnd::kExit);
    EXPECT_EQ(c.source.max_frames, 300);
    EXPECT_EQ(c.source.sim_seed, 9U);
    EXPECT_EQ(c.socket.path, std::filesystem::path("/etc/scaled/run/s.sock"));
    EXPECT_EQ(c.socket.mode, 0640U);
    EXPECT_EQ(c.socket.group, "scaled");
    EXPECT_EQ(c.socket.max_clients, 1024);
    EXPECT_EQ(c.socket.reserved_query_slots, 0);
    EXPECT_DOUBLE_EQ(c.socket.request_timeout_s, 0.25);
    EXPECT_DOUBLE_EQ(c.socket.stall_timeout_s, 3600.0);
    EXPECT_DOUBLE_EQ(c.socket.pose_rate_hz, 12.5);
    EXPECT_FALSE(c.log.enabled);
    EXPECT_TRUE(c.log.dir.empty());
    EXPECT_DOUBLE_EQ(c.log.pose_rate_hz, 0.0);
    EXPECT_EQ(c.log.max_total_bytes, 4096U);
    EXPECT_EQ(c.queues.capture_queue_frames, 2);
    EXPECT_DOUBLE_EQ(c.pipeline.detection.period_s, 0.5);
    // Untouched keys keep their values.
    EXPECT_EQ(c.queues.status_interval_ms, 1000);
    EXPECT_EQ(c.log.frame_every, 30);

    ASSERT_TRUE(applyDaemonToml("[socket]\nmode = \"600\"\n", "s", "/", c).ok());
    EXPECT_EQ(c.socket.mode, 0600U);
    const std::string live = R"([source]
kind = "v4l2"
device = "/dev/video2"
[camera]
width_px = 1280
height_px = 720
fps = 60
pixel_format = "MJPEG"
buffers = 6
frame_timeout_s = 1.5
retry_initial_s = 0.25
retry_max_s = 8
fx_px = 910.5
fy_px = 911
cx_px = 640.2
cy_px = 359.8
k1 = -0.12
k2 = 0.03
[gpio]
chip = "pinctrl-bcm2711"
status_line = 17
heartbeat_line = 27
active_low = true
consumer = "scaled-leds"
)";
    auto ok = applyDaemonToml(live, "s", "/", c);
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(c.source.kind, SourceKind::kV4l2);
    EXPECT_EQ(c.source.device, "/dev/video2");
    EXPECT_EQ(c.camera.width_px, 1280);
    EXPECT_EQ(c.camera.height_px, 720);
    EXPECT_DOUBLE_EQ(c.camera.fps, 60);
    EXPECT_EQ(c.camera.pixel_format, drivers::camera::PixelFormat::kMjpeg);
    EXPECT_EQ(c.camera.buffers, 6);
    EXPECT_DOUBLE_EQ(c.camera.frame_timeout_s, 1.5);
    EXPECT_DOUBLE_EQ(c.camera.retry_initial_s, 0.25);
    EXPECT_DOUBLE_EQ(c.camera.retry_max_s, 8);
    EXPECT_DOUBLE_EQ(c.camera.fx_px, 910.5);
    EXPECT_DOUBLE_EQ(c.camera.fy_px, 911);
    EXPECT_DOUBLE_EQ(c.camera.cx_px, 640.2);
    EXPECT_DOUBLE_EQ(c.camera.cy_px, 359.8);
    EXPECT_DOUBLE_EQ(c.camera.k1, -0.12);
    EXPECT_DOUBLE_EQ(c.camera.k2, 0.03);
    EXPECT_EQ(c.gpio.chip, "pinctrl-bcm2711");
    EXPECT_EQ(c.gpio.status_line, 17);
    EXPECT_EQ(c.gpio.heartbeat_line, 27);
    EXPECT_TRUE(c.gpio.active_low);
    EXPECT_EQ(c.gpio.consumer, "scaled-leds");
}

TEST(DaemonConfig, ErrorsNameFileLineKeyRangeAndValue) {
    const std::string mode_range =
        "must be an octal mode like \"0660\" (a string of octal digits, or an integer such as "
        "0o660) in [0000, 0777]";
    const std::string world_write = "must not let others write (no o+w bit, e.g. \"0660\")";
    const std::string long_path = "/" + std::string(120, 'x');
    struct Case {
        std::string text;
        std::string message;  // after "scaled.toml:"
    };
    const std::vector<Case> cases = {
        {"[socket]\nmax_clients = 0\n",
         "2: socket.max_clients: must be an integer in [1, 1024] (got 0)"},
        {"[source]\nkind = \"sim\"\ncolour = 1\n",
         "3: source.colour: unknown key (allowed in [source]: kind, replay, device, pacing, "
         "speed, at_end, max_frames, sim_seed, sim_fps, sim_width_px, sim_height_px)"},
        {"\n\n[sorce]\n",
         "3: sorce: unknown section (allowed: source, tracker, detector, detection, estimator, "
         "objects, camera, gpio, imu, pipeline, socket, log)"},
        {"[source]\nkind = \"usb\"\n",
         "2: source.kind: must be one of \"sim\", \"replay\", \"v4l2\", \"libcamera\" (got "
         "\"usb\")"},
        {"[log]\nenabled = \"yes\"\n", "2: log.enabled: must be true or false (got \"yes\")"},
        {"[log]\ndir = 3\n", "2: log.dir: must be a path string (got 3)"},
        {"[socket]\ngroup = false\n", "2: socket.group: must be a string (got false)"},
        {"[socket]\npose_rate_hz = -1\n",
         "2: socket.pose_rate_hz: must be a number in [0, 1000] (got -1)"},
        {"[socket]\nreserved_query_slots = -1\n",
         "2: socket.reserved_query_slots: must be an integer in [0, 1024] (got -1)"},
        {"[socket]\nreserved_query_slots = 1025\n",
         "2: socket.reserved_query_slots: must be an integer in [0, 1024] (got 1025)"},
        {"[socket]\nreserved_query_slots = 1.5\n",
         "2: socket.reserved_query_slots: must be an integer in [0, 1024] (got 1.5)"},
        {"[socket]\nrequest_timeout_s = 0\n",
         "2: socket.request_timeout_s: must be a number in (0, 3600] (got 0)"},
        {"[socket]\nrequest_timeout_s = 3601\n",
         "2: socket.request_timeout_s: must be a number in (0, 3600] (got 3601)"},
        {"[socket]\n\nrequest_timeout_s = nan\n",
         "3: socket.request_timeout_s: must be a number in (0, 3600] (got nan)"},
        {"[socket]\nstall_timeout_s = -0.5\n",
         "2: socket.stall_timeout_s: must be a number in (0, 3600] (got -0.5)"},
        {"[socket]\nstall_timeout_s = \"10\"\n",
         "2: socket.stall_timeout_s: must be a number in (0, 3600] (got \"10\")"},
        {"[socket]\npose_rate_hz = \"fast\"\n",
         "2: socket.pose_rate_hz: must be a number in [0, 1000] (got \"fast\")"},
        {"[log]\npose_rate_hz = 1001\n",
         "2: log.pose_rate_hz: must be a number in [0, 1000] (got 1001)"},
        {"[log]\npose_rate_hz = nan\n",
         "2: log.pose_rate_hz: must be a number in [0, 1000] (got nan)"},
        {"[source]\nspeed = 0\n", "2: source.speed: must be a number in (0, 1000] (got 0)"},
        {"[pipeline]\nstatus_interval_ms = 10\n",
         "2: pipeline.status_interval_ms: must be an integer in [100, 60000] (got 10)"},
        {"[detection]\nperiod_s = 3601\n",
         "2: detection.period_s: must be a number in [0, 3600] (got 3601)"},
        {"[detection]\nperiod_s = inf\n",
         "2: detection.period_s: must be a number in [0, 3600] (got inf)"},
        {"[detection]\nperiod_s = -1\n",
         "2: detection.period_s: must be a number in [0, 3600] (got -1)"},
        // The socket's mode.
        {"[socket]\nmode = \"0666\"\n", "2: socket.mode: " + world_write + " (got \"0666\")"},
        {"[socket]\nmode = 0o662\n", "2: socket.mode: " + world_write + " (got \"0662\")"},
        {"[socket]\nmode = \"0460\"\n",
         "2: socket.mode: must give the owner read and write (0600) (got \"0460\")"},
        {"[socket]\nmode = \"0680\"\n", "2: socket.mode: " + mode_range + " (got \"0680\")"},
        {"[socket]\nmode = 660\n", "2: socket.mode: " + mode_range + " (got 660)"},
        {"[socket]\nmode = \"\"\n", "2: socket.mode: " + mode_range + " (got \"\")"},
        // Cross-field checks name the line of the key (or of the key it depends on).
        {"[source]\nkind = \"replay\"\n",
         "2: source.replay: required when source.kind = \"replay\" (a dataset directory or "
         "video file) (got \"\")"},
        {"[source]\n\nkind = \"v4l2\"\n",
         "3: source.device: required when source.kind = \"v4l2\" (e.g. \"/dev/video0\") (got "
         "\"\")"},
        {"[source]\nkind = \"libcamera\"\ndevice = \"\"\n",
         "3: source.device: required when source.kind = \"libcamera\" (a camera index such as "
         "\"0\" or a libcamera id) (got \"\")"},
        {"[log]\nmax_file_bytes = 100000\nmax_total_bytes = 99999\n",
         "3: log.max_total_bytes: must be >= log.max_file_bytes = 100000 (got 99999)"},
        {"[log]\nmax_file_bytes = 1000000000\n",
         "2: log.max_total_bytes: must be >= log.max_file_bytes = 1000000000 (got 67108864)"},
        {"[log]\ndir = \"\"\n", "2: log.dir: must not be empty when log.enabled = true (got \"\")"},
        {"[socket]\nmax_request_bytes = 8192\nclient_buffer_bytes = 4096\n",
         "3: socket.client_buffer_bytes: must be >= socket.max_request_bytes = 8192 (got "
         "4096)"},
        {"[socket]\npath = \"" + long_path + "\"\n",
         "2: socket.path: must be a path of 1 to 107 bytes (a Unix socket) (got \"" + long_path +
             "\")"},
        // The IMU.
        {"[imu]\nmode = \"poll\"\n",
         "2: imu.mode: must be one of \"sysfs\", \"buffer\" (got \"poll\")"},
        {"[imu]\nrate_hz = 0.5\n", "2: imu.rate_hz: must be a number in [1, 10000] (got 0.5)"},
        {"[imu]\nrotation_imu_to_camera = [1, 0, 0, 0, 1, 0]\n",
         "2: imu.rotation_imu_to_camera: must be an array of 9 numbers in [-1, 1] (got an "
         "array of 6)"},
        {"[imu]\nrotation_imu_to_camera = [1, 0, 0, 0, 1, 0, 0, 0, 2]\n",
         "2: imu.rotation_imu_to_camera: must be an array of 9 numbers in [-1, 1]: entry 8 (got "
         "2)"},
        {"[imu]\nrotation_imu_to_camera = [1, 0, 0, 0, 1, 0, 0, 0, -1]\n",
         "2: imu.rotation_imu_to_camera: must be a rotation, row-major (determinant +1, not a "
         "reflection) (got det = -1)"},
        {"[imu]\nrotation_imu_to_camera = [1, 0, 0, 0, 0.9, 0, 0, 0, 1]\n",
         "2: imu.rotation_imu_to_camera: must be a rotation, row-major (orthonormal rows: max "
         "|R^T R - I| <= 0.001) (got max |R^T R - I| = 0.19)"},
        // The live camera and the LEDs.
        {"[camera]\npixel_format = \"RGB3\"\n",
         "2: camera.pixel_format: must be one of \"auto\", \"YUYV\", \"MJPEG\", \"GREY\", "
         "\"NV12\" (got \"RGB3\")"},
        {"[camera]\nbuffers = 1\n", "2: camera.buffers: must be an integer in [2, 32] (got 1)"},
        {"[camera]\nframe_timeout_s = 0\n",
         "2: camera.frame_timeout_s: must be a number in (0, 3600] (got 0)"},
        {"[camera]\nk1 = nan\n", "2: camera.k1: must be a number in [-10, 10] (got nan)"},
        {"[source]\nkind = \"v4l2\"\ndevice = \"vivid\"\n[camera]\nfx_px = 500\n",
         "5: camera.fx_px: a live source (source.kind = \"v4l2\") needs the camera's "
         "calibration: camera.fx_px, fy_px, cx_px and cy_px must all be > 0 (got fx_px = 500)"},
        {"[source]\nkind = \"libcamera\"\ndevice = \"0\"\n",
         "2: camera.fx_px: a live source (source.kind = \"libcamera\") needs the camera's "
         "calibration: camera.fx_px, fy_px, cx_px and cy_px must all be > 0 (got fx_px = 0)"},
        {"[camera]\nretry_initial_s = 10\nretry_max_s = 2\n",
         "3: camera.retry_max_s: must be >= camera.retry_initial_s = 10 (got 2)"},
        {"[source]\nkind = \"libcamera\"\ndevice = \"0\"\n[camera]\nfx_px = 500\nfy_px = 500\n"
         "cx_px = 320\ncy_px = 240\ndrop_repeated_frames = true\n",
         "9: camera.drop_repeated_frames: is a V4L2 option (a grabber or loopback device); "
         "libcamera's sensors never repeat a frame (got true with source.kind = \"libcamera\")"},
        {"[camera]\ndrop_repeated_frames = 1\n",
         "2: camera.drop_repeated_frames: must be true or false (got 1)"},
        {"[gpio]\nchip = \"gpiochip0\"\n",
         "2: gpio.status_line: gpio.chip is set (\"gpiochip0\") but no line is: set "
         "gpio.status_line and/or gpio.heartbeat_line (got -1)"},
        {"[gpio]\nchip = \"leds\"\nstatus_line = 3\nheartbeat_line = 3\n",
         "4: gpio.heartbeat_line: must differ from gpio.status_line (got 3 for both)"},
        {"[gpio]\nheartbeat_line = 2\n",
         "2: gpio.chip: required when gpio.status_line or gpio.heartbeat_line is set (a path, "
         "name or label) (got \"\")"},
        {"[gpio]\nstatus_line = 4096\n",
         "2: gpio.status_line: must be an integer in [-1, 4095] (got 4096)"},
        // The pipeline's cross-field checks have lines too.
        {"[estimator]\ngrid_d_min = 5\ngrid_d_max = 2\n",
         "3: estimator.grid_d_max: must be greater than estimator.grid_d_min = 5 (got 2)"},
    };
    DaemonConfig c = defaultDaemonConfig();
    for (const auto& [text, message] : cases) {
        EXPECT_EQ(applyError(text, c), "scaled.toml:" + message);
    }
    // Syntax errors carry the line (and column).
    const std::string syntax = applyError("[source]\nkind = \"sim\"\nspeed = = 2\n", c);
    EXPECT_EQ(syntax.rfind("scaled.toml:3:", 0), 0U) << syntax;
}

TEST(DaemonConfig, AFailedApplyChangesNothing) {
    DaemonConfig c = defaultDaemonConfig();
    const std::string before = toToml(c);
    applyError("[socket]\nmax_clients = 3\n[log]\nmax_total_bytes = 4096\n", c);
    applyError("[source]\nkind = \"replay\"\n", c);
    applyError("[detection]\nevery_frames = 3\n[source]\nspeed = -1\n", c);
    EXPECT_EQ(toToml(c), before);
    EXPECT_FALSE(applyDaemonOverrides({"socket.max_clients=3", "socket.mode=0777"}, c).ok());
    EXPECT_EQ(toToml(c), before);
}

TEST(DaemonConfig, FileErrors) {
    test::TempDir dir("daemon_config");
    DaemonConfig c = defaultDaemonConfig();
    auto missing = applyDaemonFile(dir.path() / "none.toml", c);
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().code, core::ErrorCode::kIo);
    EXPECT_EQ(missing.error().message,
              (dir.path() / "none.toml").string() + ": cannot read configuration: no such file");
    const auto file = dir.path() / "scaled.toml";
    std::ofstream(file) << "# comment\n[socket]\nmax_clients = 2000\n";
    auto bad = applyDaemonFile(file, c);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message, file.string() +
                                       ":3: socket.max_clients: must be an integer in [1, 1024] "
                                       "(got 2000)");
    EXPECT_TRUE(c.file.empty());
    std::ofstream(file) << "[log]\ndir = \"logs\"\n[source]\nkind = \"replay\"\nreplay = "
                           "\"../seq\"\n";
    ASSERT_TRUE(applyDaemonFile(file, c).ok());
    EXPECT_EQ(c.log.dir, dir.path() / "logs");
    EXPECT_EQ(c.source.replay_path, dir.path().parent_path() / "seq");
    EXPECT_EQ(c.file, file);
}

TEST(DaemonConfig, Overrides) {
    DaemonConfig c = defaultDaemonConfig();
    ASSERT_TRUE(applyDaemonOverrides(
                    {"socket.max_clients=4", "source.at_end=loop", "socket.mode=0600",
                     "detection.every_frames=3", "source.kind=replay", "source.replay=/data/x"},
                    c)
                    .ok());
    EXPECT_EQ(c.socket.max_clients, 4);
    EXPECT_EQ(c.source.at_end, AtEnd::kLoop);
    EXPECT_EQ(c.socket.mode, 0600U);
    EXPECT_EQ(c.pipeline.detection.every_frames, 3);
    EXPECT_EQ(c.source.replay_path, std::filesystem::path("/data/x"));
    // Cross-field checks run once, after all assignments, and name the one to blame.
    ASSERT_TRUE(
        applyDaemonOverrides({"log.max_total_bytes=100000000", "log.max_file_bytes=90000000"}, c)
            .ok());
    DaemonConfig d = defaultDaemonConfig();
    auto bad = applyDaemonOverrides({"source.kind=replay"}, d);
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message,
              "--set source.kind=replay: source.replay: required when source.kind = \"replay\" "
              "(a dataset directory or video file) (got \"\")");
    auto range = applyDaemonOverrides({"socket.max_clients=0"}, d);
    ASSERT_FALSE(range.ok());
    EXPECT_EQ(range.error().message,
              "--set socket.max_clients=0: socket.max_clients: must be an integer in [1, 1024] "
              "(got 0)");
    auto form = applyDaemonOverrides({"socket=1"}, d);
    ASSERT_FALSE(form.ok());
    EXPECT_NE(form.error().message.find("expected section.key=value"), std::string::npos);
}

TEST(DaemonConfig, ToTomlRoundTrips) {
    DaemonConfig a = defaultDaemonConfig();
    a.source.kind = SourceKind::kLibcamera;
    a.source.device = "0";
    a.camera.fx_px = a.camera.fy_px = 500;
    a.camera.cx_px = 320;
    a.camera.cy_px = 240;
    a.camera.pixel_format = drivers::camera::PixelFormat::kNv12;
    a.gpio.chip = "gpiochip4";
    a.gpio.heartbeat_line = 3;
    a.source.at_end = AtEnd::kLoop;
    a.socket.mode = 0640;
    a.socket.group = "robot";
    a.log.enabled = false;
    a.pipeline.detection.period_s = 0.25;
    const std::string text = toToml(a);
    EXPECT_NE(text.find("mode = \"0640\""), std::string::npos) << text;
    DaemonConfig b;
    auto r = applyDaemonToml(text, "dump", "/", b);
    ASSERT_TRUE(r.ok()) << r.error().message << "\n" << text;
    EXPECT_EQ(toToml(b), text);
    EXPECT_EQ(daemonConfigKeys().size(),
              static_cast<std::size_t>(std::count(text.begin(), text.end(), '=')));
}

// Found by fuzz_daemon_config (tests/fuzz/regressions/daemon_config): a string
// value with a control character (a "\r" escape in the file) was written back
// raw, which TOML does not allow, so toToml's output did not read back.
TEST(DaemonConfig, ToTomlEscapesControlCharacters) {
    DaemonConfig a = defaultDaemonConfig();
    auto r = applyDaemonToml("[socket]\ngroup = \"a\\rb\\u0001c\\u007fd\\te\\\\f\\\"g\"\n", "in",
                             "/", a);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(a.socket.group, std::string("a\rb\x01"
                                          "c\x7f"
                                          "d\te\\f\"g"));
    const std::string text = toToml(a);
    EXPECT_NE(text.find(R"(group = "a\u000Db\u0001c\u007Fd\u0009e\\f\"g")"), std::string::npos)
        << text;
    DaemonConfig b = defaultDaemonConfig();
    auto again = applyDaemonToml(text, "dump", "/", b);
    ASSERT_TRUE(again.ok()) << again.error().message << "\n" << text;
    EXPECT_EQ(b.socket.group, a.socket.group);
    EXPECT_EQ(toToml(b), text);
}
TEST(DaemonConfig, SourceSpecs) {
    SourceConfig s;
    ASSERT_TRUE(applySourceSpec("replay:/data/rk", s).ok());
    EXPECT_EQ(s.kind, SourceKind::kReplay);
    EXPECT_EQ(s.replay_path, std::filesystem::path("/data/rk"));
    ASSERT_TRUE(applySourceSpec("replay:rel/dir", s).ok());
    EXPECT_TRUE(s.replay_path.is_absolute());
    EXPECT_EQ(s.replay_path.filename(), "dir");
    ASSERT_TRUE(applySourceSpec("v4l2:/dev/video0", s).ok());
    EXPECT_EQ(s.kind, SourceKind::kV4l2);
    EXPECT_EQ(s.device, "/dev/video0");
    ASSERT_TRUE(applySourceSpec("libcamera:0", s).ok());
    EXPECT_EQ(s.kind, SourceKind::kLibcamera);
    EXPECT_EQ(s.device, "0");
    ASSERT_TRUE(applySourceSpec("sim", s).ok());
    EXPECT_EQ(s.kind, SourceKind::kSim);

    const std::string before_device = s.device;
    struct Bad {
        const char* spec;
        const char* message;
    };
    for (const Bad& b :
         {Bad{"usb:0",
              "--source usb:0: unknown source \"usb\" (expected sim, replay:DIR, "
              "v4l2:DEVICE or libcamera:ID)"},
          Bad{"",
              "--source : unknown source \"\" (expected sim, replay:DIR, v4l2:DEVICE or "
              "libcamera:ID)"},
          Bad{"replay",
              "--source replay: missing argument: expected replay:DIR (a dataset "
              "directory or video file)"},
          Bad{"replay:",
              "--source replay:: missing argument: expected replay:DIR (a dataset "
              "directory or video file)"},
          Bad{"v4l2:",
              "--source v4l2:: missing argument: expected v4l2:DEVICE (e.g. "
              "v4l2:/dev/video0)"},
          Bad{"libcamera",
              "--source libcamera: missing argument: expected libcamera:ID (e.g. "
              "libcamera:0)"},
          Bad{"sim:3", "--source sim:3: sim takes no argument (expected sim)"}}) {
        auto r = applySourceSpec(b.spec, s);
        ASSERT_FALSE(r.ok()) << b.spec;
        EXPECT_EQ(r.error().message, b.message);
        EXPECT_EQ(s.kind, SourceKind::kSim);
        EXPECT_EQ(s.device, before_device);
    }
}

TEST(DaemonCommandLine, Options) {
    const auto p = parse({"--config", "/etc/x.toml", "--source", "replay:/d", "--socket",
                          "/tmp/s.sock", "--log-dir", "/tmp/logs", "--pacing", "fast", "--set",
                          "socket.max_clients=3", "--set", "detection.every_frames=5", "--no-tty"});
    ASSERT_FALSE(p.exit_now) << p.error;
    EXPECT_EQ(p.cli.config, std::filesystem::path("/etc/x.toml"));
    EXPECT_EQ(p.cli.source, "replay:/d");
    EXPECT_EQ(p.cli.socket, std::filesystem::path("/tmp/s.sock"));
    EXPECT_EQ(p.cli.log_dir, std::filesystem::path("/tmp/logs"));
    EXPECT_EQ(p.cli.pacing, "fast");
    EXPECT_EQ(p.cli.sets,
              (std::vector<std::string>{"socket.max_clients=3", "detection.every_frames=5"}));
    EXPECT_TRUE(p.cli.no_tty);
    EXPECT_FALSE(p.cli.check_config);
    EXPECT_FALSE(p.cli.version);

    const auto none = parse({});
    ASSERT_FALSE(none.exit_now) << none.error;
    EXPECT_FALSE(none.cli.config.has_value());
    EXPECT_FALSE(none.cli.source.has_value());
    EXPECT_TRUE(none.cli.sets.empty());
    EXPECT_FALSE(none.cli.no_tty);
}

TEST(DaemonCommandLine, CheckConfig) {
    const auto alone = parse({"--check-config"});
    ASSERT_FALSE(alone.exit_now) << alone.error;
    EXPECT_TRUE(alone.cli.check_config);
    EXPECT_FALSE(alone.cli.config.has_value());

    const auto with_file = parse({"--check-config", "my.toml"});
    ASSERT_FALSE(with_file.exit_now) << with_file.error;
    EXPECT_TRUE(with_file.cli.check_config);
    EXPECT_EQ(with_file.cli.config, std::filesystem::path("my.toml"));

    const auto with_config = parse({"--config", "a.toml", "--check-config"});
    ASSERT_FALSE(with_config.exit_now) << with_config.error;
    EXPECT_TRUE(with_config.cli.check_config);
    EXPECT_EQ(with_config.cli.config, std::filesystem::path("a.toml"));

    const auto before_flag = parse({"--check-config", "--no-tty"});
    ASSERT_FALSE(before_flag.exit_now) << before_flag.error;
    EXPECT_TRUE(before_flag.cli.check_config);
    EXPECT_TRUE(before_flag.cli.no_tty);
    EXPECT_FALSE(before_flag.cli.config.has_value());

    const auto both = parse({"--config", "a.toml", "--check-config", "b.toml"});
    EXPECT_TRUE(both.exit_now);
    EXPECT_EQ(both.exit_code, 64);
    EXPECT_NE(both.error.find("name different files"), std::string::npos) << both.error;
}

TEST(DaemonCommandLine, HelpAndVersion) {
    const auto help = parse({"--help"});
    EXPECT_TRUE(help.exit_now);
    EXPECT_EQ(help.exit_code, 0);
    EXPECT_TRUE(help.error.empty());
    for (const char* word :
         {"--config", "--source", "--socket", "--log-dir", "--pacing", "--set", "--no-tty",
          "--verbose", "--check-config", "--version", "config/scaled.toml"}) {
        EXPECT_NE(help.output.find(word), std::string::npos) << word << " not in\n" << help.output;
    }
    const auto version = parse({"--version"});
    EXPECT_TRUE(version.exit_now);
    EXPECT_EQ(version.exit_code, 0);
    EXPECT_EQ(version.output, "scaled 0.1.0\n");
}

TEST(DaemonCommandLine, BadUsageIs64) {
    struct Bad {
        std::vector<std::string> args;
        const char* mentions;
    };
    for (const Bad& b :
         {Bad{{"--bogus"}, "--bogus"}, Bad{{"extra"}, "extra"},
          Bad{{"--set", "log.enabled=false", "stray"}, "stray"}, Bad{{"--config"}, "--config"},
          Bad{{"--source", "usb:0"}, "unknown source \"usb\""},
          Bad{{"--source", "replay"}, "missing argument"},
          Bad{{"--pacing", "slow"}, "--pacing slow: expected realtime or fast"},
          Bad{{"--set", "robust"}, "--set robust: expected section.key=value"},
          Bad{{"--set", "=3"}, "expected section.key=value"},
          Bad{{"--socket", ""}, "--socket needs a non-empty path"}}) {
        const auto p = parse(b.args);
        EXPECT_TRUE(p.exit_now) << b.args.front();
        EXPECT_EQ(p.exit_code, 64) << b.args.front();
        EXPECT_NE(p.error.find(b.mentions), std::string::npos) << p.error;
        EXPECT_TRUE(p.output.empty());
    }
}

TEST(DaemonLoad, DefaultsWhenNoFile) {
    test::TempDir dir("daemon_load");
    auto c = loadDaemonConfig(CommandLine{}, dir.path() / "absent.toml");
    ASSERT_TRUE(c.ok()) << c.error().message;
    EXPECT_TRUE(c->file.empty());
    EXPECT_EQ(toToml(*c), toToml(defaultDaemonConfig()));
    auto empty = loadDaemonConfig(CommandLine{}, "");
    ASSERT_TRUE(empty.ok());
    EXPECT_TRUE(empty->file.empty());
}

TEST(DaemonLoad, FileThenSetThenDedicatedOptions) {
    test::TempDir dir("daemon_load");
    const auto def = dir.path() / "default.toml";
    std::ofstream(def) << "[socket]\nmax_clients = 5\npath = \"d.sock\"\n";
    const auto other = dir.path() / "other.toml";
    std::ofstream(other) << "[socket]\nmax_clients = 6\n[log]\ndir = \"logs\"\n";

    // The default file when it exists.
    auto from_default = loadDaemonConfig(CommandLine{}, def);
    ASSERT_TRUE(from_default.ok()) << from_default.error().message;
    EXPECT_EQ(from_default->file, def);
    EXPECT_EQ(from_default->socket.max_clients, 5);
    EXPECT_EQ(from_default->socket.path, dir.path() / "d.sock");

    // --config instead of it; --set over the file; dedicated options over --set.
    CommandLine cli;
    cli.config = other;
    cli.sets = {"socket.max_clients=7", "log.dir=/set/logs", "source.pacing=realtime",
                "camera.fx_px=500",     "camera.fy_px=500",  "camera.cx_px=320",
                "camera.cy_px=240"};
    cli.log_dir = "/cli/logs";
    cli.socket = "/cli/s.sock";
    cli.pacing = "fast";
    cli.source = "v4l2:/dev/video1";
    auto c = loadDaemonConfig(cli, def);
    ASSERT_TRUE(c.ok()) << c.error().message;
    EXPECT_EQ(c->file, other);
    EXPECT_EQ(c->socket.max_clients, 7);
    EXPECT_EQ(c->log.dir, std::filesystem::path("/cli/logs"));
    EXPECT_EQ(c->socket.path, std::filesystem::path("/cli/s.sock"));
    EXPECT_EQ(c->source.pacing, drivers::source::PacingMode::kAsFastAsPossible);
    EXPECT_EQ(c->source.kind, SourceKind::kV4l2);
    EXPECT_EQ(c->source.device, "/dev/video1");

    // --set source.kind=replay with the path from --source: checked together.
    CommandLine together;
    together.sets = {"source.kind=replay"};
    together.source = "replay:/data/seq";
    auto t = loadDaemonConfig(together, "");
    ASSERT_TRUE(t.ok()) << t.error().message;
    EXPECT_EQ(t->source.replay_path, std::filesystem::path("/data/seq"));
}

// log.level: the daemon's messages; --verbose (-v) sets debug over the file.
TEST(DaemonLoad, LogLevelFromTheFileAndVerbose) {
    test::TempDir dir("daemon_load");
    const auto file = dir.path() / "quiet.toml";
    std::ofstream(file) << "[log]\nlevel = \"warning\"\n";
    CommandLine cli;
    cli.config = file;
    auto quiet = loadDaemonConfig(cli, "");
    ASSERT_TRUE(quiet.ok()) << quiet.error().message;
    EXPECT_EQ(quiet->log.level, drivers::base::LogLevel::kWarning);
    EXPECT_NE(toToml(*quiet).find("level = \"warning\""), std::string::npos) << toToml(*quiet);

    const auto parsed = parse({"-v", "--config", file.string()});
    ASSERT_FALSE(parsed.exit_now) << parsed.error;
    EXPECT_TRUE(parsed.cli.verbose);
    auto verbose = loadDaemonConfig(parsed.cli, "");
    ASSERT_TRUE(verbose.ok()) << verbose.error().message;
    EXPECT_EQ(verbose->log.level, drivers::base::LogLevel::kDebug);

    const auto loud = dir.path() / "loud.toml";
    std::ofstream(loud) << "[log]\nlevel = \"loud\"\n";
    cli.config = loud;
    auto bad = loadDaemonConfig(cli, "");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("loud.toml:2"), std::string::npos) << bad.error().message;
    EXPECT_NE(bad.error().message.find("log.level"), std::string::npos) << bad.error().message;
    EXPECT_NE(bad.error().message.find("\"loud\""), std::string::npos) << bad.error().message;
}

TEST(DaemonLoad, Errors) {
    test::TempDir dir("daemon_load");
    CommandLine missing;
    missing.config = dir.path() / "none.toml";
    auto m = loadDaemonConfig(missing, "");
    ASSERT_FALSE(m.ok());
    EXPECT_EQ(m.error().code, core::ErrorCode::kIo);

    const auto bad = dir.path() / "bad.toml";
    std::ofstream(bad) << "[log]\nframe_every = -1\n";
    CommandLine file;
    file.config = bad;
    auto b = loadDaemonConfig(file, "");
    ASSERT_FALSE(b.ok());
    EXPECT_EQ(b.error().message,
              bad.string() + ":2: log.frame_every: must be an integer in [0, 1000000] (got -1)");
    // A broken default file is an error too (it exists, so it is used).
    auto d = loadDaemonConfig(CommandLine{}, bad);
    ASSERT_FALSE(d.ok());

    CommandLine cross;
    cross.sets = {"source.kind=v4l2"};
    auto x = loadDaemonConfig(cross, "");
    ASSERT_FALSE(x.ok());
    EXPECT_EQ(x.error().message.rfind("--set source.kind=v4l2: source.device: required", 0), 0U)
        << x.error().message;

    CommandLine empty_socket;
    empty_socket.socket = "";
    auto s = loadDaemonConfig(empty_socket, "");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().message.rfind("--socket : socket.path: must be a path of 1 to 107", 0), 0U)
        << s.error().message;
}

TEST(DaemonConfig, PipelineApiReadsTheDaemonFile) {
    // scale-eval --config config/scaled.toml: the daemon's sections are
    // checked and ignored.
    PipelineConfig p = defaultPipelineConfig();
    auto r = applyPipelineFile(kShipped, p);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(p.detector.model_path, defaultDaemonConfig().pipeline.detector.model_path);
    EXPECT_EQ(p.priors_path, kShipped.parent_path().lexically_normal() / "priors.toml");
    PipelineConfig q = defaultPipelineConfig();
    ASSERT_TRUE(applyPipelineToml("[socket]\nmax_clients = 3\n[source]\nkind = \"replay\"\n"
                                  "replay = \"x\"\n",
                                  "t.toml", "/", q)
                    .ok());
    EXPECT_EQ(toToml(q), toToml(defaultPipelineConfig()));
    auto typo = applyPipelineToml("[socket]\nmax_clients = 0\n", "t.toml", "/", q);
    ASSERT_FALSE(typo.ok());
    EXPECT_EQ(typo.error().message,
              "t.toml:2: socket.max_clients: must be an integer in [1, 1024] (got 0)");
    auto cross = applyPipelineOverrides({"source.kind=replay"}, q);
    ASSERT_FALSE(cross.ok());
    ASSERT_TRUE(applyPipelineOverrides({"log.enabled=false"}, q).ok());
}

}  // namespace
}  // namespace scaled::daemon
