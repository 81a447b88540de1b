// scalectl: reply parsing, formatting, exit-code decisions, and the client
// against a real listening UNIX socket served by a thread of the test (a fake
// daemon speaking the protocol of docs/protocol.md; the integration tests run
// scalectl against the real daemon).

#include "scalectl.h"

#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <functional>
#include <mutex>
#include <poll.h>
#include <sstream>
#include <string>
#include <sys/socket.h>
#include <sys/un.h>
#include <thread>
#include <unistd.h>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/base/unique_fd.h>

#include "sysexits.h"
#include "temp_dir.h"

namespace {

namespace ctl = scaled::tools::scalectl;
using scaled::core::ErrorCode;

constexpr const char* kVersion =
    R"({"class":"VERSION","release":"0.1.0","proto_major":1,"proto_minor":0})";
constexpr const char* kScaleConverged =
    R"({"class":"SCALE","scale":0.976,"mean":0.977,"ci68":[0.97,0.982],"ci95":[0.964,0.988],)"
    R"("state":"converged","epoch":1,"observations":137,"frame_id":510,"t_ns":17000000000,)"
    R"("time":1712345678.5,"age_s":0.41})";
constexpr const char* kScaleNone =
    R"({"class":"SCALE","scale":null,"mean":null,"ci68":null,"ci95":null,"state":"tracking",)"
    R"("epoch":0,"observations":0,"frame_id":12,"t_ns":400000000,"time":1712345678.5,)"
    R"("age_s":null})";
constexpr const char* kStatus =
    R"({"class":"STATUS","source":"replay:/data/redkitchen","uptime_s":12.5,"fps":29.97,)"
    R"("frame_id":374,"frames_total":1000,"source_finished":false,)"
    R"("frames":{"captured":375,"tracked":370,"dropped":1},)"
    R"("detector":{"runs":37,"skipped":2,"latency_ms":{"last":41.2,"mean":39.8,"max":77.0}},)"
    R"("tracking_ms_mean":8.4,"features":{"in_map":31,"tracked":22},"scale_updates":55,)"
    R"("epoch":1,"clients":{"connected":2,"max":16,"accepted":5,"rejected":0,"detached":1,)"
    R"("watchers":1,"reserved":2,"timed_out":3,"evicted":0},)"
    R"("log":{"state":"writing","lines":410,"dropped":0,"bytes":91234,"error":""}})";
constexpr const char* kPosterior =
    R"({"class":"POSTERIOR","epoch":1,"frame_id":510,"observations":137,)"
    R"("d":[0.5,1.0,2.0],"log_p":[-3.5,-0.25,null]})";

constexpr const char* kVersion13 =
    R"({"class":"VERSION","release":"0.2.0","proto_major":1,"proto_minor":3})";
constexpr const char* kObjects =
    R"({"class":"OBJECTS","epoch":1,"frame_id":450,"model":"object","objects":[)"
    R"({"id":3,"class":"chair","state":"used","anchor":[0.4123457,-0.125,2.5],)"
    R"("anchor_rel_sigma":0.0431,"detections":12,"views":10,"views_used":9,"first_frame":120,)"
    R"("last_frame":450,"local_estimate":1.2101,"height_m":0.87,"height_ci95_m":[0.82,0.93]},)"
    R"({"id":7,"class":"cup","state":"tentative","anchor":null,"anchor_rel_sigma":null,)"
    R"("detections":1,"views":1,"views_used":0,"first_frame":450,"last_frame":450,)"
    R"("local_estimate":null,"height_m":null,"height_ci95_m":null,"new_member":1}]})";

constexpr const char* kVersion14 =
    R"({"class":"VERSION","release":"0.3.0","proto_major":1,"proto_minor":4})";
// docs/protocol.md's first POSE: the camera 30 degrees left of G's x and 10
// degrees down, no roll.
constexpr const char* kPose =
    R"({"class":"POSE","epoch":1,"frame_id":512,"t_ns":1700000016896666667,)"
    R"("time":1700000016.8966667,"state":"converging","scale":0.9763412,"scale_sigma":0.03,)"
    R"("position":[1.220427,-0.3905365,0.3026658],"velocity":[0.1952682,0.04881706,0],)"
    R"("position_cov":[[0.001787547,-0.0004404676,0.00034875],)"
    R"([-0.0004404676,0.0004299726,-0.0001116],[0.00034875,-0.0001116,0.0002771384]],)"
    R"("orientation":[0.5566704,-0.6634139,0.3830222,-0.3213938],)"
    R"("attitude_cov":[[7.6e-05,0,0],[0,7.6e-05,0],[0,0,1.2e-04]],)"
    R"("position_map":[1.25,-0.4,0.31],"velocity_map":[0.2,0.05,0],)"
    R"("position_map_cov":[[0.0004,1e-05,0],[1e-05,0.0003,0],[0,0,0.0002]],"new":1})";
constexpr const char* kPoseNoScale =
    R"({"class":"POSE","epoch":2,"frame_id":37,"t_ns":1233333333,"time":1.233333333,)"
    R"("state":"tracking","scale":null,"scale_sigma":null,"position":null,"velocity":null,)"
    R"("position_cov":null,"orientation":[0.5,-0.5,0.5,-0.5],)"
    R"("attitude_cov":[[2.5e-05,0,0],[0,2.5e-05,0],[0,0,2.5e-05]],)"
    R"("position_map":[0.0525,0.001,-0.002],"velocity_map":[0.04,0,0],)"
    R"("position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]})";
