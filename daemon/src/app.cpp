#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <pthread.h>
#include <string>
#include <sysexits.h>
#include <unistd.h>
#include <utility>
#include <vector>

#include <scaled/daemon/app.h>
#include <scaled/daemon/config_check.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/imu_service.h>
#include <scaled/daemon/log_service.h>
#include <scaled/daemon/pipeline.h>
#include <scaled/daemon/report.h>
#include <scaled/daemon/sd_notify.h>
#include <scaled/daemon/socket_service.h>
#include <scaled/daemon/status_lights.h>
#include <scaled/daemon/version.h>
#include <scaled/drivers/base/log.h>
#include <scaled/drivers/camera/v4l2_camera.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/detector/thread_priority.h>
#include <scaled/drivers/libcamera/libcamera_camera.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/sim/sim_source.h>
#include <scaled/drivers/source/paced_source.h>

#include "live_source.h"
#include "log_events.h"

namespace scaled::daemon {

using core::Error;
using core::ErrorCode;
using core::makeError;
using core::Result;

namespace {

// An error with the exit code it should end the process with.
struct Failure {
    int exit_code = EX_SOFTWARE;
    std::string message;
};

// The daemon's message categories (drivers/base/log.h); kMain's messages
// carry no category of their own.
using drivers::base::logDebug;
using drivers::base::logError;
using drivers::base::logInfo;
using drivers::base::logWarning;
const drivers::base::LogCategory kMain{"scaled"};
const drivers::base::LogCategory kFieldLog{"log"};
const drivers::base::LogCategory kGpio{"gpio"};
const drivers::base::LogCategory kImu{"imu"};
const drivers::base::LogCategory kSocket{"socket"};
const drivers::base::LogCategory kPipelineLog{"pipeline"};
const drivers::base::LogCategory kReload{"reload"};

int exitCodeFor(const Error& e, int fallback) {
    switch (e.code) {
        case ErrorCode::kNotFound:
            return EX_NOINPUT;
        case ErrorCode::kInvalidArgument:
        case ErrorCode::kParse:
            return EX_CONFIG;
        default:
            return fallback;
    }
}

// --check-config: every problem on stderr, notes and the verdict on stdout.
int checkConfigurationAndReport(const CommandLine& cli, const std::filesystem::path& default_file) {
    const ConfigCheckReport report = checkConfiguration(cli, default_file);
    for (const auto& e : report.errors) {
        logError(kMain, e);
    }
    const std::string name = report.file.empty() ? "built-in defaults" : report.file.string();
    for (const auto& n : report.notes) {
        std::printf("%s: note: %s\n", name.c_str(), n.c_str());
    }
    if (!report.ok()) {
        logError(kMain, name + ": " + std::to_string(report.errors.size()) +
                            (report.errors.size() == 1 ? " error" : " errors"));
        return EX_CONFIG;
    }
    std::printf("%s: configuration OK\n", name.c_str());
    return EX_OK;
}

drivers::sim::SimConfig simConfig(const SourceConfig& s) {
    drivers::sim::SimConfig c;
    c.seed = s.sim_seed;
    c.fps = s.sim_fps;
    c.width_px = s.sim_width_px;
    c.height_px = s.sim_height_px;
    c.duration_s = 0;  // unbounded: the loop goes on
    return c;
}

std::string sourceName(const SourceConfig& s) {
    switch (s.kind) {
        case SourceKind::kSim:
            return "sim";
        case SourceKind::kReplay:
            return "replay:" + s.replay_path.string();
        case SourceKind::kV4l2:
            return "v4l2:" + s.device;
        case SourceKind::kLibcamera:
            return "libcamera:" + s.device;
    }
    return "?";
}

// The detector the source needs: the simulated one for `sim`, the network otherwise.
Result<std::unique_ptr<drivers::detector::ObjectDetector>> openDetector(
    const DaemonConfig& config) {
    if (config.source.kind == SourceKind::kSim) {
        return drivers::sim::createSimDetector(simConfig(config.source));
    }
    const auto& d = config.pipeline.detector;
    if (d.model_path.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         "detector.model: not set (the YOLOX-Nano ONNX model; see "
                         "config/scaled.toml)");
    }
    auto det = drivers::detector::DnnDetector::create(d);
    if (!det) {
        return det.error();
    }
    return std::unique_ptr<drivers::detector::ObjectDetector>(std::move(*det));
}

Result<core::PriorTable> openPriors(const DaemonConfig& config) {
    if (config.pipeline.priors_path.empty()) {
        return makeError(ErrorCode::kInvalidArgument,
                         "estimator.priors: not set (the height priors file, e.g. "
                         "/etc/scaled/priors.toml)");
    }
    // The installed default missing (e.g. the daemon run from a build tree):
    // the repository's config/priors.toml, built into this binary. A priors
    // file configured anywhere else, or an installed one, always wins.
    std::error_code ec;
    const auto& path = config.pipeline.priors_path;
    if (path == defaultDaemonConfig().pipeline.priors_path && !std::filesystem::exists(path, ec)) {
        logInfo(kMain,
                path.string() +
                    " not found: using the priors built into this binary (config/priors.toml of "
                    "its source tree)");
        return drivers::priors::parsePriors(drivers::priors::builtinPriorsToml(),
                                            "built-in config/priors.toml");
    }
    return drivers::priors::loadPriorsFile(path);
}

std::optional<Failure> openDetectorAndPriors(const DaemonConfig& config, PipelineParts& parts);

// The source, paced as configured, and what goes with it.
std::optional<Failure> openParts(const DaemonConfig& config, PipelineParts& parts) {
    const auto& s = config.source;
    parts.source_name = sourceName(s);
    std::unique_ptr<drivers::source::FrameSource> source;
    switch (s.kind) {
        case SourceKind::kSim: {
            auto src = drivers::sim::openSimSource(simConfig(s));
            if (!src) {
                return Failure{EX_CONFIG, "source sim: " + src.error().message};
            }
            source = std::move(*src);
            break;
        }
        case SourceKind::kReplay: {
            auto src = drivers::dataset::openDataset(s.replay_path);
            if (!src) {
                return Failure{EX_NOINPUT,
                               "source " + parts.source_name + ": " + src.error().message};
            }
            source = std::move(*src);
            break;
        }
        case SourceKind::kV4l2:
        case SourceKind::kLibcamera: {
            std::string missing;
            auto live = openLive(config, missing);
            if (!live) {
                const auto code = live.error().code;
                return Failure{code == ErrorCode::kInvalidArgument ? EX_CONFIG
                               : code == ErrorCode::kUnavailable   ? EX_UNAVAILABLE
                                                                   : EX_NOINPUT,
                               "source " + parts.source_name + ": " + live.error().message};
            }
            if (!missing.empty()) {
                logInfo(kMain, "source " + parts.source_name + ": not available yet (" + missing +
                                   "); running in the fault state and retrying");
            } else {
                logInfo(kMain, "source " + parts.source_name + ": " + (*live)->describe() + ", " +
                                   (*live)->mode());
                for (const auto& note : (*live)->info().notes) {
                    logInfo(kMain, "source " + parts.source_name + ": " + note);
                }
            }
            parts.live = live->get();
            parts.source = std::move(*live);
            parts.lossless = false;  // a camera does not wait: late frames are dropped
            return openDetectorAndPriors(config, parts);
        }
    }
    parts.lossless = s.pacing == drivers::source::PacingMode::kAsFastAsPossible;
    if (s.pacing == drivers::source::PacingMode::kRealTime) {
        drivers::source::PacingOptions pacing;
        pacing.mode = drivers::source::PacingMode::kRealTime;
        pacing.speed = s.speed;
        pacing.drop_late = false;  // the capture ring drops, and counts, instead
        auto paced = drivers::source::PacedFrameSource::create(std::move(source), pacing);
        if (!paced) {
            return Failure{EX_CONFIG, "source.speed: " + paced.error().message};
        }
        source = std::move(*paced);
    }
    parts.source = std::move(source);
    return openDetectorAndPriors(config, parts);
}

std::optional<Failure> openDetectorAndPriors(const DaemonConfig& config, PipelineParts& parts) {
    auto det = openDetector(config);
    if (!det) {
        return Failure{exitCodeFor(det.error(), EX_UNAVAILABLE), det.error().message};
    }
    parts.detector = std::move(*det);
    auto priors = openPriors(config);
    if (!priors) {
        return Failure{EX_CONFIG, priors.error().message};
    }
    parts.priors = std::move(*priors);
    return std::nullopt;
}

std::string formatScale(const ScaleReport& r) {
    char buf[160];
    if (!r.has_scale) {
        std::snprintf(buf, sizeof buf, "scale -  %s  epoch %llu", toString(r.state),
                      static_cast<unsigned long long>(r.epoch));
    } else {
        std::snprintf(buf, sizeof buf, "scale %.4f (95%% %.4f-%.4f)  %s  epoch %llu  obs %d",
                      r.scale, r.ci95_lo, r.ci95_hi, toString(r.state),
                      static_cast<unsigned long long>(r.epoch), r.observations);
    }
    return buf;
}

// The live status line on a terminal: frame/total, fps, scale ± interval, state.
void printStatusLine(const PipelineStatus& st, const ScaleReport& r) {
    char frames[64];
    const auto shown = static_cast<long long>(st.frame_id) + 1;  // frames are counted from 1
    if (st.frames_total > 0) {
        std::snprintf(frames, sizeof frames, "frame %lld/%lld", shown,
                      static_cast<long long>(st.frames_total));
    } else {
        std::snprintf(frames, sizeof frames, "frame %lld", shown);
    }
    char scale[96];
    if (r.has_scale) {
        std::snprintf(scale, sizeof scale, "scale %.4f ± %.4f", r.scale,
                      (r.ci95_hi - r.ci95_lo) / 2);
    } else {
        std::snprintf(scale, sizeof scale, "scale -");
    }
    std::fprintf(stderr, "\r\033[K%s  %5.1f fps  %s  %s  epoch %llu", frames, st.fps, scale,
                 toString(r.state), static_cast<unsigned long long>(r.epoch));
    std::fflush(stderr);
}

class Daemon {
public:
    Daemon(CommandLine cli, DaemonConfig config)
        : cli_(std::move(cli)), config_(std::move(config)) {}
    int run();

private:
    [[nodiscard]] std::optional<int> start();
    [[nodiscard]] std::optional<int> startServing(PipelineParts parts);
    int mainLoop(const sigset_t& signals);
    void reload();
    void tick(std::int64_t now_ns);
    void teardown(const char* reason);
    void openLights();
    void openImu();

