// The socket protocol's request parser (daemon: parseRequest, protocol.cpp) on
// any bytes a client may send as one line, and the ERROR reply that echoes
// the client's "cmd" back, whole or cut (docs/protocol.md).

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

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
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
        // A long "cmd" is echoed cut to a UTF-8 prefix, with "truncated":true.
        const auto cmd = doc.find("cmd");
        check(cmd != doc.end() && cmd->is_string(), "ERROR echoes \"cmd\"");
        const auto& echoed = cmd->get_ref<const std::string&>();
        const auto truncated = doc.find("truncated");
        if (truncated != doc.end()) {
            check(*truncated == true, "\"truncated\" is true when present");
            check(echoed.size() < r.cmd.size() && scaled::fuzz::startsWith(r.cmd, echoed),
                  "a truncated echo is a prefix of \"cmd\"");
        } else {
            check(echoed == r.cmd, "ERROR echoes \"cmd\" exactly");
        }
    }
    return 0;
}
