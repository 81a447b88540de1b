// The daemon's configuration loader (applyDaemonToml, daemon_config.cpp) on
// any text: an error leaves the configuration unchanged (as documented), and
// a configuration it accepts, written back with toToml, reads back the same.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <scaled/daemon/daemon_config.h>

#include "fuzz_support.h"

using scaled::daemon::applyDaemonToml;
using scaled::daemon::DaemonConfig;
using scaled::daemon::defaultDaemonConfig;
using scaled::fuzz::check;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const std::string kDefaultToml = toToml(defaultDaemonConfig());
    static const std::filesystem::path kBase = "/nonexistent/fuzz";
    const std::string_view text = scaled::fuzz::asText(data, size);

    DaemonConfig config = defaultDaemonConfig();
    const auto applied = applyDaemonToml(text, "fuzz.toml", kBase, config);
    const std::string written = toToml(config);
    if (!applied) {
        check(!applied.error().message.empty(), "an error has a message");
        check(written == kDefaultToml, "on error the configuration is unchanged");
        return 0;
    }
    DaemonConfig again = defaultDaemonConfig();
    const auto reread = applyDaemonToml(written, "written.toml", kBase, again);
    check(reread.ok(), "toToml's output of an accepted configuration is accepted");
    check(toToml(again) == written, "toToml's output reads back to the same configuration");
    return 0;
}
