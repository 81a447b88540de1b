#pragma once

// The command line of the tools, on CLI11 and in the daemon's style
// (daemon/src/daemon_config.cpp): --help prints CLI11's help on stdout (a
// description, the options, a footer with what the tool does and its exit
// codes) and exits 0; a usage error is one line on stderr naming the option and
// the bad value, then "Run 'TOOL --help' for the options.", exit 64 (EX_USAGE).

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace scaled::tools {

// Sets the help's footer and the tools' conventions: an option given twice
// keeps its last value (repeatable options say TakeAll themselves), and
// arguments CLI11 does not know are left to parseArgs (its own wording).
void configureApp(CLI::App& app, std::string footer);

// Parses argv into `app`. nullopt: go on; else main's exit code, its output
// printed: 0 after --help, kExUsage after a usage error ("X needs a value",
// "unknown option X", "unexpected argument 'X'", else CLI11's message).
std::optional<int> parseArgs(CLI::App& app, int argc, const char* const* argv);

// "TOOL: message" and "Run 'TOOL --help' for the options." on stderr
// (TOOL: the app's name); returns kExUsage.
int usageError(const CLI::App& app, std::string_view message);

// "bad value for OPTION: 'VALUE'", the usage error of a value that does not parse.
std::string badValue(std::string_view option, std::string_view value);

// Returns run(argc, argv), a tool's whole main, with no exception escaping: one
// that reaches here is said on stderr ("TOOL: internal error: ...") and the
// exit code is kExSoftware.
int runGuarded(const char* tool, int (*run)(int, char**), int argc, char** argv);

// One option of a tool whose value is checked by the tool: CLI11 keeps the
// text, `take` converts and checks it (false: a bad value, the usage error
// "OPTION: " + bad_value with {} standing for the value, or badValue(OPTION,
// VALUE) when bad_value is not given).
template <typename Options>
struct OptionSpec {
    const char* name = nullptr;       // "--frames", "-v,--verbose"
    const char* type_name = nullptr;  // "A:B"; nullptr: a flag (take gets "")
    const char* help = nullptr;
    bool (*take)(std::string_view value, Options& options) = nullptr;
    const char* bad_value = nullptr;  // "expected on or off, got '{}'"
};

// --camera FILE, shared by the tools that read a dataset: the path into
// Options::camera_file (read by the tool, which owns the dataset library).
template <typename Options>
constexpr OptionSpec<Options> cameraFileOption() {
    return {"--camera", "FILE",
            "intrinsics `width height fx fy cx cy [k1 k2]` (camera.txt\n"
            "format); overrides the dataset's",
            [](std::string_view v, Options& o) {
                o.camera_file = std::string(v);
                return !o.camera_file.empty();
            }};
}

// A tool's options as a table of OptionSpecs. Every option may be given more
// than once; takeInto applies them in the order of the command line, as the
// hand-written parsers did: a later value overrides an earlier one (or adds to
// it: --set, --blank), and the first bad value is the usage error.
template <typename Options>
class OptionTable {
public:
    explicit OptionTable(std::span<const OptionSpec<Options>> specs) : specs_(specs) {}

    void addTo(CLI::App& app) {
        for (const OptionSpec<Options>& spec : specs_) {
            const std::string help(spec.help);
            CLI::Option* option = nullptr;
            if (spec.type_name == nullptr) {
                option = app.add_flag(spec.name, help)->disable_flag_override();
            } else {
                option = app.add_option(spec.name, CLI::callback_t{}, help)
                             ->type_name(spec.type_name)
                             ->allow_extra_args(false);
            }
            option->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
            options_.push_back(option);
        }
    }

    // nullopt when every value is good, else the usage error.
    std::optional<std::string> takeInto(const CLI::App& app, Options& out) const {
        std::vector<std::size_t> taken(options_.size(), 0);
        for (const CLI::Option* option : app.parse_order()) {
            const auto it = std::find(options_.begin(), options_.end(), option);
            if (it == options_.end()) {
                continue;  // an option the tool added itself
            }
            const auto i = static_cast<std::size_t>(it - options_.begin());
            const OptionSpec<Options>& spec = specs_[i];
            std::string value;
            if (spec.type_name != nullptr) {
                value = option->results().at(taken[i]++);
            }
            if (!spec.take(value, out)) {
                if (spec.bad_value == nullptr) {
                    return badValue(option->get_name(), value);
                }
                std::string message = option->get_name() + ": " + spec.bad_value;
                if (const auto at = message.find("{}"); at != std::string::npos) {
                    message.replace(at, 2, value);
                }
                return message;
            }
        }
        return std::nullopt;
    }

private:
    std::span<const OptionSpec<Options>> specs_;
    std::vector<const CLI::Option*> options_;
};

// A tool's whole command line: `app` configured with the footer, the
// OptionSpecs added, argv parsed and every value taken into `options` in
// command-line order. nullopt: go on; else main's exit code, the help or the
// usage error printed.
template <typename Options, std::size_t N>
std::optional<int> parseToolOptions(CLI::App& app, std::string footer,
                                    const OptionSpec<Options> (&specs)[N], int argc,
                                    const char* const* argv, Options& options) {
    configureApp(app, std::move(footer));
    OptionTable<Options> table(specs);
    table.addTo(app);
    if (auto rc = parseArgs(app, argc, argv)) {
        return rc;
    }
    if (auto bad = table.takeInto(app, options)) {
        return usageError(app, *bad);
    }
    return std::nullopt;
}

}  // namespace scaled::tools
