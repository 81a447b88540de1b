// scalectl: asks the scaled daemon for the metric scale over its UNIX socket.
//
//   scalectl [--socket PATH] [--json] [--timeout SECONDS]
//            get [--require-converged] | watch [--count N] [--pose] | status | posterior |
//            objects | pose
//
// Exit codes (sysexits): 0 ok, 64 usage, 69 the daemon cannot be reached (no
// socket, refused, no answer within --timeout, closed early), 75 `get
// --require-converged` and not converged, 76 malformed reply, wrong protocol
// version (objects: a daemon older than protocol 1.3; pose, watch --pose: 1.4) or an ERROR
// reply. The logic is in
// scalectl.{h,cpp}.

#include <CLI/CLI.hpp>
#include <array>
#include <csignal>
#include <cstdint>
#include <fcntl.h>
#include <iostream>
#include <string>
#include <unistd.h>

#include "scalectl.h"
#include "sysexits.h"

namespace {

namespace ctl = scaled::tools::scalectl;

// The write end of the self-pipe that ends `watch` on SIGINT/SIGTERM.
int g_interrupt_write_fd = -1;  // NOLINT(cppcoreguidelines-avoid-non-const-global-variables)

extern "C" void onInterrupt(int /*signal*/) {
    const char byte = 1;
    [[maybe_unused]] const auto n = ::write(g_interrupt_write_fd, &byte, 1);
}

// A pipe whose read end becomes readable on SIGINT or SIGTERM; -1 on failure
// (the signals then keep their default action).
int installInterruptPipe() {
    std::array<int, 2> fds{-1, -1};
    if (::pipe2(fds.data(), O_CLOEXEC | O_NONBLOCK) != 0) {
        return -1;
    }
    g_interrupt_write_fd = fds[1];
    struct sigaction action = {};
    action.sa_handler = onInterrupt;
    sigemptyset(&action.sa_mask);
    action.sa_flags = 0;  // no SA_RESTART: poll() returns at once
    ::sigaction(SIGINT, &action, nullptr);
    ::sigaction(SIGTERM, &action, nullptr);
    return fds[0];
}

}  // namespace

int main(int argc, char** argv) {
    ctl::Options options;
    options.socket_path = ctl::defaultSocketPath();

    CLI::App app{
        "Asks the scaled daemon for the metric scale of its SLAM map (metres per SLAM unit).\n"
        "Exit codes: 0 ok, 64 usage, 69 daemon unreachable or silent, 75 get "
        "--require-converged\nand not converged, 76 malformed reply, wrong protocol or ERROR "
        "reply.",
        "scalectl"};
    app.footer(
        "usage: scalectl [--socket PATH] [--json] [--timeout SECONDS]\n"
        "                get [--require-converged] | watch [--count N] [--pose] | status |\n"
        "                posterior | objects | pose\n");
    app.require_subcommand(1);
    app.fallthrough();  // global options may also follow the subcommand
    app.add_option("--socket", options.socket_path,
                   "the daemon's socket (default: $SCALED_SOCKET, else /run/scaled/scaled.sock)");
    app.add_flag("--json", options.json, "print the daemon's JSON lines as they are");
    double timeout_s = 0.0;
    auto* timeout_opt = app.add_option("--timeout", timeout_s,
                                       "bound on every wait, seconds (default 5; watch: no "
                                       "bound between lines unless given)")
                            ->check(CLI::Range(0.001, 86400.0));

    auto* get = app.add_subcommand("get", "print the current scale estimate (one line)");
    get->add_flag("--require-converged", options.require_converged,
                  "exit 75 (EX_TEMPFAIL) unless the state is converged");
    auto* watch = app.add_subcommand("watch", "print a line per scale update or state change");
    std::int64_t count = 0;
    auto* count_opt = watch->add_option("--count", count, "stop after N lines")
                          ->check(CLI::Range(std::int64_t{1}, std::int64_t{1000000000}));
    watch->add_flag("--pose", options.pose,
                    "stream the camera pose (POSE, a line per tracked frame up to "
                    "socket.pose_rate_hz) instead of the scale");
    auto* status = app.add_subcommand("status", "print the daemon's status");
    auto* posterior =
        app.add_subcommand("posterior", "print the scale posterior as d<TAB>log_p rows");
    auto* objects = app.add_subcommand(
        "objects", "print the object table (estimator.model = \"object\"), a row per object");
    auto* pose = app.add_subcommand(
        "pose",
        "print the latest camera pose: position (m) and its 1-sigma, yaw/pitch/roll, "
        "velocity, scale state (one line)");

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        const int rc = app.exit(e);
        return rc == 0 ? 0 : scaled::tools::kExUsage;
    }

    if (timeout_opt->count() > 0) {
        options.timeout_s = timeout_s;
    }
    if (get->parsed()) {
        options.command = ctl::Command::kGet;
    } else if (watch->parsed()) {
        options.command = ctl::Command::kWatch;
        if (count_opt->count() > 0) {
            options.count = count;
        }
        options.interrupt_fd = installInterruptPipe();
    } else if (status->parsed()) {
        options.command = ctl::Command::kStatus;
    } else if (posterior->parsed()) {
        options.command = ctl::Command::kPosterior;
    } else if (objects->parsed()) {
        options.command = ctl::Command::kObjects;
    } else if (pose->parsed()) {
        options.command = ctl::Command::kPose;
    }
    return ctl::run(options, std::cout, std::cerr);
}
