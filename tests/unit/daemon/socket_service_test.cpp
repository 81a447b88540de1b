// The socket service over real UNIX sockets in a temporary directory: the
// protocol's conversations, the limits (clients, request length, output
// buffer), the socket file's life (stale, live, mode, group, removal) and
// socket activation. Clients wait with poll() and a timeout, never sleep.

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <grp.h>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <poll.h>
#include <string>
#include <string_view>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/socket_service.h>
#include <scaled/drivers/base/unique_fd.h>
#include <scaled/drivers/ipc/unix_socket.h>

#include "temp_dir.h"

namespace scaled::daemon {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kTimeoutMs = 5000;

// A protocol client: line-oriented reads with a timeout.
class TestClient {
public:
    explicit TestClient(const fs::path& path) {
        auto fd = drivers::ipc::connectUnix(path);
        if (fd) {
            fd_ = std::move(*fd);
        } else {
            ADD_FAILURE() << fd.error().message;
        }
    }

    [[nodiscard]] bool connected() const { return fd_.isValid(); }
    [[nodiscard]] int fd() const { return fd_.get(); }
    void close() { fd_.reset(); }

    bool send(std::string_view text) {
        while (!text.empty()) {
            const ssize_t n = ::send(fd_.get(), text.data(), text.size(), MSG_NOSIGNAL);
            if (n <= 0) {
                return false;
            }
            text.remove_prefix(static_cast<std::size_t>(n));
        }
        return true;
    }

    // The next line (without '\n'); nullopt on EOF, error or timeout (eof() tells).
    std::optional<std::string> readLine(int timeout_ms = kTimeoutMs) {
        for (;;) {
            const auto nl = buffer_.find('\n');
            if (nl != std::string::npos) {
                std::string line = buffer_.substr(0, nl);
                buffer_.erase(0, nl + 1);
                return line;
            }
            pollfd p{fd_.get(), POLLIN, 0};
            if (::poll(&p, 1, timeout_ms) <= 0) {
                return std::nullopt;
            }
            char chunk[65536];
            const ssize_t n = ::recv(fd_.get(), chunk, sizeof chunk, 0);
            if (n <= 0) {
                eof_ = true;
                return std::nullopt;
            }
            buffer_.append(chunk, static_cast<std::size_t>(n));
        }
    }

    json readJson(int timeout_ms = kTimeoutMs) {
        const auto line = readLine(timeout_ms);
        if (!line) {
            ADD_FAILURE() << (eof_ ? "EOF" : "timeout") << " instead of a line";
            return json();
        }
        json j = json::parse(*line, nullptr, false);
        EXPECT_FALSE(j.is_discarded()) << *line;
        return j;
    }

    json request(std::string_view line) {
        EXPECT_TRUE(send(std::string(line) + "\n"));
        return readJson();
    }

    // Reads until EOF; true when EOF came before the timeout.
    bool waitEof(int timeout_ms = kTimeoutMs) {
        while (readLine(timeout_ms)) {
        }
        return eof_;
    }

    // Nothing arrives within `timeout_ms`.
    bool silent(int timeout_ms) {
        if (!buffer_.empty()) {
            return false;
        }
        pollfd p{fd_.get(), POLLIN, 0};
        return ::poll(&p, 1, timeout_ms) == 0;
    }

private:
    drivers::base::UniqueFd fd_;
    std::string buffer_;
    bool eof_ = false;
};

ScaleReport reportAt(std::int64_t frame_id) {
    ScaleReport r;
    r.has_scale = true;
    r.scale = 0.976 + 1e-6 * static_cast<double>(frame_id);
    r.mean = 0.98;
    r.ci68_lo = 0.95;
    r.ci68_hi = 1.0;
    r.ci95_lo = 0.9;
    r.ci95_hi = 1.05;
    r.state = DaemonState::kConverging;
    r.epoch = 1;
    r.observations = static_cast<int>(frame_id / 10);
    r.frame_id = frame_id;
    r.t_ns = frame_id * 33'000'000;
    r.updated_mono_ns = monotonicNowNs();
    return r;
}

class SocketServiceTest : public ::testing::Test {
protected:
    SocketServiceTest() : dir_("sock"), hub_(64) { config_.path = dir_.path() / "s.sock"; }

    std::unique_ptr<SocketService> startService() {
        auto svc = SocketService::create(config_, hub_, "0.1.0");
        if (!svc) {
            ADD_FAILURE() << svc.error().message;
            return nullptr;
        }
        auto started = (*svc)->start();
        EXPECT_TRUE(started.ok());
        return std::move(*svc);
    }

    // A connected client that has read its VERSION line.
    std::unique_ptr<TestClient> connect() {
        auto c = std::make_unique<TestClient>(config_.path);
        const json v = c->readJson();
        EXPECT_EQ(v.value("class", ""), "VERSION");
        return c;
    }

    test::TempDir dir_;
    ReportHub hub_;
    SocketConfig config_;
};

TEST_F(SocketServiceTest, SendsVersionOnConnect) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    EXPECT_FALSE(svc->socketActivated());
    EXPECT_EQ(svc->path(), config_.path);
    TestClient c(config_.path);
    const json v = c.readJson();
    EXPECT_EQ(v, json::parse(R"({"class":"VERSION","release":"0.1.0","proto_major":1,
        "proto_minor":5})"));
    EXPECT_EQ(svc->stats().accepted, 1U);
    EXPECT_EQ(svc->stats().connected, 1);
}

TEST_F(SocketServiceTest, PollReturnsThePublishedReport) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    json s = c->request(R"({"cmd":"poll"})");
    EXPECT_EQ(s["class"], "SCALE");
    EXPECT_TRUE(s["scale"].is_null());
    EXPECT_EQ(s["state"], "initialising");

    ScaleReport r = reportAt(510);
    r.fault = "log: No space left on device";
    hub_.publishScale(r);
    s = c->request(R"({"cmd":"poll"})");
    EXPECT_EQ(s["scale"].get<double>(), r.scale);
    EXPECT_EQ(s["frame_id"], 510);
    EXPECT_EQ(s["state"], "converging");
    EXPECT_EQ(s["ci95"], json::array({0.9, 1.05}));
    EXPECT_EQ(s["fault"], "log: No space left on device");
    ASSERT_TRUE(s["age_s"].is_number());
    EXPECT_GE(s["age_s"].get<double>(), 0.0);
    EXPECT_LT(s["age_s"].get<double>(), 60.0);
    EXPECT_EQ(svc->stats().requests, 2U);
}

