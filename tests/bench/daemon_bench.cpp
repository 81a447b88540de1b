// daemon_bench: the whole `scaled` daemon measured as a process (not Google
// Benchmark). It spawns scaled with a temporary socket, log directory and
// sd_notify socket, waits for READY=1, connects N watchers (watch enable, every
// line read and counted) and one poller (`poll` every interval, round trip timed
// on the monotonic clock; `status` every second), samples /proc/PID/stat and
// /proc/PID/status every second, and ends when the daemon exits by itself
// (source.at_end=exit), when STATUS says the source has finished (then one more
// STATUS is taken, so the counters are final, and the daemon gets SIGTERM:
// source.at_end=stay), or after --duration. The sd_notify socket is read all
// along, as systemd does. Prints a JSON summary on stdout and on stderr a
// markdown table row plus the per-stage timing table (STATUS.timing of the
// final STATUS). Results: docs/benchmarks.md; runner: scripts/bench-daemon.sh.
// The process and socket helpers are the daemon tests' (daemon_harness.h).
//
//   daemon_bench [--scaled PATH] [--watchers N] [--poll-interval-ms MS]
//                [--status-interval-ms MS] [--duration S] [--ready-timeout S]
//                [--label TEXT] [--keep-dir] [--pose] [--] scaled-args...
// --pose: the watchers stream POSE lines too (socket.pose_rate_hz applies).
//
// The daemon gets `--socket DIR/s.sock --log-dir DIR/log
// --set socket.max_clients=N+4` before the given arguments, and NOTIFY_SOCKET.
// Exit codes: 0 measured (the daemon exited with 0), 1 the daemon failed or
// exited with another code, 64 usage, 69 the daemon did not start.

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
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
#include <sys/resource.h>
#include <sys/time.h>
#include <sysexits.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include "daemon_harness.h"

