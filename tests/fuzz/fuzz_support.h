#pragma once

// Helpers of the libFuzzer targets (tests/fuzz, docs/fuzzing.md).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

namespace scaled::fuzz {

// The fuzzer's bytes as text (any bytes, NUL included).
inline std::string_view asText(const std::uint8_t* data, std::size_t size) {
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-reinterpret-cast)
    return {reinterpret_cast<const char*>(data), size};
}

// A property of the code under test. A failure aborts, which libFuzzer
// reports as a crash and saves the input (then: tests/fuzz/regressions/NAME/).
inline void check(bool ok, const char* what) {
    if (!ok) {
        std::fputs("fuzz check failed: ", stderr);
        std::fputs(what, stderr);
        std::fputc('\n', stderr);
        std::abort();
    }
}

inline bool startsWith(std::string_view s, std::string_view prefix) {
    return s.substr(0, prefix.size()) == prefix;
}

inline bool isFinite(double x) {
    return std::isfinite(x);
}

}  // namespace scaled::fuzz