TEST_F(SocketServiceTest, WatchStreamsEveryPublishAndStops) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    hub_.publishScale(reportAt(1));
    auto c = connect();
    ASSERT_TRUE(c->send("{\"cmd\":\"watch\",\"enable\":true}\n"));
    EXPECT_EQ(c->readJson(), json::parse(R"({"class":"WATCH","enable":true,"pose":false})"));
    json s = c->readJson();
    EXPECT_EQ(s["class"], "SCALE");
    EXPECT_EQ(s["frame_id"], 1);
    for (std::int64_t f = 2; f <= 30; ++f) {
        hub_.publishScale(reportAt(f));
        s = c->readJson();
        ASSERT_EQ(s["class"], "SCALE");
        ASSERT_EQ(s["frame_id"], f);
    }
    // A state change alone is a new report too.
    ScaleReport lost = reportAt(30);
    lost.state = DaemonState::kLost;
    hub_.publishScale(lost);
    EXPECT_EQ(c->readJson()["state"], "lost");

    EXPECT_EQ(c->request(R"({"cmd":"watch","enable":false})"),
              json::parse(R"({"class":"WATCH","enable":false,"pose":false})"));
    hub_.publishScale(reportAt(31));
    // Had the stream continued, a SCALE would come before the STATUS.
    EXPECT_EQ(c->request(R"({"cmd":"status"})")["class"], "STATUS");
}

TEST_F(SocketServiceTest, CoalescedPublishesStillIncrease) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    c->request(R"({"cmd":"watch","enable":true})");
    EXPECT_EQ(c->readJson()["class"], "SCALE");
    for (std::int64_t f = 0; f < 200; ++f) {
        hub_.publishScale(reportAt(f));
    }
    ASSERT_TRUE(c->send("{\"cmd\":\"status\"}\n"));
    std::int64_t last = -1;
    for (;;) {
        const json j = c->readJson();
        ASSERT_TRUE(j.is_object());
        if (j["class"] == "STATUS") {
            break;
        }
        ASSERT_EQ(j["class"], "SCALE");
        const auto f = j["frame_id"].get<std::int64_t>();
        EXPECT_GT(f, last);
        last = f;
    }
    EXPECT_EQ(last, 199);  // the latest always arrives
}

// --- POSE (proto_minor 4) -------------------------------------------------------

// A pose of epoch 1 (reportAt's) at frame f, t_ns = t_ns.
PoseReport poseAt(std::int64_t frame_id, std::int64_t t_ns, std::uint64_t epoch = 1) {
    PoseReport p;
    p.epoch = epoch;
    p.frame_id = frame_id;
    p.t_ns = t_ns;
    p.position_map = {0.01 * static_cast<double>(frame_id), 0, 2};
    p.position_cov_map = {1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4};
    p.attitude_cov_rad2 = {1e-5, 0, 0, 0, 1e-5, 0, 0, 0, 1e-5};
    return p;
}

TEST_F(SocketServiceTest, PoseAnswersTheLatestPoseWithTheScale) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    json p = c->request(R"({"cmd":"pose"})");
    EXPECT_EQ(p["class"], "POSE");
    EXPECT_EQ(p["frame_id"], -1);
    EXPECT_TRUE(p["position_map"].is_null());
    EXPECT_TRUE(p["position"].is_null());

    // A pose before a scale: map units only.
    hub_.publishPose(poseAt(5, std::int64_t{5} * 33'333'333));
    p = c->request(R"({"cmd":"pose"})");
    EXPECT_EQ(p["frame_id"], 5);
    EXPECT_EQ(p["position_map"], json::parse("[0.05,0,2]"));
    EXPECT_TRUE(p["position"].is_null());
    EXPECT_TRUE(p["scale"].is_null());

    // With a scale of the same epoch: metres, and the scale's variance along p.
    const ScaleReport r = reportAt(5);
    hub_.publishScale(r);
    p = c->request(R"({"cmd":"pose"})");
    ASSERT_FALSE(p["position"].is_null()) << p;
    EXPECT_EQ(p["scale"].get<double>(), r.scale);
    EXPECT_NEAR(p["position"][2].get<double>(), 2 * r.scale, 1e-6);
    const double sigma = (r.ci68_hi - r.ci68_lo) / 2;
    EXPECT_NEAR(p["position_cov"][2][2].get<double>(), r.scale * r.scale * 1e-4 + sigma * sigma * 4,
                1e-9);
    EXPECT_EQ(p["state"], "converging");
    EXPECT_EQ(svc->stats().poses_streamed, 0U);  // nobody watches poses
}

TEST_F(SocketServiceTest, WatchWithPoseStreamsPosesAndNonBooleanPoseIsAnError) {
    config_.pose_rate_hz = 0;  // every pose
    auto svc = startService();
    ASSERT_TRUE(svc);
    hub_.publishScale(reportAt(1));
    hub_.publishPose(poseAt(1, 33'333'333));
    auto c = connect();
    json e = c->request(R"({"cmd":"watch","pose":"yes"})");
    EXPECT_EQ(e["class"], "ERROR");
    EXPECT_EQ(e["message"], "\"pose\" must be true or false");
    EXPECT_EQ(e["cmd"], "watch");
    // Poses only: WATCH, then the latest POSE at once.
    ASSERT_TRUE(c->send("{\"cmd\":\"watch\",\"enable\":false,\"pose\":true}\n"));
    EXPECT_EQ(c->readJson(), json::parse(R"({"class":"WATCH","enable":false,"pose":true})"));
    json p = c->readJson();
    EXPECT_EQ(p["class"], "POSE");
    EXPECT_EQ(p["frame_id"], 1);
    for (std::int64_t f = 2; f <= 20; ++f) {
        hub_.publishPose(poseAt(f, f * 33'333'333));
        p = c->readJson();
        ASSERT_EQ(p["class"], "POSE");
        ASSERT_EQ(p["frame_id"], f);
    }
    // Both streams: a new scale comes as SCALE, the next pose uses it.
    ASSERT_TRUE(c->send("{\"cmd\":\"watch\",\"pose\":true}\n"));
    EXPECT_EQ(c->readJson(), json::parse(R"({"class":"WATCH","enable":true,"pose":true})"));
    EXPECT_EQ(c->readJson()["class"], "SCALE");
    EXPECT_EQ(c->readJson()["frame_id"], 20);  // the latest POSE
    hub_.publishScale(reportAt(21));
    EXPECT_EQ(c->readJson()["class"], "SCALE");
    hub_.publishPose(poseAt(21, std::int64_t{21} * 33'333'333));
    p = c->readJson();
    EXPECT_EQ(p["class"], "POSE");
    EXPECT_EQ(p["scale"].get<double>(), reportAt(21).scale);
    // `watch` without "pose" stops the pose stream: the next line after a
    // publish is the STATUS reply.
    EXPECT_EQ(c->request(R"({"cmd":"watch","enable":false})"),
              json::parse(R"({"class":"WATCH","enable":false,"pose":false})"));
    hub_.publishPose(poseAt(22, std::int64_t{22} * 33'333'333));
    EXPECT_EQ(c->request(R"({"cmd":"status"})")["class"], "STATUS");
    EXPECT_EQ(svc->stats().poses_streamed, 20U);  // frames 2..21
}

