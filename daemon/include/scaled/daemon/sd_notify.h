#pragma once

// The systemd notification protocol (sd_notify(3)), spoken directly: one
// datagram of `KEY=VALUE` lines to the AF_UNIX socket named by $NOTIFY_SOCKET
// (a path, or an abstract name when it starts with '@'). Without
// $NOTIFY_SOCKET (not started by systemd) every call is a no-op that reports
// false. No libsystemd: the protocol is stable and tiny, and this keeps the
// daemon free of a library it would use for two calls.

#include <chrono>
#include <optional>
#include <string_view>

#include <scaled/drivers/base/unique_fd.h>

namespace scaled::daemon {

class SdNotifier {
public:
    // Reads $NOTIFY_SOCKET, $WATCHDOG_USEC and $WATCHDOG_PID once.
    SdNotifier();
    ~SdNotifier();
    SdNotifier(const SdNotifier&) = delete;
    SdNotifier& operator=(const SdNotifier&) = delete;
    SdNotifier(SdNotifier&&) = delete;
    SdNotifier& operator=(SdNotifier&&) = delete;

    // Sends `state` (e.g. "READY=1", "STATUS=converged 0.976", "WATCHDOG=1",
    // "STOPPING=1"; several lines joined by '\n'). true when it was sent.
    // Never blocks: when the manager's queue is full the message is dropped
    // (false).
    bool notify(std::string_view state) const;

    [[nodiscard]] bool enabled() const { return fd_.isValid(); }
    // The watchdog timeout systemd expects WATCHDOG=1 within (WatchdogSec=),
    // when set for this process.
    [[nodiscard]] std::optional<std::chrono::microseconds> watchdogTimeout() const {
        return watchdog_;
    }

private:
    drivers::base::UniqueFd fd_;
    alignas(8) char address_[128] = {};  // a sockaddr_un (110 bytes)
    unsigned address_len_ = 0;
    std::optional<std::chrono::microseconds> watchdog_;
};

}  // namespace scaled::daemon
