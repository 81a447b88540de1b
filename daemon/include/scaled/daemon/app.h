#pragma once

// The daemon as a program: parses the command line, loads the configuration,
// brings the parts up in dependency order (field log, report hub, source and
// detector, socket, pipeline), tells systemd it is ready, then runs the main
// loop (signals, watchdog, STATUS=, the live status line) until SIGTERM/SIGINT
// or the end of a replay with at_end = "exit", and takes the parts down in
// reverse order. main.cpp only calls runMain, so the tests link everything
// but main (chrony's layout).

namespace scaled::daemon {

// Returns the process exit code (sysexits: 0, 64 usage, 66 missing input,
// 69 unavailable, 70 internal, 73 cannot create the socket, 78 bad config).
int runMain(int argc, const char* const* argv);

}  // namespace scaled::daemon