// socket.pose_rate_hz = 10 with poses every 10 ms of frame time: one per
// 100 ms slot (slots centred on 0, 100, 200, ... ms after the first pose).
// Each publish is followed by a poll, whose SCALE reply comes after any POSE
// of that publish (the server reads the hub before the request), so the
// count is exact without waiting for time to pass.
TEST_F(SocketServiceTest, PoseRateLimitCountsFrameTime) {
    config_.pose_rate_hz = 10;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    c->request(R"({"cmd":"watch","enable":false,"pose":true})");  // no pose yet: WATCH only
    constexpr std::int64_t kStepNs = 10'000'000;                  // 100 Hz
    std::vector<std::int64_t> sent;
    const auto publishAndCount = [&](const PoseReport& pose) {
        hub_.publishPose(pose);
        ASSERT_TRUE(c->send("{\"cmd\":\"poll\"}\n"));
        for (;;) {
            const json j = c->readJson();
            ASSERT_TRUE(j.is_object());
            if (j["class"] == "SCALE") {
                return;
            }
            ASSERT_EQ(j["class"], "POSE") << j;
            sent.push_back(j["frame_id"].get<std::int64_t>());
        }
    };
    for (std::int64_t f = 0; f < 100; ++f) {  // 1 s of frames
        publishAndCount(poseAt(f, 5'000'000'000 + f * kStepNs));
    }
    // 11 poses within 0.95 s: at most 10 * 0.95 + 2.
    EXPECT_EQ(sent, (std::vector<std::int64_t>{0, 5, 15, 25, 35, 45, 55, 65, 75, 85, 95}));
    EXPECT_EQ(svc->stats().poses_streamed, 11U);

    // A new epoch restarts at once; poses at the rate itself all pass with
    // jitter below half a period, a second one within a slot does not.
    sent.clear();
    const std::int64_t t0 = 1'000'000'000;
    const std::int64_t jitter_ms[] = {0, -30, 20, -10, 40, -40, 10};
    for (std::int64_t i = 0; i < 7; ++i) {
        publishAndCount(poseAt(200 + i, t0 + i * 100'000'000 + jitter_ms[i] * 1'000'000, 2));
    }
    publishAndCount(poseAt(207, t0 + 620'000'000, 2));  // slot 6 again
    publishAndCount(poseAt(208, t0 + 660'000'000, 2));  // slot 7
    EXPECT_EQ(sent, (std::vector<std::int64_t>{200, 201, 202, 203, 204, 205, 206, 208}));
    // Time going back (a replay restarted) restarts the slots too.
    sent.clear();
    publishAndCount(poseAt(0, t0, 2));
    publishAndCount(poseAt(1, t0 + kStepNs, 2));
    EXPECT_EQ(sent, (std::vector<std::int64_t>{0}));
}

TEST(PoseRateLimiter, BoundsTheRateOverAnyWindow) {
    PoseRateLimiter limiter(30);
    // 60 fps with +-5 ms of jitter for 10 s: about 300 admitted, never more
    // than 30 * T + 2 within any window of T seconds.
    std::vector<std::int64_t> admitted;
    std::uint64_t rng = 12345;
    for (std::int64_t i = 0; i < 600; ++i) {
        rng = rng * 6364136223846793005ULL + 1442695040888963407ULL;
        const auto jitter_ns = static_cast<std::int64_t>((rng >> 33) % 10'000'000) - 5'000'000;
        const std::int64_t t = 100'000'000 + i * 16'666'667 + jitter_ns;
        if (limiter.admit(1, t)) {
            admitted.push_back(t);
        }
    }
    EXPECT_GE(admitted.size(), 295U);
    EXPECT_LE(admitted.size(), 301U);
    for (std::size_t a = 0; a < admitted.size(); ++a) {
        for (std::size_t b = a + 1; b < admitted.size(); ++b) {
            const double window_s = static_cast<double>(admitted[b] - admitted[a]) * 1e-9;
            ASSERT_LE(static_cast<double>(b - a + 1), 30 * window_s + 2) << a << ", " << b;
        }
    }
    // Every frame of a 30 fps source with up to 7 ms of jitter (14 ms relative to
    // the first frame, under half of 33 ms) passes a 30 Hz limit.
    PoseRateLimiter same(30);
    int n = 0;
    for (std::int64_t i = 0; i < 300; ++i) {
        const std::int64_t jitter_ns = (i % 3 - 1) * 7'000'000;
        const std::int64_t t = std::llround(static_cast<double>(i) * 1e9 / 30) + jitter_ns;
        n += same.admit(1, 1'000'000'000 + t) ? 1 : 0;
    }
    EXPECT_EQ(n, 300);
    // 0: no limit.
    PoseRateLimiter none(0);
    EXPECT_TRUE(none.admit(1, 0));
    EXPECT_TRUE(none.admit(1, 1));
    EXPECT_TRUE(none.admit(1, 1));
}

TEST_F(SocketServiceTest, StatusAndPosterior) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    json p = c->request(R"({"cmd":"posterior"})");
    EXPECT_EQ(p, json::parse(R"({"class":"POSTERIOR","epoch":0,"frame_id":-1,
        "observations":0,"d":[],"log_p":[]})"));

    PipelineStatus st;
    st.source = "sim";
    st.frame_id = 42;
    st.fps = 30;
    st.frames_tracked = 43;
    hub_.publishStatus(st);
    LogStatus log;
    log.state = LogStatus::State::kOk;
    log.lines_written = 9;
    hub_.publishLogStatus(log);
    const std::vector<double> d = {0.5, 1.0, 1.5, 2.0};
    const std::vector<double> lp = {-3, 0, -1, -4.5};
    hub_.publishScale(reportAt(42), d, lp);

    const json s = c->request(R"({"cmd":"status"})");
    EXPECT_EQ(s["class"], "STATUS");
    EXPECT_EQ(s["source"], "sim");
    EXPECT_EQ(s["frame_id"], 42);
    EXPECT_EQ(s["fps"], 30);
    EXPECT_EQ(s["frames"]["tracked"], 43);
    EXPECT_EQ(s["clients"]["connected"], 1);
    EXPECT_EQ(s["clients"]["max"], 16);
    EXPECT_EQ(s["clients"]["reserved"], 2);
    EXPECT_EQ(s["clients"]["watchers"], 0);
    EXPECT_EQ(s["clients"]["timed_out"], 0);
    EXPECT_EQ(s["clients"]["evicted"], 0);
    EXPECT_EQ(s["clients"]["accepted"], 1);
    EXPECT_EQ(s["log"]["state"], "ok");
    EXPECT_EQ(s["log"]["lines"], 9);
    for (const char* k : {"uptime_s", "frames_total", "source_finished", "detector",
                          "tracking_ms_mean", "features", "scale_updates", "epoch", "timing"}) {
        EXPECT_TRUE(s.contains(k)) << k;
    }

    p = c->request(R"({"cmd":"posterior"})");
    EXPECT_EQ(p["frame_id"], 42);
    EXPECT_EQ(p["epoch"], 1);
    EXPECT_EQ(p["d"], json(d));
    EXPECT_EQ(p["log_p"], json(lp));
}

// OBJECTS: the hub's table of the latest update, the model in use; a new
// epoch empties it.
TEST_F(SocketServiceTest, ObjectsReplyCarriesThePublishedTable) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    EXPECT_EQ(c->request(R"({"cmd":"objects"})"),
              json::parse(R"({"class":"OBJECTS","epoch":0,"frame_id":-1,"model":"paper",
                  "objects":[]})"));

    hub_.setObjectModel(core::EstimatorModel::kObject, 8);
    hub_.publishScale(reportAt(42));  // epoch 1
    ObjectsSnapshot objects;
    objects.epoch = 1;
    objects.frame_id = 42;
    objects.model = core::EstimatorModel::kObject;
    for (int id : {2, 4}) {
        ObjectReport& o = objects.objects.emplace_back();
        o.id = id;
        o.setClassName(id == 2 ? "chair" : "tv");
        o.state = id == 2 ? core::ObjectState::kUsed : core::ObjectState::kTentative;
        o.anchor = {0.5, -1, 2};
        o.anchor_rel_sigma = 0.05;
        o.detections = 3 * id;
        o.views = 2 * id;
        o.views_used = id == 2 ? 4 : 0;
        o.first_frame = 10;
        o.last_frame = 42;
        o.local_estimate = id == 2 ? 1.25 : 0;
        o.has_height = id == 2;
        o.height_m = 0.875;
        o.height_ci95_lo_m = 0.75;
        o.height_ci95_hi_m = 1;
    }
    hub_.publishObjects(objects);
    const json j = c->request(R"({"cmd":"objects"})");
    EXPECT_EQ(j["class"], "OBJECTS");
    EXPECT_EQ(j["epoch"], 1);
    EXPECT_EQ(j["frame_id"], 42);
    EXPECT_EQ(j["model"], "object");
    ASSERT_EQ(j["objects"].size(), 2U) << j.dump();
    EXPECT_EQ(j["objects"][0], json::parse(R"({"id":2,"class":"chair","state":"used",
        "anchor":[0.5,-1,2],"anchor_rel_sigma":0.05,"detections":6,"views":4,"views_used":4,
        "first_frame":10,"last_frame":42,"local_estimate":1.25,"height_m":0.875,
        "height_ci95_m":[0.75,1]})"));
    EXPECT_EQ(j["objects"][1]["class"], "tv");
    EXPECT_TRUE(j["objects"][1]["anchor"].is_null());
    EXPECT_TRUE(j["objects"][1]["height_m"].is_null());

    ScaleReport next = reportAt(50);
    next.epoch = 2;  // a new map: its objects are gone
    hub_.publishScale(next);
    EXPECT_EQ(c->request(R"({"cmd":"objects"})"),
              json::parse(R"({"class":"OBJECTS","epoch":2,"frame_id":-1,"model":"object",
                  "objects":[]})"));
}

TEST_F(SocketServiceTest, SetGravityIsNormalisedAndForwarded) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    EXPECT_EQ(c->request(R"({"cmd":"set_gravity","down":[0,2,0]})"),
              json::parse(R"({"class":"ACK","cmd":"set_gravity"})"));
    const auto g = hub_.takeGravityRequest();
    ASSERT_TRUE(g.has_value());
    EXPECT_DOUBLE_EQ(static_cast<double>((*g)[1]), 1.0);
    EXPECT_DOUBLE_EQ(static_cast<double>((*g)[0]), 0.0);
    const json e = c->request(R"({"cmd":"set_gravity","down":[0,0,0]})");
    EXPECT_EQ(e["class"], "ERROR");
    EXPECT_EQ(e["cmd"], "set_gravity");
    EXPECT_FALSE(hub_.takeGravityRequest().has_value());
}

