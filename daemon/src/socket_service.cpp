#include <algorithm>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <linux/sockios.h>
#include <poll.h>
#include <pthread.h>
#include <string_view>
#include <sys/eventfd.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <scaled/daemon/protocol.h>
#include <scaled/daemon/socket_service.h>

namespace scaled::daemon {
namespace {

// Bytes read from one client per recv() and at most kReadRounds times per
// loop turn, so one busy client cannot starve the others.
constexpr std::size_t kReadChunk = 16384;
constexpr int kReadRounds = 4;
// Poll timeouts (ms): without a hub eventfd the loop polls scaleSequence();
// after accept() failed (EMFILE, ...) the listening socket rests a while.
constexpr int kNoWakeFdPollMs = 20;
constexpr int kAcceptBackoffMs = 100;
constexpr std::int64_t kNoDeadline = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kNsPerMs = 1'000'000;

bool sameReport(const ScaleReport& a, const ScaleReport& b) {
    return a.has_scale == b.has_scale && a.scale == b.scale && a.mean == b.mean &&
           a.ci68_lo == b.ci68_lo && a.ci68_hi == b.ci68_hi && a.ci95_lo == b.ci95_lo &&
           a.ci95_hi == b.ci95_hi && a.state == b.state && a.epoch == b.epoch &&
           a.observations == b.observations && a.frame_id == b.frame_id && a.t_ns == b.t_ns &&
           a.updated_mono_ns == b.updated_mono_ns && a.fault == b.fault;
}

bool isBlank(std::string_view line) {
    return std::all_of(line.begin(), line.end(),
                       [](char c) { return c == ' ' || c == '\t' || c == '\r'; });
}

std::int64_t secondsToNs(double s) {
    return static_cast<std::int64_t>(std::llround(s * 1e9));
}

// The shortest text of `v` that reads back the same ("5", "0.2").
std::string shortest(double v) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return {buf, r.ptr};
}

// Bytes the peer has not read yet from the socket's queue (SIOCOUTQ); 0 when
// the kernel does not say.
int unreadBytes(int fd) {
    int n = 0;
    return ::ioctl(fd, SIOCOUTQ, &n) == 0 ? n : 0;
}

}  // namespace

struct SocketService::Loop {
    struct Client {
        drivers::base::UniqueFd fd;
        std::string in;           // received, not handled yet: in[in_off, size)
        std::size_t in_off = 0;   // (complete lines first, then an incomplete one)
        bool discarding = false;  // skipping the rest of an oversize line
        std::string out;          // unsent output: out[out_off, size)
        std::size_t out_off = 0;
        bool watching = false;       // SCALE stream
        bool watching_pose = false;  // POSE stream
        bool paused = false;         // not reading: output above the high-water mark
        bool eof = false;            // the client closed its sending side
        bool closing = false;        // close once the output is sent (timed out)
        bool dead = false;
        std::int64_t line_since_ns = 0;   // an incomplete line waits since (0: none)
        std::int64_t stall_since_ns = 0;  // output waits, none read since (0: none)
        int stall_unread_bytes = 0;       // the kernel's unread bytes then
        std::int64_t active_ns = 0;       // the last bytes received (or the connect)
        [[nodiscard]] std::size_t pending() const { return out.size() - out_off; }
        [[nodiscard]] bool reading() const { return !paused && !eof && !closing && !dead; }
        [[nodiscard]] bool watcher() const { return watching || watching_pose; }
        [[nodiscard]] std::string_view input() const { return std::string_view(in).substr(in_off); }
    };

    explicit Loop(SocketService& s)
        : svc(s),
          pose_limiter(s.config_.pose_rate_hz),
          high_water(s.config_.client_buffer_bytes / 2),
          low_water(s.config_.client_buffer_bytes / 4),
          request_timeout_ns(secondsToNs(s.config_.request_timeout_s)),
          stall_timeout_ns(secondsToNs(s.config_.stall_timeout_s)),
          max_connections(s.config_.max_clients + s.config_.reserved_query_slots),
          timeout_message("request incomplete after " + shortest(s.config_.request_timeout_s) +
                          " s (closing)") {
        reply.reserve(1 << 16);
        scale_line.reserve(1024);
        pose_line.reserve(2048);
        clients.reserve(static_cast<std::size_t>(std::max(max_connections, 1)) + 2);
        fds.reserve(clients.capacity() + 3);
    }