constexpr const char* kPoseNone =
    R"({"class":"POSE","epoch":0,"frame_id":-1,"t_ns":0,"time":0,"state":"initialising",)"
    R"("scale":null,"scale_sigma":null,"position":null,"velocity":null,"position_cov":null,)"
    R"("orientation":null,"attitude_cov":null,"position_map":null,"velocity_map":null,)"
    R"("position_map_cov":null})";

// ---- parsing and formatting ----------------------------------------------

TEST(ScalectlParse, ScaleLineWithEveryField) {
    auto s = ctl::parseScale(kScaleConverged);
    ASSERT_TRUE(s.ok()) << s.error().message;
    ASSERT_TRUE(s->scale.has_value());
    EXPECT_DOUBLE_EQ(*s->scale, 0.976);
    ASSERT_TRUE(s->ci95.has_value());
    EXPECT_DOUBLE_EQ(s->ci95->lo, 0.964);
    EXPECT_DOUBLE_EQ(s->ci95->hi, 0.988);
    EXPECT_EQ(s->state, "converged");
    EXPECT_EQ(s->epoch, 1);
    EXPECT_EQ(s->observations, 137);
    EXPECT_EQ(s->frame_id, 510);
    ASSERT_TRUE(s->age_s.has_value());
    EXPECT_DOUBLE_EQ(*s->age_s, 0.41);
    EXPECT_TRUE(s->fault.empty());
}

TEST(ScalectlParse, UnknownFieldsAreIgnored) {
    auto s = ctl::parseScale(
        R"({"class":"SCALE","scale":1.5,"state":"converging","epoch":2,"observations":3,)"
        R"("future_field":{"a":[1,2]},"another":"x","ci99":[1,2]})");
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_DOUBLE_EQ(*s->scale, 1.5);
    EXPECT_EQ(s->state, "converging");
    EXPECT_FALSE(s->ci95.has_value());

    auto v = ctl::parseVersion(
        R"({"class":"VERSION","release":"0.3.0","proto_major":1,"proto_minor":7,"x":true})");
    ASSERT_TRUE(v.ok()) << v.error().message;
    EXPECT_EQ(v->proto_minor, 7);
    EXPECT_EQ(v->release, "0.3.0");
}

TEST(ScalectlParse, MalformedLinesAreParseErrors) {
    const std::vector<std::string> bad = {
        "",
        "not json",
        R"({"class":"SCALE","state":"converged")",  // truncated
        R"([1,2,3])",                               // not an object
        R"({"scale":0.9,"state":"converged"})",     // no class
        R"({"class":7})",                           // class not a string
        R"({"class":"SCALE","scale":"0.9","state":"converged","epoch":1,"observations":1})",
        R"({"class":"SCALE","scale":0.9,"epoch":1,"observations":1})",  // no state
        R"({"class":"SCALE","scale":0.9,"state":"converged","epoch":1.5,"observations":1})",
        R"({"class":"SCALE","scale":0.9,"ci95":[0.8],"state":"converged","epoch":1,"observations":1})",
        R"({"class":"STATUS","uptime_s":1})",  // another class
    };
    for (const auto& line : bad) {
        auto s = ctl::parseScale(line);
        ASSERT_FALSE(s.ok()) << line;
        EXPECT_EQ(s.error().code, ErrorCode::kParse) << line;
        EXPECT_EQ(ctl::exitCodeFor(s.error()), scaled::tools::kExProtocol) << line;
    }
}

TEST(ScalectlParse, ErrorReplyCarriesTheDaemonsMessage) {
    auto s = ctl::parseScale(R"({"class":"ERROR","message":"unknown cmd 'pol'"})");
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.error().code, ErrorCode::kParse);
    EXPECT_NE(s.error().message.find("unknown cmd 'pol'"), std::string::npos);
    EXPECT_EQ(ctl::exitCodeFor(s.error()), 76);
}

TEST(ScalectlParse, VersionOtherThanMajorOneIsRejected) {
    auto v2 = ctl::parseVersion(R"({"class":"VERSION","release":"2.0.0","proto_major":2,)"
                                R"("proto_minor":0})");
    ASSERT_FALSE(v2.ok());
    EXPECT_EQ(v2.error().code, ErrorCode::kParse);
    EXPECT_NE(v2.error().message.find("protocol 2.0"), std::string::npos);
    EXPECT_FALSE(ctl::parseVersion(R"({"class":"VERSION","release":"0.1.0"})").ok());
    EXPECT_FALSE(ctl::parseVersion(R"({"class":"VERSION","proto_major":"1"})").ok());
    EXPECT_FALSE(ctl::parseVersion(kScaleConverged).ok());
    EXPECT_TRUE(ctl::parseVersion(kVersion).ok());
}

TEST(ScalectlParse, ReplyClass) {
    EXPECT_EQ(*ctl::replyClass(kStatus), "STATUS");
    EXPECT_EQ(*ctl::replyClass(R"({"class":"SOMETHING_NEW","x":1})"), "SOMETHING_NEW");
    EXPECT_FALSE(ctl::replyClass("{}").ok());
}

TEST(ScalectlFormat, ScaleLine) {
    EXPECT_EQ(ctl::formatScale(*ctl::parseScale(kScaleConverged)),
              "scale 0.9760 m/unit  95% [0.9640, 0.9880]  converged  epoch 1  obs 137  age 0.4 s");
    EXPECT_EQ(ctl::formatScale(*ctl::parseScale(kScaleNone)), "scale -  tracking  epoch 0  obs 0");
    ctl::ScaleReply fault;
    fault.state = "fault";
    fault.fault = "camera disconnected";
    fault.epoch = 3;
    EXPECT_EQ(ctl::formatScale(fault),
              "scale -  fault  epoch 3  obs 0  fault: camera disconnected");
}

