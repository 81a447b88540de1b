#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <poll.h>
#include <pthread.h>
#include <string_view>
#include <sys/eventfd.h>
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

}  // namespace

struct SocketService::Loop {
    struct Client {
        drivers::UniqueFd fd;
        std::string in;           // the incomplete request line
        bool discarding = false;  // skipping the rest of an oversize line
        std::string out;          // unsent output: out[out_off, size)
        std::size_t out_off = 0;
        bool watching = false;       // SCALE stream
        bool watching_pose = false;  // POSE stream
        bool dead = false;
        [[nodiscard]] std::size_t pending() const { return out.size() - out_off; }
    };

    explicit Loop(SocketService& s)
        : svc(s), read_buffer(kReadChunk), pose_limiter(s.config_.pose_rate_hz) {
        reply.reserve(1 << 16);
        scale_line.reserve(1024);
        pose_line.reserve(2048);
        clients.reserve(static_cast<std::size_t>(std::max(s.config_.max_clients, 1)) + 1);
        fds.reserve(clients.capacity() + 3);
    }

    SocketService& svc;
    std::vector<std::unique_ptr<Client>> clients;
    std::vector<pollfd> fds;
    std::vector<char> read_buffer;
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

    void run();
    void refreshScale();
    void refreshPose();
    void acceptAll();
    void readClient(Client& c);
    void consume(Client& c, const char* data, std::size_t n);
    void handleLine(Client& c, std::string_view line);
    void queue(Client& c, std::string_view msg);
    void flush(Client& c);
    std::size_t sendSome(Client& c, std::string_view data);
    void close(Client& c);
    void detach(Client& c);
    void error(Client& c, std::string_view message, std::string_view cmd);
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
            const auto events = static_cast<short>(POLLIN | (c->pending() > 0 ? POLLOUT : 0));
            fds.push_back({c->fd.get(), events, 0});
        }
        int timeout_ms = wake_fd >= 0 ? -1 : kNoWakeFdPollMs;
        if (accept_paused) {
            timeout_ms = kAcceptBackoffMs;
        }
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
            if ((re & (POLLIN | POLLHUP | POLLERR)) != 0) {
                readClient(c);
            }
            if (!c.dead && (re & POLLOUT) != 0) {
                flush(c);
            }
        }
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
            queue(*c, scale_line);
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
            queue(*c, pose_line);
        }
    }
}