    SocketService& svc;
    std::vector<std::unique_ptr<Client>> clients;
    std::vector<pollfd> fds;
    std::string reply;       // every reply is built here
    std::string scale_line;  // the SCALE for the watchers, built once per publish
    ScaleReport latest;      // the report the watchers saw last
    std::uint64_t seen_seq = 0;
    std::string pose_line;   // the POSE for the pose watchers, built once per admitted pose
    PoseReport latest_pose;  // the hub's latest pose as this loop saw it
    std::uint64_t seen_pose_seq = 0;
    PoseRateLimiter pose_limiter;
    PosteriorSnapshot posterior;
    ObjectsSnapshot objects;  // the hub's table, copied for an OBJECTS reply
    bool accept_paused = false;
    const std::size_t high_water;  // stop reading a client above this much unsent output
    const std::size_t low_water;   // read it again at this much
    const std::int64_t request_timeout_ns;
    const std::int64_t stall_timeout_ns;
    const int max_connections;
    const std::string timeout_message;

    void run();
    [[nodiscard]] int pollTimeoutMs(int base_ms, std::int64_t now) const;
    void checkDeadlines(std::int64_t now);
    void refreshScale();
    void refreshPose();
    void acceptAll();
    bool evictIdle(std::int64_t now);
    void readClient(Client& c);
    void processInput(Client& c);
    void handleLine(Client& c, std::string_view line);
    void queue(Client& c, std::string_view msg, bool stream);
    void flush(Client& c);
    void afterOutput(Client& c);
    std::size_t sendSome(Client& c, std::string_view data);
    void startStall(Client& c, std::int64_t now);
    void close(Client& c);
    void detach(Client& c);
    void error(Client& c, std::string_view message, std::string_view cmd);
    [[nodiscard]] int watchers() const;
};

void SocketService::Loop::run() {
    seen_seq = svc.hub_.scaleSequence();
    latest = svc.hub_.scale();
    const int wake_fd = svc.hub_.wakeFd();
    const int listen_fd = svc.listener_.fd.get();
    for (;;) {
        fds.clear();
        fds.push_back({svc.stop_fd_.get(), POLLIN, 0});
        const std::size_t wake_idx = fds.size();
        if (wake_fd >= 0) {
            fds.push_back({wake_fd, POLLIN, 0});
        }
        const std::size_t listen_idx = fds.size();
        if (!accept_paused) {
            fds.push_back({listen_fd, POLLIN, 0});
        }
        const std::size_t first_client = fds.size();
        const std::size_t polled_clients = clients.size();
        for (const auto& c : clients) {
            // No POLLIN while paused: the client's requests wait in the kernel.
            const auto events =
                static_cast<short>((c->reading() ? POLLIN : 0) | (c->pending() > 0 ? POLLOUT : 0));
            fds.push_back({c->fd.get(), events, 0});
        }
        int timeout_ms = wake_fd >= 0 ? -1 : kNoWakeFdPollMs;
        if (accept_paused) {
            timeout_ms = kAcceptBackoffMs;
        }
        timeout_ms = pollTimeoutMs(timeout_ms, monotonicNowNs());
        const int n = ::poll(fds.data(), fds.size(), timeout_ms);
        if (n < 0 && errno != EINTR) {
            // EINVAL/ENOMEM: nothing sensible to do but try again shortly.
            ::poll(nullptr, 0, kAcceptBackoffMs);
        }
        if (fds[0].revents != 0) {
            break;
        }
        const bool accept_was_paused = accept_paused;
        accept_paused = false;
        if (wake_fd >= 0 && (fds[wake_idx].revents & POLLIN) != 0) {
            svc.hub_.consumeWake();
        }
        refreshScale();
        refreshPose();
        for (std::size_t i = 0; i < polled_clients; ++i) {
            Client& c = *clients[i];
            const short re = fds[first_client + i].revents;
            if (c.dead || re == 0) {
                continue;
            }
            const bool hangup = (re & (POLLHUP | POLLERR)) != 0;
            if (c.pending() > 0 && ((re & POLLOUT) != 0 || hangup)) {
                flush(c);  // a peer that is gone fails here (EPIPE) and is closed
            }
            if (c.reading() && ((re & POLLIN) != 0 || hangup)) {
                readClient(c);
            }
            if (!c.dead && hangup && !c.reading() && c.pending() == 0) {
                close(c);  // nothing left to read or to send: do not spin on POLLHUP
            }
        }
        checkDeadlines(monotonicNowNs());
        if (!accept_was_paused && (fds[listen_idx].revents & POLLIN) != 0) {
            acceptAll();
        }
        std::erase_if(clients, [](const auto& c) { return c->dead; });
    }
    for (auto& c : clients) {
        c->fd.reset();
    }
    clients.clear();
    svc.connected_.store(0);
}