TEST_F(SocketServiceTest, BadRequestsGetErrorsAndTheConnectionStaysUsable) {
    config_.max_request_bytes = 256;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    json e = c->request("{\"cmd\":");
    EXPECT_EQ(e, json::parse(R"({"class":"ERROR","message":"request is not valid JSON"})"));
    e = c->request("[1]");
    EXPECT_EQ(e["message"], "request must be a JSON object");
    e = c->request("{\"command\":\"poll\"}");
    EXPECT_EQ(e["message"], "request has no \"cmd\"");
    e = c->request("{\"cmd\":\"fly\"}");
    EXPECT_EQ(e["class"], "ERROR");
    EXPECT_EQ(e["cmd"], "fly");
    // Blank lines are ignored; CRLF is accepted.
    EXPECT_EQ(c->request("\n  \n{\"cmd\":\"poll\"}\r")["class"], "SCALE");

    // An oversize line, sent in pieces: one ERROR, the rest is discarded.
    const std::string big = "{\"cmd\":\"poll\",\"pad\":\"" + std::string(1000, 'x') + "\"}";
    ASSERT_TRUE(c->send(big.substr(0, 100)));
    ASSERT_TRUE(c->send(big.substr(100, 400)));
    ASSERT_TRUE(c->send(big.substr(500) + "\n"));
    e = c->readJson();
    EXPECT_EQ(e, json::parse(R"j({"class":"ERROR",
        "message":"request longer than 256 bytes (discarded)"})j"));
    // The next request still works, also one that follows an oversize line at once.
    EXPECT_EQ(c->request(R"({"cmd":"poll"})")["class"], "SCALE");
    ASSERT_TRUE(c->send(std::string(300, ' ') + "x\n{\"cmd\":\"status\"}\n"));
    EXPECT_EQ(c->readJson()["class"], "ERROR");
    EXPECT_EQ(c->readJson()["class"], "STATUS");
    const SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.errors, 6U);
    EXPECT_EQ(st.requests, 9U);
    EXPECT_EQ(st.connected, 1);
}

TEST_F(SocketServiceTest, RequestWithoutNewlineBeforeEofIsAnswered) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    ASSERT_TRUE(c->send(R"({"cmd":"poll"})"));
    ASSERT_EQ(::shutdown(c->fd(), SHUT_WR), 0);
    EXPECT_EQ(c->readJson()["class"], "SCALE");
    EXPECT_TRUE(c->waitEof());
}

TEST_F(SocketServiceTest, TheClientOverTheLimitIsRejected) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    // max_clients (16) that do not watch: the reserved slots are not for them.
    std::vector<std::unique_ptr<TestClient>> clients;
    clients.reserve(16);
    for (int i = 0; i < 16; ++i) {
        clients.push_back(connect());
    }
    TestClient extra(config_.path);
    EXPECT_EQ(extra.readJson(),
              json::parse(R"j({"class":"ERROR","message":"too many clients (16 connected)"})j"));
    EXPECT_TRUE(extra.waitEof());
    SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.connected, 16);
    EXPECT_EQ(st.accepted, 16U);
    EXPECT_EQ(st.rejected, 1U);
    EXPECT_EQ(st.evicted, 0U);  // none idle for request_timeout_s (5 s)
    // The others still work; once one leaves, a new client is accepted.
    EXPECT_EQ(clients[3]->request(R"({"cmd":"poll"})")["class"], "SCALE");
    clients[0]->close();
    auto again = std::make_unique<TestClient>(config_.path);
    json first = again->readJson();
    for (int retry = 0; retry < 100 && first["class"] == "ERROR"; ++retry) {
        // The server saw the new connection before the old one's EOF.
        EXPECT_TRUE(again->waitEof());
        again = std::make_unique<TestClient>(config_.path);
        first = again->readJson();
    }
    EXPECT_EQ(first["class"], "VERSION");
}

