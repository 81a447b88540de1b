#pragma once

// The socket protocol (docs/protocol.md): newline-delimited JSON objects, each
// with a "class". Pure functions: encoders append one complete line (ending in
// '\n') to a caller's buffer, so a server reuses one buffer for every message;
// parseRequest turns one request line into a Request or an error to send back.
//
// Versioning: proto_major changes only when an existing field changes meaning
// or disappears; new fields, classes and commands only bump proto_minor.

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <scaled/daemon/json_write.h>
#include <scaled/daemon/pose.h>
#include <scaled/daemon/report.h>

namespace scaled::daemon {

inline constexpr int kProtoMajor = 1;
// 1: STATUS.camera; 2: STATUS.timing; 3: OBJECTS; 4: POSE (pose, watch "pose");
// 5: STATUS.window_ba
inline constexpr int kProtoMinor = 5;

// The most bytes of a client's text (its "cmd") an ERROR echoes; a longer
// one is cut at a UTF-8 character boundary and marked "truncated":true.
inline constexpr std::size_t kMaxEchoBytes = 64;

// The service's own client counters, for STATUS.
struct ClientCounts {
    int connected = 0;
    int max = 0;  // socket.max_clients
    std::uint64_t accepted = 0;
    std::uint64_t rejected = 0;
    std::uint64_t detached = 0;
    // Additive (issue 22): watchers now (at most `max`), the connections
    // beyond `max` kept for clients that do not watch
    // (socket.reserved_query_slots), connections closed for an incomplete
    // request (request_timeout_s) and idle ones closed to make room.
    int watchers = 0;
    int reserved = 0;
    std::uint64_t timed_out = 0;
    std::uint64_t evicted = 0;
};

// {"class":"VERSION","release":"0.1.0","proto_major":1,"proto_minor":5}
void appendVersion(std::string& out, std::string_view release);
// SCALE; age_s is measured against `now_mono_ns` (CLOCK_MONOTONIC).
void appendScale(std::string& out, const ScaleReport& report, std::int64_t now_mono_ns);
void appendStatus(std::string& out, const PipelineStatus& status, const LogStatus& log,
                  const ClientCounts& clients);
void appendPosterior(std::string& out, const PosteriorSnapshot& posterior);
// OBJECTS (proto_minor 3): the object table of the latest scale update.
void appendObjects(std::string& out, const ObjectsSnapshot& objects);
// The members of one object, `"id":3,"<class_key>":"chair","state":...`
// without braces: the entries of OBJECTS (class_key "class") and the field
// log's OBJECT lines (class_key "object_class"). Numbers with up to `digits`
// significant digits; anchor and anchor_rel_sigma are null while the object
// is tentative, local_estimate when it is 0, height_m and height_ci95_m
// without a height.
void appendObjectMembers(std::string& out, const ObjectReport& object, std::string_view class_key,
                         int digits);
// POSE (proto_minor 4): `pose` in the gravity-aligned frame G, with its
// metric part (position, velocity, position_cov) at the scale of `scale`
// when that report has one of the pose's epoch (metricPose, pose.h), else
// null; `state` is the scale report's. Numbers with 7 significant digits.
// Before the first pose (frame_id -1) every pose member is null.
void appendPose(std::string& out, const PoseReport& pose, const ScaleReport& scale);
// The members of a POSE from "state" to "position_map_cov", each after a
// comma, without braces: the socket's POSE (appendPose) and the field log's
// POSE lines. `metric` is metricPose(pose, the scale report), `state` that
// report's. Numbers with `digits` significant digits, the scale with
// `scale_digits` (0: the shortest that reads back exactly). Pose members are
// null when pose.frame_id < 0, metric ones without metric.has_scale.
void appendPoseMembers(std::string& out, const PoseReport& pose, const MetricPose& metric,
                       DaemonState state, int digits, int scale_digits);
// {"class":"WATCH","enable":true,"pose":false}
void appendWatch(std::string& out, bool enable, bool pose);
void appendAck(std::string& out, std::string_view cmd);
// ERROR; `cmd` is included when non-empty, cut to its first kMaxEchoBytes
// bytes (whole UTF-8 characters) with "truncated":true when longer.
void appendError(std::string& out, std::string_view message, std::string_view cmd = {});

// appendJsonString, appendJsonNumber: <scaled/daemon/json_write.h>.

enum class Command : std::uint8_t {
    kInvalid,  // see Request::error
    kPoll,
    kWatch,
    kStatus,
    kPosterior,
    kSetGravity,
    kObjects,
    kPose,
};
const char* toString(Command command);

struct Request {
    Command command = Command::kInvalid;
    // The "cmd" the client gave (also for unknown commands; empty when none),
    // echoed in ERROR replies.
    std::string cmd;
    bool enable = true;                   // watch: the SCALE stream
    bool pose = false;                    // watch: the POSE stream (proto_minor 4)
    std::array<double, 3> down{0, 0, 0};  // set_gravity: unit vector (normalised here)
    std::string error;                    // kInvalid: the ERROR message
};

// Parses one request line (without its newline). Unknown extra members are
// ignored (clients may be newer than the server). A NUL byte anywhere is an
// error (not the end of the request); a number too large for a double
// (1e400) is read as not finite: for set_gravity's "down" the set_gravity
// error, for another member as if it were null.
Request parseRequest(std::string_view line);

}  // namespace scaled::daemon
