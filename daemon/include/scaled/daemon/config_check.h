#pragma once

// `scaled --check-config`: every check that start-up runs and that can run
// without side effects, all of them reported, not the first.
//
// First the configuration itself (daemon_config.h: syntax, unknown keys,
// types, ranges, cross-field rules; every problem of the file and of the
// command line), then what it names: the priors file parses, the detector's
// model loads, the replay dataset opens, a V4L2 device given as a path is a
// character device, the socket's group exists, the socket's directory exists
// and this user may create the socket in it (and the path is not some other
// kind of file), the field log's directory is writable or can be created.
// Nothing is created, bound, opened for writing or started.
//
// Each error reads `WHERE: section.key: what (got VALUE)`, WHERE being
// `FILE:LINE` of the key, the `--set`/`--source`/... that set it, or the file
// (or "built-in defaults") when the key keeps its default. Start-up exits 78
// (EX_CONFIG) on the same problems; a directory made by systemd for the
// service (RuntimeDirectory=, LogsDirectory=) that does not exist yet is a
// note, not an error, since the unit creates it.

#include <filesystem>
#include <string>
#include <vector>

#include <scaled/daemon/daemon_config.h>

namespace scaled::daemon {

struct ConfigCheckReport {
    std::filesystem::path file;       // the file checked; empty: the built-in defaults
    std::vector<std::string> errors;  // `WHERE: section.key: what (got VALUE)`
    std::vector<std::string> notes;   // fine, but worth a line (built-in priors, ...)
    [[nodiscard]] bool ok() const { return errors.empty(); }
};

ConfigCheckReport checkConfiguration(const CommandLine& cli,
                                     const std::filesystem::path& default_config_file);

// The socket's group, when one is configured: kNotFound when no such group
// exists (start-up exits 78 on it, as --check-config reports it).
[[nodiscard]] core::Status checkSocketGroup(const SocketConfig& socket);

}  // namespace scaled::daemon