namespace {

using scaled::test::Client;
using scaled::test::Clock;
using scaled::test::Json;
using scaled::test::Millis;
using scaled::test::NotifySocket;
using scaled::test::Process;
using scaled::test::SpawnOptions;

struct Options {
    std::string scaled;
    int watchers = 16;
    int poll_interval_ms = 20;
    int status_interval_ms = 1000;
    double duration_s = 0;  // 0: until the daemon exits (or its source finishes)
    double ready_timeout_s = 60;
    std::string label;
    bool keep_dir = false;
    bool pose = false;  // watchers also stream POSE (watch with "pose":true)
    std::vector<std::string> scaled_args;
};

constexpr const char* kUsage =
    "usage: daemon_bench [--scaled PATH] [--watchers N] [--poll-interval-ms MS]\n"
    "                    [--status-interval-ms MS] [--duration S] [--ready-timeout S]\n"
    "                    [--label TEXT] [--keep-dir] [--pose] [--] scaled-args...\n"
    "Runs scaled (default: the one built beside this program) and measures it: dropped\n"
    "frames, detector latency (STATUS), CPU and RSS (/proc), poll round trip with N\n"
    "watchers connected. JSON summary on stdout, a markdown table row on stderr.\n";

bool parseInt(std::string_view text, int lo, int hi, int& out) {
    const std::string s(text);
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(s.c_str(), &end, 10);
    if (s.empty() || end != s.c_str() + s.size() || errno != 0 || v < lo || v > hi) {
        return false;
    }
    out = static_cast<int>(v);
    return true;
}

bool parseSeconds(std::string_view text, double& out) {
    const std::string s(text);
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(s.c_str(), &end);
    if (s.empty() || end != s.c_str() + s.size() || errno != 0 || !std::isfinite(v) || v < 0) {
        return false;
    }
    out = v;
    return true;
}

// nullopt: exit with the returned code (usage printed).
std::optional<int> parseArgs(int argc, char** argv, Options& o) {
    const std::vector<std::string> args(argv + 1, argv + argc);
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        const auto value = [&]() -> std::optional<std::string> {
            if (i + 1 >= args.size()) {
                return std::nullopt;
            }
            return args[++i];
        };
        const auto bad = [&](const std::string& what) {
            std::fprintf(stderr, "daemon_bench: %s: %s\n%s", a.c_str(), what.c_str(), kUsage);
            return EX_USAGE;
        };
        if (a == "--") {
            o.scaled_args.assign(args.begin() + static_cast<std::ptrdiff_t>(i) + 1, args.end());
            break;
        }
        if (a == "-h" || a == "--help") {
            std::fputs(kUsage, stdout);
            return EX_OK;
        }
        if (a == "--keep-dir") {
            o.keep_dir = true;
            continue;
        }
        if (a == "--pose") {
            o.pose = true;
            continue;
        }
        if (a == "--scaled" || a == "--watchers" || a == "--poll-interval-ms" ||
            a == "--status-interval-ms" || a == "--duration" || a == "--ready-timeout" ||
            a == "--label") {
            const auto v = value();
            if (!v) {
                return bad("needs a value");
            }
            if (a == "--scaled") {
                o.scaled = *v;
            } else if (a == "--label") {
                o.label = *v;
            } else if (a == "--watchers") {
                if (!parseInt(*v, 0, 1000, o.watchers)) {
                    return bad("an integer 0-1000 (got " + *v + ")");
                }
            } else if (a == "--poll-interval-ms") {
                if (!parseInt(*v, 1, 60'000, o.poll_interval_ms)) {
                    return bad("an integer 1-60000 (got " + *v + ")");
                }
            } else if (a == "--status-interval-ms") {
                if (!parseInt(*v, 10, 60'000, o.status_interval_ms)) {
                    return bad("an integer 10-60000 (got " + *v + ")");
                }
            } else if (a == "--duration") {
                if (!parseSeconds(*v, o.duration_s)) {
                    return bad("seconds >= 0 (got " + *v + ")");
                }
            } else if (!parseSeconds(*v, o.ready_timeout_s) || o.ready_timeout_s <= 0) {
                return bad("seconds > 0 (got " + *v + ")");
            }
            continue;
        }
        if (a.starts_with("-")) {
            return bad("unknown option (scaled's own arguments go after --)");
        }
        // The first bare word starts scaled's arguments.
        o.scaled_args.assign(args.begin() + static_cast<std::ptrdiff_t>(i), args.end());
        break;
    }
    if (o.scaled.empty()) {
#ifdef SCALED_BIN
        o.scaled = SCALED_BIN;
#else
        std::fprintf(stderr, "daemon_bench: --scaled PATH is required\n%s", kUsage);
        return EX_USAGE;
#endif
    }
    return std::nullopt;
}

double secondsSince(Clock::time_point t0, Clock::time_point t1) {
    return std::chrono::duration<double>(t1 - t0).count();
}

// ---- /proc sampling -------------------------------------------------------

struct ProcSample {
    Clock::time_point t;
    std::uint64_t cpu_ticks = 0;  // utime + stime
    double rss_mb = 0;            // VmRSS
    double hwm_mb = 0;            // VmHWM
    int threads = 0;
};

std::optional<ProcSample> sampleProc(pid_t pid) {
    ProcSample s;
    s.t = Clock::now();
    const std::string dir = "/proc/" + std::to_string(pid);
    {
        std::ifstream in(dir + "/stat");
        std::string text;
        if (!std::getline(in, text)) {
            return std::nullopt;
        }
        const auto paren = text.rfind(')');
        if (paren == std::string::npos) {
            return std::nullopt;
        }
        std::istringstream fields(text.substr(paren + 1));
        std::vector<std::string> f;
        for (std::string tok; fields >> tok;) {
            f.push_back(tok);
        }
        // f[0] is field 3 (state); utime is field 14, stime 15, num_threads 20.
        if (f.size() < 18 || f[0] == "Z" || f[0] == "X") {
            return std::nullopt;
        }
        s.cpu_ticks = std::stoull(f[11]) + std::stoull(f[12]);
        s.threads = std::stoi(f[17]);
    }
    std::ifstream in(dir + "/status");
    bool have_rss = false;
    for (std::string line; std::getline(in, line);) {
        const auto kb = [&line]() {
            return std::strtod(line.c_str() + line.find(':') + 1, nullptr) / 1024.0;
        };
        if (line.starts_with("VmRSS:")) {
            s.rss_mb = kb();
            have_rss = true;
        } else if (line.starts_with("VmHWM:")) {
            s.hwm_mb = kb();
        }
    }
    if (!have_rss) {
        return std::nullopt;  // exiting (no mm any more)
    }
    return s;
}

double readLoadAverage() {
    std::ifstream in("/proc/loadavg");
    double l = -1;
    in >> l;
    return l;
}

// ---- watchers -------------------------------------------------------------

struct WatcherCounts {
    std::uint64_t lines = 0;
    std::uint64_t scale_lines = 0;
    std::uint64_t pose_lines = 0;
    std::uint64_t watch_acks = 0;
    std::uint64_t other_lines = 0;
    bool eof = false;
    Clock::time_point eof_at;
};

// Reads every watcher's socket in one thread (poll over all of them); ends
// when every socket is at EOF or `stop` is set.
void readWatchers(std::vector<Client>& clients, std::vector<WatcherCounts>& counts,
                  const std::atomic<bool>& stop) {
    std::vector<pollfd> fds;
    std::vector<std::size_t> index;
    while (!stop.load()) {
        fds.clear();
        index.clear();
        for (std::size_t i = 0; i < clients.size(); ++i) {
            if (!counts[i].eof) {
                fds.push_back({clients[i].fd(), POLLIN, 0});
                index.push_back(i);
            }
        }
        if (fds.empty()) {
            return;
        }
        const int r = ::poll(fds.data(), fds.size(), 200);
        if (r < 0 && errno != EINTR) {
            return;
        }
        for (std::size_t k = 0; r > 0 && k < fds.size(); ++k) {
            if (fds[k].revents == 0) {
                continue;
            }
            const std::size_t i = index[k];
            WatcherCounts& c = counts[i];
            while (auto line = clients[i].readLine(Millis(0))) {
                ++c.lines;
                if (line->find(R"("class":"SCALE")") != std::string::npos) {
                    ++c.scale_lines;
                } else if (line->find(R"("class":"POSE")") != std::string::npos) {
                    ++c.pose_lines;
                } else if (line->find(R"("class":"WATCH")") != std::string::npos) {
                    ++c.watch_acks;
                } else {
                    ++c.other_lines;
                }
            }
            if (clients[i].eof()) {
                c.eof = true;
                c.eof_at = Clock::now();
            }
        }
    }
}

// ---- poller ---------------------------------------------------------------

struct PollerResult {
    std::vector<double> rtt_ms;
    std::uint64_t errors = 0;  // no reply, or not a SCALE
    std::optional<Json> last_scale;
    std::optional<Json> last_status;
    Clock::time_point last_status_at;
    std::uint64_t statuses = 0;
    bool source_finished = false;
    Clock::time_point source_finished_at;
    bool eof = false;
};

// Polls every `interval` and asks for STATUS every `status_interval` until
// `stop`, the daemon closes the connection, or STATUS reports the source
// finished (then one more STATUS is taken, so its counters are final).
void runPoller(Client& client, Millis interval, Millis status_interval, std::atomic<bool>& stop,
               PollerResult& out) {
    // Sent as they are (sendRaw): no JSON encoding or allocation in the timed part.
    constexpr std::string_view poll_req = "{\"cmd\":\"poll\"}\n";
    constexpr std::string_view status_req = "{\"cmd\":\"status\"}\n";
    out.rtt_ms.reserve(1 << 16);
    auto next = Clock::now();
    auto next_status = next;
    while (!stop.load()) {
        const auto now = Clock::now();
        if (now >= next_status) {
            next_status = now + status_interval;
            if (!client.sendRaw(status_req)) {
                out.eof = true;
                return;
            }
            auto j = client.readJson(Millis(5000));
            if (!j) {
                out.eof = client.eof();
                ++out.errors;
                if (out.eof) {
                    return;
                }
            } else if (j->is_object() && j->value("class", std::string()) == "STATUS") {
                ++out.statuses;
                out.last_status_at = Clock::now();
                const bool finished = j->value("source_finished", false);
                out.last_status = std::move(*j);
                if (finished) {
                    if (out.source_finished) {
                        return;  // this STATUS came after the first one saying so
                    }
                    out.source_finished = true;
                    out.source_finished_at = out.last_status_at;
                    next_status = Clock::now();
                    continue;
                }
            }
        }
        std::this_thread::sleep_until(next);
        next += interval;
        if (const auto late = Clock::now(); late > next) {
            next = late;  // behind schedule: no burst to catch up
        }
        const auto t0 = Clock::now();
        if (!client.sendRaw(poll_req)) {
            out.eof = true;
            return;
        }
        auto line = client.readLine(Millis(5000));
        const auto t1 = Clock::now();
        if (!line) {
            out.eof = client.eof();
            ++out.errors;
            if (out.eof) {
                return;
            }
            continue;
        }
        if (line->find(R"("class":"SCALE")") == std::string::npos) {
            ++out.errors;
            continue;
        }
        out.rtt_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        auto j = Json::parse(*line, nullptr, false);
        if (j.is_object()) {
            out.last_scale = std::move(j);
        }
    }
}

// Nearest-rank percentile of sorted values.
double percentile(const std::vector<double>& sorted, double p) {
    if (sorted.empty()) {
        return 0;
    }
    const auto rank =
        static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(sorted.size())));
    return sorted[std::clamp<std::size_t>(rank, 1, sorted.size()) - 1];
}