TEST_F(SocketServiceTest, AClientThatNeverReadsIsDetached) {
    config_.client_buffer_bytes = 16384;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto stalled = connect();
    auto reader = connect();
    stalled->request(R"({"cmd":"watch","enable":true})");
    stalled->readJson();
    reader->request(R"({"cmd":"watch","enable":true})");
    reader->readJson();
    // Stop reading `stalled`; big reports fill its socket, then its buffer.
    ScaleReport r = reportAt(0);
    r.fault = std::string(4000, 'f');
    std::int64_t f = 1;
    for (; f < 5000 && svc->stats().detached == 0; ++f) {
        r.frame_id = f;
        hub_.publishScale(r);
        const json j = reader->readJson();
        ASSERT_EQ(j["frame_id"], f);
    }
    EXPECT_EQ(svc->stats().detached, 1U);
    EXPECT_EQ(svc->stats().stalled, 0U);  // the stream overflowed its buffer, no waiting
    EXPECT_EQ(svc->stats().connected, 1);
    // The reader keeps receiving.
    r.frame_id = f;
    hub_.publishScale(r);
    EXPECT_EQ(reader->readJson()["frame_id"], f);
    // The stalled one finds its data so far, then EOF.
    EXPECT_TRUE(stalled->waitEof());
}

// --- issue 22: flow control, timeouts, reserved slots, hostile requests --------

double secondsSince(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// `{"cmd":"poll","pad":"xx..."}` of exactly `bytes` bytes.
std::string paddedPoll(std::size_t bytes) {
    const std::string head = R"({"cmd":"poll","pad":")";
    return head + std::string(bytes - head.size() - 2, 'x') + "\"}";
}

std::string repeated(std::string_view line, int n) {
    std::string out;
    out.reserve(line.size() * static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
        out += line;
    }
    return out;
}

// Requests sent in one burst before reading: the server stops reading while
// the replies wait (flow control) instead of detaching the client when they
// outgrow client_buffer_bytes (1000 STATUS are about 1.3 MB, 5000 SCALE 1.5 MB).
TEST_F(SocketServiceTest, APipelinedBurstIsAnsweredInFull) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    hub_.publishScale(reportAt(510));
    auto c = connect();
    ASSERT_TRUE(c->send(repeated("{\"cmd\":\"status\"}\n", 1000)));
    for (int i = 0; i < 1000; ++i) {
        const json j = c->readJson();
        ASSERT_EQ(j.value("class", ""), "STATUS") << i;
    }
    ASSERT_TRUE(c->send(repeated("{\"cmd\":\"poll\"}\n", 5000)));
    for (int i = 0; i < 5000; ++i) {
        const auto line = c->readLine();
        ASSERT_TRUE(line.has_value()) << i;
        ASSERT_EQ(line->rfind(R"({"class":"SCALE",)", 0), 0U) << i << ": " << *line;
    }
    const SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.requests, 6000U);
    EXPECT_EQ(st.detached, 0U);
    EXPECT_EQ(st.connected, 1);
}

// The load test: one thread writes 100,000 polls as fast as the socket takes
// them while the test reads; every one is answered, nobody is detached. Runs
// with the default buffer and with the smallest one (4096 bytes: reading
// pauses at 2 KiB of unsent replies, about 7 SCALE lines). 60 s is a failure.
TEST_F(SocketServiceTest, HundredThousandPipelinedPollsWhileReadingAreAllAnswered) {
    constexpr int kPolls = 100'000;
    constexpr int kPerWrite = 1000;
    for (const std::size_t buffer_bytes : {std::size_t{262144}, std::size_t{4096}}) {
        SCOPED_TRACE(buffer_bytes);
        config_.client_buffer_bytes = buffer_bytes;
        auto svc = startService();
        ASSERT_TRUE(svc);
        hub_.publishScale(reportAt(1));
        auto c = connect();
        const auto t0 = std::chrono::steady_clock::now();
        bool write_failed = false;
        std::thread writer([fd = c->fd(), &write_failed] {
            const std::string chunk = repeated("{\"cmd\":\"poll\"}\n", kPerWrite);
            for (int i = 0; i < kPolls / kPerWrite; ++i) {
                std::string_view rest = chunk;
                while (!rest.empty()) {
                    const ssize_t n = ::send(fd, rest.data(), rest.size(), MSG_NOSIGNAL);
                    if (n <= 0) {
                        write_failed = true;  // the test gave up and shut the socket
                        return;
                    }
                    rest.remove_prefix(static_cast<std::size_t>(n));
                }
            }
        });
        const auto deadline = t0 + std::chrono::seconds(60);
        std::vector<char> buf(1 << 16);
        std::string partial;
        int replies = 0;
        int bad = 0;
        bool eof = false;
        while (replies < kPolls && !eof) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                deadline - std::chrono::steady_clock::now());
            pollfd p{c->fd(), POLLIN, 0};
            if (left.count() <= 0 || ::poll(&p, 1, static_cast<int>(left.count())) <= 0) {
                break;
            }
            const ssize_t n = ::recv(c->fd(), buf.data(), buf.size(), 0);
            if (n <= 0) {
                eof = true;
                break;
            }
            partial.append(buf.data(), static_cast<std::size_t>(n));
            std::size_t from = 0;
            for (std::size_t nl = partial.find('\n'); nl != std::string::npos;
                 nl = partial.find('\n', from)) {
                bad += partial.compare(from, 17, R"({"class":"SCALE",)") == 0 ? 0 : 1;
                ++replies;
                from = nl + 1;
            }
            partial.erase(0, from);
        }
        const double elapsed_s = secondsSince(t0);
        ::shutdown(c->fd(), SHUT_RDWR);  // releases the writer if the server stopped reading
        writer.join();
        EXPECT_FALSE(eof) << "the server closed the connection after " << replies << " replies";
        EXPECT_FALSE(write_failed);
        EXPECT_EQ(replies, kPolls) << "in " << elapsed_s << " s";
        EXPECT_EQ(bad, 0);
        const SocketServiceStats st = svc->stats();
        EXPECT_EQ(st.requests, static_cast<std::uint64_t>(kPolls));
        EXPECT_EQ(st.detached, 0U);
        EXPECT_EQ(st.errors, 0U);
        std::cout << "[ info     ] " << kPolls << " pipelined polls, client_buffer_bytes "
                  << buffer_bytes << ": " << elapsed_s << " s\n";
        svc->stop();
    }
}

// A client that sends requests and then reads nothing is not held forever by
// flow control: after stall_timeout_s without reading it is detached (not
// before), and the other clients are served meanwhile.
TEST_F(SocketServiceTest, AClientThatStopsReadingIsDetachedAfterTheStallTimeout) {
    config_.client_buffer_bytes = 16384;
    config_.stall_timeout_s = 0.3;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    auto other = connect();
    const auto t0 = std::chrono::steady_clock::now();
    ASSERT_TRUE(c->send(repeated("{\"cmd\":\"status\"}\n", 3000)));
    EXPECT_EQ(other->request(R"({"cmd":"poll"})")["class"], "SCALE");
    // Wait for the server to hang up, reading nothing.
    pollfd p{c->fd(), 0, 0};
    ASSERT_EQ(::poll(&p, 1, kTimeoutMs), 1);
    EXPECT_NE(p.revents & POLLHUP, 0);
    EXPECT_GE(secondsSince(t0), 0.3);
    SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.stalled, 1U);
    EXPECT_EQ(st.detached, 1U);
    EXPECT_EQ(st.connected, 1);
    // What it was sent are whole STATUS lines (and maybe the start of one).
    int lines = 0;
    while (const auto line = c->readLine()) {
        EXPECT_EQ(line->rfind(R"({"class":"STATUS",)", 0), 0U) << *line;
        ++lines;
    }
    EXPECT_GT(lines, 0);
    EXPECT_LT(lines, 3000);
    EXPECT_EQ(other->request(R"({"cmd":"status"})")["clients"]["detached"], 1);
}