// `base_ms` (-1: none), shortened to the nearest client deadline: an
// incomplete request line (while the client is read) or output waiting to be
// read. Rounded up, so the loop wakes at or after the deadline, never spins.
int SocketService::Loop::pollTimeoutMs(int base_ms, std::int64_t now) const {
    std::int64_t deadline = kNoDeadline;
    for (const auto& c : clients) {
        if (c->dead) {
            continue;
        }
        if (c->reading() && c->line_since_ns != 0) {
            deadline = std::min(deadline, c->line_since_ns + request_timeout_ns);
        }
        if (c->pending() > 0 && c->stall_since_ns != 0) {
            deadline = std::min(deadline, c->stall_since_ns + stall_timeout_ns);
        }
    }
    if (deadline == kNoDeadline) {
        return base_ms;
    }
    const std::int64_t wait_ns = std::max<std::int64_t>(deadline - now, 0);
    const std::int64_t wait_ms =
        std::min<std::int64_t>((wait_ns + kNsPerMs - 1) / kNsPerMs, INT_MAX);
    return base_ms < 0 ? static_cast<int>(wait_ms) : std::min(base_ms, static_cast<int>(wait_ms));
}

void SocketService::Loop::checkDeadlines(std::int64_t now) {
    for (auto& cp : clients) {
        Client& c = *cp;
        if (!c.dead && c.reading() && c.line_since_ns != 0 &&
            now - c.line_since_ns >= request_timeout_ns) {
            svc.timed_out_.fetch_add(1);
            c.closing = true;
            c.in.clear();
            c.in_off = 0;
            c.line_since_ns = 0;
            error(c, timeout_message, {});
            afterOutput(c);
        }
        if (!c.dead && c.pending() > 0 && c.stall_since_ns != 0 &&
            now - c.stall_since_ns >= stall_timeout_ns) {
            // POLLOUT comes only once the peer has read most of the kernel's
            // buffer; a slow reader shows up here as fewer unread bytes.
            const int unread = unreadBytes(c.fd.get());
            if (unread < c.stall_unread_bytes) {
                c.stall_since_ns = now;
                c.stall_unread_bytes = unread;
            } else {
                svc.stalled_.fetch_add(1);
                detach(c);
            }
        }
    }
}

void SocketService::Loop::refreshScale() {
    const std::uint64_t seq = svc.hub_.scaleSequence();
    if (seq == seen_seq) {
        return;
    }
    seen_seq = seq;
    ScaleReport report = svc.hub_.scale();
    // A publish racing the sequence read is already in `report`; its wake
    // then finds the same report and sends nothing twice.
    if (sameReport(report, latest)) {
        return;
    }
    latest = std::move(report);
    scale_line.clear();
    for (auto& c : clients) {
        if (c->watching && !c->dead) {
            if (scale_line.empty()) {
                appendScale(scale_line, latest, monotonicNowNs());
            }
            queue(*c, scale_line, true);
        }
    }
}

void SocketService::Loop::refreshPose() {
    const std::uint64_t seq = svc.hub_.poseSequence();
    if (seq == seen_pose_seq) {
        return;
    }
    seen_pose_seq = seq;
    const PoseReport pose = svc.hub_.pose();
    if (pose.frame_id == latest_pose.frame_id && pose.epoch == latest_pose.epoch &&
        pose.t_ns == latest_pose.t_ns) {
        return;  // a racing publish already seen
    }
    latest_pose = pose;
    const bool any = std::any_of(clients.begin(), clients.end(),
                                 [](const auto& c) { return c->watching_pose && !c->dead; });
    if (!any || !pose_limiter.admit(pose.epoch, pose.t_ns)) {
        return;
    }
    pose_line.clear();
    // The scale as refreshScale() just read it: the newest SCALE goes out first.
    appendPose(pose_line, latest_pose, latest);
    svc.poses_streamed_.fetch_add(1);
    for (auto& c : clients) {
        if (c->watching_pose && !c->dead) {
            queue(*c, pose_line, true);
        }
    }
}

