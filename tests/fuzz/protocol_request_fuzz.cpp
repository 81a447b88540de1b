// The socket protocol's request parser (daemon: parseRequest, protocol.cpp) on
// any bytes a client may send as one line, and the ERROR reply that echoes
// the client's "cmd" back (docs/protocol.md).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include <scaled/daemon/protocol.h>

#include "fuzz_support.h"

using scaled::daemon::Command;
using scaled::fuzz::check;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view line = scaled::fuzz::asText(data, size);
    const scaled::daemon::Request r = scaled::daemon::parseRequest(line);
    if (r.command == Command::kInvalid) {
        check(!r.error.empty(), "an invalid request carries an error message");
    } else {
        check(r.error.empty(), "a valid request carries no error message");
        check(r.cmd == scaled::daemon::toString(r.command), "the command is the \"cmd\" given");
    }
    if (r.command == Command::kSetGravity) {
        const double norm =
            std::sqrt(r.down[0] * r.down[0] + r.down[1] * r.down[1] + r.down[2] * r.down[2]);
        check(std::abs(norm - 1) < 1e-9, "set_gravity's down is a unit vector");
    }

    // The reply to a bad request echoes "cmd" (whatever the client wrote):
    // one line of valid JSON that reads back the same.
    std::string out;
    scaled::daemon::appendError(out, r.error.empty() ? "fuzz" : r.error, r.cmd);
    check(!out.empty() && out.find('\n') == out.size() - 1, "ERROR is one line ending in \\n");
    const auto doc = nlohmann::json::parse(out.begin(), out.end() - 1, nullptr, false);
    check(!doc.is_discarded() && doc.is_object(), "ERROR is a JSON object");
    if (!r.cmd.empty()) {
        const auto cmd = doc.find("cmd");
        check(cmd != doc.end() && cmd->is_string() && cmd->get<std::string>() == r.cmd,
              "ERROR echoes \"cmd\" exactly");
    }
    return 0;
}
