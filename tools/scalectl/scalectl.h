#pragma once

// scalectl's logic: the client of the daemon's UNIX socket (newline-delimited
// JSON, docs/protocol.md), the parsing of its reply lines, the human-readable
// formatting and the exit-code decisions. main.cpp only parses argv and calls
// run().
//
// Exit codes (sysexits): 0 ok; 64 usage; 69 the daemon cannot be reached, does
// not answer within --timeout or closes the connection early; 75 `get
// --require-converged` and the state is not converged; 76 a malformed reply, a
// proto_major other than 1, an ERROR reply or a daemon whose proto_minor is
// below what the command needs (`objects` 3, `pose` and `watch --pose` 4).

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <ostream>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/base/unique_fd.h>

namespace scaled::tools::scalectl {

// The protocol major version this client speaks.
inline constexpr int kProtoMajor = 1;
inline constexpr const char* kDefaultSocket = "/run/scaled/scaled.sock";
inline constexpr double kDefaultTimeoutS = 5.0;

// $SCALED_SOCKET when set and not empty, else /run/scaled/scaled.sock.
std::string defaultSocketPath();

// ---- reply lines ----------------------------------------------------------
// Every parse* returns an Error with ErrorCode::kParse for a malformed line
// (not JSON, not an object, no "class", a field of the wrong type), a line of
// another class than expected, a proto_major other than 1 or an ERROR reply
// (its message in the Error). Unknown fields are ignored: the schema is additive.

// The "class" of a line (kParse when it has none).
core::Result<std::string> replyClass(std::string_view line);

struct VersionReply {
    std::string release;
    int proto_major = 0;
    int proto_minor = 0;
};
core::Result<VersionReply> parseVersion(std::string_view line);

struct Interval {
    double lo = 0.0;
    double hi = 0.0;
};

struct ScaleReply {
    std::optional<double> scale;  // metres per SLAM unit; none before the first estimate
    std::optional<double> mean;
    std::optional<Interval> ci68;
    std::optional<Interval> ci95;
    std::string state;  // initialising | tracking | converging | converged | lost | fault
    std::int64_t epoch = 0;
    std::int64_t observations = 0;
    std::int64_t frame_id = 0;
    std::optional<double> age_s;
    std::string fault;  // empty unless the daemon reports one
};
core::Result<ScaleReply> parseScale(std::string_view line);

struct PosteriorReply {
    std::int64_t epoch = 0;
    std::int64_t frame_id = 0;
    std::int64_t observations = 0;
    std::vector<double> d;
    std::vector<double> log_p;  // same length as d
};
core::Result<PosteriorReply> parsePosterior(std::string_view line);

// POSE (proto_minor 4): the camera pose in the gravity-aligned frame G
// (docs/protocol.md). Metric members are absent while the epoch has no scale,
// every pose member before the first pose.
struct PoseReply {
    std::int64_t epoch = 0;
    std::int64_t frame_id = -1;
    std::string state;
    std::optional<double> scale;
    std::optional<double> scale_sigma;
    std::optional<std::array<double, 3>> position;      // m
    std::optional<std::array<double, 3>> velocity;      // m/s
    std::optional<std::array<double, 9>> position_cov;  // m^2, row-major
    std::optional<std::array<double, 4>> orientation;   // [w, x, y, z], camera to G
    std::optional<std::array<double, 3>> position_map;  // SLAM units
    std::optional<std::array<double, 3>> velocity_map;  // SLAM units/s
};
core::Result<PoseReply> parsePose(std::string_view line);

// The camera's heading from a POSE orientation, degrees: yaw of the optical
// axis from G's x towards y (left), pitch of the optical axis above the
// horizontal, roll about it (positive: the image's right side down).
struct YawPitchRoll {
    double yaw_deg = 0;
    double pitch_deg = 0;
    double roll_deg = 0;
};
YawPitchRoll yawPitchRoll(const std::array<double, 4>& wxyz);

// ---- formatting -----------------------------------------------------------

// One line, no newline:
//   scale 0.9760 m/unit  95% [0.9640, 0.9880]  converged  epoch 1  obs 137  age 0.4 s
//   scale -  tracking  epoch 0  obs 0
// A fault is appended as `  fault: TEXT`.
std::string formatScale(const ScaleReply& scale);

// The STATUS line as a readable multi-line summary (each line ends in '\n');
// absent fields show as `-`.
core::Result<std::string> formatStatus(std::string_view line);

// One line, no newline:
//   pose 512  pos 1.220 -0.391 0.303 m  1-sigma 0.042 0.021 0.017 m  ypr 30.0 -10.0 0.0 deg
//     vel 0.195 0.049 0.000 m/s  converging  epoch 1
// (one line), without a scale `pos - (map 0.053 0.001 -0.002 units)` and
// `vel -`, before the first pose `pose -  initialising  epoch 0`.
std::string formatPose(const PoseReply& pose);

// The protocol minor version that added POSE.
inline constexpr int kPoseProtoMinor = 4;

// `d<TAB>log_p` rows, one per grid point, each ending in '\n'.
std::string formatPosterior(const PosteriorReply& posterior);

// The OBJECTS line (proto_minor 3) as a table (each line ends in '\n'): a
// header line (model, epoch, frame, counts), then one row per object: id,
// class, state, views used/detections, local estimate, height with its 95%
// bounds, anchor (map units) and its relative sigma; `-` for a null. The
// paper model says it keeps no object table. kParse when `objects` is not an
// array of objects.
core::Result<std::string> formatObjects(std::string_view line);

// The protocol minor version that added the `objects` request.
inline constexpr int kObjectsProtoMinor = 3;

// ---- exit codes -----------------------------------------------------------

// The exit code for a failed request: kParse -> 76 (EX_PROTOCOL),
// kInvalidArgument -> 64 (EX_USAGE), everything else (kIo, kNotFound: no
// socket, refused, timed out, closed early) -> 69 (EX_UNAVAILABLE).
int exitCodeFor(const core::Error& error);

// The exit code of `get`: 75 (EX_TEMPFAIL) when converged is required and the
// state is not "converged", else 0.
int getExitCode(const ScaleReply& scale, bool require_converged);

// ---- the connection -------------------------------------------------------

using Clock = std::chrono::steady_clock;

// A connected UNIX stream socket reading and writing lines. Every wait has a
// deadline (none: wait for ever). When an interrupt fd is set, a readable
// interrupt fd ends a wait with ErrorCode::kDegenerate ("interrupted").
class Client {
public:
    Client() = default;
    Client(const Client&) = delete;
    Client& operator=(const Client&) = delete;
    Client(Client&& other) noexcept = default;
    Client& operator=(Client&& other) noexcept = default;
    ~Client() = default;

