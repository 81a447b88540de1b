// The diagnostic log (drivers/base/log.h): line format, severities, journald
// priority prefixes and the journal's detection from JOURNAL_STREAM.

#include <cstdio>
#include <cstdlib>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <scaled/drivers/base/log.h>

namespace scaled::drivers::base {
namespace {

TEST(Log, LinesNameTheProgramTheSeverityAndTheCategory) {
    setLogProgram("scaled");
    const LogCategory socket{"socket"};
    const LogCategory main{"scaled"};
    EXPECT_EQ(formatLogLine(LogLevel::kError, socket, "in use", false), "scaled: socket: in use");
    EXPECT_EQ(formatLogLine(LogLevel::kInfo, main, "listening", false), "scaled: listening");
    EXPECT_EQ(formatLogLine(LogLevel::kWarning, socket, "slow", false),
              "scaled: warning: socket: slow");
    EXPECT_EQ(formatLogLine(LogLevel::kDebug, main, "tick", false), "scaled: debug: tick");
}

TEST(Log, TheJournalGetsSyslogPriorities) {
    const LogCategory gpio{"gpio"};
    EXPECT_EQ(formatLogLine(LogLevel::kError, gpio, "x", true), "<3>scaled: gpio: x");
    EXPECT_EQ(formatLogLine(LogLevel::kWarning, gpio, "x", true), "<4>scaled: warning: gpio: x");
    EXPECT_EQ(formatLogLine(LogLevel::kInfo, gpio, "x", true), "<6>scaled: gpio: x");
    EXPECT_EQ(formatLogLine(LogLevel::kDebug, gpio, "x", true), "<7>scaled: debug: gpio: x");
}

TEST(Log, LevelsParseAndFilter) {
    LogLevel l = LogLevel::kInfo;
    ASSERT_TRUE(parseLogLevel("debug", l));
    EXPECT_EQ(l, LogLevel::kDebug);
    ASSERT_TRUE(parseLogLevel("warning", l));
    EXPECT_EQ(l, LogLevel::kWarning);
    EXPECT_FALSE(parseLogLevel("verbose", l));
    EXPECT_EQ(l, LogLevel::kWarning);  // unchanged
    for (const LogLevel x :
         {LogLevel::kError, LogLevel::kWarning, LogLevel::kInfo, LogLevel::kDebug}) {
        LogLevel back = LogLevel::kError;
        ASSERT_TRUE(parseLogLevel(toString(x), back));
        EXPECT_EQ(back, x);
    }
    const LogLevel before = logLevel();
    setLogLevel(LogLevel::kWarning);
    EXPECT_TRUE(logEnabled(LogLevel::kError));
    EXPECT_TRUE(logEnabled(LogLevel::kWarning));
    EXPECT_FALSE(logEnabled(LogLevel::kInfo));
    EXPECT_FALSE(logEnabled(LogLevel::kDebug));
    setLogLevel(before);
}

// JOURNAL_STREAM names stderr's device and inode when systemd connected it
// to the journal; any other value (another stream, garbage) is not it.
TEST(Log, TheJournalIsRecognisedByStderrsDeviceAndInode) {
    const char* saved = std::getenv("JOURNAL_STREAM");
    const std::string restore = saved != nullptr ? saved : "";
    struct stat st = {};
    ASSERT_EQ(::fstat(STDERR_FILENO, &st), 0);
    const std::string mine = std::to_string(static_cast<unsigned long long>(st.st_dev)) + ":" +
                             std::to_string(static_cast<unsigned long long>(st.st_ino));
    ASSERT_EQ(::setenv("JOURNAL_STREAM", mine.c_str(), 1), 0);
    EXPECT_TRUE(stderrIsJournal());
    const std::string other = std::to_string(static_cast<unsigned long long>(st.st_dev)) + ":" +
                              std::to_string(static_cast<unsigned long long>(st.st_ino) + 1);
    ASSERT_EQ(::setenv("JOURNAL_STREAM", other.c_str(), 1), 0);
    EXPECT_FALSE(stderrIsJournal());
    ASSERT_EQ(::setenv("JOURNAL_STREAM", "not a stream", 1), 0);
    EXPECT_FALSE(stderrIsJournal());
    ASSERT_EQ(::unsetenv("JOURNAL_STREAM"), 0);
    EXPECT_FALSE(stderrIsJournal());
    if (saved != nullptr) {
        ASSERT_EQ(::setenv("JOURNAL_STREAM", restore.c_str(), 1), 0);
    }
}

}  // namespace
}  // namespace scaled::drivers::base