void SocketService::Loop::acceptAll() {
    for (;;) {
        auto accepted = drivers::ipc::acceptClient(svc.listener_.fd.get(), svc.path_.string());
        if (!accepted) {
            accept_paused = true;  // e.g. EMFILE: rest instead of spinning
            return;
        }
        if (!accepted->isValid()) {
            return;
        }
        // Up to max_clients connections, and beyond that while fewer than
        // reserved_query_slots of them are not watchers (so a query gets in
        // when the watchers take max_clients); else an idle one makes room.
        const std::int64_t now = monotonicNowNs();
        const int connected = svc.connected_.load();
        const bool room = connected < svc.config_.max_clients ||
                          (connected - watchers() < svc.config_.reserved_query_slots &&
                           connected < max_connections);
        if (!room && !evictIdle(now)) {
            reply.clear();
            appendError(reply, "too many clients (" + std::to_string(svc.connected_.load()) +
                                   " connected)");
            [[maybe_unused]] const ssize_t sent =
                ::send(accepted->get(), reply.data(), reply.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
            svc.rejected_.fetch_add(1);
            svc.errors_.fetch_add(1);
            continue;  // closed by UniqueFd
        }
        auto client = std::make_unique<Client>();
        client->fd = std::move(*accepted);
        client->active_ns = now;
        svc.accepted_.fetch_add(1);
        svc.connected_.fetch_add(1);
        reply.clear();
        appendVersion(reply, svc.release_);
        queue(*client, reply, false);
        clients.push_back(std::move(client));
    }
}

// There is no room: closes the connection that is not a watcher,
// has nothing to read or send and has been idle longest, if that is at least
// request_timeout_s. False when there is none.
bool SocketService::Loop::evictIdle(std::int64_t now) {
    Client* oldest = nullptr;
    for (auto& c : clients) {
        if (c->dead || c->closing || c->watcher() || c->discarding || c->pending() > 0 ||
            !c->input().empty() || now - c->active_ns < request_timeout_ns) {
            continue;
        }
        if (oldest == nullptr || c->active_ns < oldest->active_ns) {
            oldest = c.get();
        }
    }
    if (oldest == nullptr) {
        return false;
    }
    error(*oldest, "idle connection closed: the server is full", {});
    svc.evicted_.fetch_add(1);
    close(*oldest);
    return true;
}

void SocketService::Loop::readClient(Client& c) {
    for (int round = 0; round < kReadRounds && c.reading(); ++round) {
        // Only an incomplete line is left over here (processInput handles
        // every complete one unless the client is paused): move it to the front.
        if (c.in_off > 0) {
            c.in.erase(0, c.in_off);
            c.in_off = 0;
        }
        const std::size_t old_size = c.in.size();
        c.in.resize(old_size + kReadChunk);
        const ssize_t n = ::recv(c.fd.get(), c.in.data() + old_size, kReadChunk, 0);
        c.in.resize(old_size + static_cast<std::size_t>(std::max<ssize_t>(n, 0)));
        if (n > 0) {
            c.active_ns = monotonicNowNs();
            processInput(c);
            if (static_cast<std::size_t>(n) < kReadChunk) {
                return;
            }
            continue;
        }
        if (n == 0) {
            // EOF: what is left is still answered, a last request without its
            // newline too (`printf '{"cmd":"poll"}' | socat - UNIX:...`); the
            // connection closes once the replies are sent.
            c.eof = true;
            processInput(c);
            return;
        }
        if (errno == EINTR) {
            continue;
        }
        if (errno != EAGAIN) {
            close(c);  // ECONNRESET, ...
        }
        return;
    }
}

// Handles the complete lines in c.in while the client's unsent output is at
// most the high-water mark; after EOF also the last line without a newline.
// A line's limit (max_request_bytes) is without its "\n" or "\r\n".
void SocketService::Loop::processInput(Client& c) {
    const std::size_t limit = svc.config_.max_request_bytes;
    while (!c.dead && !c.closing && !c.paused) {
        const std::string_view rest = c.input();
        if (rest.empty()) {
            break;
        }
        const auto* nl = static_cast<const char*>(std::memchr(rest.data(), '\n', rest.size()));
        if (nl == nullptr) {
            if (c.discarding) {
                c.in_off = c.in.size();  // the oversize line goes on
            } else if (c.eof) {
                std::string_view line = rest;
                if (!line.empty() && line.back() == '\r') {
                    line.remove_suffix(1);
                }
                c.in_off = c.in.size();
                if (line.size() > limit) {
                    svc.requests_.fetch_add(1);
                    error(c, "request longer than " + std::to_string(limit) + " bytes (discarded)",
                          {});
                } else {
                    handleLine(c, line);
                }
            } else if (rest.size() > limit + 1 ||
                       (rest.size() == limit + 1 && rest.back() != '\r')) {
                // Too long already, whatever ends it (a "\r" may still be
                // the first half of its "\r\n").
                svc.requests_.fetch_add(1);
                error(c, "request longer than " + std::to_string(limit) + " bytes (discarded)", {});
                c.discarding = true;
                c.in_off = c.in.size();
            }
            break;
        }
        const auto length = static_cast<std::size_t>(nl - rest.data());
        c.in_off += length + 1;
        c.line_since_ns = 0;
        if (c.discarding) {
            c.discarding = false;
            continue;
        }
        std::string_view line = rest.substr(0, length);
        if (!line.empty() && line.back() == '\r') {
            line.remove_suffix(1);
        }
        if (line.size() > limit) {
            svc.requests_.fetch_add(1);
            error(c, "request longer than " + std::to_string(limit) + " bytes (discarded)", {});
            continue;
        }
        handleLine(c, line);
    }
    if (c.dead) {
        return;
    }
    if (c.in_off == c.in.size()) {
        c.in.clear();
        c.in_off = 0;
    }
    // An incomplete line (or the rest of an oversize one: what is left while
    // the client is read) is on the clock; a paused client's clock starts
    // again when it is read again.
    if (!c.reading() || (!c.discarding && c.input().empty())) {
        c.line_since_ns = 0;
    } else if (c.line_since_ns == 0) {
        c.line_since_ns = monotonicNowNs();
    }
    afterOutput(c);
}

void SocketService::Loop::handleLine(Client& c, std::string_view line) {
    if (isBlank(line)) {
        return;
    }
    svc.requests_.fetch_add(1);
    const Request req = parseRequest(line);
    reply.clear();
    switch (req.command) {
        case Command::kInvalid:
            error(c, req.error, req.cmd);
            return;
        case Command::kPoll:
            appendScale(reply, svc.hub_.scale(), monotonicNowNs());
            break;
        case Command::kWatch:
            if ((req.enable || req.pose) && !c.watcher() && watchers() >= svc.config_.max_clients) {
                // The reserved connections stay for clients that only ask.
                svc.watch_refused_.fetch_add(1);
                error(c, "too many watchers (" + std::to_string(watchers()) + " watching)",
                      req.cmd);
                return;
            }
            c.watching = req.enable;
            c.watching_pose = req.pose;
            appendWatch(reply, req.enable, req.pose);
            if (req.enable) {
                appendScale(reply, latest, monotonicNowNs());
            }
            if (req.pose && latest_pose.frame_id >= 0) {
                appendPose(reply, latest_pose, latest);
            }
            break;
        case Command::kPose:
            appendPose(reply, svc.hub_.pose(), svc.hub_.scale());
            break;
        case Command::kStatus: {
            ClientCounts counts;
            counts.connected = svc.connected_.load();
            counts.max = svc.config_.max_clients;
            counts.accepted = svc.accepted_.load();
            counts.rejected = svc.rejected_.load();
            counts.detached = svc.detached_.load();
            counts.watchers = watchers();
            counts.reserved = svc.config_.reserved_query_slots;
            counts.timed_out = svc.timed_out_.load();
            counts.evicted = svc.evicted_.load();
            appendStatus(reply, svc.hub_.status(), svc.hub_.logStatus(), counts);
            break;
        }
        case Command::kPosterior:
            if (!svc.hub_.posterior(posterior)) {
                // No evidence yet in this epoch: an empty grid, the current epoch.
                posterior.epoch = svc.hub_.scale().epoch;
                posterior.frame_id = -1;
                posterior.observations = 0;
                posterior.d.clear();
                posterior.log_p.clear();
            }
            appendPosterior(reply, posterior);
            break;
        case Command::kObjects:
            svc.hub_.objects(objects);
            appendObjects(reply, objects);
            break;
        case Command::kSetGravity:
            svc.hub_.requestGravity(core::Vec3(static_cast<core::Scalar>(req.down[0]),
                                               static_cast<core::Scalar>(req.down[1]),
                                               static_cast<core::Scalar>(req.down[2])));
            appendAck(reply, req.cmd);
            break;
    }
    queue(c, reply, false);
}

void SocketService::Loop::error(Client& c, std::string_view message, std::string_view cmd) {
    svc.errors_.fetch_add(1);
    reply.clear();
    appendError(reply, message, cmd);
    queue(c, reply, false);
}

int SocketService::Loop::watchers() const {
    return static_cast<int>(std::count_if(clients.begin(), clients.end(),
                                          [](const auto& c) { return !c->dead && c->watcher(); }));
}

// Replies (stream = false) are always queued: the client's reading pauses
// above the high-water mark, so they stay within about half the buffer plus
// one line's replies. A SCALE/POSE line (stream = true) that would take the
// unsent output above client_buffer_bytes detaches the client.
void SocketService::Loop::queue(Client& c, std::string_view msg, bool stream) {
    if (c.dead) {
        return;
    }
    if (c.pending() == 0) {
        const std::size_t sent = sendSome(c, msg);
        if (c.dead) {
            return;
        }
        msg.remove_prefix(sent);
        if (msg.empty()) {
            return;
        }
        c.out.clear();
        c.out_off = 0;
        startStall(c, monotonicNowNs());
    }
    if (stream && c.pending() + msg.size() > svc.config_.client_buffer_bytes) {
        detach(c);
        return;
    }
    if (c.out_off > 0 && c.out_off >= c.out.size() / 2) {
        c.out.erase(0, c.out_off);
        c.out_off = 0;
    }
    c.out.append(msg);
    if (c.pending() > high_water) {
        c.paused = true;
    }
}

void SocketService::Loop::flush(Client& c) {
    const std::size_t sent = sendSome(c, std::string_view(c.out).substr(c.out_off));
    if (c.dead) {
        return;
    }
    c.out_off += sent;
    if (c.out_off == c.out.size()) {
        c.out.clear();
        c.out_off = 0;
    }
    if (sent > 0) {
        c.stall_since_ns = 0;
        if (c.pending() > 0) {
            startStall(c, monotonicNowNs());  // the client reads: a new clock
        }
    }
    if (c.paused && c.pending() <= low_water) {
        c.paused = false;
        processInput(c);  // the requests read before the pause, then afterOutput()
        return;
    }
    afterOutput(c);
}

// Closes a client that has finished (EOF or timed out) once its output is sent.
void SocketService::Loop::afterOutput(Client& c) {
    if (c.dead || c.pending() > 0) {
        return;
    }
    if (c.closing || (c.eof && c.input().empty())) {
        close(c);
    }
}

std::size_t SocketService::Loop::sendSome(Client& c, std::string_view data) {
    std::size_t sent = 0;
    while (sent < data.size()) {
        const ssize_t n =
            ::send(c.fd.get(), data.data() + sent, data.size() - sent, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) {
            sent += static_cast<std::size_t>(n);
            continue;
        }
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            break;
        }
        close(c);  // EPIPE, ECONNRESET, ...
        break;
    }
    return sent;
}