double processCpuSeconds() {
    rusage u{};
    ::getrusage(RUSAGE_SELF, &u);
    const auto seconds = [](const timeval& t) {
        return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec);
    };
    return seconds(u.ru_utime) + seconds(u.ru_stime);
}

// A client the server stopped reading (its replies wait) costs the loop
// nothing while it waits (no POLLIN asked, nothing to spin on), and one that
// then closes with its replies unread is removed.
TEST_F(SocketServiceTest, APausedClientCostsNothingAndIsRemovedWhenItCloses) {
    config_.client_buffer_bytes = 16384;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    auto other = connect();
    ASSERT_TRUE(c->send(repeated("{\"cmd\":\"status\"}\n", 3000)));
    // Answered after c's burst was read up to the pause.
    EXPECT_EQ(other->request(R"({"cmd":"status"})")["class"], "STATUS");
    const double cpu0 = processCpuSeconds();
    EXPECT_TRUE(other->silent(300));
    EXPECT_LT(processCpuSeconds() - cpu0, 0.03);  // a spinning loop: up to 0.3 s
    EXPECT_EQ(svc->stats().connected, 2);
    c->close();
    int connected = -1;
    for (int i = 0; i < 1000 && connected != 1; ++i) {
        connected = other->request(R"({"cmd":"status"})")["clients"]["connected"].get<int>();
    }
    EXPECT_EQ(connected, 1);
    EXPECT_LT(svc->stats().requests, 3000U);  // the rest of the burst was never read
}

// max_clients (16) watchers, and a 17th and 18th client still get their
// queries answered (socket.reserved_query_slots = 2); those cannot watch.
TEST_F(SocketServiceTest, TheReservedSlotsAnswerQueriesWhenMaxClientsWatch) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    hub_.publishScale(reportAt(3));
    std::vector<std::unique_ptr<TestClient>> watchers;
    watchers.reserve(16);
    for (int i = 0; i < 16; ++i) {
        watchers.push_back(connect());
        ASSERT_EQ(watchers.back()->request(R"({"cmd":"watch"})")["class"], "WATCH");
        ASSERT_EQ(watchers.back()->readJson()["class"], "SCALE");
    }
    auto query = connect();
    json st = query->request(R"({"cmd":"status"})");
    ASSERT_EQ(st["class"], "STATUS");
    EXPECT_EQ(st["clients"]["connected"], 17);
    EXPECT_EQ(st["clients"]["watchers"], 16);
    EXPECT_EQ(st["clients"]["max"], 16);
    EXPECT_EQ(st["clients"]["reserved"], 2);
    EXPECT_EQ(query->request(R"({"cmd":"watch","enable":false,"pose":true})"),
              json::parse(R"j({"class":"ERROR","message":"too many watchers (16 watching)",
                  "cmd":"watch"})j"));
    EXPECT_EQ(query->request(R"({"cmd":"poll"})")["frame_id"], 3);
    // Asking for no stream is not watching.
    EXPECT_EQ(query->request(R"({"cmd":"watch","enable":false})")["class"], "WATCH");
    auto second = connect();
    EXPECT_EQ(second->request(R"({"cmd":"status"})")["clients"]["connected"], 18);
    TestClient extra(config_.path);
    EXPECT_EQ(extra.readJson(),
              json::parse(R"j({"class":"ERROR","message":"too many clients (18 connected)"})j"));
    EXPECT_TRUE(extra.waitEof());
    // A watcher may change its streams; one that stops frees its slot.
    EXPECT_EQ(watchers[0]->request(R"({"cmd":"watch","enable":false,"pose":true})"),
              json::parse(R"({"class":"WATCH","enable":false,"pose":true})"));
    EXPECT_EQ(watchers[1]->request(R"({"cmd":"watch","enable":false})")["class"], "WATCH");
    EXPECT_EQ(query->request(R"({"cmd":"watch"})")["class"], "WATCH");
    EXPECT_EQ(query->readJson()["class"], "SCALE");
    EXPECT_EQ(svc->stats().watch_refused, 1U);
}

// Connections holding half a request are sent an ERROR and closed after
// request_timeout_s (not before); then the next client is served.
TEST_F(SocketServiceTest, HalfWrittenRequestsAreClosedAfterTheRequestTimeout) {
    config_.request_timeout_s = 0.2;
    auto svc = startService();
    ASSERT_TRUE(svc);
    std::vector<std::unique_ptr<TestClient>> clients;
    clients.reserve(16);
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < 16; ++i) {  // max_clients: every connection a non-watcher gets
        clients.push_back(connect());
        ASSERT_TRUE(clients.back()->send(R"({"cmd":"po)"));
    }
    for (auto& c : clients) {
        EXPECT_EQ(c->readJson(), json::parse(R"j({"class":"ERROR",
            "message":"request incomplete after 0.2 s (closing)"})j"));
        EXPECT_TRUE(c->waitEof());
    }
    EXPECT_GE(secondsSince(t0), 0.2);
    SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.timed_out, 16U);
    EXPECT_EQ(st.connected, 0);
    EXPECT_EQ(st.detached, 0U);
    auto next = connect();
    EXPECT_EQ(next->request(R"({"cmd":"status"})")["clients"]["timed_out"], 16);
    // A line completed in time is answered.
    ASSERT_TRUE(next->send(R"({"cmd":"po)"));
    EXPECT_EQ(next->request(R"(ll"})")["class"], "SCALE");
    // An oversize line gets its ERROR; its rest is on the clock too.
    ASSERT_TRUE(next->send(std::string(5000, ' ')));
    EXPECT_EQ(next->readJson()["message"], "request longer than 4096 bytes (discarded)");
    EXPECT_EQ(next->readJson()["message"], "request incomplete after 0.2 s (closing)");
    EXPECT_TRUE(next->waitEof());
}

