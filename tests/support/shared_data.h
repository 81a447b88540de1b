#pragma once

// Where the real data lives (../shared, or $SCALED_SHARED_DIR), and a skip
// for tests that need it.

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>

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

}  // namespace scaled::test

// Skips the current test when a dataset under ../shared/data is absent.
#define SCALED_REQUIRE_DATASET(dir, name)                                                  \
    const std::filesystem::path dir = ::scaled::test::sharedDataset(name);                 \
    if (!std::filesystem::is_directory(dir)) {                                             \
        GTEST_SKIP() << "data/" << (name) << " not found in "                              \
                     << ::scaled::test::sharedDir().string() << ", set SCALED_SHARED_DIR"; \
    }