TEST(ScalectlFormat, StatusSummary) {
    auto text = ctl::formatStatus(kStatus);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_NE(text->find("source         replay:/data/redkitchen\n"), std::string::npos) << *text;
    EXPECT_NE(text->find("captured 375  tracked 370  dropped 1  (frame 374 of 1000, 30.0 fps)"),
              std::string::npos)
        << *text;
    EXPECT_NE(text->find("latency last 41.2 ms  mean 39.8 ms  max 77.0 ms"), std::string::npos);
    EXPECT_NE(text->find("connected 2/16+2  watchers 1  accepted 5  rejected 0  detached 1  "
                         "timed out 3  evicted 0"),
              std::string::npos)
        << *text;
    EXPECT_NE(text->find("log            writing  lines 410"), std::string::npos);
    EXPECT_EQ(text->find("error:"), std::string::npos);  // an empty error is not shown
    EXPECT_EQ(text->back(), '\n');

    // Absent fields show as '-', finished sources say so, log errors are shown.
    auto sparse = ctl::formatStatus(
        R"({"class":"STATUS","source":"sim","source_finished":true,"log":{"error":"disk full"}})");
    ASSERT_TRUE(sparse.ok());
    EXPECT_NE(sparse->find("sim (finished)"), std::string::npos) << *sparse;
    EXPECT_NE(sparse->find("uptime         - s"), std::string::npos) << *sparse;
    EXPECT_NE(sparse->find("error: disk full"), std::string::npos) << *sparse;

    EXPECT_FALSE(ctl::formatStatus(kScaleConverged).ok());
    EXPECT_FALSE(ctl::formatStatus(R"({"class":"ERROR","message":"busy"})").ok());
}

// STATUS.timing (proto_minor 2): one row per stage, known stages in pipeline
// order, unknown ones after them; nothing from a daemon without it.
TEST(ScalectlFormat, StatusStageTimes) {
    const std::string line =
        R"({"class":"STATUS","source":"sim","timing":{)"
        R"("predict":{"samples":599,"last_ms":0.041,"mean_ms":0.0384,"max_ms":0.21},)"
        R"("update":{"samples":599,"last_ms":0.9,"mean_ms":0.85,"max_ms":3.5},)"
        R"("scale_update":{"samples":59,"last_ms":1.25,"mean_ms":1.5,"max_ms":4},)"
        R"("zz_new":{"samples":1,"last_ms":2,"mean_ms":2,"max_ms":2}}})";
    auto text = ctl::formatStatus(line);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_NE(text->find("timing (ms)                         last     mean      max  samples\n"),
              std::string::npos)
        << *text;
    EXPECT_NE(text->find("               predict             0.041    0.038    0.210      599\n"),
              std::string::npos)
        << *text;
    EXPECT_NE(text->find("scale_update        1.250    1.500    4.000       59\n"),
              std::string::npos)
        << *text;
    const auto predict = text->find("predict");
    const auto update = text->find("update  ");
    const auto scale = text->find("scale_update");
    const auto unknown = text->find("zz_new");
    EXPECT_LT(predict, update);
    EXPECT_LT(update, scale);
    EXPECT_LT(scale, unknown);
    EXPECT_NE(unknown, std::string::npos);

    auto old = ctl::formatStatus(kStatus);
    ASSERT_TRUE(old.ok());
    EXPECT_EQ(old->find("timing"), std::string::npos) << *old;
}

// STATUS.window_ba (proto_minor 5): the camera the window used, what it
// estimates marked, then its latest optimisation; nothing without it.
TEST(ScalectlFormat, StatusWindowBa) {
    const std::string line =
        R"({"class":"STATUS","source":"sim","window_ba":{"optimisations":14,)"
        R"("estimated":["rolling_shutter_s"],"rolling_shutter_s":0.0227,"focal_scale":1,)"
        R"("k1":-0.125,"last":{"frame_id":517,"epoch":2,"keyframes":67,"points":412,)"
        R"("observations":5120,"rms_px":0.75,"scale":1.0125}}})";
    auto text = ctl::formatStatus(line);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_NE(text->find("window         optimisations 14  readout 22.7 ms (estimated)  focal "
                         "x1.0000  k1 -0.1250\n"),
              std::string::npos)
        << *text;
    EXPECT_NE(text->find("               last: frame 517  epoch 2  keyframes 67  points 412  rms "
                         "0.750 px  scale 1.0125\n"),
              std::string::npos)
        << *text;

    auto before = ctl::formatStatus(
        R"({"class":"STATUS","source":"sim","window_ba":{"optimisations":0,"estimated":[],)"
        R"("rolling_shutter_s":0,"focal_scale":1,"k1":0,"last":null}})");
    ASSERT_TRUE(before.ok());
    EXPECT_NE(before->find("optimisations 0  readout 0.0 ms  focal x1.0000  k1 0.0000\n"),
              std::string::npos)
        << *before;
    EXPECT_EQ(before->find("last:"), std::string::npos) << *before;

    auto old = ctl::formatStatus(kStatus);
    ASSERT_TRUE(old.ok());
    EXPECT_EQ(old->find("window "), std::string::npos) << *old;
}

