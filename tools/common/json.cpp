#include "json.h"

#include <scaled/daemon/json_write.h>

namespace scaled::tools {

std::string jsonString(std::string_view text) {
    std::string out;
    out.reserve(text.size() + 2);
    daemon::appendJsonString(out, text);
    return out;
}

std::string jsonNumber(double value, int digits) {
    std::string out;
    daemon::appendJsonNumber(out, value, digits);
    return out;
}

std::string jsonNumberOr(std::optional<double> value, int digits, std::string_view absent) {
    return value ? jsonNumber(*value, digits) : std::string(absent);
}

}  // namespace scaled::tools