void SocketService::Loop::acceptAll() {
    for (;;) {
        auto accepted = drivers::acceptClient(svc.listener_.fd.get(), svc.path_.string());
        if (!accepted) {
            accept_paused = true;  // e.g. EMFILE: rest instead of spinning
            return;
        }
        if (!accepted->isValid()) {
            return;
        }
        if (svc.connected_.load() >= svc.config_.max_clients) {
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
        svc.accepted_.fetch_add(1);
        svc.connected_.fetch_add(1);
        reply.clear();
        appendVersion(reply, svc.release_);
        queue(*client, reply);
        clients.push_back(std::move(client));
    }
}

void SocketService::Loop::readClient(Client& c) {
    for (int round = 0; round < kReadRounds && !c.dead; ++round) {
        const ssize_t n = ::recv(c.fd.get(), read_buffer.data(), read_buffer.size(), 0);
        if (n > 0) {
            consume(c, read_buffer.data(), static_cast<std::size_t>(n));
            if (static_cast<std::size_t>(n) < read_buffer.size()) {
                return;
            }
            continue;
        }
        if (n == 0) {
            // EOF: a last request without its newline still counts
            // (`printf '{"cmd":"poll"}' | socat - UNIX:...`); answer, then close.
            if (!c.discarding && !c.in.empty()) {
                const std::string line = std::move(c.in);
                c.in.clear();
                handleLine(c, line);
            }
            close(c);
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

void SocketService::Loop::consume(Client& c, const char* data, std::size_t n) {
    const std::size_t limit = svc.config_.max_request_bytes;
    const char* p = data;
    const char* const end = data + n;
    while (p < end && !c.dead) {
        const auto* nl =
            static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(end - p)));
        const char* chunk_end = nl != nullptr ? nl : end;
        const auto chunk = static_cast<std::size_t>(chunk_end - p);
        if (c.discarding) {
            if (nl == nullptr) {
                return;
            }
            c.discarding = false;
            p = nl + 1;
            continue;
        }
        if (c.in.size() + chunk > limit) {
            svc.requests_.fetch_add(1);
            error(c, "request longer than " + std::to_string(limit) + " bytes (discarded)", {});
            c.in.clear();
            if (nl == nullptr) {
                c.discarding = true;
                return;
            }
            p = nl + 1;
            continue;
        }
        if (nl == nullptr) {
            c.in.append(p, chunk);
            return;
        }
        if (c.in.empty()) {
            handleLine(c, std::string_view(p, chunk));
        } else {
            c.in.append(p, chunk);
            handleLine(c, c.in);
            c.in.clear();
        }
        p = nl + 1;
    }
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
            const ClientCounts counts{svc.connected_.load(), svc.config_.max_clients,
                                      svc.accepted_.load(), svc.rejected_.load(),
                                      svc.detached_.load()};
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
    queue(c, reply);
}

void SocketService::Loop::error(Client& c, std::string_view message, std::string_view cmd) {
    svc.errors_.fetch_add(1);
    reply.clear();
    appendError(reply, message, cmd);
    queue(c, reply);
}

void SocketService::Loop::queue(Client& c, std::string_view msg) {
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
    }
    if (c.pending() + msg.size() > svc.config_.client_buffer_bytes) {
        detach(c);
        return;
    }
    if (c.out_off > 0 && c.out_off >= c.out.size() / 2) {
        c.out.erase(0, c.out_off);
        c.out_off = 0;
    }
    c.out.append(msg);
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

void SocketService::Loop::close(Client& c) {
    if (c.dead) {
        return;
    }
    c.dead = true;
    c.fd.reset();
    c.out.clear();
    c.out_off = 0;
    svc.connected_.fetch_sub(1);
}

void SocketService::Loop::detach(Client& c) {
    if (!c.dead) {
        svc.detached_.fetch_add(1);
        close(c);
    }
}

// --- SocketService ------------------------------------------------------------

SocketService::SocketService(const SocketConfig& config, ReportHub& hub, std::string release,
                             drivers::ListeningSocket listener, drivers::UniqueFd stop_fd)
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
    if (!(config.pose_rate_hz >= 0) || !std::isfinite(config.pose_rate_hz)) {
        return makeError(ErrorCode::kInvalidArgument,
                         "socket: pose_rate_hz must be a finite number >= 0 (got " +
                             std::to_string(config.pose_rate_hz) + ")");
    }
    drivers::UniqueFd stop_fd(::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC));
    if (!stop_fd.isValid()) {
        return makeError(ErrorCode::kIo,
                         "socket: cannot create an eventfd: " +
                             std::error_code(errno, std::generic_category()).message());
    }
    auto activated = drivers::takeActivatedSocket(3);
    if (!activated) {
        return activated.error();
    }
    drivers::ListeningSocket listener;
    if (activated->has_value()) {
        listener = std::move(**activated);
    } else {
        auto made = drivers::listenUnix({config.path, config.mode, config.group});
        if (!made) {
            return made.error();
        }
        listener = std::move(*made);
    }
    return std::unique_ptr<SocketService>(new SocketService(
        config, hub, std::move(release), std::move(listener), std::move(stop_fd)));
}

core::Result<bool> SocketService::start() {
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
    return true;
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
    drivers::removeSocketFile(listener_);
    listener_.fd.reset();
}

void SocketService::run() {
    Loop loop(*this);
    loop.run();
}

SocketServiceStats SocketService::stats() const {
    return {connected_.load(), accepted_.load(), rejected_.load(),      detached_.load(),
            requests_.load(),  errors_.load(),   poses_streamed_.load()};
}

}  // namespace scaled::daemon
