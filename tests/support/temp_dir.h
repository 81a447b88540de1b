#pragma once

// A temporary directory for one test, removed with everything in it when the
// object goes out of scope. The name carries the tag, the test's name, the
// process id and a counter, so parallel test processes never share one.

#include <algorithm>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <unistd.h>

#include <gtest/gtest.h>

namespace scaled::test {

class TempDir {
public:
    explicit TempDir(std::string_view tag) {
        static int counter = 0;
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        std::string name = "scaled_" + std::string(tag) + "_" +
                           (info != nullptr ? std::string(info->name()) : std::string("x")) + "_" +
                           std::to_string(::getpid()) + "_" + std::to_string(counter++);
        std::replace(name.begin(), name.end(), '/', '_');
        path_ = std::filesystem::temp_directory_path() / name;
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
        std::filesystem::create_directories(path_);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    TempDir(TempDir&&) = delete;
    TempDir& operator=(TempDir&&) = delete;
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(path_, ec);
    }
    [[nodiscard]] const std::filesystem::path& path() const { return path_; }

private:
    std::filesystem::path path_;
};

}  // namespace scaled::test