// When every connection is taken, a new client replaces the non-watching
// connection that has been idle longest (at least request_timeout_s).
// Watchers are never replaced.
TEST_F(SocketServiceTest, AnIdleConnectionMakesRoomWhenTheServerIsFull) {
    config_.max_clients = 2;
    config_.reserved_query_slots = 0;
    config_.request_timeout_s = 0.3;
    auto svc = startService();
    ASSERT_TRUE(svc);
    hub_.publishScale(reportAt(1));
    auto idle = connect();
    auto watcher = connect();
    ASSERT_EQ(watcher->request(R"({"cmd":"watch"})")["class"], "WATCH");
    ASSERT_EQ(watcher->readJson()["class"], "SCALE");
    // An idle connection is left alone while there is room...
    EXPECT_TRUE(idle->silent(400));
    // ...and closed when a new client needs its slot.
    auto fresh = connect();
    EXPECT_EQ(idle->readJson(), json::parse(R"({"class":"ERROR",
        "message":"idle connection closed: the server is full"})"));
    EXPECT_TRUE(idle->waitEof());
    ASSERT_EQ(fresh->request(R"({"cmd":"watch"})")["class"], "WATCH");
    ASSERT_EQ(fresh->readJson()["class"], "SCALE");
    TestClient extra(config_.path);
    EXPECT_EQ(extra.readJson(),
              json::parse(R"j({"class":"ERROR","message":"too many clients (2 connected)"})j"));
    EXPECT_TRUE(extra.waitEof());
    hub_.publishScale(reportAt(2));
    EXPECT_EQ(watcher->readJson()["frame_id"], 2);
    EXPECT_EQ(fresh->readJson()["frame_id"], 2);
    const SocketServiceStats st = svc->stats();
    EXPECT_EQ(st.evicted, 1U);
    EXPECT_EQ(st.rejected, 1U);
}

// The service checks the keys it is given (daemon_config.cpp checks the file).
TEST_F(SocketServiceTest, CreateRefusesBadLimits) {
    SocketConfig bad = config_;
    bad.request_timeout_s = 0;
    auto r = SocketService::create(bad, hub_, "0.1.0");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, "socket: request_timeout_s must be in (0, 3600] (got 0.000000)");
    bad = config_;
    bad.stall_timeout_s = std::nan("");
    r = SocketService::create(bad, hub_, "0.1.0");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message.rfind("socket: stall_timeout_s must be in (0, 3600]", 0), 0U);
    bad = config_;
    bad.reserved_query_slots = -1;
    r = SocketService::create(bad, hub_, "0.1.0");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, "socket: reserved_query_slots must be >= 0 (got -1)");
    EXPECT_FALSE(fs::exists(fs::symlink_status(config_.path)));
}

// max_request_bytes counts the line without its terminator, "\n" or "\r\n",
// also when the two arrive apart.
TEST_F(SocketServiceTest, TheRequestLimitCountsTheLineWithoutCrLf) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    ASSERT_EQ(config_.max_request_bytes, 4096U);
    auto c = connect();
    const std::string exact = paddedPoll(4096);
    EXPECT_EQ(c->request(exact + "\r")["class"], "SCALE");
    EXPECT_EQ(c->request(exact)["class"], "SCALE");
    ASSERT_TRUE(c->send(exact + "\r"));
    EXPECT_EQ(c->request("")["class"], "SCALE");
    const std::string too_long = "request longer than 4096 bytes (discarded)";
    EXPECT_EQ(c->request(paddedPoll(4097))["message"], too_long);
    EXPECT_EQ(c->request(paddedPoll(4097) + "\r")["message"], too_long);
    // A "\r" that turns out not to end the line counts.
    ASSERT_TRUE(c->send(exact + "\r"));
    EXPECT_EQ(c->request("x")["message"], too_long);
    EXPECT_EQ(c->request(R"({"cmd":"poll"})")["class"], "SCALE");
    EXPECT_EQ(svc->stats().errors, 3U);
    // The last request before EOF, with its "\r".
    auto last = connect();
    ASSERT_TRUE(last->send(exact + "\r"));
    ASSERT_EQ(::shutdown(last->fd(), SHUT_WR), 0);
    EXPECT_EQ(last->readJson()["class"], "SCALE");
    EXPECT_TRUE(last->waitEof());
}

// A NUL byte is an ERROR (it does not end the request), a number beyond a
// double gets set_gravity's message, and an unknown command of 900 KB an
// ERROR line of a few hundred bytes.
TEST_F(SocketServiceTest, HostileRequestsGetShortErrors) {
    config_.max_request_bytes = 1 << 20;
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    ASSERT_TRUE(c->send(std::string("{\"cmd\":\"poll\"}\0garbage\n", 23)));
    EXPECT_EQ(c->readJson(),
              json::parse(R"({"class":"ERROR","message":"request contains a NUL byte"})"));
    EXPECT_EQ(c->request(R"({"cmd":"set_gravity","down":[1e400,0,1]})"),
              json::parse(R"({"class":"ERROR","cmd":"set_gravity",
                  "message":"\"down\" must be an array of 3 finite numbers, not all zero"})"));
    EXPECT_FALSE(hub_.takeGravityRequest().has_value());
    const std::string name = "fly" + std::string(900'000, 'z');
    ASSERT_TRUE(c->send(R"({"cmd":")" + name + "\"}\n"));
    const auto line = c->readLine();
    ASSERT_TRUE(line.has_value());
    EXPECT_LT(line->size(), 250U);
    const json e = json::parse(*line, nullptr, false);
    EXPECT_EQ(e["cmd"], name.substr(0, 64));
    EXPECT_EQ(e["truncated"], true);
    EXPECT_EQ(c->request(R"({"cmd":"poll"})")["class"], "SCALE");
    EXPECT_EQ(svc->stats().detached, 0U);
}

TEST_F(SocketServiceTest, ClosedClientsAreCleanedUp) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto a = connect();
    auto b = connect();
    auto c = connect();
    a->close();
    ASSERT_EQ(::shutdown(b->fd(), SHUT_RDWR), 0);
    int connected = -1;
    for (int i = 0; i < 1000 && connected != 1; ++i) {
        connected = c->request(R"({"cmd":"status"})")["clients"]["connected"].get<int>();
    }
    EXPECT_EQ(connected, 1);
    EXPECT_EQ(svc->stats().detached, 0U);
}

TEST_F(SocketServiceTest, StopRemovesTheSocketFileAndClosesClients) {
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    EXPECT_TRUE(fs::exists(fs::symlink_status(config_.path)));
    svc->stop();
    EXPECT_FALSE(fs::exists(fs::symlink_status(config_.path)));
    EXPECT_TRUE(c->waitEof());
    svc->stop();  // idempotent
}

TEST_F(SocketServiceTest, StaleSocketFileIsReplaced) {
    {
        // A socket file nobody listens on any more (a crashed daemon's).
        auto stale = drivers::ipc::listenUnix({config_.path, 0600, ""});
        ASSERT_TRUE(stale.ok()) << stale.error().message;
    }
    ASSERT_TRUE(fs::is_socket(config_.path));
    auto svc = startService();
    ASSERT_TRUE(svc);
    auto c = connect();
    EXPECT_TRUE(c->connected());
}

TEST_F(SocketServiceTest, LiveSocketIsRefused) {
    auto first = startService();
    ASSERT_TRUE(first);
    auto second = SocketService::create(config_, hub_, "0.1.0");
    ASSERT_FALSE(second.ok());
    EXPECT_EQ(second.error().message,
              config_.path.string() + ": already in use by another process");
    // The first one is untouched.
    auto c = connect();
    EXPECT_EQ(c->request(R"({"cmd":"poll"})")["class"], "SCALE");
}

