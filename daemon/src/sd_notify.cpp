#include <charconv>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <string>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <scaled/daemon/sd_notify.h>

namespace scaled::daemon {

namespace {

std::optional<unsigned long long> envNumber(const char* name) {
    const char* v = std::getenv(name);  // NOLINT(concurrency-mt-unsafe): read once at start-up
    if (v == nullptr || *v == '\0') {
        return std::nullopt;
    }
    unsigned long long out = 0;
    const char* end = v + std::strlen(v);
    const auto [p, ec] = std::from_chars(v, end, out);
    if (ec != std::errc() || p != end) {
        return std::nullopt;
    }
    return out;
}

}  // namespace

SdNotifier::SdNotifier() {
    // WATCHDOG_USEC applies to us only when WATCHDOG_PID is absent or ours.
    const auto usec = envNumber("WATCHDOG_USEC");
    const auto pid = envNumber("WATCHDOG_PID");
    if (usec && *usec > 0 && (!pid || *pid == static_cast<unsigned long long>(getpid()))) {
        watchdog_ = std::chrono::microseconds(static_cast<std::int64_t>(*usec));
    }
    const char* path = std::getenv("NOTIFY_SOCKET");  // NOLINT(concurrency-mt-unsafe)
    if (path == nullptr) {
        return;
    }
    const std::size_t n = std::strlen(path);
    sockaddr_un addr{};
    if (n < 2 || n >= sizeof addr.sun_path || (path[0] != '/' && path[0] != '@')) {
        return;
    }
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, path, n);
    if (path[0] == '@') {
        addr.sun_path[0] = '\0';  // abstract namespace
    }
    address_len_ = static_cast<unsigned>(offsetof(sockaddr_un, sun_path) + n);
    static_assert(sizeof address_ >= sizeof(sockaddr_un));
    std::memcpy(address_, &addr, sizeof addr);
    fd_.reset(socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
}

SdNotifier::~SdNotifier() = default;

bool SdNotifier::notify(std::string_view state) const {
    if (!fd_.isValid()) {
        return false;
    }
    // Never block: if the manager does not read its socket (its queue holds
    // net.unix.max_dgram_qlen datagrams), a notification is dropped rather
    // than stalling the main loop, which must stay free to handle SIGTERM.
    const ssize_t sent =
        sendto(fd_.get(), state.data(), state.size(), MSG_NOSIGNAL | MSG_DONTWAIT,
               reinterpret_cast<const sockaddr*>(address_),  // NOLINT: sockaddr API
               address_len_);
    return sent == static_cast<ssize_t>(state.size());
}

}  // namespace scaled::daemon
