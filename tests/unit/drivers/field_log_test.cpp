// The field log's files: naming, rotation, the total cap, restarts, faults
// (a real ENOSPC from /dev/full) and the reader on partial and garbage lines.

#include <cerrno>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/drivers/fieldlog/field_log.h>

#include "temp_dir.h"

namespace scaled::drivers::fieldlog {
namespace {

using test::TempDir;
namespace fs = std::filesystem;

constexpr std::int64_t kT0 = 1700000000;  // 2023-11-14T22:13:20Z

// A JSON line of exactly `bytes` bytes including its newline.
std::string lineOf(int n, std::size_t bytes) {
    std::string s = "{\"n\":" + std::to_string(n) + ",\"pad\":\"";
    const std::size_t fixed = s.size() + 3;  // "}\n
    EXPECT_GE(bytes, fixed);
    s.append(bytes - fixed, 'x');
    s += "\"}\n";
    return s;
}

FieldLogWriterOptions options(const fs::path& dir, std::uint64_t max_file,
                              std::uint64_t max_total) {
    FieldLogWriterOptions o;
    o.dir = dir;
    o.max_file_bytes = max_file;
    o.max_total_bytes = max_total;
    o.utc_now_s = [] { return kT0; };
    return o;
}

void writeFile(const fs::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
}

// The "n" of each line read back, in order.
std::vector<int> numbers(const FieldLogContents& c) {
    std::vector<int> n;
    for (const auto& l : c.lines) {
        const auto p = l.text.find("\"n\":");
        n.push_back(p == std::string::npos ? -1 : std::stoi(l.text.substr(p + 4)));
    }
    return n;
}

TEST(FieldLogWriter, FileNamesAreUtcAndSequenced) {
    EXPECT_EQ(fieldLogFileName(0, 1), "scaled-19700101T000000Z-000001.jsonl");
    EXPECT_EQ(fieldLogFileName(kT0, 42), "scaled-20231114T221320Z-000042.jsonl");
    EXPECT_EQ(fieldLogFileName(kT0, 1234567), "scaled-20231114T221320Z-1234567.jsonl");
}

TEST(FieldLogWriter, CreatesDirectoryAndFirstFile) {
    TempDir tmp("field_log");
    const fs::path dir = tmp.path() / "a" / "b";
    auto w = FieldLogWriter::open(options(dir, 1000, 10000));
    ASSERT_TRUE(w) << w.error().message;
    EXPECT_TRUE(fs::is_directory(dir));
    EXPECT_EQ((*w)->currentPath(), dir / fieldLogFileName(kT0, 1));
    EXPECT_TRUE(fs::exists((*w)->currentPath()));
    ASSERT_TRUE((*w)->write(lineOf(0, 50)));
    ASSERT_TRUE((*w)->sync());
    EXPECT_EQ(fs::file_size((*w)->currentPath()), 50u);
    EXPECT_EQ((*w)->bytesWritten(), 50u);
}

TEST(FieldLogWriter, RotatesBeforeAFilePassesTheLimit) {
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 100, 1u << 20));
    ASSERT_TRUE(w) << w.error().message;
    // 10 lines of 30 bytes, in batches of 2: 3 lines (90 bytes) fit a file.
    for (int i = 0; i < 10; i += 2) {
        ASSERT_TRUE((*w)->write(lineOf(i, 30) + lineOf(i + 1, 30)));
    }
    const auto files = listFieldLogFiles(tmp.path());
    ASSERT_EQ(files.size(), 4u);
    for (std::size_t i = 0; i < files.size(); ++i) {
        EXPECT_EQ(files[i].sequence, i + 1);
        EXPECT_LE(files[i].bytes, 100u) << files[i].path;
    }
    EXPECT_EQ(files[0].bytes, 90u);
    EXPECT_EQ(files[3].bytes, 30u);
    auto read = readFieldLog(tmp.path());
    ASSERT_TRUE(read) << read.error().message;
    EXPECT_EQ(numbers(*read), (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
    EXPECT_EQ(read->corrupt_lines, 0u);
    EXPECT_EQ(read->partial_lines, 0u);
}

TEST(FieldLogWriter, ALineLongerThanAFileGetsOneOfItsOwn) {
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 100, 1u << 20));
    ASSERT_TRUE(w);
    ASSERT_TRUE((*w)->write(lineOf(0, 30)));
    ASSERT_TRUE((*w)->write(lineOf(1, 250) + lineOf(2, 30)));
    const auto files = listFieldLogFiles(tmp.path());
    ASSERT_EQ(files.size(), 3u);
    EXPECT_EQ(files[0].bytes, 30u);
    EXPECT_EQ(files[1].bytes, 250u);
    EXPECT_EQ(files[2].bytes, 30u);
}

