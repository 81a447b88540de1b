#pragma once

// Small helpers shared by the TOML readers (drivers/src/priors_toml.cpp,
// daemon/src/pipeline_config.cpp, daemon/src/daemon_config.cpp): parsing with
// errors that name source, line and column, errors at a node's line, and how
// a value is shown in a message.
//
// Not part of the drivers' public API: it includes toml++, which only the
// .cpp files of drivers and daemon can see (tomlplusplus is linked PRIVATE).

#include <optional>
#include <sstream>
#include <string>
#include <string_view>

#include <toml++/toml.h>

#include <scaled/core/result.h>

namespace scaled::drivers::priors::tomlread {

// A value as the user wrote it, for "(got ...)": strings quoted, arrays and
// tables by kind.
inline std::string show(const toml::node& n) {
    std::ostringstream os;
    if (n.is_string()) {
        os << '"' << n.as_string()->get() << '"';
    } else if (n.is_array()) {
        os << "an array";
    } else if (n.is_table()) {
        os << "a table";
    } else {
        n.visit([&](const auto& v) { os << v; });
    }
    return os.str();
}

// A number as the shortest readable text (ostream's default precision).
inline std::string num(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

// An integer or floating-point node as a double; nullopt for anything else.
inline std::optional<double> asNumber(const toml::node& n) {
    if (const auto* f = n.as_floating_point()) {
        return f->get();
    }
    if (const auto* i = n.as_integer()) {
        return static_cast<double>(i->get());
    }
    return std::nullopt;
}

// `SOURCE[:LINE]: KEY: WHAT`, the line being the node's (none without one).
inline core::Error errorAt(core::ErrorCode code, std::string_view source, const toml::node* node,
                           const std::string& key, const std::string& what) {
    std::string where(source);
    if (node != nullptr && node->source().begin.line > 0) {
        where += ":" + std::to_string(node->source().begin.line);
    }
    return core::makeError(code, where + ": " + key + ": " + what);
}

// Parses a document; a syntax error reads `SOURCE:LINE:COLUMN: description`.
inline core::Result<toml::table> parse(std::string_view text, std::string_view source) {
    try {
        return toml::parse(text, source);
    } catch (const toml::parse_error& e) {
        return core::makeError(core::ErrorCode::kParse,
                               std::string(source) + ":" + std::to_string(e.source().begin.line) +
                                   ":" + std::to_string(e.source().begin.column) + ": " +
                                   std::string(e.description()));
    }
}

}  // namespace scaled::drivers::priors::tomlread
