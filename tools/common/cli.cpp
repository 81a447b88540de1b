#include "cli.h"

#include <cstdio>
#include <exception>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "sysexits.h"

namespace scaled::tools {

void configureApp(CLI::App& app, std::string footer) {
    app.footer(std::move(footer));
    app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    app.allow_extras();
}

std::optional<int> parseArgs(CLI::App& app, int argc, const char* const* argv) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() != 0) {
            return usageError(app, e.what());
        }
        std::cout << app.help() << std::flush;  // --help
        return 0;
    }
    const std::vector<std::string> extra = app.remaining();
    if (extra.empty()) {
        return std::nullopt;
    }
    const std::string& first = extra.front();
    if (first.size() > 1 && first.front() == '-') {
        return usageError(app, "unknown option " + first);
    }
    return usageError(app, "unexpected argument '" + first + "'");
}

int usageError(const CLI::App& app, std::string_view message) {
    const std::string& name = app.get_name();
    std::cerr << name << ": " << message << "\nRun '" << name << " --help' for the options.\n"
              << std::flush;
    return kExUsage;
}

std::string badValue(std::string_view option, std::string_view value) {
    return "bad value for " + std::string(option) + ": '" + std::string(value) + "'";
}

int runGuarded(const char* tool, int (*run)(int, char**), int argc, char** argv) {
    try {
        return run(argc, argv);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: internal error: %s\n", tool, e.what());
    } catch (...) {
        std::fprintf(stderr, "%s: internal error: an exception not derived from std::exception\n",
                     tool);
    }
    return kExSoftware;
}

}  // namespace scaled::tools
