#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <string>
#include <string_view>
#include <sys/stat.h>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <scaled/daemon/config_check.h>
#include <scaled/drivers/dataset/dataset.h>
#include <scaled/drivers/detector/dnn_detector.h>
#include <scaled/drivers/ipc/unix_socket.h>
#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/source/frame_source.h>

#include "config_registry.h"

namespace scaled::daemon {
namespace {

std::string quoted(const std::filesystem::path& p) {
    return "\"" + p.string() + "\"";
}

std::string errnoMessage(int err) {
    return std::error_code(err, std::generic_category()).message();
}

// Reports problems at the place that set their key; keys whose value was
// already refused are not checked again (their default would be blamed).
class Reporter {
public:
    Reporter(const CheckedConfig& checked, ConfigCheckReport& report)
        : checked_(checked), report_(report) {}

    [[nodiscard]] bool refused(std::string_view key) const {
        return std::any_of(checked_.error_keys.begin(), checked_.error_keys.end(),
                           [&](const std::string& k) { return config_detail::keyCovers(k, key); });
    }
    void error(const std::string& key, const std::string& what, const std::string& got) {
        report_.errors.push_back(checked_.locate({key}) + ": " + key + ": " + what + " (got " +
                                 got + ")");
    }
    void note(std::string what) { report_.notes.push_back(std::move(what)); }
    [[nodiscard]] const DaemonConfig& config() const { return checked_.config; }

private:
    const CheckedConfig& checked_;
    ConfigCheckReport& report_;
};

// The directory `dir` exists and this process may create files in it, or it
// does not exist yet and the nearest existing ancestor lets it be created.
// Returns what is wrong, empty when fine.
std::string creatableIn(const std::filesystem::path& dir, bool may_create) {
    std::error_code ec;
    const auto st = std::filesystem::status(dir, ec);
    if (std::filesystem::exists(st)) {
        if (!std::filesystem::is_directory(st)) {
            return quoted(dir) + " is not a directory";
        }
        if (::access(dir.c_str(), W_OK | X_OK) != 0) {
            return "cannot create files in " + quoted(dir) + ": " + errnoMessage(errno);
        }
        return {};
    }
    if (!may_create) {
        return "the directory " + quoted(dir) + " does not exist";
    }
    auto parent = dir.parent_path();
    while (!parent.empty() && !std::filesystem::exists(parent, ec)) {
        if (parent == parent.parent_path()) {
            break;
        }
        parent = parent.parent_path();
    }
    if (parent.empty()) {
        parent = ".";
    }
    if (!std::filesystem::is_directory(parent, ec)) {
        return "cannot create " + quoted(dir) + ": " + quoted(parent) + " is not a directory";
    }
    if (::access(parent.c_str(), W_OK | X_OK) != 0) {
        return "cannot create " + quoted(dir) + ": " + quoted(parent) + ": " + errnoMessage(errno);
    }
    return {};
}

void checkPriors(Reporter& r) {
    const auto& path = r.config().pipeline.priors_path;
    if (r.refused("estimator.priors") || path.empty()) {
        return;  // an empty path is the configuration check's
    }
    std::error_code ec;
    if (path == defaultDaemonConfig().pipeline.priors_path && !std::filesystem::exists(path, ec)) {
        r.note("estimator.priors: " + path.string() +
               " does not exist: the daemon will use the priors built into it (the "
               "repository's config/priors.toml)");
        return;
    }
    if (auto priors = drivers::priors::loadPriorsFile(path); !priors) {
        r.error("estimator.priors", priors.error().message, quoted(path));
    }
}

void checkDetector(Reporter& r) {
    const auto& c = r.config();
    if (c.source.kind == SourceKind::kSim) {
        return;  // the sim source detects its own objects
    }
    const auto& d = c.pipeline.detector;
    if (r.refused("detector")) {
        return;
    }
    if (d.model_path.empty()) {
        r.error("detector.model", "not set (the YOLOX-Nano ONNX model; see config/scaled.toml)",
                "\"\"");
        return;
    }
    if (auto det = drivers::detector::DnnDetector::create(d); !det) {
        r.error("detector.model", det.error().message, quoted(d.model_path));
    }
}

void checkSource(Reporter& r) {
    const auto& s = r.config().source;
    switch (s.kind) {
        case SourceKind::kSim:
            return;
        case SourceKind::kReplay:
            if (!r.refused("source.replay") && !s.replay_path.empty()) {
                if (auto src = drivers::dataset::openDataset(s.replay_path); !src) {
                    r.error("source.replay", src.error().message, quoted(s.replay_path));
                }
            }
            return;
        case SourceKind::kV4l2: {
            if (r.refused("source.device") || s.device.empty()) {
                return;
            }
            if (s.device.front() != '/') {
                r.note("source.device \"" + s.device +
                       "\" is a card name: it is looked up when the camera opens");
                return;
            }
            struct stat st = {};
            if (::stat(s.device.c_str(), &st) != 0) {
                r.error("source.device", "cannot open the camera: " + errnoMessage(errno),
                        "\"" + s.device + "\"");
            } else if (!S_ISCHR(st.st_mode)) {
                r.error("source.device", "not a character device (a V4L2 node, /dev/videoN)",
                        "\"" + s.device + "\"");
            }
            return;
        }
        case SourceKind::kLibcamera:
            r.note("source.device \"" + s.device +
                   "\": libcamera cameras are looked up when the camera opens");
            return;
    }
}

void checkSocket(Reporter& r) {
    const auto& k = r.config().socket;
    if (!r.refused("socket.group")) {
        if (auto g = checkSocketGroup(k); !g) {
            r.error("socket.group", g.error().message, "\"" + k.group + "\"");
        }
    }
    if (r.refused("socket.path") || k.path.empty()) {
        return;
    }
    const auto dir =
        k.path.parent_path().empty() ? std::filesystem::path(".") : k.path.parent_path();
    std::error_code ec;
    if (dir == defaultDaemonConfig().socket.path.parent_path() &&
        !std::filesystem::exists(dir, ec)) {
        r.note("socket.path: " + dir.string() +
               " does not exist: the service's unit makes it (RuntimeDirectory=scaled); to run "
               "by hand, --socket PATH in a directory you can write");
        return;
    }
    if (auto bad = creatableIn(dir, false); !bad.empty()) {
        r.error("socket.path", bad, quoted(k.path));
        return;
    }
    const auto st = std::filesystem::symlink_status(k.path, ec);
    if (std::filesystem::exists(st) && !std::filesystem::is_socket(st)) {
        r.error("socket.path", "exists and is not a socket (it is not replaced)", quoted(k.path));
    }
}

void checkLog(Reporter& r) {
    const auto& l = r.config().log;
    if (!l.enabled || r.refused("log.dir") || l.dir.empty()) {
        return;
    }
    std::error_code ec;
    if (l.dir == defaultDaemonConfig().log.dir && !std::filesystem::exists(l.dir, ec)) {
        r.note("log.dir: " + l.dir.string() +
               " does not exist: the service's unit makes it (LogsDirectory=scaled)");
        return;
    }
    if (auto bad = creatableIn(l.dir, true); !bad.empty()) {
        r.error("log.dir", bad, quoted(l.dir));
    }
}

}  // namespace

core::Status checkSocketGroup(const SocketConfig& socket) {
    if (socket.group.empty()) {
        return {};
    }
    auto gid = drivers::ipc::lookupGroup(socket.path, socket.group);
    if (!gid) {
        return gid.error();
    }
    return {};
}

ConfigCheckReport checkConfiguration(const CommandLine& cli,
                                     const std::filesystem::path& default_config_file) {
    const CheckedConfig checked = checkDaemonConfig(cli, default_config_file);
    ConfigCheckReport report;
    report.file = checked.config.file;
    for (const auto& e : checked.errors) {
        report.errors.push_back(e.message);
    }
    // A file that could not be read or parsed has nothing more to check.
    const bool unreadable =
        !checked.errors.empty() && std::all_of(checked.error_keys.begin(), checked.error_keys.end(),
                                               [](const std::string& k) { return k.empty(); });
    if (unreadable) {
        return report;
    }
    Reporter r(checked, report);
    checkSource(r);
    checkDetector(r);
    checkPriors(r);
    checkSocket(r);
    checkLog(r);
    return report;
}

}  // namespace scaled::daemon