double round3(double v) {
    return std::round(v * 1000.0) / 1000.0;
}

// A member of a JSON object path, or `fallback`.
Json at(const std::optional<Json>& j, std::initializer_list<const char*> path,
        Json fallback = nullptr) {
    if (!j) {
        return fallback;
    }
    const Json* cur = &*j;
    for (const char* key : path) {
        if (!cur->is_object() || !cur->contains(key)) {
            return fallback;
        }
        cur = &(*cur)[key];
    }
    return *cur;
}

std::string fmt(double v, int decimals) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
    return buf;
}

std::string fmtJson(const Json& v, int decimals) {
    return v.is_number() ? fmt(v.get<double>(), decimals) : std::string("-");
}

// The final STATUS's per-stage timing (proto_minor 2) as a markdown table on
// stderr, stages in the daemon's order (docs/protocol.md, "Stage timing").
void printStageTable(const std::string& label, const Json& timing) {
    if (!timing.is_object()) {
        std::fprintf(stderr, "(%s: no STATUS.timing: a daemon older than proto_minor 2)\n",
                     label.c_str());
        return;
    }
    std::fprintf(stderr,
                 "\nper-stage timing (%s), final STATUS:\n\n| stage | samples | last ms | "
                 "mean ms | max ms |\n|---|---|---|---|---|\n",
                 label.empty() ? "-" : label.c_str());
    for (const char* name :
         {"predict", "search", "match", "update", "map", "tracking", "detect_pre", "detect_forward",
          "detect_post", "scale_update", "scale_publish"}) {
        const Json stage = timing.contains(name) ? timing[name] : Json(nullptr);
        const Json samples =
            stage.is_object() && stage.contains("samples") ? stage["samples"] : Json(nullptr);
        const auto field = [&](const char* key) {
            return stage.is_object() && stage.contains(key) ? fmtJson(stage[key], 3)
                                                            : std::string("-");
        };
        std::fprintf(
            stderr, "| %s | %s | %s | %s | %s |\n", name,
            samples.is_number() ? std::to_string(samples.get<std::uint64_t>()).c_str() : "-",
            field("last_ms").c_str(), field("mean_ms").c_str(), field("max_ms").c_str());
    }
}