TEST(FieldLogWriter, RefusesABatchThatDoesNotEndWithANewline) {
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 100, 1000));
    ASSERT_TRUE(w);
    auto r = (*w)->write("{\"a\":1}");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().code, core::ErrorCode::kInvalidArgument);
    EXPECT_FALSE((*w)->faulted());
    EXPECT_EQ((*w)->currentBytes(), 0u);
}

TEST(FieldLogWriter, TotalCapDeletesTheOldestFiles) {
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 100, 250));
    ASSERT_TRUE(w);
    for (int i = 0; i < 30; ++i) {
        ASSERT_TRUE((*w)->write(lineOf(i, 50)));
        EXPECT_LE((*w)->totalBytes(), 250u);
    }
    // 15 files of 2 lines; 250 bytes keep the current one and the two before it.
    const auto files = listFieldLogFiles(tmp.path());
    ASSERT_EQ(files.size(), 2u);
    EXPECT_EQ(files.back().path, (*w)->currentPath());
    EXPECT_EQ(files.front().sequence, 14u);
    EXPECT_EQ((*w)->filesDeleted(), 13u);
    auto read = readFieldLog(tmp.path());
    ASSERT_TRUE(read);
    EXPECT_EQ(numbers(*read), (std::vector<int>{26, 27, 28, 29}));
}

TEST(FieldLogWriter, NeverDeletesTheCurrentFile) {
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 1000, 10));
    ASSERT_TRUE(w);
    ASSERT_TRUE((*w)->write(lineOf(0, 50) + lineOf(1, 50)));
    EXPECT_TRUE(fs::exists((*w)->currentPath()));
    EXPECT_EQ(listFieldLogFiles(tmp.path()).size(), 1u);
    EXPECT_EQ((*w)->currentBytes(), 100u);
}

TEST(FieldLogWriter, SequenceContinuesAfterARestart) {
    TempDir tmp("field_log");
    {
        auto w = FieldLogWriter::open(options(tmp.path(), 100, 1u << 20));
        ASSERT_TRUE(w);
        ASSERT_TRUE((*w)->write(lineOf(0, 60)));
        ASSERT_TRUE((*w)->write(lineOf(1, 60)));  // rotates: file 2
    }
    // Someone else's file and an older, unrelated name are ignored.
    writeFile(tmp.path() / "notes.txt", "hello\n");
    writeFile(tmp.path() / "scaled-2023.jsonl", "{}\n");
    {
        auto w = FieldLogWriter::open(options(tmp.path(), 100, 1u << 20));
        ASSERT_TRUE(w);
        EXPECT_EQ((*w)->currentPath().filename(), fieldLogFileName(kT0, 3));
        ASSERT_TRUE((*w)->write(lineOf(2, 60)));
    }
    // The order is the sequence, even when the clock went back (no RTC).
    auto opts = options(tmp.path(), 100, 1u << 20);
    opts.utc_now_s = [] { return std::int64_t{0}; };
    {
        auto w = FieldLogWriter::open(opts);
        ASSERT_TRUE(w);
        EXPECT_EQ((*w)->currentPath().filename(), fieldLogFileName(0, 4));
        ASSERT_TRUE((*w)->write(lineOf(3, 60)));
    }
    auto read = readFieldLog(tmp.path());
    ASSERT_TRUE(read);
    EXPECT_EQ(numbers(*read), (std::vector<int>{0, 1, 2, 3}));
    EXPECT_TRUE(fs::exists(tmp.path() / "notes.txt"));
}

TEST(FieldLogWriter, ADirectoryThatCannotBeCreatedIsAnErrorNamingIt) {
    TempDir tmp("field_log");
    writeFile(tmp.path() / "plain", "x");
    const fs::path dir = tmp.path() / "plain" / "logs";  // parent is a file: works as root too
    auto w = FieldLogWriter::open(options(dir, 100, 1000));
    ASSERT_FALSE(w);
    EXPECT_EQ(w.error().code, core::ErrorCode::kIo);
    EXPECT_NE(w.error().message.find(dir.string()), std::string::npos) << w.error().message;
    EXPECT_NE(w.error().message.find("Not a directory"), std::string::npos) << w.error().message;
}

