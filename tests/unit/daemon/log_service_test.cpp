// The daemon's log service: lines complete after stop(), the event lines,
// the bounded queue, faults (a real ENOSPC from /dev/full, a directory that
// cannot be created), LogStatus in the hub, and a SIGKILLed writer process.

#include <atomic>
#include <csignal>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/daemon/log_service.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/protocol.h>
#include <scaled/drivers/base/unique_fd.h>
#include <scaled/drivers/fieldlog/field_log.h>

#include "log_events.h"
#include "temp_dir.h"

namespace scaled::daemon {
namespace {

using nlohmann::json;
using test::TempDir;
namespace fs = std::filesystem;

LogConfig configIn(const fs::path& dir) {
    LogConfig c;
    c.enabled = true;
    c.dir = dir;
    c.max_file_bytes = 1u << 20;
    c.max_total_bytes = 16u << 20;
    c.fsync_interval_ms = 3'600'000;  // tests drive flush() / stop() themselves
    c.queue_bytes = 1u << 16;
    return c;
}

std::unique_ptr<LogService> make(const LogConfig& config, ReportHub& hub,
                                 LogServiceHooks hooks = {}) {
    auto s = LogService::create(config, hub, std::move(hooks));
    EXPECT_TRUE(s) << s.error().message;
    return s ? std::move(*s) : nullptr;
}

json parse(const std::string& line) {
    json j = json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << line;
    return j;
}

drivers::fieldlog::FieldLogContents readAll(const fs::path& dir) {
    auto r = drivers::fieldlog::readFieldLog(dir);
    EXPECT_TRUE(r) << r.error().message;
    return r ? std::move(*r) : drivers::fieldlog::FieldLogContents{};
}

TEST(LogService, LinesAreCompleteAfterStop) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogConfig c = configIn(tmp.path());
    c.queue_bytes = 1u << 20;  // room for all 500 lines: none dropped however the thread runs
    auto log = make(c, hub);
    ASSERT_NE(log, nullptr);
    log->start();
    for (int i = 0; i < 500; ++i) {
        FrameEvent f;
        f.frame_id = i;
        f.t_ns = 1000LL * i;
        f.features = 40;
        f.tracked = 25;
        f.ms = 3.25;
        ASSERT_TRUE(log->frameEvent(f));
    }
    log->stop();
    const auto contents = readAll(tmp.path());
    ASSERT_EQ(contents.lines.size(), 500u);
    EXPECT_EQ(contents.partial_lines, 0u);
    EXPECT_EQ(contents.corrupt_lines, 0u);
    for (std::size_t i = 0; i < contents.lines.size(); ++i) {
        const json j = parse(contents.lines[i].text);
        EXPECT_EQ(j["frame_id"], static_cast<int>(i));
    }
    const LogStatus st = hub.logStatus();
    EXPECT_EQ(st.state, LogStatus::State::kOk);
    EXPECT_EQ(st.lines_written, 500u);
    EXPECT_EQ(st.lines_dropped, 0u);
    EXPECT_EQ(st.bytes_written, fs::file_size(contents.files.at(0)));
    EXPECT_TRUE(st.error.empty());
    EXPECT_FALSE(log->append("{\"late\":1}"));  // after stop: refused and counted
    EXPECT_EQ(log->status().lines_dropped, 1u);
}

TEST(LogService, FlushWritesWithoutTheThreadAndPublishes) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    auto log = make(configIn(tmp.path()), hub);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(hub.logStatus().state, LogStatus::State::kOk);
    EXPECT_TRUE(log->append("{\"a\":1}\n"));  // one trailing newline is allowed
    EXPECT_TRUE(log->append("{\"a\":2}"));
    EXPECT_FALSE(log->append("{\"a\":3}\n{\"a\":4}"));  // two lines in one: refused
    EXPECT_FALSE(log->append(""));
    EXPECT_EQ(hub.logStatus().lines_written, 0u);  // nothing written before a batch
    ASSERT_TRUE(log->flush());
    const LogStatus st = hub.logStatus();
    EXPECT_EQ(st.lines_written, 2u);
    EXPECT_EQ(st.lines_dropped, 2u);
    EXPECT_EQ(st.bytes_written, 16u);
    const auto contents = readAll(tmp.path());
    ASSERT_EQ(contents.lines.size(), 2u);
    EXPECT_EQ(contents.lines[1].text, "{\"a\":2}");
}

