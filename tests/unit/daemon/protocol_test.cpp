// The socket protocol's encoders and request parser (docs/protocol.md): every
// object is one line of valid JSON with the documented members, and every bad
// request becomes an error message instead of a crash.

#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <scaled/daemon/pipeline_config.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/protocol.h>

namespace scaled::daemon {
namespace {

using nlohmann::json;

// Parses one encoded line: it must end in exactly one newline.
json parseLine(const std::string& line) {
    EXPECT_FALSE(line.empty());
    EXPECT_EQ(line.back(), '\n') << line;
    EXPECT_EQ(line.find('\n'), line.size() - 1) << line;
    json j = json::parse(line, nullptr, false);
    EXPECT_FALSE(j.is_discarded()) << line;
    return j;
}

ScaleReport sampleReport() {
    ScaleReport r;
    r.has_scale = true;
    r.scale = 0.9763412345678;
    r.mean = 0.981;
    r.ci68_lo = 0.95;
    r.ci68_hi = 1.01;
    r.ci95_lo = 0.9;
    r.ci95_hi = 1.05;
    r.state = DaemonState::kConverging;
    r.epoch = 2;
    r.observations = 137;
    r.frame_id = 510;
    r.t_ns = 1'700'000'000'123'456'789;
    r.updated_mono_ns = 5'000'000'000;
    return r;
}

TEST(Protocol, Version) {
    std::string out;
    appendVersion(out, "0.1.0");
    EXPECT_EQ(out,
              "{\"class\":\"VERSION\",\"release\":\"0.1.0\",\"proto_major\":1,"
              "\"proto_minor\":5}\n");
}

// Three objects, one of each state: what OBJECTS and the field log's OBJECT
// lines are tested with.
ObjectsSnapshot sampleObjects() {
    ObjectsSnapshot s;
    s.epoch = 2;
    s.frame_id = 450;
    s.model = core::EstimatorModel::kObject;
    ObjectReport used;
    used.id = 3;
    used.setClassName("chair");
    used.state = core::ObjectState::kUsed;
    used.anchor = {0.4123456789, -0.125, 2.5};
    used.anchor_rel_sigma = 0.0431;
    used.detections = 12;
    used.views = 10;
    used.views_used = 9;
    used.first_frame = 120;
    used.last_frame = 450;
    used.local_estimate = 1.2101;
    used.has_height = true;
    used.height_m = 0.87;
    used.height_ci95_lo_m = 0.82;
    used.height_ci95_hi_m = 0.93;
    ObjectReport anchored;
    anchored.id = 5;
    anchored.setClassName("potted plant");
    anchored.state = core::ObjectState::kAnchored;
    anchored.anchor = {1, 2, 3};
    anchored.anchor_rel_sigma = 0.25;
    anchored.detections = 3;
    anchored.views = 3;
    anchored.first_frame = 300;
    anchored.last_frame = 440;
    ObjectReport tentative;
    tentative.id = 7;
    tentative.setClassName("cup \"a\"");
    tentative.anchor = {9, 9, 9};  // not valid while tentative: not written
    tentative.anchor_rel_sigma = 0.5;
    tentative.detections = 1;
    tentative.views = 1;
    tentative.first_frame = 450;
    tentative.last_frame = 450;
    s.objects = {used, anchored, tentative};
    return s;
}

TEST(Protocol, ScaleWithAScale) {
    std::string out;
    appendScale(out, sampleReport(), 5'410'000'000);
    const json j = parseLine(out);
    EXPECT_EQ(j["class"], "SCALE");
    EXPECT_EQ(j["scale"].get<double>(), 0.9763412345678);  // shortest exact form
    EXPECT_EQ(j["mean"].get<double>(), 0.981);
    EXPECT_EQ(j["ci68"], json::array({0.95, 1.01}));
    EXPECT_EQ(j["ci95"], json::array({0.9, 1.05}));
    EXPECT_EQ(j["state"], "converging");
    EXPECT_EQ(j["epoch"], 2);
    EXPECT_EQ(j["observations"], 137);
    EXPECT_EQ(j["frame_id"], 510);
    EXPECT_EQ(j["t_ns"].get<std::int64_t>(), 1'700'000'000'123'456'789);
    EXPECT_NEAR(j["time"].get<double>(), 1'700'000'000.123456789, 1e-6);
    EXPECT_NEAR(j["age_s"].get<double>(), 0.41, 1e-12);
    EXPECT_FALSE(j.contains("fault"));
}

TEST(Protocol, ScaleWithoutAScaleHasNulls) {
    ScaleReport r;
    r.fault = "log: No space left on device";
    std::string out;
    appendScale(out, r, 123);
    const json j = parseLine(out);
    EXPECT_TRUE(j["scale"].is_null());
    EXPECT_TRUE(j["mean"].is_null());
    EXPECT_TRUE(j["ci68"].is_null());
    EXPECT_TRUE(j["ci95"].is_null());
    EXPECT_TRUE(j["age_s"].is_null());
    EXPECT_EQ(j["state"], "initialising");
    EXPECT_EQ(j["frame_id"], -1);
    EXPECT_EQ(j["fault"], "log: No space left on device");
    EXPECT_FALSE(j.contains("previous")) << out;
}

// A new map: no scale of its own yet, the previous map's last one beside it.
TEST(Protocol, ScaleOfANewMapCarriesThePreviousMapsScale) {
    ScaleReport r;
    r.state = DaemonState::kTracking;
    r.epoch = 3;
    r.frame_id = 1204;
    r.previous = {true, 2, 0.971, 0.95, 0.99, 52, 1180};
    std::string out;
    appendScale(out, r, 123);
    const json j = parseLine(out);
    EXPECT_TRUE(j["scale"].is_null());
    EXPECT_EQ(j["previous"], json::parse(R"({"epoch":2,"scale":0.971,"ci95":[0.95,0.99],
        "observations":52,"frame_id":1180})"))
        << out;
}

TEST(Protocol, StatusHasEveryMember) {
    PipelineStatus s;
    s.source = "replay:/data/rk";
    s.frame_id = 99;
    s.frames_total = 1000;
    s.fps = 29.5;
    s.frames_captured = 101;
    s.frames_tracked = 100;
    s.frames_dropped = 1;
    s.detections_run = 10;
    s.detections_skipped = 2;
    s.detector_latency_ms_last = 40.5;
    s.detector_latency_ms_mean = 41;
    s.detector_latency_ms_max = 80;
    s.tracking_ms_mean = 12.5;
    s.features_in_map = 40;
    s.features_tracked = 25;
    s.scale_updates = 7;
    s.epoch = 1;
    s.uptime_s = 3.5;
    LogStatus log;
    log.state = LogStatus::State::kFault;
    log.lines_written = 5;
    log.lines_dropped = 1;
    log.bytes_written = 500;
    log.error = "No space left on device";
    std::string out;
    ClientCounts clients{3, 16, 5, 1, 1};
    clients.watchers = 2;
    clients.reserved = 2;
    clients.timed_out = 4;
    clients.evicted = 6;
    appendStatus(out, s, log, clients);
    const json j = parseLine(out);
    EXPECT_EQ(j["class"], "STATUS");
    EXPECT_EQ(j["source"], "replay:/data/rk");
    EXPECT_EQ(j["uptime_s"], 3.5);
    EXPECT_EQ(j["fps"], 29.5);
    EXPECT_EQ(j["frame_id"], 99);
    EXPECT_EQ(j["frames_total"], 1000);
    EXPECT_EQ(j["source_finished"], false);
    EXPECT_EQ(j["frames"], json::parse(R"({"captured":101,"tracked":100,"dropped":1})"));
    EXPECT_EQ(j["detector"], json::parse(R"({"runs":10,"skipped":2,
        "latency_ms":{"last":40.5,"mean":41,"max":80}})"));
    EXPECT_EQ(j["tracking_ms_mean"], 12.5);
    EXPECT_EQ(j["features"], json::parse(R"({"in_map":40,"tracked":25})"));
    EXPECT_EQ(j["scale_updates"], 7);
    EXPECT_EQ(j["epoch"], 1);
    EXPECT_EQ(j["clients"], json::parse(R"({"connected":3,"max":16,"accepted":5,"rejected":1,
        "detached":1,"watchers":2,"reserved":2,"timed_out":4,"evicted":6})"));
    EXPECT_EQ(j["log"], json::parse(R"({"state":"fault","lines":5,"dropped":1,"bytes":500,
        "error":"No space left on device"})"));

    // Without an IMU and before the first map: no imu, no vertical.
    EXPECT_FALSE(j.contains("imu")) << out;
    EXPECT_FALSE(j.contains("gravity_down_C")) << out;
    EXPECT_FALSE(j.contains("gravity_source")) << out;
    s.gravity_source = "assumed level camera (down = +y)";
    s.gravity_down_C = std::array<double, 3>{0, 1, 0};
    s.imu.configured = true;
    s.imu.device = "mpu6050";
    s.imu.mode = "sysfs";
    s.imu.error = "no IIO device named 'mpu6050'";
    out.clear();
    appendStatus(out, s, log, ClientCounts{});
    const json with_imu = parseLine(out);
    EXPECT_EQ(with_imu["gravity_down_C"], json::parse("[0,1,0]"));
    EXPECT_EQ(with_imu["imu"], json::parse(R"({"device":"mpu6050","mode":"sysfs","samples":0,
        "errors":0,"error":"no IIO device named 'mpu6050'"})"));
    EXPECT_FALSE(with_imu.contains("gyro")) << out;  // no gyroscope feeds the prior
    s.gyro.present = true;
    s.gyro.source = "iio:device0 [lsm6dsl]";
    s.gyro.frames = 5120;
    s.gyro.bias_C_radps = {0.0031, -0.0102, 0.0007};
    out.clear();
    appendStatus(out, s, log, ClientCounts{});
    EXPECT_EQ(parseLine(out)["gyro"], json::parse(R"({"source":"iio:device0 [lsm6dsl]",
        "frames":5120,"bias_C_radps":[0.0031,-0.0102,0.0007]})"));

    out.clear();
    appendStatus(out, PipelineStatus{}, LogStatus{}, ClientCounts{});
    const json empty = parseLine(out);
    EXPECT_EQ(empty["log"], json::parse(R"({"state":"off","lines":0,"dropped":0,"bytes":0})"));
    // Every stage is always present, zero before its first sample.
    ASSERT_TRUE(empty["timing"].is_object()) << out;
    EXPECT_EQ(empty["timing"].size(), 11U);
    for (const auto& [name, stage] : empty["timing"].items()) {
        EXPECT_EQ(stage, json::parse(R"({"samples":0,"last_ms":0,"mean_ms":0,"max_ms":0})"))
            << name;
    }
}

// STATUS.timing (proto_minor 2): one object per stage with its sample count
// and last / mean / max milliseconds (4 significant digits).
TEST(Protocol, StatusTiming) {
    PipelineStatus s;
    StageTiming predict;
    predict.add(0.25);
    predict.add(0.75);  // mean of the first samples is exact
    s.timing.predict = predict;
    s.timing.search.add(0.0123456);
    s.timing.match.add(1.5);
    s.timing.update.add(0.875);
    s.timing.map.add(2.0);
    s.timing.tracking.add(4.625);
    s.timing.detect_pre.add(0.5);
    s.timing.detect_forward.add(38.25);
    s.timing.detect_post.add(0.0155);
    s.timing.scale_update.add(1.25);
    s.timing.scale_publish.add(0.0625);
    std::string out;
    appendStatus(out, s, LogStatus{}, ClientCounts{});
    const json j = parseLine(out);
    const json& t = j["timing"];
    ASSERT_TRUE(t.is_object()) << out;
    EXPECT_EQ(t["predict"], json::parse(R"({"samples":2,"last_ms":0.75,"mean_ms":0.5,
        "max_ms":0.75})"));
    EXPECT_EQ(t["search"]["last_ms"].get<double>(), 0.01235);  // 4 significant digits
    const std::pair<const char*, double> expected[] = {
        {"match", 1.5},          {"update", 0.875},      {"map", 2.0},
        {"tracking", 4.625},     {"detect_pre", 0.5},    {"detect_forward", 38.25},
        {"detect_post", 0.0155}, {"scale_update", 1.25}, {"scale_publish", 0.0625},
    };
    for (const auto& [name, ms] : expected) {
        const json& stage = t[name];
        ASSERT_TRUE(stage.is_object()) << name << ": " << out;
        EXPECT_EQ(stage.size(), 4U) << name;
        EXPECT_TRUE(stage["samples"].is_number_unsigned()) << name;
        EXPECT_EQ(stage["samples"], 1) << name;
        for (const char* field : {"last_ms", "mean_ms", "max_ms"}) {
            ASSERT_TRUE(stage[field].is_number()) << name << "." << field;
            EXPECT_EQ(stage[field].get<double>(), ms) << name << "." << field;
        }
    }
    EXPECT_EQ(t.size(), 11U);
}

// STATUS.window_ba (proto_minor 5): only with tracker.window_ba on; what the
// window estimates by name, the camera it used, and its latest optimisation
// ("last": null before the first).
TEST(Protocol, StatusWindowBa) {
    PipelineStatus s;
    std::string out;
    appendStatus(out, s, LogStatus{}, ClientCounts{});
    EXPECT_FALSE(parseLine(out).contains("window_ba")) << out;

    s.window_ba.present = true;
    s.window_ba.k1 = -0.25;
    out.clear();
    appendStatus(out, s, LogStatus{}, ClientCounts{});
    EXPECT_EQ(parseLine(out)["window_ba"], json::parse(R"({"optimisations":0,"estimated":[],
        "rolling_shutter_s":0,"focal_scale":1,"k1":-0.25,"last":null})"))
        << out;

    WindowBaStatus& w = s.window_ba;
    w.rolling_shutter_estimated = true;
    w.k1_estimated = true;
    w.optimisations = 14;
    w.frame_id = 517;
    w.epoch = 2;
    w.keyframes = 67;
    w.points = 412;
    w.observations = 5120;
    w.rms_px = 0.75;
    w.scale = 1.0125;
    w.rolling_shutter_s = 0.0227;
    w.focal_scale = 1;
    w.k1 = -0.125;
    out.clear();
    appendStatus(out, s, LogStatus{}, ClientCounts{});
    const json j = parseLine(out);
    EXPECT_EQ(j["window_ba"], json::parse(R"({"optimisations":14,
        "estimated":["rolling_shutter_s","k1"],"rolling_shutter_s":0.0227,"focal_scale":1,
        "k1":-0.125,"last":{"frame_id":517,"epoch":2,"keyframes":67,"points":412,
        "observations":5120,"rms_px":0.75,"scale":1.0125}})"))
        << out;
    // Additive: the members before and after it are where they were.
    EXPECT_TRUE(j["timing"].is_object());
    EXPECT_TRUE(j["clients"].is_object());
    EXPECT_TRUE(j["log"].is_object());
    w.focal_estimated = true;
    out.clear();
    appendStatus(out, s, LogStatus{}, ClientCounts{});
    EXPECT_EQ(parseLine(out)["window_ba"]["estimated"],
              json::parse(R"(["rolling_shutter_s","focal_scale","k1"])"));
}

// The mean follows the recent samples: exact over the first 100, then an
// exponential average with weight 1/100; the max is kept since the start.
TEST(Protocol, StageTimingMeanAndMax) {
    StageTiming t;
    for (int i = 0; i < 100; ++i) {
        t.add(i < 50 ? 1.0 : 3.0);
    }
    EXPECT_EQ(t.samples, 100U);
    EXPECT_DOUBLE_EQ(t.mean_ms, 2.0);
    EXPECT_DOUBLE_EQ(t.max_ms, 3.0);
    t.add(102.0);
    EXPECT_DOUBLE_EQ(t.mean_ms, 3.0);  // 2 + (102 - 2) / 100
    EXPECT_DOUBLE_EQ(t.last_ms, 102.0);
    for (int i = 0; i < 2000; ++i) {
        t.add(1.0);
    }
    EXPECT_NEAR(t.mean_ms, 1.0, 1e-6);  // the spike has faded from the mean...
    EXPECT_DOUBLE_EQ(t.max_ms, 102.0);  // ...not from the max
    EXPECT_EQ(t.samples, 2101U);
}

// OBJECTS (proto_minor 3) with the paper model: no table, the model says so.
TEST(Protocol, ObjectsOfThePaperModel) {
    std::string out;
    appendObjects(out, ObjectsSnapshot{});
    EXPECT_EQ(out,
              "{\"class\":\"OBJECTS\",\"epoch\":0,\"frame_id\":-1,\"model\":\"paper\","
              "\"objects\":[]}\n");
}

// OBJECTS: every member of every object; anchors while tentative, local
// estimates of 0 and heights of unused objects are null; numbers with 7
// significant digits; names escaped.
TEST(Protocol, ObjectsHaveEveryMember) {
    std::string out;
    appendObjects(out, sampleObjects());
    const json j = parseLine(out);
    EXPECT_EQ(j["class"], "OBJECTS");
    EXPECT_EQ(j["epoch"], 2);
    EXPECT_EQ(j["frame_id"], 450);
    EXPECT_EQ(j["model"], "object");
    ASSERT_TRUE(j["objects"].is_array()) << out;
    ASSERT_EQ(j["objects"].size(), 3U) << out;
    EXPECT_EQ(j["objects"][0], json::parse(R"({"id":3,"class":"chair","state":"used",
        "anchor":[0.4123457,-0.125,2.5],"anchor_rel_sigma":0.0431,"detections":12,"views":10,
        "views_used":9,"first_frame":120,"last_frame":450,"local_estimate":1.2101,
        "height_m":0.87,"height_ci95_m":[0.82,0.93]})"));
    EXPECT_EQ(j["objects"][1], json::parse(R"({"id":5,"class":"potted plant","state":"anchored",
        "anchor":[1,2,3],"anchor_rel_sigma":0.25,"detections":3,"views":3,"views_used":0,
        "first_frame":300,"last_frame":440,"local_estimate":null,"height_m":null,
        "height_ci95_m":null})"));
    EXPECT_EQ(j["objects"][2], json::parse(R"({"id":7,"class":"cup \"a\"","state":"tentative",
        "anchor":null,"anchor_rel_sigma":null,"detections":1,"views":1,"views_used":0,
        "first_frame":450,"last_frame":450,"local_estimate":null,"height_m":null,
        "height_ci95_m":null})"));
    // The members in their documented order.
    EXPECT_NE(out.find(R"("objects":[{"id":3,"class":"chair","state":"used","anchor":[)"),
              std::string::npos)
        << out;
}

// Class names live in fixed storage: a long one is cut to 31 bytes, never in
// the middle of a UTF-8 character.
TEST(Protocol, ObjectClassNamesAreCut) {
    ObjectReport o;
    o.setClassName("chair");
    EXPECT_EQ(o.className(), "chair");
    const std::string longer(40, 'x');
    o.setClassName(longer);
    EXPECT_EQ(o.className(), longer.substr(0, kObjectClassChars - 1));
    // 30 ASCII bytes, then a 2-byte character that would end at byte 32.
    o.setClassName(std::string(30, 'a') + "\xC3\xA9z");
    EXPECT_EQ(o.className(), std::string(30, 'a'));
    o.setClassName(std::string(29, 'a') + "\xC3\xA9z");
    EXPECT_EQ(o.className(), std::string(29, 'a') + "\xC3\xA9");
    o.setClassName("");
    EXPECT_EQ(o.className(), "");
}

// The hub keeps the table of the latest update within the size it was given,
// and empties it when a report of another epoch (a new map) is published.
TEST(Protocol, HubObjectTable) {
    ReportHub hub(4);
    ObjectsSnapshot got;
    hub.objects(got);
    EXPECT_EQ(got.model, core::EstimatorModel::kPaper);
    EXPECT_EQ(got.frame_id, -1);
    EXPECT_TRUE(got.objects.empty());

    hub.setObjectModel(core::EstimatorModel::kObject, 2);
    ObjectsSnapshot three = sampleObjects();
    hub.objects(got);
    EXPECT_EQ(got.model, core::EstimatorModel::kObject);
    ScaleReport r;
    r.epoch = 2;
    hub.publishScale(r);
    hub.publishObjects(three);  // three entries, room for two
    hub.objects(got);
    EXPECT_EQ(got.epoch, 2U);
    EXPECT_EQ(got.frame_id, 450);
    ASSERT_EQ(got.objects.size(), 2U);
    EXPECT_EQ(got.objects[0].id, 3);
    EXPECT_EQ(got.objects[1].className(), "potted plant");

    r.frame_id = 460;
    hub.publishScale(r);  // same epoch: the table stays
    hub.objects(got);
    EXPECT_EQ(got.objects.size(), 2U);
    r.epoch = 3;
    hub.publishScale(r);  // a new map
    hub.objects(got);
    EXPECT_EQ(got.epoch, 3U);
    EXPECT_EQ(got.frame_id, -1);
    EXPECT_TRUE(got.objects.empty());
    EXPECT_EQ(got.model, core::EstimatorModel::kObject);
}

TEST(Protocol, Posterior) {
    std::string out;
    appendPosterior(out, PosteriorSnapshot{});
    json j = parseLine(out);
    EXPECT_EQ(j, json::parse(R"({"class":"POSTERIOR","epoch":0,"frame_id":-1,"observations":0,
        "d":[],"log_p":[]})"));

    PosteriorSnapshot p;
    p.epoch = 3;
    p.frame_id = 77;
    p.observations = 4;
    p.d = {0.5, 1.0, 1.5};
    p.log_p = {-2.25, 0, -std::numeric_limits<double>::infinity()};
    out.clear();
    appendPosterior(out, p);
    j = parseLine(out);
    EXPECT_EQ(j["d"], json::array({0.5, 1.0, 1.5}));
    EXPECT_EQ(j["log_p"], json::parse("[-2.25,0,null]"));  // zero density: null
    EXPECT_EQ(j["epoch"], 3);
    EXPECT_EQ(j["frame_id"], 77);
    EXPECT_EQ(j["observations"], 4);
}

TEST(Protocol, WatchAckError) {
    std::string out;
    appendWatch(out, true, false);
    appendWatch(out, false, false);
    appendAck(out, "set_gravity");
    appendError(out, "bad", "");
    appendError(out, "worse", "watch");
    EXPECT_EQ(out,
              "{\"class\":\"WATCH\",\"enable\":true,\"pose\":false}\n"
              "{\"class\":\"WATCH\",\"enable\":false,\"pose\":false}\n"
              "{\"class\":\"ACK\",\"cmd\":\"set_gravity\"}\n"
              "{\"class\":\"ERROR\",\"message\":\"bad\"}\n"
              "{\"class\":\"ERROR\",\"message\":\"worse\",\"cmd\":\"watch\"}\n");
}

// An unknown command is echoed once, in "cmd", cut to 64 bytes (whole UTF-8
// characters) and marked truncated: a 900 KB command gets a short line.
TEST(Protocol, ErrorEchoesTheCommandOnceAndAtMost64Bytes) {
    const std::string name = "fly" + std::string(900'000, 'x');
    const Request r = parseRequest(R"({"cmd":")" + name + R"("})");
    ASSERT_EQ(r.command, Command::kInvalid);
    EXPECT_EQ(
        r.error,
        "unknown command (known: poll, watch, status, posterior, objects, pose, set_gravity)");
    std::string out;
    appendError(out, r.error, r.cmd);
    EXPECT_LT(out.size(), 250U) << out.substr(0, 300);
    json j = parseLine(out);
    EXPECT_EQ(j["cmd"], name.substr(0, kMaxEchoBytes));
    EXPECT_EQ(j["truncated"], true);
    ASSERT_NE(out.find("flyx"), std::string::npos);
    EXPECT_EQ(out.find("flyx"), out.rfind("flyx")) << "the command appears once: " << out;

    // 64 bytes exactly: not cut, no "truncated".
    out.clear();
    appendError(out, "m", std::string(64, 'a'));
    j = parseLine(out);
    EXPECT_EQ(j["cmd"], std::string(64, 'a'));
    EXPECT_FALSE(j.contains("truncated")) << out;
    // A two-byte character across byte 64 is left out whole: 63 bytes remain.
    std::string accents = "a";
    for (int i = 0; i < 40; ++i) {
        accents += "\xC3\xA9";  // é
    }
    out.clear();
    appendError(out, "m", accents);
    j = parseLine(out);
    EXPECT_EQ(j["cmd"], accents.substr(0, 63));
    EXPECT_EQ(j["truncated"], true);
}

// A NUL byte does not end the request: nlohmann::json would stop there and
// answer `{"cmd":"poll"}\0garbage` as a poll.
TEST(Protocol, NulByteAnywhereIsAnError) {
    using namespace std::string_literals;
    for (const std::string& line : {"{\"cmd\":\"poll\"}\0garbage"s, "{\"cmd\":\"po\0ll\"}"s,
                                    "\0{\"cmd\":\"poll\"}"s, "{\"cmd\":\"poll\"}\0"s, "\0"s}) {
        const Request r = parseRequest(line);
        EXPECT_EQ(r.command, Command::kInvalid) << line.size();
        EXPECT_EQ(r.error, "request contains a NUL byte") << line.size();
        EXPECT_TRUE(r.cmd.empty());
    }
}

// A number too large for a double is valid JSON that nlohmann::json refuses
// ("number overflow"): the member's own check answers, not "not valid JSON".
TEST(Protocol, NumbersBeyondADoubleGetTheMembersMessage) {
    const char* gravity = "\"down\" must be an array of 3 finite numbers, not all zero";
    for (const std::string& down : {std::string("[1e400,0,1]"), std::string("[0,-1.5E+999,1]"),
                                    "[0,0,1" + std::string(400, '0') + "]"}) {
        const Request r = parseRequest(R"({"cmd":"set_gravity","down":)" + down + "}");
        EXPECT_EQ(r.command, Command::kInvalid) << down;
        EXPECT_EQ(r.error, gravity) << down;
        EXPECT_EQ(r.cmd, "set_gravity") << down;
    }
    // The member's position in the object does not matter.
    Request r = parseRequest(R"({"down":[1e400,0,1],"cmd":"set_gravity"})");
    EXPECT_EQ(r.error, gravity);
    // Other members: as if null.
    r = parseRequest(R"({"cmd":"watch","enable":1e999})");
    EXPECT_EQ(r.error, "\"enable\" must be true or false");
    r = parseRequest(R"({"cmd":"poll","extra":[1e999,{"a":-2e400}]})");
    EXPECT_EQ(r.command, Command::kPoll) << r.error;
    // Inside strings nothing changes, escaped quotes included.
    r = parseRequest(R"({"cmd":"1e999"})");
    EXPECT_EQ(r.cmd, "1e999");
    r = parseRequest(R"({"cmd":"poll","note":"a \"1e999\" b"})");
    EXPECT_EQ(r.command, Command::kPoll) << r.error;
    // An underflow is 0, as before; invalid JSON stays invalid.
    r = parseRequest(R"({"cmd":"set_gravity","down":[1e-400,0,2]})");
    ASSERT_EQ(r.command, Command::kSetGravity) << r.error;
    EXPECT_EQ(r.down[2], 1.0);
    for (const char* bad :
         {R"({"cmd":"poll",1e999})", R"({"cmd":"poll","x":+1e999})", R"({"cmd":"poll","x":01e999})",
          R"({"cmd":"poll","x":-})", R"({"cmd":"poll","x":1e999)"}) {
        EXPECT_EQ(parseRequest(bad).error, "request is not valid JSON") << bad;
    }
}

// --- POSE (proto_minor 4) -------------------------------------------------------

// A pose of epoch 2 (sampleReport's) at p_map = (0, 0, 2) with a diagonal
// position covariance.
PoseReport samplePose() {
    PoseReport p;
    p.epoch = 2;
    p.frame_id = 512;
    p.t_ns = 1'700'000'000'190'000'000;
    p.position_map = {0, 0, 2};
    p.velocity_map = {0.5, -0.25, 0};
    p.orientation_wxyz = {1, 0, 0, 0};
    p.position_cov_map = {0.01, 0, 0, 0, 0.02, 0, 0, 0, 0.03};
    p.attitude_cov_rad2 = {1e-4, 0, 0, 0, 2e-4, 0, 0, 0, 3e-4};
    return p;
}

std::vector<double> matrix(const json& m) {
    std::vector<double> out;
    EXPECT_TRUE(m.is_array() && m.size() == 3) << m;
    for (const json& row : m) {
        EXPECT_TRUE(row.is_array() && row.size() == 3) << m;
        for (const json& v : row) {
            out.push_back(v.get<double>());
        }
    }
    return out;
}

TEST(Protocol, PoseBeforeTheFirstPoseIsAllNull) {
    std::string out;
    appendPose(out, PoseReport{}, sampleReport());
    const json j = parseLine(out);
    EXPECT_EQ(j["class"], "POSE");
    EXPECT_EQ(j["frame_id"], -1);
    EXPECT_EQ(j["t_ns"], 0);
    EXPECT_EQ(j["state"], "converging");
    for (const char* k :
         {"scale", "scale_sigma", "position", "velocity", "position_cov", "orientation",
          "attitude_cov", "position_map", "velocity_map", "position_map_cov"}) {
        ASSERT_TRUE(j.contains(k)) << k;
        EXPECT_TRUE(j[k].is_null()) << k << ": " << j[k];
    }
}

TEST(Protocol, PoseWithoutAScaleHasOnlyItsMapPart) {
    std::string out;
    ScaleReport none;  // initialising, no scale
    none.epoch = 2;
    none.state = DaemonState::kTracking;
    appendPose(out, samplePose(), none);
    const json j = parseLine(out);
    EXPECT_EQ(j["epoch"], 2);
    EXPECT_EQ(j["frame_id"], 512);
    EXPECT_EQ(j["t_ns"], 1'700'000'000'190'000'000);
    EXPECT_DOUBLE_EQ(j["time"].get<double>(), 1700000000.19);
    EXPECT_EQ(j["state"], "tracking");
    for (const char* k : {"scale", "scale_sigma", "position", "velocity", "position_cov"}) {
        EXPECT_TRUE(j[k].is_null()) << k << ": " << j[k];
    }
    EXPECT_EQ(j["position_map"], json::parse("[0,0,2]"));
    EXPECT_EQ(j["velocity_map"], json::parse("[0.5,-0.25,0]"));
    EXPECT_EQ(j["orientation"], json::parse("[1,0,0,0]"));
    EXPECT_EQ(matrix(j["position_map_cov"]),
              (std::vector<double>{0.01, 0, 0, 0, 0.02, 0, 0, 0, 0.03}));
    EXPECT_EQ(matrix(j["attitude_cov"]), (std::vector<double>{1e-4, 0, 0, 0, 2e-4, 0, 0, 0, 3e-4}));

    // A scale of another epoch (the map before a loss) is not this map's.
    out.clear();
    ScaleReport old = sampleReport();
    old.epoch = 1;
    appendPose(out, samplePose(), old);
    const json k = parseLine(out);
    EXPECT_TRUE(k["scale"].is_null());
    EXPECT_TRUE(k["position"].is_null());
    EXPECT_FALSE(k["position_map"].is_null());
}

// p_map = (0, 0, 2) units, d = 1.5 m/unit, ci68 = [1.4, 1.6] (sigma_d 0.1):
// position (0, 0, 3) m; variance along z = d^2 0.03 + sigma_d^2 2^2 = 0.1075
// m^2, across it only d^2 Sigma (the scale moves the camera along p).
TEST(Protocol, PoseCovarianceIncludesTheScale) {
    ScaleReport s = sampleReport();
    s.scale = 1.5;
    s.ci68_lo = 1.4;
    s.ci68_hi = 1.6;
    std::string out;
    appendPose(out, samplePose(), s);
    const json j = parseLine(out);
    EXPECT_DOUBLE_EQ(j["scale"].get<double>(), 1.5);
    EXPECT_NEAR(j["scale_sigma"].get<double>(), 0.1, 1e-7);
    EXPECT_EQ(j["position"], json::parse("[0,0,3]"));
    EXPECT_EQ(j["velocity"], json::parse("[0.75,-0.375,0]"));
    const std::vector<double> c = matrix(j["position_cov"]);
    EXPECT_NEAR(c[0], 2.25 * 0.01, 1e-9);
    EXPECT_NEAR(c[4], 2.25 * 0.02, 1e-9);
    EXPECT_NEAR(c[8], 2.25 * 0.03 + 0.01 * 4, 1e-9);
    for (int i : {1, 2, 3, 5, 6, 7}) {
        EXPECT_EQ(c[static_cast<std::size_t>(i)], 0) << i;
    }
    // Off the axes the scale term couples them: p = (1, 0, 2) gives
    // sigma_d^2 * 1 * 2 between x and z.
    PoseReport p = samplePose();
    p.position_map = {1, 0, 2};
    const MetricPose m = metricPose(p, s);
    ASSERT_TRUE(m.has_scale);
    EXPECT_NEAR(m.position_cov_m2[2], 0.02, 1e-12);
    EXPECT_NEAR(m.position_cov_m2[6], 0.02, 1e-12);
    EXPECT_NEAR(m.position_cov_m2[0], 2.25 * 0.01 + 0.01, 1e-12);
    // Never NaN: a non-finite covariance entry is written as null.
    p.position_cov_map[4] = std::nan("");
    out.clear();
    appendPose(out, p, s);
    EXPECT_TRUE(parseLine(out)["position_cov"][1][1].is_null()) << out;
}

// A scale known too loosely to put poses in metres (the pipeline sets
// wide_for_poses from estimator.pose_max_rel_width95): the metric members are
// null, the pose in map units and the SCALE's numbers stay.
TEST(Protocol, AScaleTooLooseForPosesLeavesTheMetricMembersNull) {
    ScaleReport s = sampleReport();
    ASSERT_TRUE(metricPose(samplePose(), s).has_scale);
    s.wide_for_poses = true;
    EXPECT_FALSE(metricPose(samplePose(), s).has_scale);
    std::string out;
    appendPose(out, samplePose(), s);
    const json j = parseLine(out);
    for (const char* member : {"scale", "scale_sigma", "position", "velocity", "position_cov"}) {
        EXPECT_TRUE(j[member].is_null()) << member << ": " << out;
    }
    EXPECT_FALSE(j["position_map"].is_null()) << out;
    out.clear();
    appendScale(out, s, 0);
    EXPECT_DOUBLE_EQ(parseLine(out)["scale"].get<double>(), s.scale);
    // The rule: hi - lo at most pose_max_rel_width95 (1 by default) times the scale.
    const PipelineConfig defaults = defaultPipelineConfig();
    EXPECT_FALSE(wideForPoses(defaults, 1.0, 0.6, 1.6));
    EXPECT_TRUE(wideForPoses(defaults, 1.0, 0.5, 1.6));
    EXPECT_TRUE(wideForPoses(defaults, 0.0, 0.0, 0.0));
    EXPECT_TRUE(wideForPoses(defaults, std::nan(""), 0.5, 1.5));
}

// G from the tracker's world W (the first camera: x right, y down, z
// forward): a level first camera gives x_G = its optical axis, y_G = its
// left (-x_W), z_G = up (-y_W).
TEST(Protocol, PoseFrameIsGravityAlignedAlongTheFirstOpticalAxis) {
    const Eigen::Matrix3d level = gravityAlignedFromMap(Eigen::Vector3d(0, -1, 0));
    Eigen::Matrix3d expected;
    expected << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    EXPECT_TRUE(level.isApprox(expected, 1e-12)) << level;
    // A first camera pitched down by 30 degrees: up in its frame is
    // (0, -cos 30, -sin 30)... its optical axis projected onto the
    // horizontal is still x_G, and G is a rotation.
    const double a = 30.0 * M_PI / 180.0;
    const Eigen::Vector3d up(0, -std::cos(a), -std::sin(a));
    const Eigen::Matrix3d pitched = gravityAlignedFromMap(3 * up);
    EXPECT_TRUE((pitched * pitched.transpose()).isIdentity(1e-12));
    EXPECT_NEAR(pitched.determinant(), 1, 1e-12);
    EXPECT_TRUE((pitched * up).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
    const Eigen::Vector3d fwd = pitched * Eigen::Vector3d::UnitZ();
    EXPECT_NEAR(fwd.y(), 0, 1e-12);
    EXPECT_GT(fwd.x(), 0);
    EXPECT_NEAR(std::atan2(fwd.z(), fwd.x()), -a, 1e-12);  // looks 30 degrees down
    // Looking straight down: x_G is the image's up direction (-y_W).
    const Eigen::Matrix3d down = gravityAlignedFromMap(Eigen::Vector3d(0, 0, -1));
    EXPECT_TRUE((down * -Eigen::Vector3d::UnitY()).isApprox(Eigen::Vector3d::UnitX(), 1e-12));
    EXPECT_TRUE((down * Eigen::Vector3d(0, 0, -1)).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
}

// makePoseReport: position, velocity, orientation and both covariances in G.
TEST(Protocol, PoseReportFromTheFiltersPose) {
    core::CameraPose pose;
    // The camera turned 90 degrees left (about up = -y_W) and moved 2 units
    // forward and 1 up.
    pose.R_CtoW = Eigen::AngleAxis<core::Scalar>(core::Scalar(-M_PI / 2), core::Vec3::UnitY())
                      .toRotationMatrix();
    pose.p_CinW = core::Vec3(0, -1, 2);
    Eigen::Matrix<core::Scalar, 6, 6> cov = Eigen::Matrix<core::Scalar, 6, 6>::Zero();
    cov.diagonal() << 1, 2, 3, 4, 5, 6;  // x_W, y_W, z_W; delta about x_C, y_C, z_C
    const PoseReport r =
        makePoseReport(pose, core::Vec3(1, 0, 0), cov, core::Vec3(0, -1, 0), 7, 99, 123);
    EXPECT_EQ(r.epoch, 7U);
    EXPECT_EQ(r.frame_id, 99);
    EXPECT_EQ(r.t_ns, 123);
    const auto near3 = [](const std::array<double, 3>& v, double x, double y, double z) {
        return std::abs(v[0] - x) < 1e-6 && std::abs(v[1] - y) < 1e-6 && std::abs(v[2] - z) < 1e-6;
    };
    EXPECT_TRUE(near3(r.position_map, 2, 0, 1));   // forward 2, up 1
    EXPECT_TRUE(near3(r.velocity_map, 0, -1, 0));  // x_W is right: -y_G
    // The optical axis now points along +y_G (left of the first one).
    const Eigen::Quaterniond q(r.orientation_wxyz[0], r.orientation_wxyz[1], r.orientation_wxyz[2],
                               r.orientation_wxyz[3]);
    EXPECT_NEAR(q.norm(), 1, 1e-9);
    EXPECT_GE(q.w(), 0);
    EXPECT_TRUE((q * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitY(), 1e-6));
    EXPECT_TRUE((q * Eigen::Vector3d::UnitY()).isApprox(-Eigen::Vector3d::UnitZ(), 1e-6));
    // Position covariance: x_G = z_W, y_G = -x_W, z_G = -y_W.
    EXPECT_NEAR(r.position_cov_map[0], 3, 1e-6);
    EXPECT_NEAR(r.position_cov_map[4], 1, 1e-6);
    EXPECT_NEAR(r.position_cov_map[8], 2, 1e-6);
    // Attitude: after the left turn the camera's x (right) is +x_G, its y
    // (down) -z_G, its z (optical axis) +y_G.
    EXPECT_NEAR(r.attitude_cov_rad2[0], 4, 1e-6);
    EXPECT_NEAR(r.attitude_cov_rad2[4], 6, 1e-6);
    EXPECT_NEAR(r.attitude_cov_rad2[8], 5, 1e-6);
    for (int i : {1, 2, 3, 5, 6, 7}) {
        EXPECT_NEAR(r.attitude_cov_rad2[static_cast<std::size_t>(i)], 0, 1e-6) << i;
    }
}

TEST(Protocol, StringsAreEscapedAndValidUtf8) {
    std::string out;
    appendJsonString(out,
                     "a\"b\\c\nd\x01\x7f"
                     "\xC3\xA9"
                     "\xFF"
                     "z");
    EXPECT_EQ(out, "\"a\\\"b\\\\c\\nd\\u0001\\u007f\xC3\xA9\xEF\xBF\xBDz\"");
    const json j = json::parse(out, nullptr, false);
    ASSERT_FALSE(j.is_discarded());
    EXPECT_EQ(j.get<std::string>(), "a\"b\\c\nd\x01\x7f\xC3\xA9\xEF\xBF\xBDz");
    out.clear();
    appendJsonString(out, "\xE2\x82");  // truncated sequence
    EXPECT_EQ(out, "\"\xEF\xBF\xBD\xEF\xBF\xBD\"");
}

TEST(Protocol, NumbersReadBackExactly) {
    for (const double v : {0.976, 1.0 / 3.0, 1e-300, 123456789.123, -0.0, 5e-324}) {
        std::string out;
        appendJsonNumber(out, v);
        EXPECT_EQ(std::strtod(out.c_str(), nullptr), v) << out;
    }
    std::string out;
    appendJsonNumber(out, std::nan(""));
    EXPECT_EQ(out, "null");
}

TEST(Protocol, ParsesEveryCommand) {
    EXPECT_EQ(parseRequest(R"({"cmd":"poll"})").command, Command::kPoll);
    EXPECT_EQ(parseRequest(R"({"cmd":"status"})").command, Command::kStatus);
    EXPECT_EQ(parseRequest(R"({"cmd":"posterior","extra":[1,2]})").command, Command::kPosterior);
    EXPECT_EQ(parseRequest(R"({"cmd":"objects"})").command, Command::kObjects);
    EXPECT_STREQ(toString(Command::kObjects), "objects");
    Request w = parseRequest(R"( {"cmd":"watch"} )");
    EXPECT_EQ(w.command, Command::kWatch);
    EXPECT_TRUE(w.enable);
    EXPECT_FALSE(w.pose);
    w = parseRequest(R"({"cmd":"watch","enable":false})");
    EXPECT_EQ(w.command, Command::kWatch);
    EXPECT_FALSE(w.enable);
    EXPECT_FALSE(w.pose);
    w = parseRequest(R"({"cmd":"watch","enable":false,"pose":true})");
    EXPECT_EQ(w.command, Command::kWatch);
    EXPECT_FALSE(w.enable);
    EXPECT_TRUE(w.pose);
    w = parseRequest(R"({"cmd":"watch","pose":true})");
    EXPECT_TRUE(w.enable);
    EXPECT_TRUE(w.pose);
    EXPECT_EQ(parseRequest(R"({"cmd":"pose"})").command, Command::kPose);
    EXPECT_STREQ(toString(Command::kPose), "pose");
    const Request g = parseRequest(R"({"cmd":"set_gravity","down":[0,3,4]})");
    ASSERT_EQ(g.command, Command::kSetGravity) << g.error;
    EXPECT_DOUBLE_EQ(g.down[0], 0);
    EXPECT_DOUBLE_EQ(g.down[1], 0.6);
    EXPECT_DOUBLE_EQ(g.down[2], 0.8);
    const Request huge = parseRequest(R"({"cmd":"set_gravity","down":[1e308,1e308,0]})");
    ASSERT_EQ(huge.command, Command::kSetGravity) << huge.error;
    EXPECT_NEAR(huge.down[0], std::sqrt(0.5), 1e-12);
}

TEST(Protocol, RejectsBadRequests) {
    struct Case {
        const char* line;
        const char* message;
        const char* cmd;
    };
    const Case cases[] = {
        {"{\"cmd\":", "request is not valid JSON", ""},
        {"[1,2]", "request must be a JSON object", ""},
        {"\"poll\"", "request must be a JSON object", ""},
        {"{}", "request has no \"cmd\"", ""},
        {"{\"cmd\":3}", "\"cmd\" must be a string", ""},
        {"{\"cmd\":\"fly\"}",
         "unknown command (known: poll, watch, status, posterior, objects, pose, set_gravity)",
         "fly"},
        {"{\"cmd\":\"watch\",\"enable\":1}", "\"enable\" must be true or false", "watch"},
        {"{\"cmd\":\"watch\",\"pose\":\"yes\"}", "\"pose\" must be true or false", "watch"},
        {"{\"cmd\":\"watch\",\"enable\":true,\"pose\":null}", "\"pose\" must be true or false",
         "watch"},
        {"{\"cmd\":\"set_gravity\"}", "\"down\" must be an array of 3 finite numbers, not all zero",
         "set_gravity"},
        {"{\"cmd\":\"set_gravity\",\"down\":[0,0,0]}",
         "\"down\" must be an array of 3 finite numbers, not all zero", "set_gravity"},
        {"{\"cmd\":\"set_gravity\",\"down\":[0,1]}",
         "\"down\" must be an array of 3 finite numbers, not all zero", "set_gravity"},
        {"{\"cmd\":\"set_gravity\",\"down\":[0,\"1\",0]}",
         "\"down\" must be an array of 3 finite numbers, not all zero", "set_gravity"},
        {"{\"cmd\":\"set_gravity\",\"down\":[0,1e999,0]}",
         "\"down\" must be an array of 3 finite numbers, not all zero", "set_gravity"},
    };
    for (const Case& c : cases) {
        const Request r = parseRequest(c.line);
        EXPECT_EQ(r.command, Command::kInvalid) << c.line;
        EXPECT_EQ(r.error, c.message) << c.line;
        EXPECT_EQ(r.cmd, c.cmd) << c.line;
    }
}

// Writes one line of every kind to $SCALED_PROTOCOL_SAMPLES, for the ctest
// protocol.schema, which checks them against docs/protocol.schema.json.
TEST(ProtocolSamples, Write) {
    const char* path = std::getenv("SCALED_PROTOCOL_SAMPLES");
    if (path == nullptr) {
        GTEST_SKIP() << "SCALED_PROTOCOL_SAMPLES not set (run by the ctest protocol.schema)";
    }
    std::string out;
    appendVersion(out, "0.1.0");
    appendScale(out, sampleReport(), 6'000'000'000);
    ScaleReport faulty = sampleReport();
    faulty.fault = "log: No space left on device";
    faulty.state = DaemonState::kFault;
    appendScale(out, faulty, 6'000'000'000);
    appendScale(out, ScaleReport{}, 1);
    ScaleReport after_break;
    after_break.epoch = 3;
    after_break.previous = {true, 2, 0.971, 0.95, 0.99, 52, 1180};
    appendScale(out, after_break, 1);
    LogStatus log;
    log.state = LogStatus::State::kFault;
    log.error = "No space left on device";
    appendStatus(out, PipelineStatus{}, LogStatus{}, ClientCounts{});
    PipelineStatus st;
    st.source = "replay:/data/x";
    st.fps = 29.97;
    st.frame_id = 10;
    st.timing.predict.add(0.1234567);
    st.timing.detect_forward.add(40.5);
    st.timing.scale_publish.add(1e-5);
    appendStatus(out, st, log, ClientCounts{2, 16, 3, 1, 0});
    // A map started from the live IMU, and an IMU that failed.
    st.gravity_source = "accelerometer (iio:device0 [lsm6dsl], 51 samples, spread 0.012 m/s^2)";
    st.gravity_down_C = std::array<double, 3>{0, 0.866, 0.5};
    st.imu.configured = true;
    st.imu.device = "iio:device0 [lsm6dsl]";
    st.imu.mode = "sysfs 100 Hz";
    st.imu.samples = 5230;
    appendStatus(out, st, LogStatus{}, ClientCounts{});
    st.imu.errors = 3;
    st.imu.error = "/sys/bus/iio/devices/iio:device0/in_accel_z_raw: No such device";
    appendStatus(out, st, LogStatus{}, ClientCounts{});
    // Its gyroscope feeding the gyro prior.
    st.gyro.present = true;
    st.gyro.source = "iio:device0 [lsm6dsl]";
    st.gyro.frames = 5120;
    st.gyro.bias_C_radps = {0.0031, -0.0102, 0.0007};
    appendStatus(out, st, LogStatus{}, ClientCounts{});
    // The window adjustment before its first optimisation, then after one.
    st.window_ba.present = true;
    st.window_ba.rolling_shutter_estimated = true;
    appendStatus(out, st, LogStatus{}, ClientCounts{});
    st.window_ba.optimisations = 3;
    st.window_ba.frame_id = 208;
    st.window_ba.epoch = 1;
    st.window_ba.keyframes = 58;
    st.window_ba.points = 301;
    st.window_ba.observations = 4012;
    st.window_ba.rms_px = 0.61;
    st.window_ba.scale = 1.004;
    st.window_ba.rolling_shutter_s = 0.0226;
    appendStatus(out, st, LogStatus{}, ClientCounts{});
    appendPosterior(out, PosteriorSnapshot{});
    PosteriorSnapshot p;
    p.d = {0.5, 1.0};
    p.log_p = {0, -std::numeric_limits<double>::infinity()};
    appendPosterior(out, p);
    appendObjects(out, ObjectsSnapshot{});
    appendObjects(out, sampleObjects());
    appendWatch(out, true, false);
    appendWatch(out, false, true);
    appendPose(out, PoseReport{}, ScaleReport{});
    appendPose(out, samplePose(), ScaleReport{});
    appendPose(out, samplePose(), sampleReport());
    appendAck(out, "set_gravity");
    appendError(out, "request is not valid JSON");
    appendError(out, "unknown command (known: poll)", "x");
    appendError(out, "unknown command (known: poll)", std::string(100, 'y'));
    ClientCounts counts{17, 16, 30, 1, 0};
    counts.watchers = 16;
    counts.reserved = 2;
    counts.timed_out = 1;
    counts.evicted = 1;
    appendStatus(out, PipelineStatus{}, LogStatus{}, counts);
    std::ofstream file(path);
    file << out;
    EXPECT_TRUE(file.good()) << path;
}

}  // namespace
}  // namespace scaled::daemon