TEST(FieldLogWriter, OpenErrorNamesTheFileAndErrno) {
    TempDir tmp("field_log");
    auto opts = options(tmp.path(), 100, 1000);
    opts.open_file = [](const fs::path&) {
        errno = EROFS;
        return -1;
    };
    auto w = FieldLogWriter::open(opts);
    ASSERT_FALSE(w);
    EXPECT_NE(w.error().message.find(fieldLogFileName(kT0, 1)), std::string::npos);
    EXPECT_NE(w.error().message.find("Read-only file system"), std::string::npos)
        << w.error().message;
}

// The next file is a symlink to /dev/full: the rotation opens it and the
// write fails with a real ENOSPC.
TEST(FieldLogWriter, EnospcOnRotationFaultsAndRefusesFurtherWrites) {
    if (!fs::exists("/dev/full")) {
        GTEST_SKIP() << "/dev/full is missing";
    }
    TempDir tmp("field_log");
    auto w = FieldLogWriter::open(options(tmp.path(), 100, 1u << 20));
    ASSERT_TRUE(w);
    ASSERT_TRUE((*w)->write(lineOf(0, 60)));
    const fs::path next = tmp.path() / fieldLogFileName(kT0, 2);
    fs::create_symlink("/dev/full", next);
    auto r = (*w)->write(lineOf(1, 60));
    ASSERT_FALSE(r);
    EXPECT_TRUE((*w)->faulted());
    EXPECT_EQ(r.error().code, core::ErrorCode::kIo);
    EXPECT_NE(r.error().message.find(next.string()), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("No space left on device"), std::string::npos)
        << r.error().message;
    EXPECT_EQ((*w)->fault(), r.error().message);
    // Refused from now on, with the same message.
    auto again = (*w)->write(lineOf(2, 30));
    ASSERT_FALSE(again);
    EXPECT_EQ(again.error().message, r.error().message);
    EXPECT_FALSE((*w)->sync());
    // The first file is intact and the reader copes with the symlink.
    auto read = readFieldLog(tmp.path());
    ASSERT_TRUE(read) << read.error().message;
    EXPECT_EQ(numbers(*read), (std::vector<int>{0}));
}

TEST(FieldLogWriter, EnospcThroughTheOpenHook) {
    TempDir tmp("field_log");
    auto opts = options(tmp.path(), 1000, 10000);
    opts.open_file = [](const fs::path&) {
        // NOLINTNEXTLINE(cppcoreguidelines-pro-type-vararg)
        return ::open("/dev/full", O_WRONLY | O_CLOEXEC);
    };
    auto w = FieldLogWriter::open(opts);
    ASSERT_TRUE(w) << w.error().message;
    auto r = (*w)->write(lineOf(0, 40));
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("write failed: No space left on device"), std::string::npos)
        << r.error().message;
    EXPECT_EQ((*w)->bytesWritten(), 0u);
}

// --- reader --------------------------------------------------------------------------

TEST(FieldLogReader, SkipsAndCountsAPartialLastLine) {
    TempDir tmp("field_log");
    const fs::path file = tmp.path() / fieldLogFileName(kT0, 1);
    writeFile(file, "{\"n\":0}\n{\"n\":1}\n{\"class\":\"SCA");
    auto read = readFieldLog(file);
    ASSERT_TRUE(read) << read.error().message;
    EXPECT_EQ(numbers(*read), (std::vector<int>{0, 1}));
    EXPECT_EQ(read->partial_lines, 1u);
    EXPECT_EQ(read->corrupt_lines, 0u);
    ASSERT_EQ(read->problems.size(), 1u);
    EXPECT_NE(read->problems[0].find(":3: last line has no newline"), std::string::npos)
        << read->problems[0];
    EXPECT_EQ(read->lines[1].line_no, 2u);
}

TEST(FieldLogReader, AnUnterminatedLastLineIsPartialEvenIfItParses) {
    TempDir tmp("field_log");
    const fs::path file = tmp.path() / "x.jsonl";
    writeFile(file, "{\"n\":0}\n{\"n\":1}");
    auto read = readFieldLog(file);
    ASSERT_TRUE(read);
    EXPECT_EQ(numbers(*read), (std::vector<int>{0}));
    EXPECT_EQ(read->partial_lines, 1u);
}

