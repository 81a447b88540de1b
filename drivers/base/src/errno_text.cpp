#include <array>
#include <cstring>
#include <string>

#include <scaled/drivers/base/errno_text.h>

namespace scaled::drivers::base {
namespace {

// glibc's GNU strerror_r returns the text (which may be a static string, not
// the buffer); the XSI one returns 0 and fills the buffer. One of these two
// overloads fits whichever the C library declares.
[[maybe_unused]] std::string strerrorText(const char* text, const char* /*buffer*/, int /*err*/) {
    return text;
}
[[maybe_unused]] std::string strerrorText(int rc, const char* buffer, int err) {
    if (rc != 0) {
        return "error " + std::to_string(err);
    }
    return buffer;
}

}  // namespace

std::string errnoText(int err) {
    std::array<char, 256> buffer{};
    return strerrorText(strerror_r(err, buffer.data(), buffer.size()), buffer.data(), err);
}

}  // namespace scaled::drivers::base
