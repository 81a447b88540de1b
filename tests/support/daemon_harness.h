#pragma once

// Helpers for tests that run the `scaled` daemon as a process: spawning it
// with fork/execve (per-child environment, stderr to a file, an inherited
// listening socket as fd 3), waiting for it (pidfd + poll, never sleeping),
// the sd_notify datagram socket it reports to, and a line-oriented client of
// its UNIX socket. Every wait is on an event with a bounded timeout.

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <poll.h>
#include <sstream>
#include <string>
#include <string_view>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/base/unique_fd.h>

extern char** environ;  // NOLINT(readability-redundant-declaration): POSIX, not in unistd.h

namespace scaled::test {

using Json = nlohmann::json;
using Clock = std::chrono::steady_clock;
using Millis = std::chrono::milliseconds;

// Milliseconds left until `deadline` (0 when past), for poll().
inline int msLeft(Clock::time_point deadline) {
    const auto left = std::chrono::duration_cast<Millis>(deadline - Clock::now()).count();
    return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left, 1 << 30));
}

inline std::string readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream out;
    out << in.rdbuf();
    return out.str();
}

inline void writeFile(const std::filesystem::path& path, std::string_view text) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << text;
}

// A TOML basic string.
inline std::string tomlString(std::string_view text) {
    std::string out = "\"";
    for (const char c : text) {
        if (c == '"' || c == '\\') {
            out += '\\';
        }
        out += c;
    }
    out += '"';
    return out;
}

// An owned file descriptor.
using Fd = drivers::base::UniqueFd;

// A sockaddr_un for a filesystem path (false: the path is too long).
inline bool unixAddress(const std::filesystem::path& path, sockaddr_un& addr) {
    const std::string s = path.string();
    addr = sockaddr_un{};
    if (s.empty() || s.size() >= sizeof addr.sun_path) {
        return false;
    }
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, s.c_str(), s.size() + 1);
    return true;
}

// A listening SOCK_STREAM socket bound to `path` (socket activation: the test
// plays systemd). Not close-on-exec is set by the spawner when it passes it.
inline Fd listenUnix(const std::filesystem::path& path) {
    sockaddr_un addr{};
    if (!unixAddress(path, addr)) {
        return {};
    }
    Fd fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    if (!fd.isValid() ||
        ::bind(fd.get(), reinterpret_cast<const sockaddr*>(&addr),  // NOLINT: sockaddr API
               sizeof addr) != 0 ||
        ::listen(fd.get(), 64) != 0) {
        return {};
    }
    return fd;
}

