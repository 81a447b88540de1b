#pragma once

// SocketService: the daemon's UNIX socket server (protocol: docs/protocol.md).
//
// One thread runs a poll() loop over the listening socket, the clients, the
// hub's wake eventfd and a stop eventfd. Every client socket is non-blocking
// and has its own input and output buffers. Flow control: while more than
// half of SocketConfig::client_buffer_bytes of a client's output is unsent,
// the loop stops reading its requests (no POLLIN) and reads again once it is
// down to a quarter, so the replies to a pipelining client never outgrow its
// buffer and never get it detached. A client is detached (closed and
// counted) only when a SCALE/POSE line for it would take its unsent output
// above client_buffer_bytes, or when its output has waited stall_timeout_s
// with none of it read: a watcher that never reads never stalls the loop or
// the pipeline. A request line left incomplete for request_timeout_s (while
// the loop reads) gets an ERROR and the connection is closed. Connections
// are accepted up to max_clients, and beyond that (up to max_clients +
// reserved_query_slots) while fewer than reserved_query_slots connections
// are not watchers; watchers are at most max_clients. So a query gets in
// whatever the watchers do. When there is no room, a new client may replace
// the non-watching connection idle longest (at least request_timeout_s).
// poll()'s timeout is the nearest of these deadlines. Replies are built in
// one reused buffer; a SCALE for the watchers is built once per publish and
// written to each of them; so is a POSE for the pose watchers (thinned by
// PoseRateLimiter to SocketConfig::pose_rate_hz).
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
#include <scaled/drivers/ipc/unix_socket.h>

namespace scaled::daemon {

struct SocketServiceStats {
    int connected = 0;           // clients connected now
    std::uint64_t accepted = 0;  // connections accepted since start
    // Refused: no room (SocketService's comment above) and none idle.
    std::uint64_t rejected = 0;
    // Closed because they did not read their output: a SCALE/POSE line would
    // have overflowed client_buffer_bytes, or `stalled`.
    std::uint64_t detached = 0;
    std::uint64_t stalled = 0;         // of `detached`: output unread for stall_timeout_s
    std::uint64_t timed_out = 0;       // closed: a request incomplete for request_timeout_s
    std::uint64_t evicted = 0;         // idle, closed to make room for a new client
    std::uint64_t watch_refused = 0;   // `watch` refused: max_clients were watching
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
    core::Status start();
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
                  drivers::ipc::ListeningSocket listener, drivers::base::UniqueFd stop_fd);
    void run();

    SocketConfig config_;
    ReportHub& hub_;
    std::string release_;
    drivers::ipc::ListeningSocket listener_;
    std::filesystem::path path_;
    drivers::base::UniqueFd stop_fd_;
    std::thread thread_;
    bool started_ = false;
    bool stopped_ = false;

    std::atomic<int> connected_{0};
    std::atomic<std::uint64_t> accepted_{0};
    std::atomic<std::uint64_t> rejected_{0};
    std::atomic<std::uint64_t> detached_{0};
    std::atomic<std::uint64_t> stalled_{0};
    std::atomic<std::uint64_t> timed_out_{0};
    std::atomic<std::uint64_t> evicted_{0};
    std::atomic<std::uint64_t> watch_refused_{0};
    std::atomic<std::uint64_t> requests_{0};
    std::atomic<std::uint64_t> errors_{0};
    std::atomic<std::uint64_t> poses_streamed_{0};
};

}  // namespace scaled::daemon
