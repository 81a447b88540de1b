#include "json.h"

#include <array>
#include <cmath>
#include <cstdio>

namespace scaled::tools {

std::string jsonString(std::string_view text) {
    std::string out;
    out.reserve(text.size() + 2);
    out += '"';
    for (const char c : text) {
        switch (c) {
            case '"':
                out += "\\\"";
                break;
            case '\\':
                out += "\\\\";
                break;
            case '\n':
                out += "\\n";
                break;
            case '\r':
                out += "\\r";
                break;
            case '\t':
                out += "\\t";
                break;
            default:
                if (static_cast<unsigned char>(c) < 0x20) {
                    std::array<char, 8> buf{};
                    std::snprintf(buf.data(), buf.size(), "\\u%04x",
                                  static_cast<unsigned>(static_cast<unsigned char>(c)));
                    out += buf.data();
                } else {
                    out += c;
                }
        }
    }
    out += '"';
    return out;
}

std::string jsonNumber(double value, int digits) {
    if (!std::isfinite(value)) {
        return "null";
    }
    std::array<char, 64> buf{};
    std::snprintf(buf.data(), buf.size(), "%.*g", digits, value);
    return buf.data();
}

}  // namespace scaled::tools
