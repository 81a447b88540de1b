#pragma once

// The daemon's diagnostic messages (not the field log, which records data:
// drivers/fieldlog). One line per message on stderr, with a severity and a
// category, after libcamera's log categories:
//
//   scaled: socket: /run/scaled/scaled.sock: Permission denied
//   scaled: warning: gpio: line 17: Device or resource busy (the LEDs may be wrong)
//   ^prog   ^severity (warning, debug) ^category (none for the program's own)
//
// Under systemd (stderr is the journal: JOURNAL_STREAM names it) each line
// starts with its syslog priority, "<3>" for an error, "<4>" a warning, "<6>"
// info, "<7>" debug (sd-daemon(3)), so `journalctl -p warning` filters them.
// Messages below the threshold (log.level, --verbose) are not written.
// Thread-safe: one write(2) per line.

#include <string>
#include <string_view>

namespace scaled::drivers::base {

// The syslog priorities of the four severities.
enum class LogLevel { kError = 3, kWarning = 4, kInfo = 6, kDebug = 7 };

// "error", "warning", "info", "debug".
[[nodiscard]] const char* toString(LogLevel level);
// The reverse; false for anything else.
[[nodiscard]] bool parseLogLevel(std::string_view text, LogLevel& level);

// A subsystem's name in its messages (libcamera: LOG_DEFINE_CATEGORY).
struct LogCategory {
    std::string_view name;
};

// The program's name before every line ("scaled"); its own category's
// messages carry no category.
void setLogProgram(std::string_view program);
// Messages less severe than this are dropped (default kInfo).
void setLogLevel(LogLevel level);
[[nodiscard]] LogLevel logLevel();
[[nodiscard]] bool logEnabled(LogLevel level);
// Priority prefixes on or off; by default on when stderr is the journal.
void setLogJournal(bool journal);
// Whether stderr is the journal stream systemd gave us (JOURNAL_STREAM
// names stderr's device and inode).
[[nodiscard]] bool stderrIsJournal();

// Writes one line (the message has no newline of its own).
void log(LogLevel level, const LogCategory& category, std::string_view message);

inline void logError(const LogCategory& c, std::string_view m) {
    log(LogLevel::kError, c, m);
}
inline void logWarning(const LogCategory& c, std::string_view m) {
    log(LogLevel::kWarning, c, m);
}
inline void logInfo(const LogCategory& c, std::string_view m) {
    log(LogLevel::kInfo, c, m);
}
inline void logDebug(const LogCategory& c, std::string_view m) {
    log(LogLevel::kDebug, c, m);
}

// The text of one line as log() writes it (for the tests), without the
// newline.
[[nodiscard]] std::string formatLogLine(LogLevel level, const LogCategory& category,
                                        std::string_view message, bool journal);

}  // namespace scaled::drivers::base
