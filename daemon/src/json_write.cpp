#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>

#include <scaled/daemon/json_write.h>

namespace scaled::daemon {
namespace {

// Length of the valid UTF-8 sequence at s[i] (0 when invalid).
std::size_t utf8Length(std::string_view s, std::size_t i) {
    const auto b0 = static_cast<unsigned char>(s[i]);
    std::size_t n = 0;
    unsigned min = 0;
    unsigned cp = 0;
    if (b0 < 0x80U) {
        return 1;
    }
    if ((b0 & 0xE0U) == 0xC0U) {
        n = 2;
        min = 0x80U;
        cp = b0 & 0x1FU;
    } else if ((b0 & 0xF0U) == 0xE0U) {
        n = 3;
        min = 0x800U;
        cp = b0 & 0x0FU;
    } else if ((b0 & 0xF8U) == 0xF0U) {
        n = 4;
        min = 0x10000U;
        cp = b0 & 0x07U;
    } else {
        return 0;
    }
    if (i + n > s.size()) {
        return 0;
    }
    for (std::size_t k = 1; k < n; ++k) {
        const auto b = static_cast<unsigned char>(s[i + k]);
        if ((b & 0xC0U) != 0x80U) {
            return 0;
        }
        cp = (cp << 6U) | (b & 0x3FU);
    }
    if (cp < min || cp > 0x10FFFFU || (cp >= 0xD800U && cp <= 0xDFFFU)) {
        return 0;
    }
    return n;
}

}  // namespace

void appendJsonNumber(std::string& out, double value) {
    if (!std::isfinite(value)) {
        out += "null";
        return;
    }
    std::array<char, 32> buf{};
    const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), value);
    out.append(buf.data(), res.ptr);
}

void appendJsonNumber(std::string& out, double value, int digits) {
    if (!std::isfinite(value)) {
        out += "null";
        return;
    }
    std::array<char, 64> buf{};
    const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), value,
                                   std::chars_format::general, digits);
    out.append(buf.data(), res.ptr);
}

void appendJsonString(std::string& out, std::string_view text) {
    static constexpr std::string_view kHex = "0123456789abcdef";
    out += '"';
    std::size_t i = 0;
    while (i < text.size()) {
        const auto c = static_cast<unsigned char>(text[i]);
        if (c >= 0x80U) {
            const std::size_t n = utf8Length(text, i);
            if (n == 0) {
                out += "\xEF\xBF\xBD";  // U+FFFD
                ++i;
            } else {
                out.append(text.substr(i, n));
                i += n;
            }
            continue;
        }
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
                if (c < 0x20U || c == 0x7FU) {
                    out += "\\u00";
                    out += kHex[c >> 4U];
                    out += kHex[c & 0xFU];
                } else {
                    out += static_cast<char>(c);
                }
        }
        ++i;
    }
    out += '"';
}

void appendJsonKey(std::string& out, std::string_view name) {
    out += ",\"";
    out += name;
    out += "\":";
}

void appendJsonNumberOr(std::string& out, bool present, double value, int digits) {
    if (!present) {
        out += "null";
    } else if (digits == 0) {
        appendJsonNumber(out, value);
    } else {
        appendJsonNumber(out, value, digits);
    }
}

void appendJsonInterval(std::string& out, bool present, double lo, double hi, int digits) {
    if (!present) {
        out += "null";
        return;
    }
    out += '[';
    appendJsonNumberOr(out, true, lo, digits);
    out += ',';
    appendJsonNumberOr(out, true, hi, digits);
    out += ']';
}

}  // namespace scaled::daemon
