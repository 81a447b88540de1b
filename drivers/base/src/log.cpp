#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

#include <scaled/drivers/base/log.h>

namespace scaled::drivers::base {

namespace {

struct LogState {
    std::mutex mutex;  // program
    std::string program = "scaled";
    std::atomic<int> level{static_cast<int>(LogLevel::kInfo)};
    std::atomic<int> journal{-1};  // -1: not decided yet (stderrIsJournal on first use)
};

LogState& state() {
    static LogState s;
    return s;
}

}  // namespace

const char* toString(LogLevel level) {
    switch (level) {
        case LogLevel::kError:
            return "error";
        case LogLevel::kWarning:
            return "warning";
        case LogLevel::kInfo:
            return "info";
        case LogLevel::kDebug:
            return "debug";
    }
    return "info";
}

bool parseLogLevel(std::string_view text, LogLevel& level) {
    for (const LogLevel l :
         {LogLevel::kError, LogLevel::kWarning, LogLevel::kInfo, LogLevel::kDebug}) {
        if (text == toString(l)) {
            level = l;
            return true;
        }
    }
    return false;
}

void setLogProgram(std::string_view program) {
    const std::lock_guard lock(state().mutex);
    state().program = program;
}

void setLogLevel(LogLevel level) {
    state().level.store(static_cast<int>(level));
}

LogLevel logLevel() {
    return static_cast<LogLevel>(state().level.load());
}

bool logEnabled(LogLevel level) {
    return static_cast<int>(level) <= state().level.load();
}

void setLogJournal(bool journal) {
    state().journal.store(journal ? 1 : 0);
}

bool stderrIsJournal() {
    // systemd.exec(5): JOURNAL_STREAM=DEVICE:INODE of the stream it connected.
    const char* env = std::getenv("JOURNAL_STREAM");  // NOLINT(concurrency-mt-unsafe)
    if (env == nullptr) {
        return false;
    }
    unsigned long long dev = 0;
    unsigned long long ino = 0;
    if (std::sscanf(env, "%llu:%llu", &dev, &ino) != 2) {  // NOLINT(cert-err34-c)
        return false;
    }
    struct stat st = {};
    if (::fstat(STDERR_FILENO, &st) != 0) {
        return false;
    }
    return static_cast<unsigned long long>(st.st_dev) == dev &&
           static_cast<unsigned long long>(st.st_ino) == ino;
}

std::string formatLogLine(LogLevel level, const LogCategory& category, std::string_view message,
                          bool journal) {
    std::string line;
    line.reserve(message.size() + 48);
    if (journal) {
        line += '<';
        line += static_cast<char>('0' + static_cast<int>(level));
        line += '>';
    }
    const std::lock_guard lock(state().mutex);
    line += state().program;
    line += ": ";
    if (level == LogLevel::kWarning) {
        line += "warning: ";
    } else if (level == LogLevel::kDebug) {
        line += "debug: ";
    }
    if (category.name != state().program) {
        line += category.name;
        line += ": ";
    }
    line += message;
    return line;
}

void log(LogLevel level, const LogCategory& category, std::string_view message) {
    if (!logEnabled(level)) {
        return;
    }
    int journal = state().journal.load();
    if (journal < 0) {
        journal = stderrIsJournal() ? 1 : 0;
        state().journal.store(journal);
    }
    std::string line = formatLogLine(level, category, message, journal == 1);
    line += '\n';
    // One write per line: lines of several threads do not interleave.
    const char* p = line.data();
    std::size_t left = line.size();
    while (left > 0) {
        const ssize_t n = ::write(STDERR_FILENO, p, left);
        if (n <= 0) {
            return;  // nowhere to say it
        }
        p += n;
        left -= static_cast<std::size_t>(n);
    }
}

}  // namespace scaled::drivers::base
