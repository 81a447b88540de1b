#pragma once

// Where the real data lives: ../shared next to the source tree, or
// $SCALED_SHARED_DIR. No test framework here, so benchmarks can use it too.

#include <cstdlib>
#include <filesystem>

namespace scaled::test {

inline std::filesystem::path sharedDir() {
    if (const char* env = std::getenv("SCALED_SHARED_DIR"); env != nullptr && *env != '\0') {
        return env;
    }
    return std::filesystem::path(SCALED_SOURCE_DIR) / ".." / "shared";
}

inline std::filesystem::path sharedDataset(const char* name) {
    return sharedDir() / "data" / name;
}

inline std::filesystem::path sharedModel(const char* name) {
    return sharedDir() / "models" / name;
}

}  // namespace scaled::test