// OBJECTS (proto_minor 3): a header line, then one aligned row per object;
// nulls (tentative anchors, no local estimate, no height) print as `-`.
TEST(ScalectlFormat, ObjectsTable) {
    auto text = ctl::formatObjects(kObjects);
    ASSERT_TRUE(text.ok()) << text.error().message;
    EXPECT_EQ(*text,
              "model object  epoch 1  frame 450  objects 2  used 1\n"
              "  id  class           state      views/det     local  height m [95%]        "
              "  anchor (map units)          rel.sigma\n"
              "   3  chair           used            9/12    1.2101  0.870 [0.820, 0.930]  "
              "  (0.412, -0.125, 2.500)          0.043\n"
              "   7  cup             tentative        0/1         -  -                     "
              "  -                                   -\n");
}

// POSE (proto_minor 4): one line; the metric part only with a scale.
TEST(ScalectlFormat, PoseLine) {
    auto p = ctl::parsePose(kPose);
    ASSERT_TRUE(p.ok()) << p.error().message;
    EXPECT_EQ(ctl::formatPose(*p),
              "pose 512  pos 1.220 -0.391 0.303 m  1-sigma 0.042 0.021 0.017 m  "
              "ypr 30.0 -10.0 0.0 deg  vel 0.195 0.049 0.000 m/s  converging  epoch 1");
    auto none = ctl::parsePose(kPoseNoScale);
    ASSERT_TRUE(none.ok()) << none.error().message;
    EXPECT_EQ(ctl::formatPose(*none),
              "pose 37  pos - (map 0.053 0.001 -0.002 units)  ypr 0.0 0.0 0.0 deg  vel -  "
              "tracking  epoch 2");
    auto before = ctl::parsePose(kPoseNone);
    ASSERT_TRUE(before.ok()) << before.error().message;
    EXPECT_EQ(ctl::formatPose(*before), "pose -  initialising  epoch 0");
}

// Yaw, pitch and roll of the camera from the quaternion (camera to G).
TEST(ScalectlFormat, YawPitchRoll) {
    // A level camera looking along x: R_CtoG columns (0,-1,0), (0,0,-1), (1,0,0).
    const auto level = ctl::yawPitchRoll({0.5, -0.5, 0.5, -0.5});
    EXPECT_NEAR(level.yaw_deg, 0, 1e-9);
    EXPECT_NEAR(level.pitch_deg, 0, 1e-9);
    EXPECT_NEAR(level.roll_deg, 0, 1e-9);
    // Turned 90 degrees left about z: q = (cos 45, 0, 0, sin 45) * level.
    const double c = std::sqrt(0.5);
    const std::array<double, 4> turn{c, 0, 0, c};
    const std::array<double, 4> lv{0.5, -0.5, 0.5, -0.5};
    const std::array<double, 4> left{
        turn[0] * lv[0] - turn[3] * lv[3], turn[0] * lv[1] - turn[3] * lv[2],
        turn[0] * lv[2] + turn[3] * lv[1], turn[0] * lv[3] + turn[3] * lv[0]};
    const auto l = ctl::yawPitchRoll(left);
    EXPECT_NEAR(l.yaw_deg, 90, 1e-9);
    EXPECT_NEAR(l.pitch_deg, 0, 1e-9);
    EXPECT_NEAR(l.roll_deg, 0, 1e-9);
    // Rolled right side down by 20 degrees about the optical axis (G's x):
    // q = (cos 10, sin 10, 0, 0) * level.
    const double h = 10.0 * M_PI / 180.0;
    const std::array<double, 4> r{std::cos(h), std::sin(h), 0, 0};
    const std::array<double, 4> rolled{r[0] * lv[0] - r[1] * lv[1], r[0] * lv[1] + r[1] * lv[0],
                                       r[0] * lv[2] - r[1] * lv[3], r[0] * lv[3] + r[1] * lv[2]};
    const auto rr = ctl::yawPitchRoll(rolled);
    EXPECT_NEAR(rr.yaw_deg, 0, 1e-9);
    EXPECT_NEAR(rr.pitch_deg, 0, 1e-9);
    EXPECT_NEAR(rr.roll_deg, 20, 1e-9);
}

TEST(ScalectlFormat, MalformedPosesAreParseErrors) {
    for (const char* line : {
             R"({"class":"POSE","epoch":1,"frame_id":3,"state":"tracking","position":[1,2]})",
             R"({"class":"POSE","epoch":1,"frame_id":3,"state":"tracking","position_cov":[[1]]})",
             R"({"class":"POSE","epoch":1,"frame_id":3,"state":7})",
             R"({"class":"POSE","epoch":1,"state":"tracking"})",
             R"({"class":"SCALE","epoch":1})",
         }) {
        const auto p = ctl::parsePose(line);
        ASSERT_FALSE(p.ok()) << line;
        EXPECT_EQ(p.error().code, ErrorCode::kParse) << line;
    }
}

TEST(ScalectlFormat, ObjectsOfThePaperModelAndEmptyTables) {
    auto paper = ctl::formatObjects(
        R"({"class":"OBJECTS","epoch":2,"frame_id":510,"model":"paper","objects":[]})");
    ASSERT_TRUE(paper.ok()) << paper.error().message;
    EXPECT_EQ(*paper,
              "model paper  epoch 2  frame 510  objects 0  used 0\n"
              "no object table: the paper model uses every feature in a box "
              "(estimator.model = \"object\" keeps one)\n");
    auto empty = ctl::formatObjects(
        R"({"class":"OBJECTS","epoch":3,"frame_id":-1,"model":"object","objects":[]})");
    ASSERT_TRUE(empty.ok()) << empty.error().message;
    EXPECT_EQ(*empty,
              "model object  epoch 3  frame -1  objects 0  used 0\n"
              "no objects yet in this epoch\n");
}