    CommandLine cli_;
    DaemonConfig config_;
    SdNotifier notifier_;
    std::unique_ptr<ReportHub> hub_;
    std::unique_ptr<LogService> log_;
    std::unique_ptr<LogEvents> events_;
    std::unique_ptr<StatusLights> lights_;
    std::unique_ptr<ImuService> imu_;
    std::string imu_error_;
    std::unique_ptr<SocketService> socket_;
    std::unique_ptr<Pipeline> pipeline_;
    bool tty_ = false;
    std::int64_t last_beat_ns_ = 0;
    std::int64_t last_status_ns_ = 0;
    std::int64_t last_line_ns_ = 0;
    std::int64_t last_watchdog_ns_ = 0;
    std::uint64_t last_heartbeat_ = 0;
    std::uint64_t last_light_heartbeat_ = 0;
    std::string last_log_fault_;
};

int Daemon::run() {
    // Signals go to the main loop only (sigtimedwait); the threads started
    // below inherit the mask. A client that hangs up must not kill us.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGTERM);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGHUP);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
    std::signal(SIGPIPE, SIG_IGN);  // NOLINT(cert-err33-c): the previous handler is not needed

    tty_ = !cli_.no_tty && isatty(STDERR_FILENO) == 1;
    logInfo(kMain,
            std::string("scaled ") + version() + ", config " +
                (config_.file.empty() ? std::string("built-in defaults") : config_.file.string()) +
                ", source " + sourceName(config_.source));
    if (const std::optional<int> failed = start()) {
        return *failed;
    }
    notifier_.notify("READY=1\nSTATUS=started, " + sourceName(config_.source));
    return mainLoop(signals);
}

// Everything in dependency order (chrony's main.c): what a later part
// reports to comes first; teardown() stops them in reverse. The exit code
// when a part that the daemon cannot run without fails.
std::optional<int> Daemon::start() {
    // 1. The report hub everything publishes to.
    const auto bins = static_cast<std::size_t>(config_.pipeline.estimator.posterior.grid.bins);
    hub_ = std::make_unique<ReportHub>(bins);

    // 2. The field log first, so that everything after it is logged. A log
    //    that cannot open is a fault, not a reason to stop serving the scale.
    auto log = LogService::create(config_.log, *hub_);
    if (!log) {
        logError(kFieldLog, log.error().message);
        return EX_CONFIG;
    }
    log_ = std::move(*log);
    log_->start();
    events_ = std::make_unique<LogEvents>(*log_);
    events_->start(version(), sourceName(config_.source), toToml(config_));
    logDebug(kFieldLog, "field log " + std::string(config_.log.enabled ? "in " : "off, ") +
                            (config_.log.enabled ? config_.log.dir.string() : "log.enabled"));

    // 2b. The status LEDs. Without them the daemon runs on: one line says why.
    openLights();

    // 2c. The IMU. Without it the daemon runs on: one line says why.
    openImu();

    // 2d. OpenCV's worker threads, made at the detector's priority before
    //     anything runs a parallel OpenCV call (thread_priority.h).
    if (auto workers = drivers::detector::startOpenCvWorkersAtNice(config_.pipeline.detector.nice);
        !workers) {
        logWarning(kMain, "detector.nice: " + workers.error().message +
                              " (running with OpenCV's workers at the daemon's priority)");
        events_->onError("detector priority", workers.error().message);
    }

    // 3. Source, detector, priors.
    PipelineParts parts;
    if (auto f = openParts(config_, parts)) {
        logError(kMain, f->message);
        events_->onError("start", f->message);
        teardown("start failed");
        return f->exit_code;
    }
    parts.imu = imu_.get();
    parts.imu_error = imu_error_;
    logDebug(kPipelineLog, "source " + parts.source_name + " open, detector and priors loaded");
    return startServing(std::move(parts));
}

// 4. The socket and 5. the pipeline, then both started.
std::optional<int> Daemon::startServing(PipelineParts parts) {
    auto sock = SocketService::create(config_.socket, *hub_, version());
    if (!sock) {
        // The default directory is made by systemd (RuntimeDirectory=scaled);
        // say how to run without it rather than leave the user guessing.
        const bool default_dir =
            config_.socket.path.parent_path() == defaultDaemonConfig().socket.path.parent_path();
        logError(kSocket, sock.error().message +
                              (default_dir ? " (the service's unit creates it; to run by hand, "
                                             "--socket PATH in a directory you can write)"
                                           : ""));
        events_->onError("socket", sock.error().message);
        teardown("socket failed");
        return EX_CANTCREAT;
    }
    socket_ = std::move(*sock);
    auto pipeline = Pipeline::create(config_, std::move(parts), *hub_, events_.get());
    if (!pipeline) {
        logError(kPipelineLog, pipeline.error().message);
        teardown("pipeline failed");
        return exitCodeFor(pipeline.error(), EX_SOFTWARE);
    }
    pipeline_ = std::move(*pipeline);
    if (auto s = socket_->start(); !s) {
        logError(kSocket, s.error().message);
        teardown("socket failed");
        return EX_CANTCREAT;
    }
    if (auto s = pipeline_->start(); !s) {
        logError(kPipelineLog, s.error().message);
        teardown("pipeline failed");
        return EX_SOFTWARE;
    }
    logInfo(kMain, "listening on " + socket_->path().string() +
                       (socket_->socketActivated() ? " (socket activation)" : ""));
    return std::nullopt;
}

// 6. The main loop: signals, watchdog, status; until a signal or the end.
int Daemon::mainLoop(const sigset_t& signals) {
    const char* reason = "end of source";
    int exit_code = EX_OK;
    while (true) {
        timespec wait{0, 100'000'000};
        const int sig = sigtimedwait(&signals, nullptr, &wait);
        if (sig == SIGTERM || sig == SIGINT) {
            reason = sig == SIGTERM ? "SIGTERM" : "SIGINT";
            break;
        }
        if (sig == SIGHUP) {
            logDebug(kReload, "SIGHUP");
            reload();
        }
        tick(monotonicNowNs());
        if (pipeline_->finished()) {
            if (auto f = pipeline_->failure()) {
                logError(kMain, f->message);
                reason = "source failed";
                exit_code = EX_IOERR;
            }
            break;
        }
    }
    if (tty_) {
        std::fputc('\n', stderr);
    }
    logInfo(kMain, std::string("stopping (") + reason + "), " + formatScale(hub_->scale()));
    teardown(reason);
    return exit_code;
}

void Daemon::openLights() {
    auto lights = StatusLights::open(config_.gpio);
    if (!lights) {
        logError(kGpio, lights.error().message + " (running without status LEDs)");
        events_->onError("gpio", lights.error().message);
        return;
    }
    if (!*lights) {
        logInfo(kGpio, "no chip configured (gpio.chip), no status LEDs");
        return;
    }
    lights_ = std::move(*lights);
    lights_->setPattern(LightPattern::kStarting);
    lights_->start();
    logInfo(kGpio, "status LEDs on " + lights_->describe());
}

void Daemon::openImu() {
    if (config_.imu.device.empty()) {
        return;
    }
    auto imu = ImuService::open(config_.imu);
    if (!imu) {
        imu_error_ = imu.error().message;
        logError(kImu,
                 imu_error_ +
                     " (running without the IMU: a new map's vertical comes from set_gravity, "
                     "the dataset or a level camera)");
        events_->onError("imu", imu_error_);
        return;
    }
    imu_ = std::move(*imu);
    imu_->start();
    // The first map takes its vertical from the window before it: let the
    // window fill (bounded; a silent device is reported, not waited for).
    const int wait_ms = static_cast<int>(std::lround(config_.imu.window_s * 2000)) + 1000;
    const bool filled = imu_->waitForWindow(wait_ms);
    const ImuStatus st = imu_->status();
    logInfo(kImu, st.device + ", " + st.mode +
                      (filled ? std::string()
                              : ": no full window of samples within " + std::to_string(wait_ms) +
                                    " ms" + (st.error.empty() ? "" : " (" + st.error + ")")));
}

void Daemon::tick(std::int64_t now_ns) {
    const PipelineStatus st = hub_->status();
    const ScaleReport r = hub_->scale();
    if (lights_) {
        lights_->setPattern(patternFor(r.state));
        // The heartbeat LED blinks while the tracking loop moves (it beats at
        // least every 200 ms, also when idle): a stuck pipeline freezes it.
        const std::uint64_t hb = pipeline_->heartbeat();
        if (hb != last_light_heartbeat_) {
            last_light_heartbeat_ = hb;
            last_beat_ns_ = now_ns;
        }
        lights_->setAlive(now_ns - last_beat_ns_ < 1'000'000'000);
        if (auto err = lights_->takeError()) {
            logWarning(kGpio, *err + " (the LEDs may be wrong)");
            events_->onError("gpio", *err);
        }
    }
    // Watchdog: only while the tracking loop moves, so a stuck pipeline gets restarted.
    if (auto wd = notifier_.watchdogTimeout()) {
        const std::int64_t half_ns = wd->count() * 1000 / 2;
        const std::uint64_t hb = pipeline_->heartbeat();
        if (now_ns - last_watchdog_ns_ >= half_ns && hb != last_heartbeat_) {
            notifier_.notify("WATCHDOG=1");
            last_watchdog_ns_ = now_ns;
            last_heartbeat_ = hb;
        }
    }
    // A field-log fault shows in every SCALE report.
    const LogStatus ls = hub_->logStatus();
    const std::string log_fault =
        ls.state == LogStatus::State::kFault ? "log: " + ls.error : std::string();
    if (log_fault != last_log_fault_) {
        pipeline_->setFault(log_fault);
        if (!log_fault.empty()) {
            logError(kMain, log_fault + " (logging stopped; the scale is still served)");
        }
        last_log_fault_ = log_fault;
    }
    if (now_ns - last_status_ns_ >=
        static_cast<std::int64_t>(config_.queues.status_interval_ms) * 1'000'000) {
        char fps[32];
        std::snprintf(fps, sizeof fps, ", %.1f fps", st.fps);
        notifier_.notify("STATUS=" + formatScale(r) + fps);
        last_status_ns_ = now_ns;
    }
    if (tty_ && now_ns - last_line_ns_ >= 250'000'000) {
        printStatusLine(st, r);
        last_line_ns_ = now_ns;
    }
}

// SIGHUP: re-read the file; apply the priors, the detector and the detection
// schedule; keep the posterior. Anything else that changed needs a restart.
void Daemon::reload() {
    notifier_.notify("RELOADING=1");
    auto fresh = loadDaemonConfig(cli_, config_.file);
    if (!fresh) {
        logError(kReload, fresh.error().message + " (keeping the running configuration)");
        events_->onError("reload", fresh.error().message);
        notifier_.notify("READY=1");
        return;
    }
    DaemonConfig next = config_;
    next.pipeline.priors_path = fresh->pipeline.priors_path;
    next.pipeline.detector = fresh->pipeline.detector;
    next.pipeline.detection = fresh->pipeline.detection;
    auto priors = openPriors(next);
    auto det = openDetector(next);
    if (!priors || !det) {
        const std::string msg = !priors ? priors.error().message : det.error().message;
        logError(kReload, msg + " (keeping the running configuration)");
        events_->onError("reload", msg);
        notifier_.notify("READY=1");
        return;
    }
    if (toToml(*fresh) != toToml(next)) {
        logWarning(kReload,
                   "only estimator.priors, [detector] and [detection] are reloaded; other "
                   "changes take effect at the next restart");
    }
    pipeline_->reload(std::move(*priors), std::move(*det), next.pipeline.detection);
    config_ = std::move(next);
    logInfo(kReload, "priors " + config_.pipeline.priors_path.string() + " and detector reloaded");
    const ScaleReport now = hub_->scale();
    events_->onState(now.state, now.state, now.epoch, now.frame_id,
                     "reload: priors, detector and detection schedule");
    notifier_.notify("READY=1");
}

// Reverse order of start-up: nothing new comes in, then the pipeline drains,
// then the socket closes, and the log is flushed and synced last.
void Daemon::teardown(const char* reason) {
    notifier_.notify("STOPPING=1");
    if (pipeline_) {
        pipeline_->stop();
    }
    if (socket_) {
        socket_->stop();
    }
    imu_.reset();     // after the pipeline that reads it: thread joined, buffer disabled
    lights_.reset();  // lines driven inactive and released
    if (events_) {
        events_->stop(reason);
    }
    if (log_) {
        log_->stop();
    }
}

// `scaled --list-cameras`: what to put in source.device, and the modes.
int listCameras() {
    std::vector<drivers::camera::CameraDescription> all = drivers::camera::listV4l2Cameras();
    for (auto& c : drivers::libcam::listLibcameraCameras()) {
        all.push_back(std::move(c));
    }
    if (all.empty()) {
        std::printf("no cameras found (V4L2: no capture device in /dev/video*%s)\n",
                    drivers::libcam::libcameraAvailable()
                        ? "; libcamera: none listed"
                        : "; this build has no libcamera support");
        return EX_OK;
    }
    for (const auto& c : all) {
        std::printf("%s:%s  %s%s%s%s\n", c.backend.c_str(), c.device.c_str(), c.name.c_str(),
                    c.bus.empty() ? "" : " (", c.bus.c_str(), c.bus.empty() ? "" : ")");
        if (!c.note.empty()) {
            std::printf("    %s\n", c.note.c_str());
        }
        for (const auto& f : c.formats) {
            std::printf("    %s\n", f.c_str());
        }
    }
    if (!drivers::libcam::libcameraAvailable()) {
        std::printf("(this build has no libcamera support)\n");
    }
    return EX_OK;
}

}  // namespace

int runMain(int argc, const char* const* argv) {
    ParsedCommandLine parsed = parseCommandLine(argc, argv);
    if (parsed.exit_now) {
        if (!parsed.output.empty()) {
            std::fputs(parsed.output.c_str(), stdout);
        }
        if (!parsed.error.empty()) {
            std::fputs(parsed.error.c_str(), stderr);  // prefixed and terminated already
        }
        return parsed.exit_code;
    }
    if (parsed.cli.list_cameras) {
        return listCameras();
    }
    const std::filesystem::path default_file =
        std::filesystem::path(SCALED_SYSCONFDIR) / "scaled" / "scaled.toml";
    if (parsed.cli.check_config) {
        return checkConfigurationAndReport(parsed.cli, default_file);
    }
    auto config = loadDaemonConfig(parsed.cli, default_file);
    if (!config) {
        logError(kMain, config.error().message);
        return EX_CONFIG;
    }
    drivers::base::setLogLevel(config->log.level);
    if (auto group = checkSocketGroup(config->socket); !group) {
        logError(kMain, "socket.group: " + group.error().message);
        return group.error().code == ErrorCode::kNotFound ? EX_CONFIG : EX_OSERR;
    }
    Daemon daemon(std::move(parsed.cli), std::move(*config));
    return daemon.run();
}

}  // namespace scaled::daemon
