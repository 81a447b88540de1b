#pragma once

// Small helpers for the tools' one-line JSON output.

#include <string>
#include <string_view>

namespace scaled::tools {

// `text` as a JSON string literal, quotes included: '"' and '\\' escaped,
// control characters as \n, \t, \uXXXX. Bytes >= 0x80 pass through (UTF-8).
std::string jsonString(std::string_view text);

// A number with up to `digits` significant digits; null when not finite
// (JSON has no NaN or Inf).
std::string jsonNumber(double value, int digits = 6);

}  // namespace scaled::tools