std::string tail(const std::string& text, std::size_t n) {
    return text.size() <= n ? text : "..." + text.substr(text.size() - n);
}

int run(const Options& o) {
    // The daemon's directory.
    std::string tmpl = (std::filesystem::temp_directory_path() / "scaled-bench.XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) {
        std::perror("daemon_bench: mkdtemp");
        return EX_CANTCREAT;
    }
    const std::filesystem::path dir = tmpl;
    const auto socket_path = dir / "s.sock";
    const auto log_dir = dir / "log";
    const auto err_path = dir / "scaled.err";
    NotifySocket notify(dir / "n.sock");
    const auto cleanup = [&] {
        if (!o.keep_dir) {
            std::error_code ec;
            std::filesystem::remove_all(dir, ec);
        } else {
            std::fprintf(stderr, "daemon_bench: kept %s\n", dir.c_str());
        }
    };
    if (!notify.valid()) {
        std::fprintf(stderr, "daemon_bench: cannot bind %s\n", notify.path().c_str());
        cleanup();
        return EX_CANTCREAT;
    }

    SpawnOptions so;
    so.args = {"--socket",  socket_path.string(),
               "--log-dir", log_dir.string(),
               "--set",     "socket.max_clients=" + std::to_string(o.watchers + 4)};
    so.args.insert(so.args.end(), o.scaled_args.begin(), o.scaled_args.end());
    so.env = {"NOTIFY_SOCKET=" + notify.path().string()};
    so.stderr_path = err_path;
    const double load_at_start = readLoadAverage();
    const auto spawned_at = Clock::now();
    Process proc = Process::spawn(o.scaled, so);
    if (!proc.valid()) {
        std::fprintf(stderr, "daemon_bench: cannot spawn %s\n", o.scaled.c_str());
        cleanup();
        return EX_UNAVAILABLE;
    }
    const auto ready_timeout = Millis(static_cast<long long>(o.ready_timeout_s * 1000));
    if (!notify.waitFor("READY=1", ready_timeout, proc.pidfd())) {
        const auto code = proc.wait(Millis(0));
        const std::string why =
            code ? "it exited with " + std::to_string(*code)
                 : "none within " + std::to_string(static_cast<int>(o.ready_timeout_s)) + " s";
        std::fprintf(stderr, "daemon_bench: no READY=1 from %s (%s); its stderr:\n%s",
                     o.scaled.c_str(), why.c_str(),
                     tail(scaled::test::readFile(err_path), 4000).c_str());
        proc.kill();
        cleanup();
        return EX_UNAVAILABLE;
    }
    const auto ready_at = Clock::now();
    const pid_t pid = proc.pid();
    const long ticks_per_s = ::sysconf(_SC_CLK_TCK);
    std::vector<ProcSample> samples;
    if (auto s = sampleProc(pid)) {
        samples.push_back(*s);
    }

    // Watchers: connected, greeted, watching, before the poller starts.
    std::vector<Client> watchers(static_cast<std::size_t>(o.watchers));
    std::vector<WatcherCounts> counts(watchers.size());
    int watchers_ok = 0;
    for (auto& w : watchers) {
        if (!w.connect(socket_path)) {
            continue;
        }
        auto v = w.readJson(Millis(5000));
        if (!v || !v->is_object() || v->value("class", std::string()) != "VERSION" ||
            !w.sendRaw(o.pose ? "{\"cmd\":\"watch\",\"enable\":true,\"pose\":true}\n"
                              : "{\"cmd\":\"watch\",\"enable\":true}\n")) {
            w.close();
            continue;
        }
        ++watchers_ok;
    }
    for (std::size_t i = 0; i < watchers.size(); ++i) {
        counts[i].eof = !watchers[i].connected();
    }
    std::atomic<bool> stop_watchers{false};
    std::thread watcher_thread([&] { readWatchers(watchers, counts, stop_watchers); });

    Client poller;
    PollerResult polled;
    std::atomic<bool> stop_poller{false};
    std::thread poller_thread;
    std::atomic<bool> poller_done{false};
    bool poller_ok = false;
    if (poller.connect(socket_path)) {
        auto v = poller.readJson(Millis(5000));
        poller_ok = v && v->is_object() && v->value("class", std::string()) == "VERSION";
    }
    if (poller_ok) {
        poller_thread = std::thread([&] {
            runPoller(poller, Millis(o.poll_interval_ms), Millis(o.status_interval_ms), stop_poller,
                      polled);
            poller_done.store(true);
        });
    } else {
        std::fprintf(stderr, "daemon_bench: the poller cannot connect to %s\n",
                     socket_path.c_str());
    }

    // Main loop: a /proc sample every second; end at the daemon's exit, at
    // --duration, or when the poller has the final STATUS of a finished source.
    std::string ended_by = "daemon exit";
    auto next_sample = ready_at + std::chrono::seconds(1);
    const bool bounded = o.duration_s > 0;
    const auto deadline = ready_at + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(o.duration_s));
    const auto joinPoller = [&] {
        stop_poller.store(true);
        if (poller_thread.joinable()) {
            poller_thread.join();
        }
    };
    std::optional<Clock::time_point> socket_closed_at;
    while (true) {
        pollfd pfd{proc.pidfd(), POLLIN, 0};
        auto until = std::min(next_sample, Clock::now() + Millis(100));
        if (bounded) {
            until = std::min(until, deadline);
        }
        if (::poll(&pfd, 1, scaled::test::msLeft(until)) > 0) {
            break;  // exited
        }
        const auto now = Clock::now();
        if (now >= next_sample) {
            if (auto s = sampleProc(pid)) {
                samples.push_back(*s);
            }
            next_sample += std::chrono::seconds(1);
        }
        if (poller_done.load() && poller_thread.joinable()) {
            joinPoller();
            if (polled.source_finished) {
                ended_by = "source finished";
                break;
            }
            // Otherwise the daemon closed the connection: it is on its way out.
            socket_closed_at = now;
        }
        if (socket_closed_at && now - *socket_closed_at > std::chrono::seconds(30)) {
            ended_by = "no exit 30 s after the socket closed";
            break;
        }
        if (bounded && now >= deadline) {
            ended_by = "duration";
            break;
        }
    }
    const auto end_at = Clock::now();
    joinPoller();
    if (auto s = sampleProc(pid)) {
        samples.push_back(*s);
    }
    // Waits for the exit (the harness's NotifySocket reads the sd_notify
    // socket on its own thread meanwhile, as systemd does).
    const auto waitExit = [&](Millis timeout) -> std::optional<int> {
        const auto until = Clock::now() + timeout;
        while (true) {
            if (auto c = proc.wait(std::min(Millis(100), Millis(scaled::test::msLeft(until))))) {
                return c;
            }
            if (Clock::now() >= until) {
                return std::nullopt;
            }
        }
    };
    // A finished source: the daemon may be stopping by itself (source.at_end=exit).
    std::optional<int> code = waitExit(ended_by == "source finished" ? Millis(2000) : Millis(0));
    bool signalled = false;
    if (!code) {
        proc.signal(SIGTERM);
        signalled = true;
        code = waitExit(Millis(20'000));
    }
    if (!code) {
        std::fprintf(stderr, "daemon_bench: scaled did not stop within 20 s of SIGTERM; killed\n");
        proc.kill();
        code = proc.wait(Millis(0));
    }
    const auto exited_at = Clock::now();
    stop_watchers.store(true);
    watcher_thread.join();

    rusage children{};
    ::getrusage(RUSAGE_CHILDREN, &children);
    rusage self{};
    ::getrusage(RUSAGE_SELF, &self);
    const auto tv = [](const timeval& t) {
        return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) * 1e-6;
    };

    // ---- summary ----------------------------------------------------------
    const double run_s = secondsSince(ready_at, end_at);
    double cpu_mean = 0;
    double cpu_max = 0;
    double hwm = 0;
    double rss_last = 0;
    int threads = 0;
    if (samples.size() >= 2) {
        const auto& a = samples.front();
        const auto& b = samples.back();
        const double dt = secondsSince(a.t, b.t);
        if (dt > 0) {
            cpu_mean = 100.0 * static_cast<double>(b.cpu_ticks - a.cpu_ticks) /
                       static_cast<double>(ticks_per_s) / dt;
        }
        for (std::size_t i = 1; i < samples.size(); ++i) {
            const double d = secondsSince(samples[i - 1].t, samples[i].t);
            if (d >= 0.5) {
                cpu_max = std::max(
                    cpu_max,
                    100.0 * static_cast<double>(samples[i].cpu_ticks - samples[i - 1].cpu_ticks) /
                        static_cast<double>(ticks_per_s) / d);
            }
        }
    }
    for (const auto& s : samples) {
        hwm = std::max(hwm, s.hwm_mb);
        rss_last = s.rss_mb;
        threads = std::max(threads, s.threads);
    }
    std::vector<double> rtt = polled.rtt_ms;
    std::sort(rtt.begin(), rtt.end());
    double rtt_mean = 0;
    for (const double v : rtt) {
        rtt_mean += v;
    }
    rtt_mean = rtt.empty() ? 0 : rtt_mean / static_cast<double>(rtt.size());

    std::uint64_t lines = 0;
    std::uint64_t scale_lines = 0;
    std::uint64_t pose_lines = 0;
    std::uint64_t min_pose = UINT64_MAX;
    std::uint64_t min_scale = UINT64_MAX;
    std::uint64_t max_scale = 0;
    int closed_early = 0;  // EOF well before the daemon exited: detached
    for (std::size_t i = 0; i < watchers.size(); ++i) {
        const auto& c = counts[i];
        if (!watchers[i].connected() && c.lines == 0) {
            continue;
        }
        lines += c.lines;
        scale_lines += c.scale_lines;
        pose_lines += c.pose_lines;
        min_pose = std::min(min_pose, c.pose_lines);
        min_scale = std::min(min_scale, c.scale_lines);
        max_scale = std::max(max_scale, c.scale_lines);
        if (c.eof && c.eof_at + std::chrono::seconds(2) < end_at) {
            ++closed_early;
        }
    }
    if (min_scale == UINT64_MAX) {
        min_scale = 0;
    }
    if (min_pose == UINT64_MAX) {
        min_pose = 0;
    }

    const auto& st = polled.last_status;
    const auto& sc = polled.last_scale;
    const Json dropped = at(st, {"frames", "dropped"});
    const Json rtt_p99 = rtt.empty() ? Json(nullptr) : Json(round3(percentile(rtt, 99)));
    Json summary = {
        {"label", o.label},
        {"scaled", o.scaled},
        {"scaled_args", o.scaled_args},
        {"watchers", o.watchers},
        {"pose_watchers", o.pose},
        {"poll_interval_ms", o.poll_interval_ms},
        {"loadavg_1m_at_start", load_at_start},
        {"ended_by", ended_by},
        {"sigterm_sent", signalled},
        {"exit_code", code ? Json(*code) : Json(nullptr)},
        {"ready_s", round3(secondsSince(spawned_at, ready_at))},
        {"run_s", round3(run_s)},
        {"frames",
         {{"total", at(st, {"frames_total"})},
          {"captured", at(st, {"frames", "captured"})},
          {"tracked", at(st, {"frames", "tracked"})},
          {"dropped", dropped},
          {"source_finished", at(st, {"source_finished"}, false)}}},
        {"status_age_at_end_s", polled.statuses > 0
                                    ? Json(round3(secondsSince(polled.last_status_at, exited_at)))
                                    : Json(nullptr)},
        {"detector",
         {{"runs", at(st, {"detector", "runs"})},
          {"skipped", at(st, {"detector", "skipped"})},
          {"latency_ms_mean", at(st, {"detector", "latency_ms", "mean"})},
          {"latency_ms_max", at(st, {"detector", "latency_ms", "max"})}}},
        {"tracking_ms_mean", at(st, {"tracking_ms_mean"})},
        {"timing", at(st, {"timing"})},
        {"cpu_pct_mean", round3(cpu_mean)},
        {"cpu_pct_max_1s", round3(cpu_max)},
        {"cpu_s_total", round3(tv(children.ru_utime) + tv(children.ru_stime))},
        {"threads", threads},
        {"rss_mb_peak", round3(std::max(hwm, static_cast<double>(children.ru_maxrss) / 1024.0))},
        {"rss_mb_last", round3(rss_last)},
        {"poll_rtt_ms",
         {{"count", rtt.size()},
          {"errors", polled.errors},
          {"mean", round3(rtt_mean)},
          {"p50", rtt.empty() ? Json(nullptr) : Json(round3(percentile(rtt, 50)))},
          {"p99", rtt_p99},
          {"max", rtt.empty() ? Json(nullptr) : Json(round3(rtt.back()))}}},
        {"watcher_lines",
         {{"connected", watchers_ok},
          {"total", lines},
          {"scale", scale_lines},
          {"scale_per_watcher_min", min_scale},
          {"scale_per_watcher_max", max_scale},
          {"pose", pose_lines},
          {"pose_per_watcher_min", min_pose},
          {"closed_early", closed_early}}},
        {"clients_detached", at(st, {"clients", "detached"})},
        {"final",
         {{"scale", at(sc, {"scale"})},
          {"state", at(sc, {"state"})},
          {"epoch", at(sc, {"epoch"})},
          {"observations", at(sc, {"observations"})}}},
        {"bench_cpu_s", round3(tv(self.ru_utime) + tv(self.ru_stime))},
    };
    const double peak = summary["rss_mb_peak"].get<double>();
    summary["goals"] = {
        {"zero_dropped",
         dropped.is_number() ? Json(dropped.get<std::uint64_t>() == 0) : Json(nullptr)},
        {"rss_under_200mb", peak < 200.0},
        {"poll_p99_under_2ms",
         rtt_p99.is_number() ? Json(rtt_p99.get<double>() < 2.0) : Json(nullptr)},
    };
    std::cout << summary.dump(2) << std::endl;

    std::fprintf(stderr,
                 "| run | tracked | dropped | detector runs / skipped | detector ms mean / max "
                 "| CPU %% | RSS peak MB | poll p50 / p99 / max ms (n) | watcher lines | "
                 "scale | state |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    const auto num = [](const Json& v) {
        return v.is_number() ? std::to_string(v.get<std::int64_t>()) : std::string("-");
    };
    std::fprintf(
        stderr,
        "| %s | %s | %s | %s / %s | %s / %s | %.0f | %.1f | %s / %s / %s (%zu) | %llu | %s | %s "
        "|\n",
        o.label.empty() ? "-" : o.label.c_str(), num(at(st, {"frames", "tracked"})).c_str(),
        num(dropped).c_str(), num(at(st, {"detector", "runs"})).c_str(),
        num(at(st, {"detector", "skipped"})).c_str(),
        fmtJson(at(st, {"detector", "latency_ms", "mean"}), 2).c_str(),
        fmtJson(at(st, {"detector", "latency_ms", "max"}), 2).c_str(), cpu_mean, peak,
        rtt.empty() ? "-" : fmt(percentile(rtt, 50), 3).c_str(),
        rtt.empty() ? "-" : fmt(percentile(rtt, 99), 3).c_str(),
        rtt.empty() ? "-" : fmt(rtt.back(), 3).c_str(), rtt.size(),
        static_cast<unsigned long long>(lines), fmtJson(at(sc, {"scale"}), 4).c_str(),
        at(sc, {"state"}).is_string() ? at(sc, {"state"}).get<std::string>().c_str() : "-");
    printStageTable(o.label, at(st, {"timing"}));

    const bool ok = code && *code == 0;
    if (!ok) {
        std::fprintf(stderr, "daemon_bench: scaled exited with %s; its stderr:\n%s",
                     code ? std::to_string(*code).c_str() : "?",
                     tail(scaled::test::readFile(err_path), 4000).c_str());
    }
    cleanup();
    return ok ? EX_OK : 1;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    if (auto code = parseArgs(argc, argv, o)) {
        return *code;
    }
    return run(o);
}