void SocketService::Loop::startStall(Client& c, std::int64_t now) {
    if (c.stall_since_ns == 0) {
        c.stall_since_ns = now;
        c.stall_unread_bytes = unreadBytes(c.fd.get());
    }
}

void SocketService::Loop::close(Client& c) {
    if (c.dead) {
        return;
    }
    c.dead = true;
    svc.connected_.fetch_sub(1);  // before the peer can see its EOF
    c.fd.reset();
    c.out.clear();
    c.out_off = 0;
}

void SocketService::Loop::detach(Client& c) {
    if (!c.dead) {
        svc.detached_.fetch_add(1);
        close(c);
    }
}

// --- SocketService ------------------------------------------------------------

SocketService::SocketService(const SocketConfig& config, ReportHub& hub, std::string release,
                             drivers::ipc::ListeningSocket listener,
                             drivers::base::UniqueFd stop_fd)
    : config_(config),
      hub_(hub),
      release_(std::move(release)),
      listener_(std::move(listener)),
      path_(listener_.activated && !listener_.path.empty() ? listener_.path : config.path),
      stop_fd_(std::move(stop_fd)) {}

SocketService::~SocketService() {
    stop();
}

core::Result<std::unique_ptr<SocketService>> SocketService::create(const SocketConfig& config,
                                                                   ReportHub& hub,
                                                                   std::string release) {
    using core::ErrorCode;
    using core::makeError;
    if (config.max_clients < 1 || config.max_request_bytes < 1 || config.client_buffer_bytes < 1) {
        return makeError(ErrorCode::kInvalidArgument,
                         "socket: max_clients, max_request_bytes and client_buffer_bytes must "
                         "be positive");
    }
    if (config.reserved_query_slots < 0 ||
        config.reserved_query_slots > std::numeric_limits<int>::max() - config.max_clients) {
        return makeError(ErrorCode::kInvalidArgument,
                         "socket: reserved_query_slots must be >= 0 (got " +
                             std::to_string(config.reserved_query_slots) + ")");
    }
    // Up to an hour (the configuration's range), so deadlines stay far from overflow.
    constexpr double kMaxTimeoutS = 3600;
    for (const auto& [name, value] : {std::pair{"request_timeout_s", config.request_timeout_s},
                                      std::pair{"stall_timeout_s", config.stall_timeout_s}}) {
        if (!(value > 0 && value <= kMaxTimeoutS)) {
            return makeError(ErrorCode::kInvalidArgument, std::string("socket: ") + name +
                                                              " must be in (0, 3600] (got " +
                                                              std::to_string(value) + ")");
        }
    }
    if (!(config.pose_rate_hz >= 0) || !std::isfinite(config.pose_rate_hz)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "socket: pose_rate_hz must be a finite number >= 0 (got " +
                             std::to_string(config.pose_rate_hz) + ")");
    }
    drivers::base::UniqueFd stop_fd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (!stop_fd.isValid()) {
        return makeError(ErrorCode::kIo,
                         "socket: cannot create an eventfd: " +
                             std::error_code(errno, std::generic_category()).message());
    }
    auto activated = drivers::ipc::takeActivatedSocket(3);
    if (!activated) {
        return activated.error();
    }
    drivers::ipc::ListeningSocket listener;
    if (activated->has_value()) {
        listener = std::move(**activated);
    } else {
        auto made = drivers::ipc::listenUnix({config.path, config.mode, config.group});
        if (!made) {
            return made.error();
        }
        listener = std::move(*made);
    }
    return std::unique_ptr<SocketService>(new SocketService(
        config, hub, std::move(release), std::move(listener), std::move(stop_fd)));
}

