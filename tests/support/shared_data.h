#pragma once

// A skip for tests that need data from ../shared (see shared_dir.h).

#include <filesystem>

#include <gtest/gtest.h>

#include "shared_dir.h"

// Skips the current test when a dataset under ../shared/data is absent.
#define SCALED_REQUIRE_DATASET(dir, name)                                                  \
    const std::filesystem::path dir = ::scaled::test::sharedDataset(name);                 \
    if (!std::filesystem::is_directory(dir)) {                                             \
        GTEST_SKIP() << "data/" << (name) << " not found in "                              \
                     << ::scaled::test::sharedDir().string() << ", set SCALED_SHARED_DIR"; \
    }

// Skips the current test when a model file under ../shared/models is absent.
#define SCALED_REQUIRE_MODEL(file, name)                                                   \
    const std::filesystem::path file = ::scaled::test::sharedModel(name);                  \
    if (!std::filesystem::is_regular_file(file)) {                                         \
        GTEST_SKIP() << "models/" << (name) << " not found in "                            \
                     << ::scaled::test::sharedDir().string() << ", set SCALED_SHARED_DIR"; \
    }