TEST(ScalectlFormat, MalformedObjectsAreParseErrors) {
    for (const char* line : {
             R"({"class":"OBJECTS","epoch":1,"frame_id":4,"model":"object"})",
             R"({"class":"OBJECTS","epoch":1,"frame_id":4,"model":"object","objects":{}})",
             R"({"class":"OBJECTS","epoch":1,"frame_id":4,"model":"object","objects":[1]})",
             R"({"class":"STATUS"})",
             R"({"class":"ERROR","message":"unknown command"})",
         }) {
        auto r = ctl::formatObjects(line);
        ASSERT_FALSE(r.ok()) << line;
        EXPECT_EQ(r.error().code, ErrorCode::kParse) << line;
    }
}

TEST(ScalectlFormat, PosteriorRows) {
    auto p = ctl::parsePosterior(kPosterior);
    ASSERT_TRUE(p.ok()) << p.error().message;
    ASSERT_EQ(p->d.size(), 3u);
    EXPECT_TRUE(std::isinf(p->log_p[2]));
    EXPECT_EQ(ctl::formatPosterior(*p), "0.5\t-3.5\n1\t-0.25\n2\t-inf\n");

    EXPECT_FALSE(ctl::parsePosterior(R"({"class":"POSTERIOR","d":[1,2],"log_p":[0]})").ok());
    EXPECT_FALSE(ctl::parsePosterior(R"({"class":"POSTERIOR","d":[1,"x"],"log_p":[0,0]})").ok());
    EXPECT_FALSE(ctl::parsePosterior(R"({"class":"POSTERIOR"})").ok());
}

TEST(ScalectlExitCodes, Decisions) {
    ctl::ScaleReply s;
    s.state = "converged";
    EXPECT_EQ(ctl::getExitCode(s, true), 0);
    EXPECT_EQ(ctl::getExitCode(s, false), 0);
    for (const char* state : {"initialising", "tracking", "converging", "lost", "fault"}) {
        s.state = state;
        EXPECT_EQ(ctl::getExitCode(s, true), scaled::tools::kExTempFail) << state;
        EXPECT_EQ(ctl::getExitCode(s, false), 0) << state;
    }
    using scaled::core::makeError;
    EXPECT_EQ(ctl::exitCodeFor(makeError(ErrorCode::kParse, "")), 76);
    EXPECT_EQ(ctl::exitCodeFor(makeError(ErrorCode::kIo, "")), 69);
    EXPECT_EQ(ctl::exitCodeFor(makeError(ErrorCode::kNotFound, "")), 69);
    EXPECT_EQ(ctl::exitCodeFor(makeError(ErrorCode::kInvalidArgument, "")), 64);
}

TEST(ScalectlExitCodes, DefaultSocketFollowsTheEnvironment) {
    ::unsetenv("SCALED_SOCKET");
    EXPECT_EQ(ctl::defaultSocketPath(), "/run/scaled/scaled.sock");
    ::setenv("SCALED_SOCKET", "/tmp/elsewhere.sock", 1);
    EXPECT_EQ(ctl::defaultSocketPath(), "/tmp/elsewhere.sock");
    ::setenv("SCALED_SOCKET", "", 1);
    EXPECT_EQ(ctl::defaultSocketPath(), "/run/scaled/scaled.sock");
    ::unsetenv("SCALED_SOCKET");
}

// ---- against a listening socket ------------------------------------------

void sendAll(int fd, std::string_view data) {
    while (!data.empty()) {
        const ssize_t n = ::send(fd, data.data(), data.size(), MSG_NOSIGNAL);
        if (n <= 0) {
            return;  // the client went away; the test's expectations tell
        }
        data.remove_prefix(static_cast<std::size_t>(n));
    }
}

// One line from `fd` (without '\n'); empty at EOF or after 5 s.
std::string recvLine(int fd) {
    std::string line;
    for (;;) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, 5000) <= 0) {
            return line;
        }
        char c = 0;
        if (::recv(fd, &c, 1, 0) != 1 || c == '\n') {
            return line;
        }
        line += c;
    }
}

// Blocks until the client closes its end (at most 5 s).
void waitForClose(int fd) {
    for (;;) {
        pollfd p{fd, POLLIN, 0};
        if (::poll(&p, 1, 5000) <= 0) {
            return;
        }
        std::array<char, 256> buf{};
        if (::recv(fd, buf.data(), buf.size(), 0) <= 0) {
            return;
        }
    }
}

// A listening UNIX socket in a temporary directory; a thread accepts one
// connection and runs `script` on it, recording the request lines it reads
// through `request()`.
class FakeDaemon {
public:
    using Script = std::function<void(FakeDaemon&, int fd)>;

    explicit FakeDaemon(Script script) : dir_("scalectl"), path_(dir_.path() / "s.sock") {
        listen_fd_.reset(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
        sockaddr_un addr{};
        addr.sun_family = AF_UNIX;
        const std::string sock = path_.string();
        EXPECT_LT(sock.size(), sizeof(addr.sun_path));
        std::memcpy(static_cast<void*>(addr.sun_path), sock.data(), sock.size());
        // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast): the sockets API
        EXPECT_EQ(::bind(listen_fd_.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)),
                  0);
        EXPECT_EQ(::listen(listen_fd_.get(), 4), 0);
        thread_ = std::thread([this, script = std::move(script)] {
            pollfd p{listen_fd_.get(), POLLIN, 0};
            if (::poll(&p, 1, 5000) <= 0) {
                return;
            }
            const scaled::drivers::base::UniqueFd fd(
                ::accept4(listen_fd_.get(), nullptr, nullptr, SOCK_CLOEXEC));
            if (!fd.isValid()) {
                return;
            }
            script(*this, fd.get());
        });
    }
    FakeDaemon(const FakeDaemon&) = delete;
    FakeDaemon& operator=(const FakeDaemon&) = delete;
    FakeDaemon(FakeDaemon&&) = delete;
    FakeDaemon& operator=(FakeDaemon&&) = delete;
    ~FakeDaemon() {
        if (thread_.joinable()) {
            thread_.join();
        }
    }

