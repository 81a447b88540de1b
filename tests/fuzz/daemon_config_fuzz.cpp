// The daemon's configuration loader (applyDaemonToml, daemon_config.cpp) on
// any text: an error leaves the configuration unchanged (as documented), and
// a configuration it accepts, written back with toToml, reads back the same.
// toToml costs several times the parse, so the unchanged-on-error check runs
// on one input in 8 (chosen by the input's bytes: a crash reproduces).

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

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const std::string kDefaultToml = toToml(defaultDaemonConfig());
    static const std::filesystem::path kBase = "/nonexistent/fuzz";
    const std::string_view text = scaled::fuzz::asText(data, size);

    DaemonConfig config = defaultDaemonConfig();
    const auto applied = applyDaemonToml(text, "fuzz.toml", kBase, config);
    if (!applied) {
        check(!applied.error().message.empty(), "an error has a message");
        std::uint32_t hash = 2166136261U;  // FNV-1a
        for (std::size_t i = 0; i < size; ++i) {
            hash = (hash ^ data[i]) * 16777619U;
        }
        if (hash % 8 == 0) {
            check(toToml(config) == kDefaultToml, "on error the configuration is unchanged");
        }
        return 0;
    }
    const std::string written = toToml(config);
    DaemonConfig again = defaultDaemonConfig();
    const auto reread = applyDaemonToml(written, "written.toml", kBase, again);
    check(reread.ok(), "toToml's output of an accepted configuration is accepted");
    check(toToml(again) == written, "toToml's output reads back to the same configuration");
    return 0;
}
