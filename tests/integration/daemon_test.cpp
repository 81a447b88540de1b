// The daemon as a process (`scaled --source sim`): the socket protocol, its
// limits, sd_notify, signals, the field log, socket activation and scalectl,
// against the contract in docs/protocol.md and daemon_config.h. Every test has
// its own directory (config, socket, log, sd_notify socket); waits are on
// events (READY=1, socket lines, the child's exit), each with a bounded timeout.

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <sys/stat.h>
#include <vector>

#include <gtest/gtest.h>

#include "daemon_harness.h"
#include "fake_iio.h"
#include "shared_dir.h"
#include "temp_dir.h"

namespace scaled::test {
namespace {

namespace fs = std::filesystem;

const fs::path kPriors = fs::path(SCALED_SOURCE_DIR) / "config" / "priors.toml";
const fs::path kExampleConfig = fs::path(SCALED_SOURCE_DIR) / "config" / "scaled.toml";
constexpr Millis kReply{10'000};  // one request/reply round trip
constexpr Millis kConverge{120'000};

const std::set<std::string> kStates = {"initialising", "tracking", "converging",
                                       "converged",    "lost",     "fault"};

std::string str(const Json& j, const char* key) {
    const auto it = j.find(key);
    return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

bool isClass(const std::optional<Json>& j, std::string_view cls) {
    return j && j->is_object() && str(*j, "class") == cls;
}

// An interval field: null, or [lo, hi] with lo <= hi.
::testing::AssertionResult checkInterval(const Json& scale, const char* key) {
    const auto it = scale.find(key);
    if (it == scale.end()) {
        return ::testing::AssertionFailure() << key << " missing in " << scale.dump();
    }
    if (it->is_null()) {
        return ::testing::AssertionSuccess();
    }
    if (!it->is_array() || it->size() != 2 || !(*it)[0].is_number() || !(*it)[1].is_number() ||
        (*it)[0].get<double>() > (*it)[1].get<double>()) {
        return ::testing::AssertionFailure() << key << " is not null or [lo, hi]: " << it->dump();
    }
    return ::testing::AssertionSuccess();
}

// Every field of a SCALE line, with its type.
::testing::AssertionResult checkScaleLine(const Json& j) {
    if (!j.is_object() || str(j, "class") != "SCALE") {
        return ::testing::AssertionFailure() << "not a SCALE line: " << j.dump();
    }
    for (const char* key : {"scale", "mean", "ci68", "ci95", "state", "epoch", "observations",
                            "frame_id", "t_ns", "time", "age_s"}) {
        if (!j.contains(key)) {
            return ::testing::AssertionFailure() << "SCALE without \"" << key << "\": " << j.dump();
        }
    }
    const bool has_scale = !j["scale"].is_null();
    if (has_scale && !j["scale"].is_number()) {
        return ::testing::AssertionFailure() << "scale is not a number or null: " << j.dump();
    }
    if (!j["state"].is_string() || kStates.count(j["state"].get<std::string>()) == 0) {
        return ::testing::AssertionFailure() << "unknown state: " << j.dump();
    }
    for (const char* key : {"epoch", "observations", "frame_id", "t_ns"}) {
        if (!j[key].is_number_integer()) {
            return ::testing::AssertionFailure() << key << " is not an integer: " << j.dump();
        }
    }
    if (!j["time"].is_number()) {
        return ::testing::AssertionFailure() << "time is not a number: " << j.dump();
    }
    if (!j["age_s"].is_null() && !j["age_s"].is_number()) {
        return ::testing::AssertionFailure() << "age_s is not a number or null: " << j.dump();
    }
    if (auto r = checkInterval(j, "ci68"); !r) {
        return r;
    }
    if (auto r = checkInterval(j, "ci95"); !r) {
        return r;
    }
    if (has_scale) {
        if (j["ci95"].is_null()) {
            return ::testing::AssertionFailure() << "a scale without ci95: " << j.dump();
        }
        const double s = j["scale"].get<double>();
        if (!(j["ci95"][0].get<double>() <= s && s <= j["ci95"][1].get<double>())) {
            return ::testing::AssertionFailure() << "scale outside its ci95: " << j.dump();
        }
    }
    if (j.contains("fault") && !j["fault"].is_string()) {
        return ::testing::AssertionFailure() << "fault is not a string: " << j.dump();
    }
    return ::testing::AssertionSuccess();
}

// Reads a watcher's SCALE lines until `pred` holds for one (returned), or the timeout.
template <typename Pred>
std::optional<Json> watchUntil(Client& c, Millis timeout, Pred pred) {
    const auto deadline = Clock::now() + timeout;
    while (true) {
        auto j = c.readClass("SCALE", Millis(msLeft(deadline)));
        if (!j) {
            return std::nullopt;
        }
        if (pred(*j)) {
            return j;
        }
    }
}

bool enableWatch(Client& c, bool enable) {
    if (!c.send(Json{{"cmd", "watch"}, {"enable", enable}})) {
        return false;
    }
    auto ack = c.readClass("WATCH", kReply);
    return ack && ack->value("enable", !enable) == enable;
}

std::optional<Json> status(Client& c) {
    if (!c.send(Json{{"cmd", "status"}})) {
        return std::nullopt;
    }
    return c.readClass("STATUS", kReply);
}

class DaemonTest : public ::testing::Test {
protected:
    DaemonTest() : tmp_("d"), daemon_(SCALED_BIN, tmp_.path()) {}

    [[nodiscard]] const DaemonPaths& paths() const { return daemon_.paths(); }

    // Writes the config (priors, socket, log dir) and starts `--source sim`
    // with `args`, waiting for READY=1.
    ::testing::AssertionResult startSim(std::vector<std::string> args,
                                        const fs::path& priors = kPriors) {
        writeFile(paths().config, daemonConfigText(paths(), priors));
        DaemonOptions opt;
        opt.args = {"--source", "sim"};
        opt.args.insert(opt.args.end(), args.begin(), args.end());
        return daemon_.start(opt);
    }

    // A client that has read VERSION (fails the test when it cannot).
    Client client() {
        auto c = daemon_.client();
        EXPECT_TRUE(c.has_value())
            << "cannot connect to " << paths().socket.string() << " or no VERSION greeting";
        return c ? std::move(*c) : Client();
    }

    // SIGTERM, STOPPING=1, exit code.
    std::optional<int> stop() {
        EXPECT_TRUE(daemon_.process().signal(SIGTERM));
        EXPECT_TRUE(daemon_.notify().waitFor("STOPPING=1", Millis(15'000)))
            << "no STOPPING=1 after SIGTERM";
        return daemon_.process().wait(Millis(30'000));
    }

    TempDir tmp_;
    DaemonUnderTest daemon_;
};

// Every line of every field-log file, parsed, in file order (files by name).
struct LogLine {
    fs::path file;
    Json json;
};
::testing::AssertionResult readLogs(const fs::path& dir, std::vector<LogLine>& out) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (const auto& e : fs::recursive_directory_iterator(dir, ec)) {
        if (e.is_regular_file() && e.path().extension() == ".jsonl") {
            files.push_back(e.path());
        }
    }
    if (files.empty()) {
        return ::testing::AssertionFailure() << "no *.jsonl file in " << dir.string();
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
        const std::string text = readFile(f);
        if (text.empty()) {
            continue;
        }
        if (text.back() != '\n') {
            return ::testing::AssertionFailure()
                   << f.string() << ": the last line is incomplete (no newline)";
        }
        std::istringstream in(text);
        std::string line;
        int n = 0;
        while (std::getline(in, line)) {
            ++n;
            Json j = Json::parse(line, nullptr, false);
            if (j.is_discarded() || !j.is_object() || !j.contains("class") ||
                !j["class"].is_string() || !j.contains("mono_ns") ||
                !j["mono_ns"].is_number_integer()) {
                return ::testing::AssertionFailure()
                       << f.string() << ":" << n
                       << ": not a log line (JSON with class, mono_ns): " << line;
            }
            out.push_back({f, std::move(j)});
        }
    }
    return ::testing::AssertionSuccess();
}

// 1. VERSION on connect; poll gives a complete SCALE; the socket file is 0660.
TEST_F(DaemonTest, VersionOnConnectThenPollGivesScale) {
    ASSERT_TRUE(startSim({}));
    const RunResult version = runCommand(SCALED_BIN, {"--version"}, tmp_.path(), kReply);
    ASSERT_EQ(version.exit_code, 0) << version.err;

    Client c(paths().socket);
    ASSERT_TRUE(c.connected()) << paths().socket.string();
    const auto v = c.readJson(kReply);
    ASSERT_TRUE(isClass(v, "VERSION")) << c.lastLine();
    EXPECT_EQ(v->value("proto_major", -1), 1) << v->dump();
    EXPECT_TRUE((*v)["proto_minor"].is_number_integer()) << v->dump();
    ASSERT_TRUE((*v)["release"].is_string()) << v->dump();
    EXPECT_FALSE((*v)["release"].get<std::string>().empty());
    EXPECT_EQ("scaled " + (*v)["release"].get<std::string>() + "\n", version.out)
        << "VERSION.release differs from scaled --version";

    const auto s = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(s.has_value()) << "no reply to poll";
    EXPECT_TRUE(checkScaleLine(*s));

    struct stat st = {};
    ASSERT_EQ(::stat(paths().socket.c_str(), &st), 0);
    EXPECT_TRUE(S_ISSOCK(st.st_mode));
    EXPECT_EQ(st.st_mode & 0777U, 0660U) << std::oct << (st.st_mode & 0777U);

    // STATUS and POSTERIOR answer on the same connection.
    const auto stat_reply = status(c);
    ASSERT_TRUE(stat_reply.has_value());
    for (const char* key :
         {"source", "uptime_s", "fps", "frame_id", "frames_total", "source_finished", "frames",
          "detector", "tracking_ms_mean", "features", "scale_updates", "epoch", "clients", "log"}) {
        EXPECT_TRUE(stat_reply->contains(key)) << key << " missing: " << stat_reply->dump();
    }
    EXPECT_EQ(str(*stat_reply, "source"), "sim");
    const auto post = c.request(Json{{"cmd", "posterior"}});
    ASSERT_TRUE(isClass(post, "POSTERIOR")) << c.lastLine().substr(0, 300);
    ASSERT_TRUE((*post)["d"].is_array() && (*post)["log_p"].is_array());
    EXPECT_EQ((*post)["d"].size(), (*post)["log_p"].size());
    for (const char* key : {"epoch", "frame_id", "observations"}) {
        EXPECT_TRUE(post->contains(key)) << key;
    }
}

// 2. watch: SCALE lines in frame order until watch is disabled.
TEST_F(DaemonTest, WatchStreamsScaleInFrameOrderUntilDisabled) {
    // A detection every second frame: ten updates come within a few hundred
    // frames, which a sanitizer build on a loaded CI machine (7 fps) reaches
    // well inside the deadline; the test is about order, not cadence.
    ASSERT_TRUE(startSim({"--pacing", "fast", "--set", "detection.every_frames=2"}));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true)) << c.lastLine();

    std::vector<Json> lines;
    int updates = 0;  // lines whose observations grew
    const auto deadline = Clock::now() + Millis(60'000);
    while (updates < 10) {
        auto j = c.readJson(Millis(msLeft(deadline)));
        ASSERT_TRUE(j.has_value())
            << "only " << lines.size() << " SCALE lines, " << updates << " updates within 60 s";
        ASSERT_TRUE(checkScaleLine(*j));
        if (!lines.empty()) {
            const Json& prev = lines.back();
            EXPECT_GE((*j)["epoch"].get<std::int64_t>(), prev["epoch"].get<std::int64_t>());
            EXPECT_GE((*j)["frame_id"].get<std::int64_t>(), prev["frame_id"].get<std::int64_t>())
                << prev.dump() << "\n"
                << j->dump();
            if ((*j)["epoch"] == prev["epoch"] && (*j)["observations"] != prev["observations"]) {
                ++updates;
                EXPECT_GT((*j)["frame_id"].get<std::int64_t>(),
                          prev["frame_id"].get<std::int64_t>())
                    << "an update on the frame of the previous one:\n"
                    << prev.dump() << "\n"
                    << j->dump();
            }
        }
        lines.push_back(std::move(*j));
    }

    // Disable: WATCH false (SCALE lines already queued may come first).
    ASSERT_TRUE(enableWatch(c, false)) << c.lastLine();
    // Another watcher sees updates going on ...
    Client w = client();
    ASSERT_TRUE(enableWatch(w, true));
    const std::int64_t frame0 = lines.back()["frame_id"].get<std::int64_t>();
    ASSERT_TRUE(watchUntil(w, Millis(30'000), [&](const Json& j) {
        return j["frame_id"].get<std::int64_t>() > frame0 + 30;
    })) << "the daemon stopped publishing";
    // ... while the first one receives none: its next line answers its request.
    ASSERT_TRUE(c.send(Json{{"cmd", "status"}}));
    const auto next = c.readJson(kReply);
    EXPECT_TRUE(isClass(next, "STATUS")) << "after watch false: " << c.lastLine();
}

// The daemon's path to "converged" (the state, its SCALE line, scalectl's
// --require-converged) needs a run that converges. The default model
// (estimator.model = "object") does not on the sim, by design and even with
// priors that know the sim's objects (tests/support/sim_priors.h) and
// objects.map_rel_sigma = 0: each object keeps a common relative error
// (objects.object_rel_sigma, 5%) besides its class's spread, so the sim's
// four objects allow a 95% width of 10.0% at best (the converged threshold is
// "narrower than 10%"), and the anchors' depth uncertainty (4-13% of their
// distance after minutes: the camera's loop is small against the objects'
// distance) widens it further. Measured with `scaled --source sim --pacing
// fast --set objects.map_rel_sigma=0` and those priors: 19% wide after 120 s
// (frame 20840), four objects used, 27-32 views each; tests/unit/sim's
// ExactPriorsNarrowTheIntervalAroundTheTrueScale. These tests are about the
// daemon's converged path, not the estimator: they pin the paper model, which
// converges on the sim within a few seconds.
const std::vector<std::string> kConvergingModel = {"--set", "estimator.model=paper"};

// 3. The sim converges (fast pacing) to a positive scale inside a narrow ci95
// (the paper model: see kConvergingModel).
TEST_F(DaemonTest, SimConvergesFast) {
    std::vector<std::string> args = {"--pacing", "fast"};
    args.insert(args.end(), kConvergingModel.begin(), kConvergingModel.end());
    ASSERT_TRUE(startSim(args));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    Json last;
    const auto conv = watchUntil(c, kConverge, [&](const Json& j) {
        last = j;
        return str(j, "state") == "converged";
    });
    ASSERT_TRUE(conv.has_value()) << "not converged within " << kConverge.count()
                                  << " ms; last: " << last.dump();
    ASSERT_TRUE(checkScaleLine(*conv));
    ASSERT_TRUE((*conv)["scale"].is_number()) << conv->dump();
    const double s = (*conv)["scale"].get<double>();
    const double lo = (*conv)["ci95"][0].get<double>();
    const double hi = (*conv)["ci95"][1].get<double>();
    EXPECT_GT(s, 0);
    EXPECT_LE(lo, s);
    EXPECT_GE(hi, s);
    EXPECT_LT((hi - lo) / s, 0.10) << conv->dump();
    EXPECT_GE((*conv)["epoch"].get<std::int64_t>(), 1);
    EXPECT_GT((*conv)["observations"].get<std::int64_t>(), 0);
    // A poll agrees.
    ASSERT_TRUE(enableWatch(c, false));
    const auto p = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(isClass(p, "SCALE"));
    EXPECT_EQ((*p)["epoch"], (*conv)["epoch"]);
    EXPECT_GE((*p)["observations"].get<std::int64_t>(),
              (*conv)["observations"].get<std::int64_t>());
}

// 5. max_clients: 16 served, the 17th gets ERROR and EOF; a freed slot is reused.
TEST_F(DaemonTest, SeventeenthClientIsRejectedAndAFreedSlotReused) {
    ASSERT_TRUE(startSim({"--set", "socket.max_clients=16"}));
    std::vector<Client> clients;
    for (int i = 0; i < 16; ++i) {
        Client c(paths().socket);
        ASSERT_TRUE(c.connected()) << "client " << i;
        ASSERT_TRUE(isClass(c.readJson(kReply), "VERSION"))
            << "client " << i << ": " << c.lastLine();
        clients.push_back(std::move(c));
    }
    for (int i = 0; i < 16; ++i) {
        const auto s = clients[static_cast<std::size_t>(i)].request(Json{{"cmd", "poll"}});
        ASSERT_TRUE(s.has_value()) << "client " << i;
        EXPECT_TRUE(checkScaleLine(*s)) << "client " << i;
    }
    Client extra(paths().socket);
    ASSERT_TRUE(extra.connected());
    const auto rejected = extra.readJson(kReply);
    EXPECT_TRUE(isClass(rejected, "ERROR")) << "17th client got: " << extra.lastLine();
    EXPECT_TRUE(extra.waitEof(kReply)) << "17th client not closed";

    // One leaves; once the daemon has seen it go, a newcomer is served.
    clients.back().close();
    clients.pop_back();
    bool freed = false;
    for (int i = 0; i < 1000 && !freed; ++i) {
        const auto st = status(clients.front());
        ASSERT_TRUE(st.has_value());
        freed = (*st)["clients"].value("connected", -1) == 15;
        if (freed) {
            EXPECT_EQ((*st)["clients"].value("max", -1), 16) << st->dump();
            EXPECT_GE((*st)["clients"].value("rejected", 0), 1) << st->dump();
            EXPECT_GE((*st)["clients"].value("accepted", 0), 16) << st->dump();
        }
    }
    ASSERT_TRUE(freed) << "STATUS never showed 15 connected clients";
    Client again(paths().socket);
    ASSERT_TRUE(again.connected());
    ASSERT_TRUE(isClass(again.readJson(kReply), "VERSION")) << again.lastLine();
    EXPECT_TRUE(isClass(again.request(Json{{"cmd", "poll"}}), "SCALE")) << again.lastLine();
}

// 6. A client that never reads is detached; a watcher is unaffected, nothing
// is dropped and the pipeline keeps ~30 fps (the daemon's own counters).
TEST_F(DaemonTest, NonReadingClientIsDetachedWithoutStallingThePipeline) {
    // stall_timeout_s: detached by its stream filling the buffer or after 1 s
    // with nothing read, whichever comes first (the default 10 s only slows the test).
    ASSERT_TRUE(startSim({"--pacing", "realtime", "--set", "socket.client_buffer_bytes=65536",
                          "--set", "socket.stall_timeout_s=1"}));
    Client watcher = client();
    ASSERT_TRUE(enableWatch(watcher, true));
    Client ctl = client();

    // POSTERIOR carries the grid (tens of kB) once there are observations.
    ASSERT_TRUE(watchUntil(watcher, Millis(60'000), [](const Json& j) {
        return j["observations"].get<std::int64_t>() > 0;
    })) << "no observation within 60 s";
    Client hog = client();
    std::string burst;
    for (int i = 0; i < 200; ++i) {
        burst += "{\"cmd\":\"posterior\"}\n";
    }
    ASSERT_TRUE(hog.sendRaw(burst));

    // Each STATUS is asked after a watcher line arrived (the pacing event).
    bool detached = false;
    const auto deadline = Clock::now() + Millis(30'000);
    while (!detached && Clock::now() < deadline) {
        ASSERT_TRUE(watcher.readClass("SCALE", kReply)) << "the watcher stopped receiving";
        const auto st = status(ctl);
        ASSERT_TRUE(st.has_value());
        detached = (*st)["clients"].value("detached", 0) >= 1;
    }
    ASSERT_TRUE(detached) << "the non-reading client was not detached within 30 s";
    EXPECT_TRUE(hog.waitEof(Millis(30'000))) << "the detached client's connection is still open";

    // The watcher keeps receiving, in order.
    std::int64_t last_frame = -1;
    for (int i = 0; i < 5; ++i) {
        const auto j = watcher.readClass("SCALE", kReply);
        ASSERT_TRUE(j.has_value()) << "the watcher stopped receiving after the detach";
        EXPECT_GE((*j)["frame_id"].get<std::int64_t>(), last_frame);
        last_frame = (*j)["frame_id"].get<std::int64_t>();
    }
    const auto st = status(ctl);
    ASSERT_TRUE(st.has_value());
    EXPECT_GE((*st)["clients"].value("detached", 0), 1);
#if defined(__SANITIZE_ADDRESS__)
    // Under ASan the real-time sim itself runs below 30 fps and drops frames
    // whatever the clients do; the frame-rate half is checked in release.
    GTEST_SKIP() << "frame rate not checked under AddressSanitizer (detach checked above)";
#endif
    EXPECT_EQ((*st)["frames"].value("dropped", -1), 0) << st->dump();
    EXPECT_GT(st->value("fps", 0.0), 20.0) << "the daemon's own fps counter: " << st->dump();
}

// 7. Malformed requests: one ERROR each, and the connection stays usable.
TEST_F(DaemonTest, MalformedRequestsGetOneErrorEachAndTheConnectionStaysUsable) {
    ASSERT_TRUE(startSim({}));
    Client c = client();
    const std::string long_line =
        R"({"cmd":"poll","pad":")" + std::string(5000, 'x') + R"("})";  // > 4096 bytes
    const std::vector<std::string> bad = {
        "not json", "[]", "{}", R"({"cmd":"fly"})", R"({"cmd":"watch","enable":"yes"})", long_line};
    for (const auto& line : bad) {
        ASSERT_TRUE(c.sendLine(line));
        const auto reply = c.readJson(kReply);
        ASSERT_TRUE(isClass(reply, "ERROR"))
            << "request " << line.substr(0, 60) << " got: " << c.lastLine().substr(0, 200);
        EXPECT_TRUE((*reply)["message"].is_string()) << reply->dump();
        EXPECT_FALSE(str(*reply, "message").empty());
    }
    // Exactly one ERROR each: the next line answers the poll.
    const auto s = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(s.has_value());
    EXPECT_TRUE(checkScaleLine(*s)) << "after the malformed requests";
}

// 8. SIGTERM: STOPPING=1, exit 0, socket removed, complete log ending in STOP.
TEST_F(DaemonTest, SigtermStopsCleanlyWithACompleteLog) {
    ASSERT_TRUE(startSim({"--set", "log.frame_every=1", "--set", "log.fsync_interval_ms=100",
                          "--set", "detection.every_frames=2"}));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    int updates = 0;
    ASSERT_TRUE(watchUntil(c, Millis(60'000), [&](const Json& j) {
        updates += j["observations"].get<std::int64_t>() > 0 ? 1 : 0;
        return updates >= 3;
    })) << "fewer than 3 SCALE updates with observations within 60 s";

    const auto code = stop();
    ASSERT_TRUE(code.has_value()) << "scaled did not exit within 30 s of SIGTERM";
    EXPECT_EQ(*code, 0);
    EXPECT_TRUE(c.waitEof(kReply)) << "the client's connection was not closed";
    EXPECT_FALSE(fs::exists(fs::symlink_status(paths().socket))) << "socket file left behind";

    std::vector<LogLine> log;
    ASSERT_TRUE(readLogs(paths().log_dir, log));
    ASSERT_FALSE(log.empty());
    std::map<std::string, int> classes;
    for (const auto& l : log) {
        ++classes[str(l.json, "class")];
    }
    EXPECT_EQ(classes["START"], 1);
    EXPECT_EQ(classes["STOP"], 1);
    EXPECT_GE(classes["FRAME"], 10) << "frame_every=1";
    EXPECT_GE(classes["SCALE"], 1);
    EXPECT_GE(classes["DETECTION"], 1);
    EXPECT_EQ(str(log.front().json, "class"), "START") << log.front().file.string();
    // The last line written (the latest mono_ns) is STOP.
    const auto last = std::max_element(log.begin(), log.end(), [](const auto& a, const auto& b) {
        return a.json["mono_ns"].template get<std::int64_t>() <
               b.json["mono_ns"].template get<std::int64_t>();
    });
    EXPECT_EQ(str(last->json, "class"), "STOP") << last->json.dump();
    EXPECT_EQ(str(log.back().json, "class"), "STOP") << log.back().json.dump();
}

// The priors file with every height (mean, std, min, max) times `factor`.
std::string scaledPriors(const std::string& text, double factor) {
    static const std::regex kLine(R"(^(mean_m|std_m|min_m|max_m)(\s*=\s*)([0-9.]+)(.*)$)");
    std::istringstream in(text);
    std::string out;
    std::string line;
    while (std::getline(in, line)) {
        std::smatch m;
        if (std::regex_match(line, m, kLine)) {
            std::ostringstream v;
            v << std::stod(m[3].str()) * factor;
            line = m[1].str() + m[2].str() + v.str() + m[4].str();
        }
        out += line + "\n";
    }
    return out;
}

// 9. SIGHUP: the priors are reloaded, the posterior (epoch, observations)
// kept; a broken file leaves the daemon running and is logged as an ERROR.
TEST_F(DaemonTest, SighupReloadsPriorsAndKeepsThePosterior) {
    const fs::path p1 = tmp_.path() / "p1.toml";
    const fs::path p2 = tmp_.path() / "p2.toml";
    const std::string priors = readFile(kPriors);
    writeFile(p1, priors);
    const std::string modified = scaledPriors(priors, 1.1);
    ASSERT_NE(modified, priors);
    writeFile(p2, modified);

    ASSERT_TRUE(
        startSim({"--set", "log.fsync_interval_ms=100", "--set", "detection.every_frames=2"}, p1));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    const auto before = watchUntil(c, Millis(60'000), [](const Json& j) {
        return j["observations"].get<std::int64_t>() >= 5;
    });
    ASSERT_TRUE(before.has_value()) << "fewer than 5 observations within 60 s";

    writeFile(paths().config, daemonConfigText(paths(), p2));
    ASSERT_TRUE(daemon_.process().signal(SIGHUP));
    ASSERT_TRUE(daemon_.notify().waitFor("RELOADING=1", kReply)) << "no RELOADING=1";
    ASSERT_TRUE(daemon_.notify().waitFor("READY=1", kReply)) << "no READY=1 after RELOADING=1";

    ASSERT_TRUE(enableWatch(c, false));
    const auto after = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(isClass(after, "SCALE")) << c.lastLine();
    EXPECT_EQ((*after)["epoch"], (*before)["epoch"]) << "epoch changed over the reload";
    EXPECT_GE((*after)["observations"].get<std::int64_t>(),
              (*before)["observations"].get<std::int64_t>())
        << "observations reset by the reload";
    // Observations keep growing from there, in the same epoch.
    ASSERT_TRUE(enableWatch(c, true));
    const std::int64_t obs_after = (*after)["observations"].get<std::int64_t>();
    const auto grown = watchUntil(c, Millis(60'000), [&](const Json& j) {
        return j["observations"].get<std::int64_t>() > obs_after ||
               j["epoch"] != (*before)["epoch"];
    });
    ASSERT_TRUE(grown.has_value()) << "no new observation after the reload";
    EXPECT_EQ((*grown)["epoch"], (*before)["epoch"]) << grown->dump();
    ASSERT_TRUE(enableWatch(c, false));

    // A broken file: the running configuration stays.
    writeFile(paths().config, daemonConfigText(paths(), p2, "[detection]\nevery_frames = 0\n"));
    ASSERT_TRUE(daemon_.process().signal(SIGHUP));
    ASSERT_TRUE(daemon_.notify().waitFor("RELOADING=1", kReply)) << "no RELOADING=1 (broken)";
    ASSERT_TRUE(daemon_.notify().waitFor("READY=1", kReply)) << "no READY=1 (broken)";
    const auto still = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(isClass(still, "SCALE")) << c.lastLine();
    EXPECT_EQ((*still)["epoch"], (*before)["epoch"]);
    EXPECT_FALSE(daemon_.process().wait(Millis(0)).has_value()) << "scaled exited";

    const auto code = stop();
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0);
    std::vector<LogLine> log;
    ASSERT_TRUE(readLogs(paths().log_dir, log));
    const bool logged = std::any_of(log.begin(), log.end(), [](const LogLine& l) {
        return str(l.json, "class") == "ERROR" &&
               l.json.dump().find("detection.every_frames") != std::string::npos;
    });
    EXPECT_TRUE(logged) << "no ERROR log line naming detection.every_frames";
    EXPECT_NE(daemon_.stderrText().find("detection.every_frames"), std::string::npos);
}

// 10. --check-config: the example file is valid; broken ones exit 78 naming the key.
TEST_F(DaemonTest, CheckConfigAcceptsTheExampleAndNamesTheBrokenKey) {
    if (!fs::exists(kExampleConfig)) {
        GTEST_SKIP() << kExampleConfig.string() << " not in the tree yet";
    }
    const auto ok =
        runCommand(SCALED_BIN, {"--check-config", kExampleConfig.string()}, tmp_.path(), kReply);
    EXPECT_EQ(ok.exit_code, 0) << ok.err;

    struct Case {
        const char* name;
        const char* toml;
        const char* expect;  // in stderr
    };
    const Case cases[] = {
        {"unknown.toml", "[socket]\nmax_clients = 4\nbogus_key = 1\n", "socket.bogus_key"},
        {"range.toml", "[socket]\nmax_clients = 0\n", "socket.max_clients"},
        {"syntax.toml", "[socket\nmax_clients = 4\n", "syntax.toml"},
    };
    for (const auto& k : cases) {
        const fs::path f = tmp_.path() / k.name;
        writeFile(f, k.toml);
        const auto r = runCommand(SCALED_BIN, {"--check-config", f.string()}, tmp_.path(), kReply);
        EXPECT_EQ(r.exit_code, 78) << k.name << ": " << r.err;
        EXPECT_NE(r.err.find(k.expect), std::string::npos)
            << k.name << ": stderr does not name " << k.expect << ": " << r.err;
    }
}

// Run from a build tree: no priors configured and none installed at
// /etc/scaled/priors.toml, the daemon serves with the priors built into it
// (config/priors.toml of its source tree) and says so.
TEST_F(DaemonTest, WithoutInstalledPriorsItUsesTheBuiltInOnes) {
    if (fs::exists("/etc/scaled/priors.toml")) {
        GTEST_SKIP() << "/etc/scaled/priors.toml is installed here: it would win";
    }
    std::string text;
    text += "[socket]\npath = \"" + paths().socket.string() + "\"\n\n";
    text += "[log]\ndir = \"" + paths().log_dir.string() + "\"\n";
    writeFile(paths().config, text);
    DaemonOptions opt;
    opt.args = {"--source", "sim"};
    ASSERT_TRUE(daemon_.start(opt));
    Client c = client();
    ASSERT_TRUE(c.send(Json{{"cmd", "status"}}));
    ASSERT_TRUE(c.readClass("STATUS", kReply).has_value());
    EXPECT_EQ(stop(), std::optional<int>(0));
    const std::string err = readFile(paths().err);
    EXPECT_NE(
        err.find("/etc/scaled/priors.toml not found: using the priors built into this binary"),
        std::string::npos)
        << err;
}

// Missing replay directory: 66; a live camera in this build: 69; bad --set: 78.
TEST_F(DaemonTest, StartupFailuresExitWithSysexitsCodes) {
    writeFile(paths().config, daemonConfigText(paths(), kPriors));
    const std::vector<std::string> base = {"--config", paths().config.string(), "--no-tty"};
    auto with = [&](std::vector<std::string> more) {
        auto a = base;
        a.insert(a.end(), more.begin(), more.end());
        return a;
    };
    const auto missing =
        runCommand(SCALED_BIN, with({"--source", "replay:" + (tmp_.path() / "none").string()}),
                   tmp_.path(), Millis(30'000));
    EXPECT_EQ(missing.exit_code, 66) << missing.err;
    // A live camera without its calibration is a configuration error.
    const auto v4l2 = runCommand(SCALED_BIN, with({"--source", "v4l2:/dev/video99"}), tmp_.path(),
                                 Millis(30'000));
    EXPECT_EQ(v4l2.exit_code, 78) << v4l2.err;
    EXPECT_NE(v4l2.err.find("camera.fx_px"), std::string::npos) << v4l2.err;
    // A path that is not a camera at all: the device answers, wrongly (not a
    // missing camera to wait for).
    const auto not_camera = runCommand(
        SCALED_BIN,
        with({"--source", "v4l2:/dev/null", "--set", "camera.fx_px=500", "--set",
              "camera.fy_px=500", "--set", "camera.cx_px=320", "--set", "camera.cy_px=240"}),
        tmp_.path(), Millis(30'000));
    EXPECT_NE(not_camera.exit_code, 0) << not_camera.err;
    EXPECT_NE(not_camera.err.find("/dev/null"), std::string::npos) << not_camera.err;
    const auto bad =
        runCommand(SCALED_BIN, with({"--source", "sim", "--set", "socket.max_clients=0"}),
                   tmp_.path(), Millis(30'000));
    EXPECT_EQ(bad.exit_code, 78) << bad.err;
    EXPECT_NE(bad.err.find("socket.max_clients"), std::string::npos) << bad.err;
    EXPECT_FALSE(fs::exists(fs::symlink_status(paths().socket)));
}

// 11. Socket activation: the inherited fd 3 is served; the configured path is not created.
TEST_F(DaemonTest, SocketActivationServesTheInheritedSocket) {
    const fs::path activated = tmp_.path() / "act.sock";
    Fd listener = listenUnix(activated);
    ASSERT_TRUE(listener.isValid()) << activated.string();
    writeFile(paths().config, daemonConfigText(paths(), kPriors));
    DaemonOptions opt;
    opt.args = {"--source", "sim"};
    opt.listen_fd = listener.get();
    ASSERT_TRUE(daemon_.start(opt));
    listener.reset();  // the daemon holds it now

    Client c(activated);
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(isClass(c.readJson(kReply), "VERSION")) << c.lastLine();
    const auto s = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(s.has_value());
    EXPECT_TRUE(checkScaleLine(*s));
    EXPECT_FALSE(fs::exists(fs::symlink_status(paths().socket)))
        << "the configured socket path was created although socket-activated";
    EXPECT_NE(daemon_.stderrText().find("socket activation"), std::string::npos);

    const auto code = stop();
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0);
    EXPECT_TRUE(fs::exists(fs::symlink_status(activated)))
        << "the activated socket's file belongs to systemd and must stay";
}

// 12. A log directory that cannot be created: the scale is served with a fault.
TEST_F(DaemonTest, UnwritableLogDirIsAFaultNotAStop) {
    const fs::path file = tmp_.path() / "plain_file";
    writeFile(file, "x");
    ASSERT_TRUE(startSim({"--log-dir", (file / "log").string()}));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    Json last;
    const auto faulted = watchUntil(c, Millis(20'000), [&](const Json& j) {
        last = j;
        return j.contains("fault");
    });
    ASSERT_TRUE(faulted.has_value()) << "no SCALE with a fault within 20 s; last: " << last.dump();
    EXPECT_EQ(str(*faulted, "fault").rfind("log:", 0), 0U) << faulted->dump();
    ASSERT_TRUE(enableWatch(c, false));
    const auto p = c.request(Json{{"cmd", "poll"}});
    ASSERT_TRUE(isClass(p, "SCALE"));
    EXPECT_EQ(str(*p, "fault").rfind("log:", 0), 0U) << p->dump();
    const auto st = status(c);
    ASSERT_TRUE(st.has_value());
    EXPECT_EQ(str((*st)["log"], "state"), "fault") << st->dump();
    EXPECT_TRUE((*st)["log"]["error"].is_string()) << st->dump();
}

// 12a. An IMU ([imu]): its accelerometer gives the first map its vertical
// (STATUS gravity_source, gravity_down_C, imu). The device is a directory
// laid out like /sys/bus/iio/devices/iio:deviceN (sysfs mode reads plain
// attribute files; the kernel's own device is vm.daemon's): a body-axes IMU
// (x forward, y left, z up) at rest on a level camera.
TEST_F(DaemonTest, TheImuGivesTheFirstMapItsVertical) {
    const fs::path dev = tmp_.path() / "iio" / "iio:device0";
    test::writeFakeAccelerometer(dev, "lsm6dsl", {0, 0, 16393}, "0.000598");
    ASSERT_TRUE(startSim({"--set", "imu.device=\"" + dev.string() + "\"", "--set",
                          "imu.rotation_imu_to_camera=[0,-1,0, 0,0,-1, 1,0,0]"}));
    Client c = client();
    std::optional<Json> st;
    const auto deadline = Clock::now() + Millis(30'000);
    while (Clock::now() < deadline) {
        st = status(c);
        ASSERT_TRUE(st.has_value()) << c.lastLine();
        if (st->contains("gravity_source")) {
            break;
        }
    }
    ASSERT_TRUE(st->contains("gravity_source")) << "no map within 30 s: " << st->dump();
    EXPECT_EQ(str(*st, "gravity_source").rfind("accelerometer (iio:device0 [lsm6dsl], ", 0), 0U)
        << st->dump();
    ASSERT_TRUE((*st)["gravity_down_C"].is_array()) << st->dump();
    EXPECT_NEAR((*st)["gravity_down_C"][0].get<double>(), 0, 1e-6);
    EXPECT_NEAR((*st)["gravity_down_C"][1].get<double>(), 1, 1e-6);
    EXPECT_NEAR((*st)["gravity_down_C"][2].get<double>(), 0, 1e-6);
    EXPECT_EQ(str((*st)["imu"], "device"), "iio:device0 [lsm6dsl]") << st->dump();
    EXPECT_EQ(str((*st)["imu"], "mode"), "sysfs 100 Hz") << st->dump();
    EXPECT_GT((*st)["imu"]["samples"].get<std::int64_t>(), 0) << st->dump();
    EXPECT_FALSE((*st)["imu"].contains("error")) << st->dump();
}

// 12a'. An IMU that is not there: said once on stderr and in STATUS.imu, and
// the daemon runs on with the next source of the vertical.
TEST_F(DaemonTest, AMissingImuIsReportedAndTheDaemonRunsOn) {
    ASSERT_TRUE(startSim({"--set", "imu.device=\"bmi270\""}));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    ASSERT_TRUE(watchUntil(c, Millis(30'000), [](const Json& j) {
        return j["frame_id"].get<std::int64_t>() > 5;
    })) << "no frames";
    ASSERT_TRUE(enableWatch(c, false));
    const auto st = status(c);
    ASSERT_TRUE(st.has_value());
    EXPECT_EQ(str((*st)["imu"], "device"), "bmi270") << st->dump();
    EXPECT_EQ((*st)["imu"]["samples"].get<std::int64_t>(), 0) << st->dump();
    EXPECT_NE(str((*st)["imu"], "error").find("bmi270"), std::string::npos) << st->dump();
    EXPECT_EQ(str(*st, "gravity_source"), "dataset gravity and ground-truth pose") << st->dump();
    EXPECT_NE(readFile(paths().err).find("imu: "), std::string::npos);
}

// 12b. A camera that is not there (yet): the daemon starts, serves SCALE with
// state "fault" naming the device, STATUS says the camera is lost, and it
// stops cleanly. (Its return is tested with a real device in the VM.)
TEST_F(DaemonTest, AMissingCameraIsAFaultAndTheDaemonRunsOn) {
    // The detector is the real network for a camera source.
    const fs::path model = sharedModel("yolox_nano.onnx");
    if (!fs::exists(model)) {
        GTEST_SKIP() << model.string() << " is missing (set SCALED_SHARED_DIR)";
    }
    writeFile(paths().config, daemonConfigText(paths(), kPriors));
    const fs::path device = tmp_.path() / "video-unplugged";
    DaemonOptions opt;
    opt.args = {"--source", "v4l2:" + device.string(), "--set", "camera.fx_px=500",
                "--set",    "camera.fy_px=500",        "--set", "camera.cx_px=320",
                "--set",    "camera.cy_px=240",        "--set", "camera.retry_initial_s=0.05",
                "--set",    "camera.retry_max_s=0.2",  "--set", "detector.model=" + model.string()};
    ASSERT_TRUE(daemon_.start(opt));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    Json last;
    const auto p = watchUntil(c, Millis(20'000), [&](const Json& j) {
        last = j;
        return str(j, "state") == "fault";
    });
    ASSERT_TRUE(p.has_value()) << "no SCALE in state fault within 20 s; last: " << last.dump();
    ASSERT_TRUE(enableWatch(c, false));
    EXPECT_TRUE(checkScaleLine(*p));
    EXPECT_NE(str(*p, "fault").find(device.string()), std::string::npos) << p->dump();
    EXPECT_EQ(str(*p, "fault").rfind("camera: ", 0), 0U) << p->dump();
    const auto st = status(c);
    ASSERT_TRUE(st.has_value());
    ASSERT_TRUE((*st)["camera"].is_object()) << st->dump();
    EXPECT_TRUE((*st)["camera"]["lost"].get<bool>()) << st->dump();
    EXPECT_EQ((*st)["camera"]["reconnects"].get<int>(), 0) << st->dump();
    EXPECT_NE(daemon_.stderrText().find("not available yet"), std::string::npos)
        << daemon_.stderrText();
    const auto code = stop();
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0);
}

// 12c. --list-cameras lists what there is (on a machine without cameras, says
// so) and exits 0 without reading a configuration.
TEST_F(DaemonTest, ListCamerasExitsZero) {
    const auto r = runCommand(SCALED_BIN, {"--list-cameras", "--config", "/nonexistent.toml"},
                              tmp_.path(), Millis(30'000));
    EXPECT_EQ(r.exit_code, 0) << r.err;
    const bool none = r.out.rfind("no cameras found", 0) == 0;
    const bool some =
        r.out.find("v4l2:") != std::string::npos || r.out.find("libcamera:") != std::string::npos;
    EXPECT_TRUE(none || some) << r.out;
}

// 13. scalectl against the running daemon.
TEST_F(DaemonTest, ScalectlAgainstTheDaemon) {
    ASSERT_TRUE(startSim({"--pacing", "realtime"}));
    const std::string sock = paths().socket.string();
    const auto get = runCommand(SCALECTL_BIN, {"--socket", sock, "get"}, tmp_.path(), kReply);
    EXPECT_EQ(get.exit_code, 0) << get.err;
    EXPECT_FALSE(get.out.empty());
    EXPECT_EQ(get.out.back(), '\n');
    EXPECT_EQ(std::count(get.out.begin(), get.out.end(), '\n'), 1) << get.out;
    const auto early = runCommand(SCALECTL_BIN, {"--socket", sock, "get", "--require-converged"},
                                  tmp_.path(), kReply);
    EXPECT_EQ(early.exit_code, 75) << "right after READY (realtime): " << early.out << early.err;
    const auto st = runCommand(SCALECTL_BIN, {"--socket", sock, "status"}, tmp_.path(), kReply);
    EXPECT_EQ(st.exit_code, 0) << st.err;
    EXPECT_FALSE(st.out.empty());
    const auto post =
        runCommand(SCALECTL_BIN, {"--socket", sock, "posterior", "--json"}, tmp_.path(), kReply);
    EXPECT_EQ(post.exit_code, 0) << post.err;
    const Json pj = Json::parse(post.out.substr(0, post.out.find('\n')), nullptr, false);
    EXPECT_TRUE(pj.is_object() && str(pj, "class") == "POSTERIOR") << post.out.substr(0, 200);
    // The object table (its header names the model; the rows depend on it).
    const auto objects =
        runCommand(SCALECTL_BIN, {"--socket", sock, "objects"}, tmp_.path(), kReply);
    EXPECT_EQ(objects.exit_code, 0) << objects.err;
    EXPECT_EQ(objects.out.rfind("model ", 0), 0U) << objects.out;
    // The camera pose (protocol 1.4): one line, and a stream of them.
    const auto pose = runCommand(SCALECTL_BIN, {"--socket", sock, "pose"}, tmp_.path(), kReply);
    EXPECT_EQ(pose.exit_code, 0) << pose.err;
    EXPECT_EQ(pose.out.rfind("pose ", 0), 0U) << pose.out;
    EXPECT_EQ(std::count(pose.out.begin(), pose.out.end(), '\n'), 1) << pose.out;
    const auto poses = runCommand(
        SCALECTL_BIN, {"--socket", sock, "--timeout", "10", "watch", "--pose", "--count", "5"},
        tmp_.path(), kReply);
    EXPECT_EQ(poses.exit_code, 0) << poses.err;
    std::istringstream pose_lines(poses.out);
    int n = 0;
    for (std::string line; std::getline(pose_lines, line); ++n) {
        EXPECT_EQ(line.rfind("pose ", 0), 0U) << line;
        EXPECT_NE(line.find(" ypr "), std::string::npos) << line;  // a tracked pose
    }
    EXPECT_EQ(n, 5) << poses.out;
    const auto none =
        runCommand(SCALECTL_BIN, {"--socket", (tmp_.path() / "nonexistent.sock").string(), "get"},
                   tmp_.path(), kReply);
    EXPECT_EQ(none.exit_code, 69) << none.err;
    EXPECT_FALSE(none.err.empty());
}

// 14. estimator.model = "object": OBJECTS lists the objects of the latest
// update (scalectl objects prints them), and the field log has, right after a
// SCALE line, one OBJECT line per object that update gave a view to.
TEST_F(DaemonTest, ObjectModelServesAndLogsItsObjects) {
    ASSERT_TRUE(startSim({"--pacing", "fast", "--set", "estimator.model=object", "--set",
                          "log.fsync_interval_ms=100"}));
    Client c = client();
    ASSERT_TRUE(enableWatch(c, true));
    std::optional<Json> objects;
    // After a scale update (not a state change), ask for the table; its reply
    // comes among the watcher's SCALE lines (skipped meanwhile).
    const auto has_objects = [&](const Json& scale) {
        const auto age = scale.find("age_s");
        if (age == scale.end() || age->is_null()) {
            return false;
        }
        objects = c.send(Json{{"cmd", "objects"}}) ? c.readClass("OBJECTS", kReply) : std::nullopt;
        return isClass(objects, "OBJECTS") && !(*objects)["objects"].empty();
    };
    ASSERT_TRUE(watchUntil(c, Millis(60'000), has_objects))
        << "no object within 60 s: " << c.lastLine().substr(0, 300);
    ASSERT_TRUE(objects.has_value());
    EXPECT_EQ(str(*objects, "model"), "object");
    EXPECT_GE((*objects)["frame_id"].get<std::int64_t>(), 0);
    for (const Json& o : (*objects)["objects"]) {
        EXPECT_GE(o["id"].get<int>(), 1) << o.dump();
        EXPECT_FALSE(str(o, "class").empty()) << o.dump();
        EXPECT_LE(o["last_frame"].get<std::int64_t>(), (*objects)["frame_id"].get<std::int64_t>());
    }
    const std::string sock = paths().socket.string();
    const auto table = runCommand(SCALECTL_BIN, {"--socket", sock, "objects"}, tmp_.path(), kReply);
    EXPECT_EQ(table.exit_code, 0) << table.err;
    EXPECT_EQ(table.out.rfind("model object  epoch ", 0), 0U) << table.out;
    EXPECT_NE(table.out.find("views/det"), std::string::npos) << table.out;

    const auto code = stop();
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0);
    std::vector<LogLine> log;
    ASSERT_TRUE(readLogs(paths().log_dir, log));
    int object_lines = 0;
    const Json* scale = nullptr;  // the SCALE line the OBJECT lines follow
    for (const auto& l : log) {
        const std::string cls = str(l.json, "class");
        if (cls == "SCALE") {
            scale = &l.json;
        } else if (cls == "OBJECT") {
            ++object_lines;
            ASSERT_NE(scale, nullptr) << "an OBJECT line before any SCALE line";
            EXPECT_EQ(l.json["frame_id"], (*scale)["frame_id"]) << l.json.dump();
            EXPECT_EQ(l.json["epoch"], (*scale)["epoch"]) << l.json.dump();
            EXPECT_EQ(l.json["last_frame"], l.json["frame_id"]) << l.json.dump();
            for (const char* k : {"id", "object_class", "state", "anchor", "anchor_rel_sigma",
                                  "detections", "views", "views_used", "first_frame",
                                  "local_estimate", "height_m", "height_ci95_m"}) {
                EXPECT_TRUE(l.json.contains(k)) << k << ": " << l.json.dump();
            }
        }
        // Only the detection thread writes SCALE lines, and it writes an
        // update's OBJECT lines right after its SCALE: the latest SCALE line
        // before an OBJECT line is its update (other threads' lines may come
        // between them).
    }
    EXPECT_GT(object_lines, 0);
}

// The paper model: see kConvergingModel.
TEST(DaemonScalectl, RequireConvergedSucceedsOnceConverged) {
    TempDir tmp("d");
    DaemonUnderTest daemon(SCALED_BIN, tmp.path());
    writeFile(daemon.paths().config, daemonConfigText(daemon.paths(), kPriors));
    DaemonOptions opt;
    opt.args = {"--source", "sim", "--pacing", "fast"};
    opt.args.insert(opt.args.end(), kConvergingModel.begin(), kConvergingModel.end());
    ASSERT_TRUE(daemon.start(opt));
    auto c = daemon.client();
    ASSERT_TRUE(c.has_value());
    ASSERT_TRUE(enableWatch(*c, true));
    ASSERT_TRUE(watchUntil(*c, kConverge, [](const Json& j) {
        return str(j, "state") == "converged";
    })) << "not converged";
    const auto r = runCommand(
        SCALECTL_BIN, {"--socket", daemon.paths().socket.string(), "get", "--require-converged"},
        tmp.path(), kReply);
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
    EXPECT_NE(r.out.find("converged"), std::string::npos) << r.out;
}

// WATCHDOG=1 while the pipeline runs, when systemd asks for it.
TEST(DaemonWatchdog, SendsWatchdogWhenAsked) {
    TempDir tmp("d");
    DaemonUnderTest daemon(SCALED_BIN, tmp.path());
    writeFile(daemon.paths().config, daemonConfigText(daemon.paths(), kPriors));
    DaemonOptions opt;
    opt.args = {"--source", "sim"};
    opt.watchdog = true;  // WATCHDOG_USEC=1 s, no WATCHDOG_PID
    ASSERT_TRUE(daemon.start(opt));
    EXPECT_TRUE(daemon.notify().waitFor("WATCHDOG=1", Millis(5'000))) << daemon.notify().history();
    EXPECT_TRUE(daemon.notify().waitFor("WATCHDOG=1", Millis(5'000))) << "only one WATCHDOG=1";
    const std::vector<std::string> lines = daemon.notify().lines();
    const bool has_status = std::any_of(lines.begin(), lines.end(), [](const std::string& l) {
        return l.rfind("STATUS=", 0) == 0 && l != "STATUS=started, sim";
    });
    EXPECT_TRUE(has_status) << daemon.notify().history();
}

// sd_notify must not stall the main loop: with a receiver that stops reading
// (its queue full), SIGTERM still stops the daemon. Disabled: it fails today,
// SdNotifier::notify() uses a blocking sendto() on the main thread (see the
// report to the lead); run with --gtest_also_run_disabled_tests.
TEST(DaemonNotify, SigtermStopsWhileTheNotifyReceiverIsStuck) {
    TempDir tmp("d");
    const DaemonPaths paths = daemonPaths(tmp.path());
    sockaddr_un addr{};
    ASSERT_TRUE(unixAddress(paths.notify, addr));
    const Fd stuck(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    ASSERT_EQ(::bind(stuck.get(), reinterpret_cast<const sockaddr*>(&addr),  // NOLINT: sockaddr
                     sizeof addr),
              0);
    writeFile(paths.config, daemonConfigText(paths, kPriors));
    SpawnOptions so;
    so.args = {"--config",
               paths.config.string(),
               "--no-tty",
               "--source",
               "sim",
               "--set",
               "pipeline.status_interval_ms=100"};
    so.env = {"NOTIFY_SOCKET=" + paths.notify.string()};
    so.stderr_path = paths.err;
    Process proc = Process::spawn(SCALED_BIN, so);
    ASSERT_TRUE(proc.valid());
    // READY=1 is the one datagram read; then the receiver is stuck.
    pollfd pfd{stuck.get(), POLLIN, 0};
    ASSERT_EQ(::poll(&pfd, 1, 30'000), 1) << "no READY=1";
    std::array<char, 4096> buf{};
    ASSERT_GT(::recv(stuck.get(), buf.data(), buf.size(), 0), 0);
    // Let it send well over a full queue of STATUS= (10 per second; a
    // datagram socket queues 10 by default, net.unix.max_dgram_qlen) while
    // the pipeline runs: 5 s of frames at 30 fps, seen by a watcher (under
    // AddressSanitizer on a loaded CI machine the sim runs at about 7 fps:
    // 150 frames take about 21 s of the 60 s allowed).
    Client c(paths.socket);
    ASSERT_TRUE(c.connected());
    ASSERT_TRUE(enableWatch(c, true));
    ASSERT_TRUE(watchUntil(c, Millis(60'000),
                           [](const Json& j) { return j["frame_id"].get<std::int64_t>() > 150; }));
    ASSERT_TRUE(proc.signal(SIGTERM));
    const auto code = proc.wait(Millis(10'000));
    EXPECT_TRUE(code.has_value()) << "SIGTERM not handled within 10 s while sd_notify is stuck";
    if (code) {
        EXPECT_EQ(*code, 0);
    }
}

}  // namespace
}  // namespace scaled::test