TEST(FieldLogReader, ZerosAfterAPowerCutArePartial) {
    TempDir tmp("field_log");
    const fs::path file = tmp.path() / "x.jsonl";
    writeFile(file, std::string("{\"n\":0}\n") + std::string(100, '\0'));
    auto read = readFieldLog(file);
    ASSERT_TRUE(read);
    EXPECT_EQ(numbers(*read), (std::vector<int>{0}));
    EXPECT_EQ(read->partial_lines, 1u);
    EXPECT_EQ(read->corrupt_lines, 0u);
}

TEST(FieldLogReader, GarbageLinesAreCountedNotFatal) {
    TempDir tmp("field_log");
    const fs::path file = tmp.path() / "x.jsonl";
    std::string text = "{\"n\":0}\n";
    text += "not json at all\n";
    text += "[1,2,3]\n";                                  // JSON, but not an object
    text += "{\"n\":\n";                                  // cut in the middle
    text += std::string(3, '\0') + "\n";                  // zeros
    text += "{\"s\":\"\xff\xfe\"}\n";                     // invalid UTF-8
    text += "{\"a\":" + std::string(100000, '[') + "\n";  // deep nesting
    text += "\n   \n";                                    // blank lines: ignored
    text += "{\"n\":1}\n";
    writeFile(file, text);
    auto read = readFieldLog(file);
    ASSERT_TRUE(read);
    EXPECT_EQ(numbers(*read), (std::vector<int>{0, 1}));
    EXPECT_EQ(read->corrupt_lines, 6u);
    EXPECT_EQ(read->partial_lines, 0u);
    EXPECT_EQ(read->lines[1].line_no, 10u);
}

TEST(FieldLogReader, RandomBytesNeverCrash) {
    TempDir tmp("field_log");
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> byte(0, 255);
    const std::string alphabet = "{}[]\":,\n0123456789abc\\ \xc3\xa9";
    std::uniform_int_distribution<std::size_t> pick(0, alphabet.size() - 1);
    for (int round = 0; round < 50; ++round) {
        std::string text;
        const int n = 1 + byte(rng) * 20;
        for (int i = 0; i < n; ++i) {
            text += round % 2 == 0 ? static_cast<char>(byte(rng)) : alphabet[pick(rng)];
        }
        const fs::path file = tmp.path() / ("r" + std::to_string(round) + ".jsonl");
        writeFile(file, text);
        auto read = readFieldLog(file);
        ASSERT_TRUE(read);
        for (const auto& l : read->lines) {
            EXPECT_TRUE(isJsonObjectLine(l.text));
        }
    }
}

TEST(FieldLogReader, ReadsADirectoryInSequenceOrder) {
    TempDir tmp("field_log");
    writeFile(tmp.path() / fieldLogFileName(kT0, 10), "{\"n\":2}\n{\"n\":3}\n{\"n\"");
    writeFile(tmp.path() / fieldLogFileName(kT0 + 100, 9), "{\"n\":0}\n{\"n\":1}\n");
    writeFile(tmp.path() / "other.jsonl", "{\"n\":99}\n");
    auto read = readFieldLog(tmp.path());
    ASSERT_TRUE(read);
    ASSERT_EQ(read->files.size(), 2u);
    EXPECT_EQ(read->files[0].filename(), fieldLogFileName(kT0 + 100, 9));
    EXPECT_EQ(numbers(*read), (std::vector<int>{0, 1, 2, 3}));
    EXPECT_EQ(read->partial_lines, 1u);
    EXPECT_EQ(read->lines[2].file, 1u);
}

TEST(FieldLogReader, MissingPathOrEmptyDirectoryIsNotFound) {
    TempDir tmp("field_log");
    auto missing = readFieldLog(tmp.path() / "nope");
    ASSERT_FALSE(missing);
    EXPECT_EQ(missing.error().code, core::ErrorCode::kNotFound);
    auto empty = readFieldLog(tmp.path());
    ASSERT_FALSE(empty);
    EXPECT_EQ(empty.error().code, core::ErrorCode::kNotFound);
    EXPECT_NE(empty.error().message.find(tmp.path().string()), std::string::npos);
}

TEST(FieldLogReader, AnEmptyFileHasNoLines) {
    TempDir tmp("field_log");
    const fs::path file = tmp.path() / "x.jsonl";
    writeFile(file, "");
    auto read = readFieldLog(file);
    ASSERT_TRUE(read);
    EXPECT_TRUE(read->lines.empty());
    EXPECT_EQ(read->partial_lines + read->corrupt_lines, 0u);
}

}  // namespace
}  // namespace scaled::drivers::fieldlog