    [[nodiscard]] std::string path() const { return path_.string(); }

    // Reads one request line and records it.
    std::string request(int fd) {
        std::string line = recvLine(fd);
        const std::lock_guard<std::mutex> lock(mutex_);
        requests_.push_back(line);
        return line;
    }
    std::vector<std::string> requests() {
        if (thread_.joinable()) {
            thread_.join();
        }
        const std::lock_guard<std::mutex> lock(mutex_);
        return requests_;
    }

private:
    scaled::test::TempDir dir_;
    std::filesystem::path path_;
    scaled::drivers::base::UniqueFd listen_fd_;
    std::thread thread_;
    std::mutex mutex_;
    std::vector<std::string> requests_;
};

struct RunResult {
    int code = -1;
    std::string out;
    std::string err;
    double seconds = 0.0;
};

RunResult runCtl(const ctl::Options& options) {
    std::ostringstream out;
    std::ostringstream err;
    const auto start = std::chrono::steady_clock::now();
    RunResult r;
    r.code = ctl::run(options, out, err);
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    r.out = out.str();
    r.err = err.str();
    return r;
}

ctl::Options optionsFor(const FakeDaemon& daemon, ctl::Command command) {
    ctl::Options o;
    o.socket_path = daemon.path();
    o.command = command;
    o.timeout_s = 2.0;
    return o;
}

// The daemon greets, reads one request and answers `reply` (several lines allowed).
FakeDaemon::Script answer(std::string reply) {
    return [reply = std::move(reply)](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion) + "\n");
        d.request(fd);
        sendAll(fd, reply);
        waitForClose(fd);
    };
}

TEST(ScalectlClient, GetPrintsOneLineAndSendsPoll) {
    FakeDaemon daemon(answer(std::string(kScaleConverged) + "\n"));
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kGet));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(
        r.out,
        "scale 0.9760 m/unit  95% [0.9640, 0.9880]  converged  epoch 1  obs 137  age 0.4 s\n");
    EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"poll"})"});
}

TEST(ScalectlClient, GetJsonPrintsTheRawLine) {
    FakeDaemon daemon(answer(std::string(kScaleNone) + "\n"));
    auto o = optionsFor(daemon, ctl::Command::kGet);
    o.json = true;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, std::string(kScaleNone) + "\n");
}

TEST(ScalectlClient, RequireConvergedExits75WhenNotConverged) {
    FakeDaemon daemon(answer(std::string(kScaleNone) + "\n"));
    auto o = optionsFor(daemon, ctl::Command::kGet);
    o.require_converged = true;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 75);
    EXPECT_EQ(r.out, "scale -  tracking  epoch 0  obs 0\n");  // still printed
    EXPECT_NE(r.err.find("not converged"), std::string::npos);
}

TEST(ScalectlClient, RequireConvergedExits0WhenConverged) {
    FakeDaemon daemon(answer(std::string(kScaleConverged) + "\n"));
    auto o = optionsFor(daemon, ctl::Command::kGet);
    o.require_converged = true;
    EXPECT_EQ(runCtl(o).code, 0);
}

TEST(ScalectlClient, SkipsUnknownClassesAndReassemblesSplitLines) {
    // A line of a future class before the reply, and the reply in small pieces.
    FakeDaemon daemon([](FakeDaemon& d, int fd) {
        const std::string greeting = std::string(kVersion) + "\n";
        sendAll(fd, greeting.substr(0, 10));
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        sendAll(fd, greeting.substr(10));
        d.request(fd);
        sendAll(fd, R"({"class":"NOTICE","text":"hello"})"
                    "\n");
        const std::string reply = std::string(kScaleConverged) + "\n";
        for (std::size_t i = 0; i < reply.size(); i += 17) {
            sendAll(fd, reply.substr(i, 17));
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        waitForClose(fd);
    });
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kGet));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out.rfind("scale 0.9760", 0), 0u) << r.out;
}

TEST(ScalectlClient, NoSocketIsUnavailable) {
    scaled::test::TempDir dir("scalectl");
    ctl::Options o;
    o.socket_path = (dir.path() / "absent.sock").string();
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("no socket at"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty());
}

TEST(ScalectlClient, RefusedConnectionIsUnavailable) {
    // A socket file nobody listens on (bound, then closed): ECONNREFUSED.
    scaled::test::TempDir dir("scalectl");
    const std::string path = (dir.path() / "stale.sock").string();
    {
        const scaled::drivers::base::UniqueFd fd(::socket(AF_UNIX, SOCK_STREAM, 0));
        sockaddr_un addr{};
        addr.sun_family = AF_UNIX;
        std::memcpy(static_cast<void*>(addr.sun_path), path.data(), path.size());
        // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast): the sockets API
        ASSERT_EQ(::bind(fd.get(), reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0);
    }  // closed: nobody listens
    ctl::Options o;
    o.socket_path = path;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("refused"), std::string::npos) << r.err;
}

