#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <grp.h>
#include <string_view>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <system_error>
#include <unistd.h>
#include <utility>
#include <vector>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/ipc/unix_socket.h>

namespace scaled::drivers::ipc {
namespace {

using core::ErrorCode;
using core::makeError;

using base::errnoText;

core::Error osError(const std::filesystem::path& path, std::string_view what, int err) {
    return makeError(ErrorCode::kIo,
                     path.string() + ": " + std::string(what) + ": " + errnoText(err));
}

// Fills a sockaddr_un; false when the path does not fit in sun_path.
bool makeAddress(const std::filesystem::path& path, sockaddr_un& addr, socklen_t& len) {
    const std::string& s = path.native();
    if (s.empty() || s.size() >= sizeof(addr.sun_path)) {
        return false;
    }
    addr = sockaddr_un{};
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, s.data(), s.size());
    len = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + s.size() + 1);
    return true;
}

// Connection probe of an existing socket file: "live" when something accepts.
enum class Probe : std::uint8_t { kStale, kLive, kGone };

core::Result<Probe> probeSocketFile(const std::filesystem::path& path, const sockaddr_un& addr,
                                    socklen_t len) {
    const base::UniqueFd fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (!fd.isValid()) {
        return osError(path, "cannot create a socket", errno);
    }
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    if (::connect(fd.get(), reinterpret_cast<const sockaddr*>(&addr), len) == 0) {
        return Probe::kLive;
    }
    const int err = errno;
    if (err == ECONNREFUSED) {
        return Probe::kStale;
    }
    if (err == EAGAIN || err == EINPROGRESS) {
        return Probe::kLive;  // a full backlog: somebody listens
    }
    if (err == ENOENT) {
        return Probe::kGone;
    }
    return osError(path, "cannot check the existing socket", err);
}

// The directory of `path` exists.
core::Status checkSocketDirectory(const std::filesystem::path& path) {
    const std::filesystem::path parent =
        path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    struct stat st = {};
    if (::stat(parent.c_str(), &st) != 0) {
        return osError(path, "directory " + parent.string(), errno);
    }
    if (!S_ISDIR(st.st_mode)) {
        return makeError(ErrorCode::kInvalidArgument,
                         path.string() + ": " + parent.string() + " is not a directory");
    }
    return {};
}

// A socket file left at `path` by a process that is gone is removed; one
// something listens on, or a file that is not a socket, is an error.
core::Status removeStaleSocket(const std::filesystem::path& path, const sockaddr_un& addr,
                               socklen_t addr_len) {
    struct stat st = {};
    if (::lstat(path.c_str(), &st) == 0) {
        if (!S_ISSOCK(st.st_mode)) {
            return makeError(ErrorCode::kInvalidArgument,
                             path.string() + ": exists and is not a socket (not replacing it)");
        }
        auto probe = probeSocketFile(path, addr, addr_len);
        if (!probe) {
            return probe.error();
        }
        if (*probe == Probe::kLive) {
            return makeError(ErrorCode::kInvalidArgument,
                             path.string() + ": already in use by another process");
        }
        if (*probe == Probe::kStale && ::unlink(path.c_str()) != 0 && errno != ENOENT) {
            return osError(path, "cannot remove the stale socket", errno);
        }
    } else if (errno != ENOENT) {
        return osError(path, "cannot inspect", errno);
    }
    return {};
}

bool setFlags(int fd) {
    const int fl = ::fcntl(fd, F_GETFL);
    const int fd_flags = ::fcntl(fd, F_GETFD);
    return fl >= 0 && fd_flags >= 0 && ::fcntl(fd, F_SETFL, fl | O_NONBLOCK) == 0 &&
           ::fcntl(fd, F_SETFD, fd_flags | FD_CLOEXEC) == 0;
}

int socketOption(int fd, int option) {
    int value = 0;
    socklen_t len = sizeof value;
    if (::getsockopt(fd, SOL_SOCKET, option, &value, &len) != 0) {
        return -1;
    }
    return value;
}