TEST(LogService, FullQueueDropsAndCounts) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogConfig c = configIn(tmp.path());
    c.queue_bytes = 512;  // two halves of 256 bytes
    auto log = make(c, hub);
    ASSERT_NE(log, nullptr);
    const std::string line = "{\"pad\":\"" + std::string(90, 'x') + "\"}";  // 100 bytes + \n
    EXPECT_TRUE(log->append(line));
    EXPECT_TRUE(log->append(line));
    EXPECT_FALSE(log->append(line));  // 303 > 256
    EXPECT_FALSE(log->append(line));
    EXPECT_EQ(log->status().lines_dropped, 2u);
    ASSERT_TRUE(log->flush());
    EXPECT_TRUE(log->append(line));  // room again
    ASSERT_TRUE(log->flush());
    EXPECT_EQ(log->status().lines_written, 3u);
    EXPECT_EQ(hub.logStatus().lines_dropped, 2u);
    // A line longer than half the queue can never fit.
    EXPECT_FALSE(log->append("{\"pad\":\"" + std::string(300, 'x') + "\"}"));
    EXPECT_EQ(log->status().lines_dropped, 3u);
}

TEST(LogService, DisabledIsOffAndWritesNothing) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogConfig c = configIn(tmp.path() / "logs");
    c.enabled = false;
    auto log = make(c, hub);
    ASSERT_NE(log, nullptr);
    log->start();
    EXPECT_EQ(hub.logStatus().state, LogStatus::State::kOff);
    EXPECT_FALSE(log->append("{\"a\":1}"));
    EXPECT_FALSE(log->stopEvent({.reason = "test"}));
    EXPECT_FALSE(log->flush());
    log->stop();
    EXPECT_FALSE(fs::exists(tmp.path() / "logs"));
    EXPECT_EQ(log->status().lines_dropped, 0u);
    EXPECT_EQ(std::string(toString(log->status().state)), "off");
}

TEST(LogService, ADirectoryThatCannotBeCreatedIsAFaultNotAFailure) {
    TempDir tmp("log_service");
    std::ofstream(tmp.path() / "plain") << "x";  // closed at the end of the statement
    const fs::path dir = tmp.path() / "plain" / "logs";
    ReportHub hub(16);
    testing::internal::CaptureStderr();
    auto log = make(configIn(dir), hub);
    const std::string err = testing::internal::GetCapturedStderr();
    ASSERT_NE(log, nullptr);
    log->start();
    EXPECT_FALSE(log->append("{\"a\":1}"));
    EXPECT_FALSE(log->flush());
    log->stop();
    const LogStatus st = hub.logStatus();
    EXPECT_EQ(st.state, LogStatus::State::kFault);
    EXPECT_NE(st.error.find(dir.string()), std::string::npos) << st.error;
    EXPECT_EQ(st.lines_dropped, 1u);
    EXPECT_NE(err.find("field log stopped"), std::string::npos) << err;
}

// Every file the log opens is /dev/full: the first batch fails with a real ENOSPC.
TEST(LogService, NoSpaceLeftFaultsOnceAndKeepsRunning) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogServiceHooks hooks;
    hooks.open_file = [](const fs::path&) {
        // NOLINTNEXTLINE(cppcoreguidelines-pro-type-vararg)
        return ::open("/dev/full", O_WRONLY | O_CLOEXEC);
    };
    auto log = make(configIn(tmp.path()), hub, hooks);
    ASSERT_NE(log, nullptr);
    EXPECT_EQ(hub.logStatus().state, LogStatus::State::kOk);
    log->start();
    EXPECT_TRUE(log->append("{\"a\":1}"));  // queued: the card is not touched yet
    EXPECT_TRUE(log->append("{\"a\":2}"));
    testing::internal::CaptureStderr();
    EXPECT_FALSE(log->flush());
    EXPECT_FALSE(log->flush());
    const std::string err = testing::internal::GetCapturedStderr();
    LogStatus st = hub.logStatus();
    EXPECT_EQ(st.state, LogStatus::State::kFault);
    EXPECT_NE(st.error.find("No space left on device"), std::string::npos) << st.error;
    EXPECT_EQ(st.lines_written, 0u);
    EXPECT_EQ(st.lines_dropped, 2u);
    // One message on stderr, not one per attempt.
    const auto first = err.find("field log stopped");
    ASSERT_NE(first, std::string::npos) << err;
    EXPECT_EQ(err.find("field log stopped", first + 1), std::string::npos) << err;
    // From now on appends are refused and counted; nothing blocks or crashes.
    for (int i = 0; i < 100; ++i) {
        EXPECT_FALSE(log->errorEvent({.where = "test", .message = "x"}));
    }
    log->stop();
    st = hub.logStatus();
    EXPECT_EQ(st.state, LogStatus::State::kFault);
    EXPECT_EQ(st.lines_dropped, 102u);
}