core::Status SocketService::start() {
    if (started_ || stopped_) {
        return core::makeError(core::ErrorCode::kInvalidArgument,
                               "socket: service already started or stopped");
    }
    try {
        thread_ = std::thread([this] { run(); });
    } catch (const std::system_error& e) {
        return core::makeError(core::ErrorCode::kIo,
                               std::string("socket: cannot start the thread: ") + e.what());
    }
    ::pthread_setname_np(thread_.native_handle(), "scaled-socket");
    started_ = true;
    return {};
}

void SocketService::stop() {
    if (stopped_) {
        return;
    }
    stopped_ = true;
    if (thread_.joinable()) {
        const std::uint64_t one = 1;
        [[maybe_unused]] const ssize_t n = ::write(stop_fd_.get(), &one, sizeof one);
        thread_.join();
    }
    drivers::ipc::removeSocketFile(listener_);
    listener_.fd.reset();
}

void SocketService::run() {
    Loop loop(*this);
    loop.run();
}

SocketServiceStats SocketService::stats() const {
    SocketServiceStats st;
    st.connected = connected_.load();
    st.accepted = accepted_.load();
    st.rejected = rejected_.load();
    st.detached = detached_.load();
    st.stalled = stalled_.load();
    st.timed_out = timed_out_.load();
    st.evicted = evicted_.load();
    st.watch_refused = watch_refused_.load();
    st.requests = requests_.load();
    st.errors = errors_.load();
    st.poses_streamed = poses_streamed_.load();
    return st;
}

}  // namespace scaled::daemon