    // kNotFound: no socket file; kIo: refused, permission denied, timed out;
    // kInvalidArgument: the path is too long for a UNIX socket address.
    static core::Result<Client> connect(const std::string& path,
                                        std::optional<Clock::time_point> deadline);

    void setInterruptFd(int fd) { interrupt_fd_ = fd; }

    // Sends `line` plus '\n'.
    core::Status sendLine(std::string_view line, std::optional<Clock::time_point> deadline);

    // The next line without its '\n'. kIo with "closed" in the message when
    // the peer closed the connection (`eof()` is then true), kIo on a timeout,
    // kParse when a line exceeds kMaxLineBytes.
    core::Result<std::string> readLine(std::optional<Clock::time_point> deadline);

    [[nodiscard]] bool eof() const { return eof_; }
    [[nodiscard]] int fd() const { return fd_.get(); }

    static constexpr std::size_t kMaxLineBytes = 16u << 20;

private:
    explicit Client(int fd) : fd_(fd) {}
    // Waits for `events` on the socket: ok when ready, an error on timeout,
    // interruption or a failed poll.
    core::Status waitFor(short events, std::optional<Clock::time_point> deadline);

    drivers::base::UniqueFd fd_;
    int interrupt_fd_ = -1;
    bool eof_ = false;
    std::string buffer_;
};

// ---- the commands ---------------------------------------------------------

enum class Command : std::uint8_t { kGet, kWatch, kStatus, kPosterior, kObjects, kPose };

struct Options {
    std::string socket_path = kDefaultSocket;
    bool json = false;
    // --timeout: bounds every wait. Unset: 5 s for connecting and replies,
    // no bound between the lines of `watch`.
    std::optional<double> timeout_s;
    Command command = Command::kGet;
    bool require_converged = false;     // get
    std::optional<std::int64_t> count;  // watch: stop after N SCALE (or POSE) lines
    bool pose = false;                  // watch --pose: the POSE stream instead of SCALE
    int interrupt_fd = -1;              // readable: stop waiting (SIGINT/SIGTERM)
};

// Runs one command: connects, checks the VERSION greeting, sends the request,
// writes the result to `out` (flushed per line) and messages to `err`
// (prefixed "scalectl: "). Returns the exit code.
int run(const Options& options, std::ostream& out, std::ostream& err);

}  // namespace scaled::tools::scalectl