// The symlink variant: the log's next file is a symlink to /dev/full.
TEST(LogService, NoSpaceLeftOnRotationThroughASymlink) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogConfig c = configIn(tmp.path());
    c.max_file_bytes = 64;
    LogServiceHooks hooks;
    hooks.utc_now_s = [] { return std::int64_t{1700000000}; };
    auto log = make(c, hub, hooks);
    ASSERT_NE(log, nullptr);
    fs::create_symlink("/dev/full",
                       tmp.path() / drivers::fieldlog::fieldLogFileName(1700000000, 2));
    ASSERT_TRUE(log->append("{\"pad\":\"" + std::string(40, 'x') + "\"}"));
    ASSERT_TRUE(log->flush());
    ASSERT_TRUE(log->append("{\"pad\":\"" + std::string(40, 'y') + "\"}"));
    testing::internal::CaptureStderr();
    EXPECT_FALSE(log->flush());
    (void)testing::internal::GetCapturedStderr();
    const LogStatus st = hub.logStatus();
    EXPECT_EQ(st.state, LogStatus::State::kFault);
    EXPECT_NE(st.error.find(drivers::fieldlog::fieldLogFileName(1700000000, 2)), std::string::npos)
        << st.error;
    EXPECT_NE(st.error.find("No space left on device"), std::string::npos) << st.error;
    EXPECT_EQ(st.lines_written, 1u);
}

TEST(LogService, EventLinesAreJsonWithTheirFields) {
    std::string out;
    formatEvent(
        StartEvent{.release = "0.1.0", .source = "sim", .config_toml = "[log]\ndir = \"x\"\n"},
        out);
    json j = parse(out);
    EXPECT_EQ(j["class"], "START");
    EXPECT_GT(j["mono_ns"].get<std::int64_t>(), 0);
    EXPECT_EQ(j["config"], "[log]\ndir = \"x\"\n");
    EXPECT_EQ(j["release"], "0.1.0");

    formatEvent(StopEvent{.reason = "SIGTERM", .mono_ns = 42}, out);
    j = parse(out);
    EXPECT_EQ(j["class"], "STOP");
    EXPECT_EQ(j["mono_ns"], 42);
    EXPECT_EQ(j["reason"], "SIGTERM");

    formatEvent(FrameEvent{.frame_id = 7,
                           .t_ns = 123456789012LL,
                           .epoch = 2,
                           .health = "lost",
                           .features = 30,
                           .tracked = 12,
                           .ms = 4.5,
                           .dropped = 3,
                           .stage_us = {.predict = 41.25,
                                        .search = 310.5,
                                        .match = 1234.5678,
                                        .update = 900,
                                        .map = 0}},
                out);
    j = parse(out);
    EXPECT_EQ(j["class"], "FRAME");
    EXPECT_EQ(j["frame_id"], 7);
    EXPECT_EQ(j["t_ns"], 123456789012LL);
    EXPECT_EQ(j["epoch"], 2);
    EXPECT_EQ(j["health"], "lost");
    EXPECT_EQ(j["features"], 30);
    EXPECT_EQ(j["tracked"], 12);
    EXPECT_DOUBLE_EQ(j["ms"].get<double>(), 4.5);
    EXPECT_EQ(j["dropped"], 3);
    // The frame's tracker stages, 4 significant digits; 0: did not run.
    EXPECT_EQ(j["stage_us"], json::parse(R"({"predict":41.25,"search":310.5,"match":1235,
        "update":900,"map":0})"));

    const std::vector<LogBox> boxes = {{"chair", 0.875, 1, 2, 30.5, 40}, {"cup", 0.5, 5, 6, 7, 8}};
    formatEvent(
        DetectionEvent{.frame_id = 9, .t_ns = 1, .epoch = 0, .latency_ms = 80.25, .boxes = boxes},
        out);
    j = parse(out);
    EXPECT_EQ(j["class"], "DETECTION");
    ASSERT_EQ(j["boxes"].size(), 2u);
    EXPECT_EQ(j["boxes"][0]["class"], "chair");
    EXPECT_DOUBLE_EQ(j["boxes"][0]["score"].get<double>(), 0.875);
    EXPECT_EQ(j["boxes"][0]["box"], json({1, 2, 30.5, 40}));
    EXPECT_DOUBLE_EQ(j["latency_ms"].get<double>(), 80.25);

    formatEvent(StateEvent{.from = DaemonState::kConverging,
                           .to = DaemonState::kLost,
                           .epoch = 3,
                           .frame_id = 100,
                           .reason = "tracking lost"},
                out);
    j = parse(out);
    EXPECT_EQ(j["class"], "STATE");
    EXPECT_EQ(j["from"], "converging");
    EXPECT_EQ(j["to"], "lost");
    EXPECT_EQ(j["epoch"], 3);
    EXPECT_EQ(j["frame_id"], 100);

    formatEvent(ErrorEvent{.where = "detector", .message = "model \"x\" missing"}, out);
    j = parse(out);
    EXPECT_EQ(j["class"], "ERROR");
    EXPECT_EQ(j["message"], "model \"x\" missing");
}

