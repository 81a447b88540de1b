#include "cli.h"

#include <cstddef>
#include <cstdio>
#include <exception>
#include <iostream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sysexits.h"

namespace scaled::tools {

void configureApp(CLI::App& app, std::string footer) {
    app.footer(std::move(footer));
    app.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    app.allow_extras();
}

namespace {

// An option that takes a value given last, or followed by another option:
// "OPTION needs a value" (the hand-written parsers' words); else nullopt.
std::optional<std::string> missingValue(const CLI::App& app, int argc, const char* const* argv) {
    const std::vector<std::string_view> args(argv + 1, argv + argc);
    for (std::size_t i = 0; i < args.size(); ++i) {
        if (args[i] == "--") {
            break;
        }
        const CLI::Option* option = app.get_option_no_throw(std::string(args[i]));
        if (option == nullptr || option->get_items_expected_min() == 0) {
            continue;  // not an option of the app, or a flag
        }
        if (i + 1 == args.size() || app.get_option_no_throw(std::string(args[i + 1])) != nullptr) {
            return std::string(args[i]) + " needs a value";
        }
        ++i;
    }
    return std::nullopt;
}

}  // namespace

std::optional<int> parseArgs(CLI::App& app, int argc, const char* const* argv) {
    if (auto missing = missingValue(app, argc, argv)) {
        return usageError(app, *missing);
    }
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