// The path a listening socket is bound to (empty when abstract or unnamed).
std::filesystem::path boundPath(int fd) {
    sockaddr_un addr{};
    socklen_t len = sizeof addr;
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0 ||
        len <= offsetof(sockaddr_un, sun_path) || addr.sun_path[0] == '\0') {
        return {};
    }
    const std::size_t max = len - offsetof(sockaddr_un, sun_path);
    return {std::string(addr.sun_path, ::strnlen(addr.sun_path, max))};
}

void unsetActivationEnvironment() {
    ::unsetenv("LISTEN_PID");
    ::unsetenv("LISTEN_FDS");
    ::unsetenv("LISTEN_FDNAMES");
}

bool parseInt(const char* text, long& out) {
    if (text == nullptr) {
        return false;
    }
    const std::string_view s(text);
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && ptr == s.data() + s.size();
}

}  // namespace

core::Result<gid_t> lookupGroup(const std::filesystem::path& path, const std::string& name) {
    long size_hint = ::sysconf(_SC_GETGR_R_SIZE_MAX);
    std::vector<char> buffer(size_hint > 0 ? static_cast<std::size_t>(size_hint) : 1024U);
    group entry{};
    group* found = nullptr;
    for (;;) {
        const int rc = ::getgrnam_r(name.c_str(), &entry, buffer.data(), buffer.size(), &found);
        if (rc == ERANGE && buffer.size() < (1U << 20)) {
            buffer.resize(buffer.size() * 2);
            continue;
        }
        if (rc != 0) {
            return osError(path, "cannot look up group '" + name + "'", rc);
        }
        break;
    }
    if (found == nullptr) {
        return makeError(ErrorCode::kNotFound, path.string() + ": unknown group '" + name + "'");
    }
    return found->gr_gid;
}