TEST(LogService, ScaleLinesHaveNullsBeforeTheFirstScaleAndCapObservations) {
    std::string out;
    ScaleReport r;
    r.frame_id = 12;
    r.epoch = 1;
    r.state = DaemonState::kTracking;
    ScaleEvent e = scaleEventFrom(r);
    formatEvent(e, out);
    json j = parse(out);
    EXPECT_EQ(j["class"], "SCALE");
    EXPECT_EQ(j["state"], "tracking");
    EXPECT_TRUE(j["scale"].is_null());
    EXPECT_TRUE(j["mean"].is_null());
    EXPECT_TRUE(j["ci68"].is_null());
    EXPECT_TRUE(j["ci95"].is_null());
    EXPECT_EQ(j["obs"].size(), 0u);

    r.has_scale = true;
    r.scale = 1.25;
    r.mean = 1.3;
    r.ci68_lo = 1.1;
    r.ci68_hi = 1.4;
    r.ci95_lo = 0.9;
    r.ci95_hi = 1.6;
    r.observations = 200;
    r.state = DaemonState::kConverging;
    e = scaleEventFrom(r);
    std::vector<LogObservation> obs(100, LogObservation{"bottle", 0.21, 0.02, 1.2, 0.5});
    obs[0].D = std::numeric_limits<double>::quiet_NaN();
    e.obs = obs;
    e.new_observations = 100;
    e.detections = 4;
    formatEvent(e, out);
    j = parse(out);
    EXPECT_DOUBLE_EQ(j["scale"].get<double>(), 1.25);
    EXPECT_DOUBLE_EQ(j["mean"].get<double>(), 1.3);
    EXPECT_EQ(j["ci68"], json({1.1, 1.4}));
    EXPECT_EQ(j["ci95"], json({0.9, 1.6}));
    EXPECT_EQ(j["observations"], 200);
    EXPECT_EQ(j["new_observations"], 100);
    EXPECT_EQ(j["detections"], 4);
    ASSERT_EQ(j["obs"].size(), kMaxLoggedObservations);
    EXPECT_TRUE(j["obs"][0]["D"].is_null());  // NaN is not JSON
    EXPECT_EQ(j["obs"][1]["class"], "bottle");
    EXPECT_DOUBLE_EQ(j["obs"][1]["D"].get<double>(), 0.21);
    EXPECT_DOUBLE_EQ(j["obs"][1]["sigma_D"].get<double>(), 0.02);
    EXPECT_DOUBLE_EQ(j["obs"][1]["local"].get<double>(), 1.2);
    EXPECT_DOUBLE_EQ(j["obs"][1]["weight"].get<double>(), 0.5);
}