TEST_F(SocketServiceTest, OtherFilesAndMissingDirectoriesAreErrors) {
    std::ofstream(config_.path) << "not a socket\n";
    auto r = SocketService::create(config_, hub_, "0.1.0");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message,
              config_.path.string() + ": exists and is not a socket (not replacing it)");
    EXPECT_TRUE(fs::is_regular_file(config_.path));

    config_.path = dir_.path() / "missing" / "s.sock";
    r = SocketService::create(config_, hub_, "0.1.0");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, config_.path.string() + ": directory " +
                                     (dir_.path() / "missing").string() +
                                     ": No such file or directory");
}

TEST_F(SocketServiceTest, ModeIgnoresTheUmask) {
    const mode_t old = ::umask(0077);
    auto a = SocketService::create(config_, hub_, "0.1.0");
    ::umask(old);
    ASSERT_TRUE(a.ok()) << a.error().message;
    struct stat st = {};
    ASSERT_EQ(::stat(config_.path.c_str(), &st), 0);
    EXPECT_TRUE(S_ISSOCK(st.st_mode));
    EXPECT_EQ(st.st_mode & 07777U, 0660U);
    (*a)->stop();

    config_.mode = 0666;
    const mode_t old2 = ::umask(0022);
    auto b = SocketService::create(config_, hub_, "0.1.0");
    ::umask(old2);
    ASSERT_TRUE(b.ok()) << b.error().message;
    ASSERT_EQ(::stat(config_.path.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777U, 0666U);
}

TEST_F(SocketServiceTest, GroupIsAppliedOrNamedWhenUnknown) {
    config_.group = "scaled-no-such-group-xyz";
    auto bad = SocketService::create(config_, hub_, "0.1.0");
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.error().message,
              config_.path.string() + ": unknown group 'scaled-no-such-group-xyz'");
    EXPECT_FALSE(fs::exists(fs::symlink_status(config_.path)));

    const group* own = ::getgrgid(::getegid());
    if (own == nullptr) {
        GTEST_SKIP() << "the process's group has no name";
    }
    config_.group = own->gr_name;
    auto good = SocketService::create(config_, hub_, "0.1.0");
    ASSERT_TRUE(good.ok()) << good.error().message;
    struct stat st = {};
    ASSERT_EQ(::stat(config_.path.c_str(), &st), 0);
    EXPECT_EQ(st.st_gid, ::getegid());
}

// --- socket activation ----------------------------------------------------------

// Puts `fd` at descriptor number 3 for one test and restores what was there.
class Fd3Guard {
public:
    explicit Fd3Guard(int fd) {
        if (fd == 3) {
            ok_ = true;  // already there (descriptor 3 was free)
            return;
        }
        if (::fcntl(3, F_GETFD) >= 0) {
            saved_.reset(::fcntl(3, F_DUPFD_CLOEXEC, 10));
        }
        ok_ = ::dup2(fd, 3) == 3;
    }
    // Puts the saved descriptor back at 3 (saved_ then closes its copy), or
    // closes 3 when there was none.
    ~Fd3Guard() {
        if (saved_.isValid()) {
            ::dup2(saved_.get(), 3);
        } else {
            drivers::base::UniqueFd(3).reset();
        }
    }
    Fd3Guard(const Fd3Guard&) = delete;
    Fd3Guard& operator=(const Fd3Guard&) = delete;
    Fd3Guard(Fd3Guard&&) = delete;
    Fd3Guard& operator=(Fd3Guard&&) = delete;
    [[nodiscard]] bool ok() const { return ok_; }

private:
    drivers::base::UniqueFd saved_;  // what was at 3 before, if anything
    bool ok_ = false;
};

void setActivationEnv(long pid, int fds) {
    ::setenv("LISTEN_PID", std::to_string(pid).c_str(), 1);
    ::setenv("LISTEN_FDS", std::to_string(fds).c_str(), 1);
    ::setenv("LISTEN_FDNAMES", "scaled.socket", 1);
}

TEST_F(SocketServiceTest, AdoptsTheSocketFromListenFds) {
    const fs::path real = dir_.path() / "activated.sock";
    auto made = drivers::ipc::listenUnix({real, 0660, ""});
    ASSERT_TRUE(made.ok()) << made.error().message;
    {
        // The adopted descriptor is number 3; the service closes it in stop().
        Fd3Guard guard(made->fd.get());
        ASSERT_TRUE(guard.ok());
        if (made->fd.get() == 3) {
            [[maybe_unused]] const int fd3 = made->fd.release();
        } else {
            made->fd.reset();
        }
        setActivationEnv(::getpid(), 1);
        auto svc = startService();
        ASSERT_TRUE(svc);
        EXPECT_TRUE(svc->socketActivated());
        EXPECT_EQ(svc->path(), real);
        EXPECT_EQ(std::getenv("LISTEN_PID"), nullptr);
        EXPECT_EQ(std::getenv("LISTEN_FDS"), nullptr);
        EXPECT_EQ(std::getenv("LISTEN_FDNAMES"), nullptr);
        EXPECT_NE(::fcntl(3, F_GETFD) & FD_CLOEXEC, 0);
        EXPECT_NE(::fcntl(3, F_GETFL) & O_NONBLOCK, 0);
        TestClient c(real);
        EXPECT_EQ(c.readJson()["class"], "VERSION");
        EXPECT_EQ(c.request(R"({"cmd":"poll"})")["class"], "SCALE");
        svc->stop();
        // The file belongs to the service manager: it stays.
        EXPECT_TRUE(fs::is_socket(real));
        EXPECT_FALSE(fs::exists(fs::symlink_status(config_.path)));
    }
}

TEST_F(SocketServiceTest, ActivationForAnotherProcessIsIgnored) {
    setActivationEnv(::getpid() + 1, 1);
    auto svc = startService();
    ASSERT_TRUE(svc);
    EXPECT_FALSE(svc->socketActivated());
    EXPECT_EQ(std::getenv("LISTEN_FDS"), nullptr);
    EXPECT_TRUE(fs::is_socket(config_.path));
}

TEST_F(SocketServiceTest, ActivationWithAnUnusableDescriptorIsAnError) {
    // A connected (not listening) socket at an injected descriptor number.
    int pair[2] = {-1, -1};
    ASSERT_EQ(::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, pair), 0);
    const drivers::base::UniqueFd other(pair[1]);
    setActivationEnv(::getpid(), 1);
    auto r = drivers::ipc::takeActivatedSocket(pair[0]);  // owns pair[0] now
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message, "socket activation (LISTEN_FDS=1): inherited socket (fd " +
                                     std::to_string(pair[0]) + "): is not listening");
    EXPECT_EQ(std::getenv("LISTEN_PID"), nullptr);

    const int file = ::open(dir_.path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    ASSERT_GE(file, 0);
    setActivationEnv(::getpid(), 1);
    r = drivers::ipc::takeActivatedSocket(file);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("is not a socket"), std::string::npos) << r.error().message;

    // Not activated at all: nothing adopted.
    auto none = drivers::ipc::takeActivatedSocket(3);
    ASSERT_TRUE(none.ok());
    EXPECT_FALSE(none->has_value());
}

}  // namespace
}  // namespace scaled::daemon
