#pragma once

// The field log on disk: JSON lines in size-capped, rotated files
// (docs/field-log.md). FieldLogWriter is the synchronous, single-threaded file
// part the daemon's log thread (daemon/log_service.h) drives; readFieldLog()
// reads the files back (tools/field_log, tests).
//
// Files: DIR/scaled-YYYYMMDDTHHMMSSZ-NNNNNN.jsonl, the UTC time the file was
// opened and a sequence number that continues across restarts (the order of
// the files is the order of the numbers, even when the clock jumped back).
// Only whole lines are written: each batch goes out with write(2) (looping on
// partial writes and EINTR), so a process killed with SIGKILL can only cut the
// last line of its last write, and a failed write is truncated back.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/core/result.h>
#include <scaled/drivers/base/unique_fd.h>

namespace scaled::drivers::fieldlog {

// One file of the log: its path, sequence number and size in bytes.
struct FieldLogFile {
    std::filesystem::path path;
    std::uint64_t sequence = 0;
    std::uint64_t bytes = 0;
};

// The files of the writer's naming pattern in `dir`, oldest (lowest sequence
// number) first. Other files are ignored. Empty when `dir` cannot be listed.
std::vector<FieldLogFile> listFieldLogFiles(const std::filesystem::path& dir);

// `scaled-YYYYMMDDTHHMMSSZ-NNNNNN.jsonl` for a UTC time (seconds since the
// epoch) and a sequence number.
std::string fieldLogFileName(std::int64_t utc_s, std::uint64_t sequence);

struct FieldLogWriterOptions {
    std::filesystem::path dir;
    std::uint64_t max_file_bytes = 8u << 20;    // rotate before a file passes this
    std::uint64_t max_total_bytes = 64u << 20;  // delete the oldest files above this
    // UTC seconds for the file names (tests fix it). Default: time(nullptr).
    std::function<std::int64_t()> utc_now_s;
    // Opens a log file for appending; returns an fd or -1 with errno set
    // (tests point it at /dev/full). Default: open(O_WRONLY|O_CREAT|O_APPEND|O_CLOEXEC, 0644).
    std::function<int(const std::filesystem::path&)> open_file;
};

class FieldLogWriter {
public:
    // Creates the directory if needed (parents too), scans it for earlier
    // files and opens the next one. Errors name the directory or file and the
    // errno text.
    static core::Result<std::unique_ptr<FieldLogWriter>> open(FieldLogWriterOptions options);

    ~FieldLogWriter();
    FieldLogWriter(const FieldLogWriter&) = delete;
    FieldLogWriter& operator=(const FieldLogWriter&) = delete;
    FieldLogWriter(FieldLogWriter&&) = delete;
    FieldLogWriter& operator=(FieldLogWriter&&) = delete;

    // Writes a batch of complete lines (each ends with '\n'; an unterminated
    // tail is an kInvalidArgument error and nothing is written). Rotates
    // between lines so that no file passes max_file_bytes (a single line
    // longer than that gets a file of its own), then deletes the oldest files
    // while the total passes max_total_bytes. Any I/O error puts the writer
    // into the fault state and is returned; after that every call returns it.
    core::Status write(std::string_view lines);

    // fdatasync(2) of the current file (a fault like write()).
    core::Status sync();

    [[nodiscard]] bool faulted() const { return !fault_.empty(); }
    // "<file>: <what failed>: <errno text>"; empty when not faulted.
    [[nodiscard]] const std::string& fault() const { return fault_; }

    [[nodiscard]] const std::filesystem::path& currentPath() const { return current_.path; }
    [[nodiscard]] std::uint64_t currentBytes() const { return current_.bytes; }
    // The bytes of all its files in the directory (current included).
    [[nodiscard]] std::uint64_t totalBytes() const;
    // Bytes written by this writer since open().
    [[nodiscard]] std::uint64_t bytesWritten() const { return bytes_written_; }
    // Files this writer deleted to keep the total cap.
    [[nodiscard]] std::uint64_t filesDeleted() const { return files_deleted_; }

private:
    explicit FieldLogWriter(FieldLogWriterOptions options);
    core::Status openNext();
    core::Status rotate();
    core::Status writeAll(std::string_view bytes);
    core::Status enforceTotal();
    core::Error setFault(const std::filesystem::path& path, const char* what, int err);

    FieldLogWriterOptions options_;
    std::vector<FieldLogFile> closed_;  // older files, oldest first
    FieldLogFile current_;
    base::UniqueFd fd_;
    std::uint64_t bytes_written_ = 0;
    std::uint64_t files_deleted_ = 0;
    std::string fault_;
};

// ---------------------------------------------------------------------------
// Reading a log back.

struct FieldLogLine {
    std::string text;         // one JSON object, without the newline
    std::size_t file = 0;     // index into FieldLogContents::files
    std::size_t line_no = 0;  // 1-based line number in that file
};

struct FieldLogContents {
    std::vector<std::filesystem::path> files;  // in log order
    std::vector<FieldLogLine> lines;           // the valid lines, in order
    // The last line of a file that has no newline or is not a JSON object
    // (a crash or power cut during the write): skipped.
    std::size_t partial_lines = 0;
    // Any other line that is not a JSON object (blank lines are ignored).
    std::size_t corrupt_lines = 0;
    // "file:line: what" for the first few skipped lines.
    std::vector<std::string> problems;
};

// `path` is one log file or a directory of them (its regular files of the
// naming pattern, read in sequence order).
// Never fails on content; fails (kNotFound / kIo) when the path does not
// exist, cannot be read, or a directory holds no log files.
core::Result<FieldLogContents> readFieldLog(const std::filesystem::path& path);

// One file's text, as readFieldLog() reads it: appends `file` to out.files
// and its lines (and skipped lines) to `out`. Never fails. The fuzz target
// tests/fuzz/field_log_fuzz.cpp calls it.
void readFieldLogText(std::string_view text, const std::filesystem::path& file,
                      FieldLogContents& out);

// Whether `text` is one JSON object (what the reader keeps).
bool isJsonObjectLine(std::string_view text);

}  // namespace scaled::drivers::fieldlog