ObjectReport objectAt(int id, const char* name, core::ObjectState state, std::int64_t last_frame) {
    ObjectReport o;
    o.id = id;
    o.setClassName(name);
    o.state = state;
    o.anchor = {0.123456789012, -1.5, 2.25};
    o.anchor_rel_sigma = 0.0625;
    o.detections = 2 * id;
    o.views = id;
    o.views_used = state == core::ObjectState::kUsed ? id : 0;
    o.first_frame = 100;
    o.last_frame = last_frame;
    o.local_estimate = state == core::ObjectState::kUsed ? 1.234567891234 : 0;
    o.has_height = state == core::ObjectState::kUsed;
    o.height_m = 0.75;
    o.height_ci95_lo_m = 0.7;
    o.height_ci95_hi_m = 0.8125;
    return o;
}

// OBJECT: the frame, then the members of an OBJECTS entry with the class as
// "object_class" (the line's own "class" is OBJECT); 9 significant digits.
TEST(LogService, ObjectLinesHaveTheMembersOfAnObjectsEntry) {
    const ObjectReport used = objectAt(3, "chair", core::ObjectState::kUsed, 450);
    std::string out;
    formatEvent(
        ObjectEvent{
            .frame_id = 450, .t_ns = 15'000'000'000, .epoch = 2, .object = &used, .mono_ns = 77},
        out);
    EXPECT_EQ(out.find('\n'), std::string::npos);
    EXPECT_EQ(parse(out), json::parse(R"({"class":"OBJECT","mono_ns":77,"frame_id":450,
        "t_ns":15000000000,"epoch":2,"id":3,"object_class":"chair","state":"used",
        "anchor":[0.123456789,-1.5,2.25],"anchor_rel_sigma":0.0625,"detections":6,"views":3,
        "views_used":3,"first_frame":100,"last_frame":450,"local_estimate":1.23456789,
        "height_m":0.75,"height_ci95_m":[0.7,0.8125]})"));

    const ObjectReport tentative = objectAt(4, "cup", core::ObjectState::kTentative, 450);
    formatEvent(ObjectEvent{.frame_id = 450, .epoch = 2, .object = &tentative}, out);
    const json j = parse(out);
    EXPECT_EQ(j["object_class"], "cup");
    EXPECT_EQ(j["state"], "tentative");
    for (const char* k :
         {"anchor", "anchor_rel_sigma", "local_estimate", "height_m", "height_ci95_m"}) {
        EXPECT_TRUE(j[k].is_null()) << k;
    }
}

// After each SCALE line the field log has one OBJECT line per object that
// received a view in that update (last_frame = the update's frame), none for
// the others.
TEST(LogService, ScaleUpdatesLogTheObjectsTheyViewed) {
    TempDir dir("log");
    ReportHub hub(16);
    auto log = make(configIn(dir.path()), hub);
    ASSERT_TRUE(log);
    LogEvents events(*log);
    ScaleReport r;
    r.frame_id = 450;
    r.t_ns = 15'000'000'000;
    r.epoch = 2;
    r.state = DaemonState::kConverging;
    const std::vector<ObjectReport> objects = {
        objectAt(3, "chair", core::ObjectState::kUsed, 450),
        objectAt(5, "tv", core::ObjectState::kAnchored, 440),
        objectAt(7, "cup", core::ObjectState::kTentative, 450),
    };
    PipelineEvents::Scale e;
    e.report = &r;
    e.objects = objects;
    events.onScale(e);
    r.frame_id = 460;
    e.objects = {};  // the paper model: no table, no OBJECT lines
    events.onScale(e);
    ASSERT_TRUE(log->flush());

    const auto contents = readAll(dir.path());
    std::vector<json> lines;
    for (const auto& l : contents.lines) {
        lines.push_back(parse(l.text));
    }
    ASSERT_EQ(lines.size(), 4U);
    EXPECT_EQ(lines[0]["class"], "SCALE");
    EXPECT_EQ(lines[1]["class"], "OBJECT");
    EXPECT_EQ(lines[1]["id"], 3);
    EXPECT_EQ(lines[1]["frame_id"], 450);
    EXPECT_EQ(lines[1]["t_ns"], 15'000'000'000);
    EXPECT_EQ(lines[1]["epoch"], 2);
    EXPECT_EQ(lines[1]["object_class"], "chair");
    EXPECT_EQ(lines[2]["class"], "OBJECT");
    EXPECT_EQ(lines[2]["id"], 7);
    EXPECT_EQ(lines[3]["class"], "SCALE");
    EXPECT_EQ(lines[3]["frame_id"], 460);
}

// A WINDOW line per window optimisation, through LogEvents: the frame that
// took it, the window's size, its RMS before and after, its scale and the
// camera it used (9 significant digits).
TEST(LogService, WindowLinesHaveTheOptimisationAndItsCamera) {
    TempDir dir("log");
    ReportHub hub(16);
    auto log = make(configIn(dir.path()), hub);
    ASSERT_TRUE(log);
    LogEvents events(*log);
    core::slam::WindowBaReport r;
    r.optimised = true;
    r.keyframes = 67;
    r.free_keyframes = 34;
    r.points = 412;
    r.observations = 5120;
    r.rms_before_px = core::Scalar(1.5);
    r.rms_after_px = core::Scalar(0.75);
    r.scale = core::Scalar(1.0625);
    r.rolling_shutter_s = core::Scalar(0.0234375);
    r.focal_scale = core::Scalar(0.9375);
    r.k1 = core::Scalar(-0.125);
    PipelineEvents::WindowBa e;
    e.frame_id = 517;
    e.t_ns = 17'233'333'333;
    e.epoch = 2;
    e.report = &r;
    events.onWindowBa(e);
    ASSERT_TRUE(log->flush());

    const auto contents = readAll(dir.path());
    ASSERT_EQ(contents.lines.size(), 1U);
    json j = parse(contents.lines[0].text);
    ASSERT_TRUE(j["mono_ns"].is_number_integer());
    j.erase("mono_ns");
    EXPECT_EQ(j, json::parse(R"({"class":"WINDOW","frame_id":517,"t_ns":17233333333,"epoch":2,
        "keyframes":67,"free_keyframes":34,"points":412,"observations":5120,
        "rms_before_px":1.5,"rms_px":0.75,"scale":1.0625,"rolling_shutter_s":0.0234375,
        "focal_scale":0.9375,"k1":-0.125})"))
        << contents.lines[0].text;
}

PoseReport poseAt(std::uint64_t epoch, std::int64_t frame_id, std::int64_t t_ns) {
    PoseReport p;
    p.epoch = epoch;
    p.frame_id = frame_id;
    p.t_ns = t_ns;
    p.position_map = {1.25, -0.4, 0.3125};
    p.velocity_map = {0.2, 0.05, 0};
    p.orientation_wxyz = {0.5, -0.5, 0.5, -0.5};
    p.position_cov_map = {4e-4, 1e-5, 0, 1e-5, 3e-4, 0, 0, 0, 2e-4};
    p.attitude_cov_rad2 = {2.5e-5, 0, 0, 0, 2.5e-5, 0, 0, 0, 1.2e-4};
    return p;
}

// A POSE line holds the members of the socket's POSE (but "time"), the
// metric ones at the scale given and null before the epoch has one.
TEST(LogService, PoseLinesHaveTheMembersOfTheSocketsPose) {
    const PoseReport pose = poseAt(2, 512, 17'066'666'667);
    ScaleReport scale;
    scale.epoch = 2;
    scale.has_scale = true;
    scale.scale = 0.976341234;
    scale.ci68_lo = 0.95;
    scale.ci68_hi = 1.01;
    scale.state = DaemonState::kConverging;
    std::string out;
    formatEvent(
        PoseEvent{
            .pose = &pose, .metric = metricPose(pose, scale), .state = scale.state, .mono_ns = 99},
        out);
    EXPECT_EQ(out.find('\n'), std::string::npos);
    json j = parse(out);
    EXPECT_EQ(j["class"], "POSE");
    EXPECT_EQ(j["mono_ns"], 99);
    EXPECT_EQ(j["frame_id"], 512);
    EXPECT_EQ(j["t_ns"], 17'066'666'667);
    EXPECT_EQ(j["epoch"], 2);
    EXPECT_EQ(j["state"], "converging");
    EXPECT_DOUBLE_EQ(j["scale"].get<double>(), 0.976341234);  // 9 digits
    EXPECT_DOUBLE_EQ(j["scale_sigma"].get<double>(), 0.03);
    ASSERT_TRUE(j["position"].is_array());
    for (std::size_t k = 0; k < 3; ++k) {
        EXPECT_NEAR(j["position"][k].get<double>(), 0.976341234 * pose.position_map.at(k), 1e-6)
            << k;
        EXPECT_EQ(j["position_map"][k].get<double>(), pose.position_map.at(k)) << k;
    }
    EXPECT_EQ(j["orientation"], json::parse("[0.5,-0.5,0.5,-0.5]"));
    // The socket's POSE of the same pose and scale: the same members.
    std::string socket;
    appendPose(socket, pose, scale);
    json expected = parse(socket);
    expected.erase("time");
    expected["class"] = "POSE";
    json got = j;
    got.erase("mono_ns");
    got["scale"] = expected["scale"];  // the log writes 9 digits, the socket all 17
    EXPECT_EQ(got, expected);

    // Before the epoch's first scale (a scale of the previous epoch): no metric part.
    scale.epoch = 1;
    scale.state = DaemonState::kTracking;
    formatEvent(PoseEvent{.pose = &pose, .metric = metricPose(pose, scale), .state = scale.state},
                out);
    j = parse(out);
    EXPECT_EQ(j["state"], "tracking");
    for (const char* k : {"scale", "scale_sigma", "position", "velocity", "position_cov"}) {
        EXPECT_TRUE(j[k].is_null()) << k;
    }
    for (const char* k :
         {"orientation", "attitude_cov", "position_map", "velocity_map", "position_map_cov"}) {
        EXPECT_TRUE(j[k].is_array()) << k;
    }
}

// LogEvents thins the poses of every tracked frame to log.pose_rate_hz per
// second of frame time (the socket's PoseRateLimiter), starts again with a
// new epoch, and writes none with pose_rate_hz = 0.
TEST(LogService, PoseLinesAreThinnedToTheRateOfFrameTime) {
    const auto run = [](double rate_hz, std::vector<json>& poses) {
        TempDir dir("log");
        ReportHub hub(16);
        LogConfig config = configIn(dir.path());
        config.pose_rate_hz = rate_hz;
        config.queue_bytes = 1u << 20;  // room for 250 lines without a drain
        auto log = make(config, hub);
        ASSERT_TRUE(log);
        LogEvents events(*log);
        // 2 s of frames at 100 Hz in epoch 1, then 0.5 s in epoch 2.
        for (int i = 0; i < 250; ++i) {
            const std::uint64_t epoch = i < 200 ? 1 : 2;
            const PoseReport pose = poseAt(epoch, i, std::int64_t{i} * 10'000'000);
            PipelineEvents::Pose e;
            e.pose = &pose;
            e.state = DaemonState::kTracking;
            events.onPose(e);
        }
        ASSERT_TRUE(log->flush());
        for (const auto& l : readAll(dir.path()).lines) {
            const json j = parse(l.text);
            EXPECT_EQ(j["class"], "POSE");
            poses.push_back(j);
        }
    };
    std::vector<json> poses;
    run(10, poses);
    // Slots of 100 ms centred on the epoch's first pose: 0, 50, 150, ...,
    // 1950 ms (21 lines), then 2000, 2050, ..., 2450 ms (6).
    ASSERT_EQ(poses.size(), 27U);
    std::vector<std::int64_t> t_ms;
    t_ms.reserve(poses.size());
    for (const json& j : poses) {
        t_ms.push_back(j["t_ns"].get<std::int64_t>() / 1'000'000);
    }
    EXPECT_EQ(t_ms[0], 0);
    EXPECT_EQ(t_ms[1], 50);
    EXPECT_EQ(t_ms[2], 150);
    EXPECT_EQ(t_ms[20], 1950);
    EXPECT_EQ(t_ms[21], 2000);
    EXPECT_EQ(poses[21]["epoch"], 2);
    EXPECT_EQ(t_ms[22], 2050);
    EXPECT_EQ(t_ms[26], 2450);
    EXPECT_TRUE(poses[0]["position"].is_null());  // no metric part without a scale

    std::vector<json> none;
    run(0, none);
    EXPECT_TRUE(none.empty());
    std::vector<json> all;
    run(1000, all);  // faster than the frames: every pose
    EXPECT_EQ(all.size(), 250U);
}

TEST(LogService, TextIsEscapedIntoValidJson) {
    std::string out;
    const std::string nasty = std::string("a\"b\\c\nd\te\x01 \x7f") + "\xc3\xa9" + "\xff\xc3" +
                              std::string(1, '\0') + "\xed\xa0\x80";
    formatEvent(ErrorEvent{.where = nasty, .message = "\xe2\x82\xac ok"}, out);
    EXPECT_EQ(out.find('\n'), std::string::npos);
    EXPECT_TRUE(drivers::fieldlog::isJsonObjectLine(out)) << out;
    const json j = parse(out);
    EXPECT_EQ(j["message"], "\xe2\x82\xac ok");
    EXPECT_EQ(j["where"].get<std::string>().substr(0, 7), "a\"b\\c\nd");
}

TEST(LogService, ConcurrentAppendersLoseNothingTheyWereToldWasQueued) {
    TempDir tmp("log_service");
    ReportHub hub(16);
    LogConfig c = configIn(tmp.path());
    c.fsync_interval_ms = 5;
    c.max_file_bytes = 20000;  // a few rotations too
    auto log = make(c, hub);
    ASSERT_NE(log, nullptr);
    log->start();
    constexpr int kThreads = 4;
    constexpr int kLines = 2000;
    std::atomic<int> accepted{0};
    std::vector<std::thread> threads;
    threads.reserve(kThreads);
    for (int t = 0; t < kThreads; ++t) {
        threads.emplace_back([&, t] {
            for (int i = 0; i < kLines; ++i) {
                // The event holds views: the text must outlive the call.
                const std::string message = std::to_string(t * kLines + i);
                ErrorEvent e{.where = "thread", .message = message};
                if (log->errorEvent(e)) {
                    accepted.fetch_add(1);
                }
            }
        });
    }
    for (auto& th : threads) {
        th.join();
    }
    log->stop();
    const auto contents = readAll(tmp.path());
    EXPECT_EQ(contents.lines.size(), static_cast<std::size_t>(accepted.load()));
    EXPECT_EQ(contents.corrupt_lines + contents.partial_lines, 0u);
    const LogStatus st = hub.logStatus();
    EXPECT_EQ(st.lines_written, static_cast<std::uint64_t>(accepted.load()));
    EXPECT_EQ(st.lines_written + st.lines_dropped, std::uint64_t{kThreads} * kLines);
    EXPECT_GT(contents.files.size(), 1u);
}

// A real crash: a child process logs until it is killed with SIGKILL. Every
// line on disk but possibly the last one of the file must parse.
TEST(LogService, SigkillLeavesOnlyWholeLinesButTheLast) {
    TempDir tmp("log_service");
    std::array<int, 2> ready{};
    ASSERT_EQ(::pipe(ready.data()), 0);
    drivers::base::UniqueFd ready_read(ready[0]);
    drivers::base::UniqueFd ready_write(ready[1]);
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        ready_read.reset();
        ReportHub hub(16);
        LogConfig c = configIn(tmp.path());
        c.fsync_interval_ms = 1;
        c.max_file_bytes = 1u << 30;
        auto created = LogService::create(c, hub);
        if (!created) {
            ::_exit(2);
        }
        LogService& log = **created;
        log.start();
        const std::string pad(200, 'z');
        for (std::int64_t i = 0;; ++i) {
            const std::string message = std::to_string(i);  // outlives the call
            ErrorEvent e{.where = pad, .message = message};
            if (!log.errorEvent(e)) {
                ::_exit(3);  // a drop would leave a gap the parent reports
            }
            if (i % 50 == 0) {
                (void)log.flush();  // keeps the queue from filling up
            }
            if (i == 1000) {
                const char byte = 'r';
                (void)!::write(ready_write.get(), &byte, 1);
            }
        }
    }
    ready_write.reset();
    char byte = 0;
    ASSERT_EQ(::read(ready_read.get(), &byte, 1), 1);  // the child has written >= 1001 lines
    ready_read.reset();
    ASSERT_EQ(::kill(child, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(::waitpid(child, &status, 0), child);
    ASSERT_TRUE(WIFSIGNALED(status));
    EXPECT_EQ(WTERMSIG(status), SIGKILL);

    const auto contents = readAll(tmp.path());
    EXPECT_EQ(contents.corrupt_lines, 0u);
    EXPECT_LE(contents.partial_lines, 1u);
    ASSERT_GE(contents.lines.size(), 1001u);
    for (std::size_t i = 0; i < contents.lines.size(); ++i) {
        const json j = parse(contents.lines[i].text);
        ASSERT_EQ(j["message"], std::to_string(i));  // in order, none missing
    }
}

}  // namespace
}  // namespace scaled::daemon