TEST(ScalectlClient, TooLongPathIsUsage) {
    ctl::Options o;
    o.socket_path = "/tmp/" + std::string(200, 'x');
    EXPECT_EQ(runCtl(o).code, 64);
}

TEST(ScalectlClient, CloseBeforeGreetingIsUnavailable) {
    FakeDaemon daemon([](FakeDaemon& /*d*/, int /*fd*/) {});
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kGet));
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("closed the connection before its VERSION greeting"), std::string::npos)
        << r.err;
}

TEST(ScalectlClient, CloseBeforeReplyIsUnavailable) {
    FakeDaemon daemon([](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion) + "\n");
        d.request(fd);
    });
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kStatus));
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("closed"), std::string::npos) << r.err;
}

TEST(ScalectlClient, SilentDaemonTimesOut) {
    FakeDaemon daemon([](FakeDaemon& /*d*/, int fd) { waitForClose(fd); });
    auto o = optionsFor(daemon, ctl::Command::kGet);
    o.timeout_s = 0.2;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("timed out"), std::string::npos) << r.err;
    EXPECT_GE(r.seconds, 0.15);
    EXPECT_LT(r.seconds, 2.0);
}

TEST(ScalectlClient, WrongProtocolMajorIsProtocolError) {
    FakeDaemon daemon([](FakeDaemon& /*d*/, int fd) {
        sendAll(fd, R"({"class":"VERSION","release":"9.0.0","proto_major":2,"proto_minor":0})"
                    "\n");
        waitForClose(fd);
    });
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kGet));
    EXPECT_EQ(r.code, 76);
    EXPECT_NE(r.err.find("protocol 2.0"), std::string::npos) << r.err;
}

TEST(ScalectlClient, ErrorReplyIsProtocolError) {
    FakeDaemon daemon(answer(R"({"class":"ERROR","message":"too many clients"})"
                             "\n"));
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kPosterior));
    EXPECT_EQ(r.code, 76);
    EXPECT_NE(r.err.find("too many clients"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty());
}

TEST(ScalectlClient, MalformedReplyIsProtocolError) {
    FakeDaemon daemon(answer("{\"class\":\"SCALE\",\"scale\":0.9,\n"));
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kGet));
    EXPECT_EQ(r.code, 76);
    EXPECT_NE(r.err.find("malformed"), std::string::npos) << r.err;
}

TEST(ScalectlClient, StatusSummaryAndJson) {
    {
        FakeDaemon daemon(answer(std::string(kStatus) + "\n"));
        const auto r = runCtl(optionsFor(daemon, ctl::Command::kStatus));
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_NE(r.out.find("replay:/data/redkitchen"), std::string::npos) << r.out;
        EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"status"})"});
    }
    {
        FakeDaemon daemon(answer(std::string(kStatus) + "\n"));
        auto o = optionsFor(daemon, ctl::Command::kStatus);
        o.json = true;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, std::string(kStatus) + "\n");
    }
}

TEST(ScalectlClient, PosteriorTsv) {
    FakeDaemon daemon(answer(std::string(kPosterior) + "\n"));
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kPosterior));
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, "0.5\t-3.5\n1\t-0.25\n2\t-inf\n");
    EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"posterior"})"});
}

TEST(ScalectlClient, ObjectsTableAndJson) {
    const auto script = [](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion13) + "\n");
        d.request(fd);
        sendAll(fd, std::string(kObjects) + "\n");
        waitForClose(fd);
    };
    {
        FakeDaemon daemon(script);
        const auto r = runCtl(optionsFor(daemon, ctl::Command::kObjects));
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, *ctl::formatObjects(kObjects));
        EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"objects"})"});
    }
    {
        FakeDaemon daemon(script);
        auto o = optionsFor(daemon, ctl::Command::kObjects);
        o.json = true;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, std::string(kObjects) + "\n");
    }
}

// A daemon older than protocol 1.3 has no objects request: scalectl says so
// instead of sending it (exit 76).
TEST(ScalectlClient, ObjectsNeedProtocolMinor3) {
    FakeDaemon daemon([](FakeDaemon& /*d*/, int fd) {
        sendAll(fd, std::string(kVersion) + "\n");
        waitForClose(fd);
    });
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kObjects));
    EXPECT_EQ(r.code, 76);
    EXPECT_NE(r.err.find("protocol 1.0; objects needs 1.3"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_TRUE(daemon.requests().empty());
}

TEST(ScalectlClient, PoseLineAndJson) {
    const auto script = [](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion14) + "\n");
        d.request(fd);
        sendAll(fd, std::string(kPose) + "\n");
        waitForClose(fd);
    };
    {
        FakeDaemon daemon(script);
        const auto r = runCtl(optionsFor(daemon, ctl::Command::kPose));
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, ctl::formatPose(*ctl::parsePose(kPose)) + "\n");
        EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"pose"})"});
    }
    {
        FakeDaemon daemon(script);
        auto o = optionsFor(daemon, ctl::Command::kPose);
        o.json = true;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, std::string(kPose) + "\n");
    }
}

// A daemon older than protocol 1.4 has no POSE: `pose` and `watch --pose`
// say so instead of asking (exit 76).
TEST(ScalectlClient, PoseNeedsProtocolMinor4) {
    for (const bool watch : {false, true}) {
        FakeDaemon daemon([](FakeDaemon& /*d*/, int fd) {
            sendAll(fd, std::string(kVersion13) + "\n");
            waitForClose(fd);
        });
        auto o = optionsFor(daemon, watch ? ctl::Command::kWatch : ctl::Command::kPose);
        o.pose = watch;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 76);
        EXPECT_NE(r.err.find(watch ? "protocol 1.3; watch --pose needs 1.4"
                                   : "protocol 1.3; pose needs 1.4"),
                  std::string::npos)
            << r.err;
        EXPECT_TRUE(r.out.empty()) << r.out;
        EXPECT_TRUE(daemon.requests().empty());
    }
}