core::Result<ListeningSocket> listenUnix(const UnixListenOptions& options) {
    const std::filesystem::path& path = options.path;
    sockaddr_un addr{};
    socklen_t addr_len = 0;
    if (!makeAddress(path, addr, addr_len)) {
        return makeError(ErrorCode::kInvalidArgument,
                         path.string() + ": socket path must be 1 to " +
                             std::to_string(sizeof(addr.sun_path) - 1) + " bytes long");
    }
    if (auto ok = checkSocketDirectory(path); !ok) {
        return ok.error();
    }

    gid_t gid = static_cast<gid_t>(-1);
    if (!options.group.empty()) {
        auto g = lookupGroup(path, options.group);
        if (!g) {
            return g.error();
        }
        gid = *g;
    }

    if (auto ok = removeStaleSocket(path, addr, addr_len); !ok) {
        return ok.error();
    }

    ListeningSocket out;
    out.path = path;
    out.fd.reset(::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    if (!out.fd.isValid()) {
        return osError(path, "cannot create a socket", errno);
    }
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    if (::bind(out.fd.get(), reinterpret_cast<const sockaddr*>(&addr), addr_len) != 0) {
        return osError(path, "cannot bind", errno);
    }
    out.created_file = true;
    struct stat st = {};
    if (::lstat(path.c_str(), &st) == 0) {
        out.file_dev = st.st_dev;
        out.file_ino = st.st_ino;
    }
    // Until listen() every connect() is refused, so the file is never usable
    // with the umask's mode or the wrong group.
    auto fail = [&](std::string_view what, int err) {
        core::Error e = osError(path, what, err);
        removeSocketFile(out);
        return e;
    };
    if (::chmod(path.c_str(), static_cast<mode_t>(options.mode & 07777U)) != 0) {
        return fail("cannot set mode", errno);
    }
    if (!options.group.empty() && ::chown(path.c_str(), static_cast<uid_t>(-1), gid) != 0) {
        return fail("cannot set group '" + options.group + "'", errno);
    }
    if (::listen(out.fd.get(), options.backlog) != 0) {
        return fail("cannot listen", errno);
    }
    return out;
}

core::Result<ListeningSocket> adoptListeningSocket(int fd) {
    ListeningSocket out;
    out.fd.reset(fd);
    out.activated = true;
    const std::string name = "inherited socket (fd " + std::to_string(fd) + ")";
    struct stat st = {};
    if (::fstat(fd, &st) != 0) {
        return osError(name, "not usable", errno);
    }
    if (!S_ISSOCK(st.st_mode)) {
        return makeError(ErrorCode::kInvalidArgument, name + ": is not a socket");
    }
    if (socketOption(fd, SO_DOMAIN) != AF_UNIX || socketOption(fd, SO_TYPE) != SOCK_STREAM) {
        return makeError(ErrorCode::kInvalidArgument,
                         name + ": is not an AF_UNIX SOCK_STREAM socket");
    }
    if (socketOption(fd, SO_ACCEPTCONN) != 1) {
        return makeError(ErrorCode::kInvalidArgument, name + ": is not listening");
    }
    if (!setFlags(fd)) {
        return osError(name, "cannot set O_NONBLOCK/FD_CLOEXEC", errno);
    }
    out.path = boundPath(fd);
    return out;
}

core::Result<std::optional<ListeningSocket>> takeActivatedSocket(int first_fd) {
    long pid = 0;
    long count = 0;
    const bool ours = parseInt(std::getenv("LISTEN_PID"), pid) &&
                      parseInt(std::getenv("LISTEN_FDS"), count) && pid == ::getpid() && count >= 1;
    unsetActivationEnvironment();
    if (!ours) {
        return std::optional<ListeningSocket>();
    }
    // Like sd_listen_fds(): every passed descriptor becomes close-on-exec.
    for (long i = 1; i < count && i < 1024; ++i) {
        const int fd = first_fd + static_cast<int>(i);
        const int flags = ::fcntl(fd, F_GETFD);
        if (flags >= 0) {
            ::fcntl(fd, F_SETFD, flags | FD_CLOEXEC);
        }
    }
    auto adopted = adoptListeningSocket(first_fd);
    if (!adopted) {
        return makeError(adopted.error().code,
                         "socket activation (LISTEN_FDS=" + std::to_string(count) +
                             "): " + adopted.error().message);
    }
    return std::optional<ListeningSocket>(std::move(*adopted));
}

bool removeSocketFile(const ListeningSocket& socket) {
    if (socket.activated || !socket.created_file || socket.path.empty()) {
        return false;
    }
    struct stat st = {};
    if (::lstat(socket.path.c_str(), &st) != 0 || !S_ISSOCK(st.st_mode) ||
        st.st_dev != socket.file_dev || st.st_ino != socket.file_ino) {
        return false;  // gone, or somebody else's file now
    }
    return ::unlink(socket.path.c_str()) == 0;
}

core::Result<base::UniqueFd> acceptClient(int listen_fd, const std::string& what) {
    const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd >= 0) {
        return base::UniqueFd(fd);
    }
    const int err = errno;
    if (err == EAGAIN || err == EINTR || err == ECONNABORTED || err == EPROTO) {
        return base::UniqueFd();
    }
    return osError(what, "cannot accept a connection", err);
}

core::Result<base::UniqueFd> connectUnix(const std::filesystem::path& path) {
    sockaddr_un addr{};
    socklen_t len = 0;
    if (!makeAddress(path, addr, len)) {
        return makeError(ErrorCode::kInvalidArgument, path.string() + ": socket path too long");
    }
    base::UniqueFd fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    if (!fd.isValid()) {
        return osError(path, "cannot create a socket", errno);
    }
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    if (::connect(fd.get(), reinterpret_cast<const sockaddr*>(&addr), len) != 0) {
        return osError(path, "cannot connect", errno);
    }
    return fd;
}

}  // namespace scaled::drivers::ipc
