#pragma once

// SocketService: the daemon's UNIX socket server (protocol: docs/protocol.md).
//
// One thread runs a poll() loop over the listening socket, the clients, the
// hub's wake eventfd and a stop eventfd. Every client socket is non-blocking
// and has its own output buffer; a client whose unsent output would exceed
// SocketConfig::client_buffer_bytes is detached (closed and counted), so a
// watcher that never reads never stalls the loop or the pipeline. Replies are
// built in one reused buffer; a SCALE for the watchers is built once per
// publish and written to each of them; so is a POSE for the pose watchers
// (thinned by PoseRateLimiter to SocketConfig::pose_rate_hz).
//
// The listening socket is made in create() (or inherited through systemd
// socket activation, LISTEN_FDS), so configuration errors appear before the
// pipeline starts; clients connecting before start() wait in the backlog.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include <scaled/core/result.h>
#include <scaled/daemon/daemon_config.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/report.h>
#include <scaled/drivers/unix_socket.h>

namespace scaled::daemon {

struct SocketServiceStats {
    int connected = 0;                 // clients connected now
    std::uint64_t accepted = 0;        // connections accepted since start
    std::uint64_t rejected = 0;        // refused because max_clients were connected
    std::uint64_t detached = 0;        // closed because their output buffer overflowed
    std::uint64_t requests = 0;        // request lines handled (blank lines not counted)
    std::uint64_t errors = 0;          // ERROR replies sent
    std::uint64_t poses_streamed = 0;  // POSE lines built for the pose watchers
};

class SocketService {
public:
    // Creates (or adopts, when socket-activated) the listening socket.
    static core::Result<std::unique_ptr<SocketService>> create(const SocketConfig& config,
                                                               ReportHub& hub, std::string release);
    ~SocketService();
    SocketService(const SocketService&) = delete;
    SocketService& operator=(const SocketService&) = delete;
    SocketService(SocketService&&) = delete;
    SocketService& operator=(SocketService&&) = delete;

    // Starts the thread (once).
    core::Result<bool> start();
    // Wakes and joins the thread, closes the clients and the listening socket
    // and removes the socket file if this process created it (never when
    // socket-activated). Idempotent; the destructor calls it.
    void stop();

    [[nodiscard]] SocketServiceStats stats() const;
    [[nodiscard]] bool socketActivated() const { return listener_.activated; }
    // The socket's path (for an activated socket: the address it is bound to,
    // else the configured path).
    [[nodiscard]] const std::filesystem::path& path() const { return path_; }

private:
    struct Loop;  // the thread's state (clients, buffers)

    SocketService(const SocketConfig& config, ReportHub& hub, std::string release,
                  drivers::ListeningSocket listener, drivers::UniqueFd stop_fd);
    void run();

    SocketConfig config_;
    ReportHub& hub_;
    std::string release_;
    drivers::ListeningSocket listener_;
    std::filesystem::path path_;
    drivers::UniqueFd stop_fd_;
    std::thread thread_;
    bool started_ = false;
    bool stopped_ = false;

    std::atomic<int> connected_{0};
    std::atomic<std::uint64_t> accepted_{0};
    std::atomic<std::uint64_t> rejected_{0};
    std::atomic<std::uint64_t> detached_{0};
    std::atomic<std::uint64_t> requests_{0};
    std::atomic<std::uint64_t> errors_{0};
    std::atomic<std::uint64_t> poses_streamed_{0};
};

}  // namespace scaled::daemon
