#pragma once

// Small helpers for the tools' one-line JSON output (the daemon's JSON writer,
// <scaled/daemon/json_write.h>, returning strings).

#include <optional>
#include <string>
#include <string_view>

namespace scaled::tools {

// `text` as a JSON string literal, quotes included: '"' and '\\' escaped,
// control characters as \n, \t, \u00XX; valid UTF-8 passes through, invalid
// bytes become U+FFFD (daemon::appendJsonString).
std::string jsonString(std::string_view text);

// A number with up to `digits` significant digits (%.*g); null when not finite
// (JSON has no NaN or Inf) (daemon::appendJsonNumber).
std::string jsonNumber(double value, int digits = 6);

// jsonNumber(*value, digits), or `absent` when there is no value ("null" in a
// JSON object, "" in a CSV field).
std::string jsonNumberOr(std::optional<double> value, int digits, std::string_view absent);

}  // namespace scaled::tools
