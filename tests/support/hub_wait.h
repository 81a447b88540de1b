#pragma once

// Waiting for the daemon's ReportHub in tests: on its wake eventfd, with a
// deadline, never a sleep.

#include <chrono>
#include <functional>
#include <poll.h>

#include <scaled/daemon/report.h>

namespace scaled::test {

// Waits until pred() holds or `timeout` passes (false then). Wakes on every
// publish of the hub (and at least every 100 ms to re-check pred).
inline bool waitUntil(const daemon::ReportHub& hub, const std::function<bool()>& pred,
                      std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!pred()) {
        if (std::chrono::steady_clock::now() >= deadline) {
            return false;
        }
        pollfd p{hub.wakeFd(), POLLIN, 0};
        if (poll(&p, 1, 100) > 0) {
            hub.consumeWake();
        }
    }
    return true;
}

}  // namespace scaled::test
