#pragma once

// Appending JSON values to a caller's buffer: the one JSON writer of the
// socket protocol, the field log and the tools' JSON output.

#include <array>
#include <charconv>
#include <string>
#include <string_view>

namespace scaled::daemon {

// Appends `text` as a JSON string literal (quotes included). Invalid UTF-8
// becomes U+FFFD, control characters are escaped ('"', '\\', \n, \r, \t, the
// rest as \u00XX, DEL included).
void appendJsonString(std::string& out, std::string_view text);

// Appends a number in the shortest form that reads back exactly; non-finite
// values become null (JSON has no NaN or Inf).
void appendJsonNumber(std::string& out, double value);

// Appends a number with up to `digits` significant digits (printf's %.*g);
// non-finite values become null.
void appendJsonNumber(std::string& out, double value, int digits);

// Appends `,"name":` (a member after the first of an object).
void appendJsonKey(std::string& out, std::string_view name);

// Appends `value` (digits == 0: the shortest exact form, else up to `digits`
// significant digits), or null when `present` is false.
void appendJsonNumberOr(std::string& out, bool present, double value, int digits = 0);

// Appends `[lo,hi]` (digits as above), or null when `present` is false: the
// credible intervals of the protocol and the field log.
void appendJsonInterval(std::string& out, bool present, double lo, double hi, int digits = 0);

// Appends an integer.
template <typename Int>
void appendJsonInt(std::string& out, Int value) {
    std::array<char, 24> buf{};
    const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), value);
    out.append(buf.data(), res.ptr);
}

}  // namespace scaled::daemon