// watch --pose: asks for the POSE stream alone and prints POSE lines (a
// SCALE among them is skipped), --count of them.
TEST(ScalectlClient, WatchPoseStreamsPoseLines) {
    const std::string stream = std::string(R"({"class":"WATCH","enable":false,"pose":true})") +
                               "\n" + kPoseNoScale + "\n" + kScaleConverged + "\n" + kPose + "\n" +
                               kPose + "\n";
    const auto script = [&](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion14) + "\n");
        d.request(fd);
        sendAll(fd, stream);
        waitForClose(fd);
    };
    {
        FakeDaemon daemon(script);
        auto o = optionsFor(daemon, ctl::Command::kWatch);
        o.pose = true;
        o.count = 2;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, ctl::formatPose(*ctl::parsePose(kPoseNoScale)) + "\n" +
                             ctl::formatPose(*ctl::parsePose(kPose)) + "\n");
        EXPECT_EQ(daemon.requests(),
                  std::vector<std::string>{R"({"cmd":"watch","enable":false,"pose":true})"});
    }
    {
        FakeDaemon daemon(script);
        auto o = optionsFor(daemon, ctl::Command::kWatch);
        o.pose = true;
        o.json = true;
        o.count = 3;
        const auto r = runCtl(o);
        EXPECT_EQ(r.code, 0) << r.err;
        EXPECT_EQ(r.out, std::string(kPoseNoScale) + "\n" + kPose + "\n" + kPose + "\n");
    }
}

// The watch stream: WATCH acknowledgement, then SCALE lines.
std::string watchStream(int scale_lines) {
    std::string s = R"({"class":"WATCH","enable":true})"
                    "\n";
    for (int i = 0; i < scale_lines; ++i) {
        s += std::string(i % 2 == 0 ? kScaleNone : kScaleConverged) + "\n";
    }
    return s;
}

TEST(ScalectlClient, WatchStopsAfterCount) {
    FakeDaemon daemon(answer(watchStream(3)));
    auto o = optionsFor(daemon, ctl::Command::kWatch);
    o.count = 2;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(
        r.out,
        "scale -  tracking  epoch 0  obs 0\n"
        "scale 0.9760 m/unit  95% [0.9640, 0.9880]  converged  epoch 1  obs 137  age 0.4 s\n");
    EXPECT_EQ(daemon.requests(), std::vector<std::string>{R"({"cmd":"watch","enable":true})"});
}

TEST(ScalectlClient, WatchJsonUntilEof) {
    FakeDaemon daemon([](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion) + "\n");
        d.request(fd);
        sendAll(fd, watchStream(2));
    });  // then closes: the stream ends
    auto o = optionsFor(daemon, ctl::Command::kWatch);
    o.json = true;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, std::string(kScaleNone) + "\n" + kScaleConverged + "\n");
}

TEST(ScalectlClient, WatchClosedBeforeCountIsUnavailable) {
    FakeDaemon daemon([](FakeDaemon& d, int fd) {
        sendAll(fd, std::string(kVersion) + "\n");
        d.request(fd);
        sendAll(fd, watchStream(1));
    });
    auto o = optionsFor(daemon, ctl::Command::kWatch);
    o.count = 5;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("after 1 of 5"), std::string::npos) << r.err;
}

TEST(ScalectlClient, WatchWithoutTimeoutWaitsUntilInterrupted) {
    FakeDaemon daemon(answer(watchStream(1)));  // then silent until the client leaves
    std::array<int, 2> pipe_fds{-1, -1};
    ASSERT_EQ(::pipe2(pipe_fds.data(), O_CLOEXEC), 0);
    const scaled::drivers::base::UniqueFd read_end(pipe_fds[0]);
    const scaled::drivers::base::UniqueFd write_end(pipe_fds[1]);
    auto o = optionsFor(daemon, ctl::Command::kWatch);
    o.timeout_s.reset();  // no bound between lines
    o.interrupt_fd = pipe_fds[0];
    std::thread interrupter([fd = pipe_fds[1]] {
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        const char byte = 1;
        EXPECT_EQ(::write(fd, &byte, 1), 1);
    });
    const auto r = runCtl(o);
    interrupter.join();
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out, "scale -  tracking  epoch 0  obs 0\n");
    EXPECT_GE(r.seconds, 0.25);
}

TEST(ScalectlClient, WatchTimeoutBetweenLines) {
    FakeDaemon daemon(answer(watchStream(1)));
    auto o = optionsFor(daemon, ctl::Command::kWatch);
    o.timeout_s = 0.2;
    const auto r = runCtl(o);
    EXPECT_EQ(r.code, 69);
    EXPECT_NE(r.err.find("timed out"), std::string::npos) << r.err;
    EXPECT_EQ(r.out, "scale -  tracking  epoch 0  obs 0\n");
}

TEST(ScalectlClient, WatchErrorReplyIsProtocolError) {
    FakeDaemon daemon(answer(R"({"class":"ERROR","message":"watch refused"})"
                             "\n"));
    const auto r = runCtl(optionsFor(daemon, ctl::Command::kWatch));
    EXPECT_EQ(r.code, 76);
    EXPECT_NE(r.err.find("watch refused"), std::string::npos) << r.err;
}

}  // namespace