// The sd_notify receiving end: a SOCK_DGRAM socket bound to a path, drained
// by its own thread at once (as systemd does: a daemon's sd_notify may block
// while the receiver's queue is full). Every line is kept; waitFor() scans
// forward from where the last match was, so a sequence (RELOADING=1, then
// READY=1) can be checked in order.
class NotifySocket {
public:
    explicit NotifySocket(std::filesystem::path path) : path_(std::move(path)) {
        sockaddr_un addr{};
        if (!unixAddress(path_, addr)) {
            return;
        }
        Fd fd(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
        if (!fd.isValid() ||
            ::bind(fd.get(), reinterpret_cast<const sockaddr*>(&addr),  // NOLINT: sockaddr API
                   sizeof addr) != 0) {
            return;
        }
        wake_ = Fd(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
        stop_ = Fd(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
        if (!wake_.isValid() || !stop_.isValid()) {
            return;
        }
        fd_ = std::move(fd);
        thread_ = std::thread([this] { run(); });
    }
    ~NotifySocket() {
        if (thread_.joinable()) {
            signalFd(stop_.get());
            thread_.join();
        }
    }
    NotifySocket(const NotifySocket&) = delete;
    NotifySocket& operator=(const NotifySocket&) = delete;
    NotifySocket(NotifySocket&&) = delete;
    NotifySocket& operator=(NotifySocket&&) = delete;

    [[nodiscard]] bool valid() const { return fd_.isValid(); }
    [[nodiscard]] const std::filesystem::path& path() const { return path_; }

    // Waits until a datagram has the line `line` (exactly), after the previous
    // match. Gives up at the timeout or when `also_fd` (e.g. the child's pidfd)
    // becomes readable without the line having arrived.
    bool waitFor(std::string_view line, Millis timeout, int also_fd = -1) {
        const auto deadline = Clock::now() + timeout;
        while (true) {
            if (scan(line)) {
                return true;
            }
            std::array<pollfd, 2> fds{};
            fds[0] = {wake_.get(), POLLIN, 0};
            fds[1] = {also_fd, POLLIN, 0};
            const int r = ::poll(fds.data(), also_fd >= 0 ? 2 : 1, msLeft(deadline));
            if (r < 0 && errno == EINTR) {
                continue;
            }
            if (r <= 0) {
                return scan(line);
            }
            if ((fds[0].revents & POLLIN) != 0) {
                std::uint64_t count = 0;
                [[maybe_unused]] const ssize_t n = ::read(wake_.get(), &count, sizeof count);
                continue;
            }
            return scan(line);  // also_fd: the child exited
        }
    }

    // Every line received so far (all datagrams, split at '\n').
    [[nodiscard]] std::vector<std::string> lines() const {
        const std::lock_guard lock(mutex_);
        return lines_;
    }
    [[nodiscard]] std::string history() const {
        std::string out;
        for (const auto& l : lines()) {
            out += "  " + l + "\n";
        }
        return out;
    }

private:
    static void signalFd(int fd) {
        const std::uint64_t one = 1;
        [[maybe_unused]] const ssize_t n = ::write(fd, &one, sizeof one);
    }

    bool scan(std::string_view line) {
        const std::lock_guard lock(mutex_);
        for (; cursor_ < lines_.size(); ++cursor_) {
            if (lines_[cursor_] == line) {
                ++cursor_;
                return true;
            }
        }
        return false;
    }

    void run() {
        std::array<char, 4096> buf{};
        while (true) {
            std::array<pollfd, 2> fds{};
            fds[0] = {fd_.get(), POLLIN, 0};
            fds[1] = {stop_.get(), POLLIN, 0};
            const int r = ::poll(fds.data(), 2, -1);
            if (r < 0 && errno == EINTR) {
                continue;
            }
            if (r < 0 || (fds[1].revents & POLLIN) != 0) {
                return;
            }
            while (true) {
                const ssize_t got = ::recv(fd_.get(), buf.data(), buf.size(), 0);
                if (got < 0) {
                    break;
                }
                std::string_view text(buf.data(), static_cast<std::size_t>(got));
                {
                    const std::lock_guard lock(mutex_);
                    while (!text.empty()) {
                        const auto nl = text.find('\n');
                        lines_.emplace_back(text.substr(0, nl));
                        if (nl == std::string_view::npos) {
                            break;
                        }
                        text.remove_prefix(nl + 1);
                    }
                }
                signalFd(wake_.get());
            }
        }
    }

    std::filesystem::path path_;
    Fd fd_;
    Fd wake_;  // eventfd: a datagram arrived
    Fd stop_;  // eventfd: the thread ends
    mutable std::mutex mutex_;
    std::vector<std::string> lines_;  // mutex_
    std::size_t cursor_ = 0;          // mutex_
    std::thread thread_;
};

struct SpawnOptions {
    std::vector<std::string> args;      // without argv[0]
    std::vector<std::string> env;       // added to (replacing) the test's environment, "K=V"
    std::filesystem::path stdout_path;  // empty: /dev/null
    std::filesystem::path stderr_path;  // empty: /dev/null
    // Socket activation: this descriptor becomes fd 3 in the child, with
    // LISTEN_FDS=1 and LISTEN_PID=<the child's pid> (set after fork).
    int listen_fd = -1;
};

// A child process, killed (SIGKILL) and reaped when the object goes away if it
// still runs.
class Process {
public:
    Process() = default;
    ~Process() { kill(); }
    Process(const Process&) = delete;
    Process& operator=(const Process&) = delete;
    Process(Process&& other) noexcept
        : pid_(std::exchange(other.pid_, -1)),
          pidfd_(std::move(other.pidfd_)),
          status_(other.status_) {}
    Process& operator=(Process&& other) noexcept {
        if (this != &other) {
            kill();
            pid_ = std::exchange(other.pid_, -1);
            pidfd_ = std::move(other.pidfd_);
            status_ = other.status_;
        }
        return *this;
    }

    // fork + execve. Everything the child needs is built before fork (the
    // child only calls async-signal-safe functions).
    static Process spawn(const std::string& exe, const SpawnOptions& opt) {
        Process p;
        std::vector<std::string> argv_s{exe};
        argv_s.insert(argv_s.end(), opt.args.begin(), opt.args.end());
        std::vector<std::string> env_s;
        const auto overridden = [&](std::string_view entry) {
            const auto eq = entry.find('=');
            const std::string_view name = entry.substr(0, eq);
            for (const char* drop : {"NOTIFY_SOCKET", "LISTEN_FDS", "LISTEN_PID", "LISTEN_FDNAMES",
                                     "WATCHDOG_USEC", "WATCHDOG_PID", "SCALED_SOCKET"}) {
                if (name == drop) {
                    return true;
                }
            }
            for (const auto& e : opt.env) {
                if (std::string_view(e).substr(0, e.find('=')) == name) {
                    return true;
                }
            }
            return false;
        };
        for (char** e = environ; *e != nullptr; ++e) {
            if (!overridden(*e)) {
                env_s.emplace_back(*e);
            }
        }
        env_s.insert(env_s.end(), opt.env.begin(), opt.env.end());
        std::size_t listen_pid_index = 0;
        if (opt.listen_fd >= 0) {
            env_s.emplace_back("LISTEN_FDS=1");
            listen_pid_index = env_s.size();
            env_s.emplace_back("LISTEN_PID=" + std::string(20, '\0'));
        }
        std::vector<char*> argv;
        argv.reserve(argv_s.size() + 1);
        for (auto& a : argv_s) {
            argv.push_back(a.data());
        }
        argv.push_back(nullptr);
        std::vector<char*> envp;
        envp.reserve(env_s.size() + 1);
        for (auto& e : env_s) {
            envp.push_back(e.data());
        }
        envp.push_back(nullptr);
        char* listen_pid_digits = opt.listen_fd >= 0
                                      ? env_s[listen_pid_index].data() + std::strlen("LISTEN_PID=")
                                      : nullptr;

        const auto openOut = [](const std::filesystem::path& path) {
            return path.empty()
                       ? ::open("/dev/null", O_WRONLY | O_CLOEXEC)
                       : ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        };
        const Fd in(::open("/dev/null", O_RDONLY | O_CLOEXEC));
        const Fd out(openOut(opt.stdout_path));
        const Fd err(openOut(opt.stderr_path));
        if (!in.isValid() || !out.isValid() || !err.isValid()) {
            return p;
        }
        const pid_t pid = ::fork();
        if (pid < 0) {
            return p;
        }
        if (pid == 0) {
            // Child: async-signal-safe calls only.
            if (listen_pid_digits != nullptr) {
                char rev[24];
                int n = 0;
                for (auto v = static_cast<unsigned long>(::getpid()); n == 0 || v > 0; v /= 10) {
                    rev[n++] = static_cast<char>('0' + v % 10);
                }
                for (int i = 0; i < n; ++i) {
                    listen_pid_digits[i] = rev[n - 1 - i];
                }
                listen_pid_digits[n] = '\0';
                // fd 3 must not be one of the standard streams' sources.
                if (opt.listen_fd == 3) {
                    ::fcntl(3, F_SETFD, 0);
                } else if (::dup2(opt.listen_fd, 3) < 0) {
                    ::_exit(126);
                }
            }
            if (::dup2(in.get(), 0) < 0 || ::dup2(out.get(), 1) < 0 || ::dup2(err.get(), 2) < 0) {
                ::_exit(126);
            }
            ::execve(argv[0], argv.data(), envp.data());
            ::_exit(127);
        }
        p.pid_ = pid;
        p.pidfd_ = Fd(static_cast<int>(::syscall(SYS_pidfd_open, pid, 0)));
        return p;
    }

    [[nodiscard]] bool valid() const { return pid_ > 0; }
    [[nodiscard]] pid_t pid() const { return pid_; }
    // Readable when the child exits (for poll).
    [[nodiscard]] int pidfd() const { return pidfd_.get(); }
    [[nodiscard]] bool exited() const { return status_.has_value(); }

    bool signal(int sig) const { return pid_ > 0 && !status_ && ::kill(pid_, sig) == 0; }

    // Waits for the child to exit; its exit code (128 + signal when killed),
    // or nullopt when it still runs at the timeout.
    std::optional<int> wait(Millis timeout) {
        if (pid_ <= 0) {
            return std::nullopt;
        }
        if (!status_) {
            if (pidfd_.isValid()) {
                pollfd pfd{pidfd_.get(), POLLIN, 0};
                const auto deadline = Clock::now() + timeout;
                while (true) {
                    const int r = ::poll(&pfd, 1, msLeft(deadline));
                    if (r < 0 && errno == EINTR) {
                        continue;
                    }
                    if (r <= 0) {
                        return std::nullopt;
                    }
                    break;
                }
            }
            int status = 0;
            pid_t r = 0;
            do {
                r = ::waitpid(pid_, &status, 0);
            } while (r < 0 && errno == EINTR);
            if (r != pid_) {
                return std::nullopt;
            }
            status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        }
        return status_;
    }

    void kill() {
        if (pid_ > 0 && !status_) {
            ::kill(pid_, SIGKILL);
            wait(Millis(60'000));
        }
    }

private:
    pid_t pid_ = -1;
    Fd pidfd_;
    std::optional<int> status_;
};

// Runs a command to completion (bounded), capturing stdout and stderr.
struct RunResult {
    int exit_code = -1;  // -1: did not finish within the timeout (killed)
    std::string out;
    std::string err;
};
inline RunResult runCommand(const std::string& exe, std::vector<std::string> args,
                            const std::filesystem::path& scratch_dir, Millis timeout,
                            std::vector<std::string> env = {}) {
    static int counter = 0;
    const auto tag = std::to_string(counter++);
    SpawnOptions opt;
    opt.args = std::move(args);
    opt.env = std::move(env);
    opt.stdout_path = scratch_dir / ("run" + tag + ".out");
    opt.stderr_path = scratch_dir / ("run" + tag + ".err");
    Process p = Process::spawn(exe, opt);
    RunResult r;
    if (!p.valid()) {
        return r;
    }
    const auto code = p.wait(timeout);
    p.kill();
    r.exit_code = code ? *code : -1;
    r.out = readFile(opt.stdout_path);
    r.err = readFile(opt.stderr_path);
    return r;
}

// A client of the daemon's socket: newline-delimited JSON.
class Client {
public:
    Client() = default;
    explicit Client(const std::filesystem::path& path) { connect(path); }

    bool connect(const std::filesystem::path& path) {
        sockaddr_un addr{};
        if (!unixAddress(path, addr)) {
            return false;
        }
        Fd fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
        if (!fd.isValid() ||
            ::connect(fd.get(), reinterpret_cast<const sockaddr*>(&addr),  // NOLINT: sockaddr API
                      sizeof addr) != 0) {
            return false;
        }
        fd_ = std::move(fd);
        buffer_.clear();
        eof_ = false;
        return true;
    }
    [[nodiscard]] bool connected() const { return fd_.isValid(); }
    [[nodiscard]] bool eof() const { return eof_; }
    [[nodiscard]] int fd() const { return fd_.get(); }
    void close() { fd_.reset(); }

    // Sends `text` as it is (blocking until written). false on an error.
    bool sendRaw(std::string_view text) {
        while (!text.empty()) {
            const ssize_t n = ::send(fd_.get(), text.data(), text.size(), MSG_NOSIGNAL);
            if (n < 0 && errno == EINTR) {
                continue;
            }
            if (n <= 0) {
                return false;
            }
            text.remove_prefix(static_cast<std::size_t>(n));
        }
        return true;
    }
    bool sendLine(std::string_view line) { return sendRaw(std::string(line) + "\n"); }
    bool send(const Json& request) { return sendLine(request.dump()); }

    // The next line (without '\n'), or nullopt at the timeout or at EOF (eof()).
    std::optional<std::string> readLine(Millis timeout) {
        const auto deadline = Clock::now() + timeout;
        while (true) {
            const auto nl = buffer_.find('\n');
            if (nl != std::string::npos) {
                std::string line = buffer_.substr(0, nl);
                buffer_.erase(0, nl + 1);
                return line;
            }
            if (eof_ || !fd_.isValid()) {
                return std::nullopt;
            }
            pollfd pfd{fd_.get(), POLLIN, 0};
            const int r = ::poll(&pfd, 1, msLeft(deadline));
            if (r < 0 && errno == EINTR) {
                continue;
            }
            if (r <= 0) {
                return std::nullopt;
            }
            std::array<char, 65536> buf{};
            const ssize_t n = ::recv(fd_.get(), buf.data(), buf.size(), 0);
            if (n < 0 && errno == EINTR) {
                continue;
            }
            if (n <= 0) {
                eof_ = true;
                continue;
            }
            buffer_.append(buf.data(), static_cast<std::size_t>(n));
        }
    }

    // The next line parsed as JSON (a discarded value when it is not JSON, so
    // the test fails on it), or nullopt at the timeout/EOF.
    std::optional<Json> readJson(Millis timeout) {
        auto line = readLine(timeout);
        if (!line) {
            return std::nullopt;
        }
        last_line_ = *line;
        return Json::parse(*line, nullptr, false);
    }

    // Reads until a line of class `cls` (other classes are skipped, e.g. SCALE
    // lines of a watch). nullopt at the timeout/EOF.
    std::optional<Json> readClass(std::string_view cls, Millis timeout) {
        const auto deadline = Clock::now() + timeout;
        while (true) {
            auto j = readJson(Millis(msLeft(deadline)));
            if (!j) {
                return std::nullopt;
            }
            if (j->is_object() && j->value("class", std::string()) == cls) {
                return j;
            }
        }
    }

    // Sends a request and returns the next line (parsed).
    std::optional<Json> request(const Json& req, Millis timeout = Millis(10'000)) {
        if (!send(req)) {
            return std::nullopt;
        }
        return readJson(timeout);
    }

    // Reads (and discards) until EOF; true when EOF came within the timeout.
    bool waitEof(Millis timeout) {
        const auto deadline = Clock::now() + timeout;
        while (!eof_) {
            if (!readLine(Millis(msLeft(deadline))) && !eof_) {
                return false;
            }
        }
        return true;
    }

    [[nodiscard]] const std::string& lastLine() const { return last_line_; }

private:
    Fd fd_;
    std::string buffer_;
    std::string last_line_;
    bool eof_ = false;
};

// Connects, retrying while the connection is refused only; for a daemon that
// has said READY=1 one attempt is enough.
inline std::optional<Client> connectClient(const std::filesystem::path& path) {
    Client c;
    if (!c.connect(path)) {
        return std::nullopt;
    }
    return c;
}

// The daemon under test, in its own directory: config file, socket, log dir,
// sd_notify socket and stderr file. Its stderr is printed when the test has
// failed, so a failure comes with the daemon's own account.
struct DaemonPaths {
    std::filesystem::path dir;
    std::filesystem::path config;
    std::filesystem::path socket;
    std::filesystem::path log_dir;
    std::filesystem::path notify;
    std::filesystem::path err;
};

inline DaemonPaths daemonPaths(const std::filesystem::path& dir) {
    return {dir, dir / "scaled.toml", dir / "s.sock", dir / "log", dir / "n.sock", dir / "err.txt"};
}

// A config file with the priors, the socket and the log directory.
inline std::string daemonConfigText(const DaemonPaths& p, const std::filesystem::path& priors,
                                    std::string_view extra_toml = {}) {
    std::string t;
    t += "[estimator]\npriors = " + tomlString(priors.string()) + "\n\n";
    t += "[socket]\npath = " + tomlString(p.socket.string()) + "\n\n";
    t += "[log]\ndir = " + tomlString(p.log_dir.string()) + "\n\n";
    t += extra_toml;
    return t;
}

struct DaemonOptions {
    std::vector<std::string> args;  // after --config FILE --no-tty
    std::vector<std::string> env;
    int listen_fd = -1;
    bool watchdog = false;  // WATCHDOG_USEC
    Millis ready_timeout = Millis(30'000);
};

class DaemonUnderTest {
public:
    DaemonUnderTest(std::string exe, const std::filesystem::path& dir)
        : exe_(std::move(exe)), paths_(daemonPaths(dir)), notify_(paths_.notify) {}
    ~DaemonUnderTest() {
        if (proc_.valid() && !proc_.exited()) {
            proc_.signal(SIGTERM);
            if (!proc_.wait(Millis(15'000))) {
                ADD_FAILURE() << "scaled did not stop within 15 s of SIGTERM; killed";
            }
        }
        if (::testing::Test::HasFailure()) {
            std::cerr << "---- scaled stderr (" << paths_.err.string() << ")\n"
                      << readFile(paths_.err) << "---- sd_notify\n"
                      << notify_.history() << "----\n";
        }
    }
    DaemonUnderTest(const DaemonUnderTest&) = delete;
    DaemonUnderTest& operator=(const DaemonUnderTest&) = delete;
    DaemonUnderTest(DaemonUnderTest&&) = delete;
    DaemonUnderTest& operator=(DaemonUnderTest&&) = delete;

    [[nodiscard]] const DaemonPaths& paths() const { return paths_; }
    NotifySocket& notify() { return notify_; }
    Process& process() { return proc_; }

    // Spawns `scaled --config CONFIG --no-tty ARGS...` and waits for READY=1.
    ::testing::AssertionResult start(const DaemonOptions& opt) {
        if (!notify_.valid()) {
            return ::testing::AssertionFailure()
                   << "cannot bind the sd_notify socket " << paths_.notify.string();
        }
        SpawnOptions so;
        so.args = {"--config", paths_.config.string(), "--no-tty"};
        so.args.insert(so.args.end(), opt.args.begin(), opt.args.end());
        so.env = opt.env;
        so.env.push_back("NOTIFY_SOCKET=" + paths_.notify.string());
        if (opt.watchdog) {
            so.env.emplace_back("WATCHDOG_USEC=1000000");
        }
        so.stderr_path = paths_.err;
        so.listen_fd = opt.listen_fd;
        proc_ = Process::spawn(exe_, so);
        if (!proc_.valid()) {
            return ::testing::AssertionFailure() << "cannot spawn " << exe_;
        }
        if (!notify_.waitFor("READY=1", opt.ready_timeout, proc_.pidfd())) {
            const auto code = proc_.wait(Millis(0));
            return ::testing::AssertionFailure()
                   << "no READY=1 from scaled within " << opt.ready_timeout.count() << " ms"
                   << (code ? " (it exited with " + std::to_string(*code) + ")" : std::string())
                   << "; stderr:\n"
                   << readFile(paths_.err);
        }
        return ::testing::AssertionSuccess();
    }

    // A connected client that has read the VERSION greeting.
    std::optional<Client> client() {
        auto c = connectClient(paths_.socket);
        if (!c) {
            return std::nullopt;
        }
        auto v = c->readJson(Millis(10'000));
        if (!v || !v->is_object() || v->value("class", std::string()) != "VERSION") {
            return std::nullopt;
        }
        return c;
    }

    [[nodiscard]] std::string stderrText() const { return readFile(paths_.err); }

private:
    std::string exe_;
    DaemonPaths paths_;
    NotifySocket notify_;
    Process proc_;
};

}  // namespace scaled::test
