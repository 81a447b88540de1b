// The field log on disk: rotated JSON-lines files and their reader.

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fcntl.h>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sys/stat.h>
#include <system_error>
#include <unistd.h>
#include <utility>

#include <scaled/drivers/base/errno_text.h>
#include <scaled/drivers/fieldlog/field_log.h>

namespace scaled::drivers::fieldlog {

using core::ErrorCode;
using core::makeError;
using core::Result;
using core::Status;

namespace {

constexpr std::string_view kPrefix = "scaled-";
constexpr std::string_view kSuffix = ".jsonl";
constexpr std::size_t kMaxProblems = 20;

bool allDigits(std::string_view s) {
    return !s.empty() &&
           std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// The sequence number of a file named like fieldLogFileName(), else false.
bool parseName(std::string_view name, std::uint64_t& sequence) {
    // scaled-YYYYMMDDTHHMMSSZ-NNNNNN.jsonl
    constexpr std::size_t kStamp = 16;  // YYYYMMDDTHHMMSSZ
    if (name.size() < kPrefix.size() + kStamp + 2 + kSuffix.size() ||
        name.substr(0, kPrefix.size()) != kPrefix ||
        name.substr(name.size() - kSuffix.size()) != kSuffix) {
        return false;
    }
    std::string_view rest = name.substr(kPrefix.size());
    rest.remove_suffix(kSuffix.size());
    const std::string_view stamp = rest.substr(0, kStamp);
    if (!allDigits(stamp.substr(0, 8)) || stamp[8] != 'T' || !allDigits(stamp.substr(9, 6)) ||
        stamp[15] != 'Z' || rest[kStamp] != '-') {
        return false;
    }
    const std::string_view seq = rest.substr(kStamp + 1);
    if (!allDigits(seq)) {
        return false;
    }
    const auto r = std::from_chars(seq.data(), seq.data() + seq.size(), sequence);
    return r.ec == std::errc() && r.ptr == seq.data() + seq.size();
}

using base::errnoText;

std::int64_t defaultUtcNow() {
    return static_cast<std::int64_t>(std::time(nullptr));
}

int defaultOpen(const std::filesystem::path& path) {
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-vararg)
    return ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
}

bool isBlank(std::string_view s) {
    return std::all_of(s.begin(), s.end(),
                       [](char c) { return c == ' ' || c == '\t' || c == '\r'; });
}

// The whole file (a read error is an Error naming it).
Result<std::string> readWhole(const std::filesystem::path& path) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (ec) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot read: " + ec.message());
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot open: " + errnoText(errno));
    }
    std::string text(static_cast<std::size_t>(size), '\0');
    in.read(text.data(), static_cast<std::streamsize>(text.size()));
    if (in.bad()) {
        return makeError(ErrorCode::kIo, path.string() + ": read failed: " + errnoText(errno));
    }
    text.resize(static_cast<std::size_t>(in.gcount()));
    return text;
}

void note(FieldLogContents& out, const std::filesystem::path& file, std::size_t line,
          const char* what) {
    if (out.problems.size() < kMaxProblems) {
        out.problems.push_back(file.string() + ":" + std::to_string(line) + ": " + what);
    }
}

void splitLines(std::string_view text, std::size_t file_index, const std::filesystem::path& file,
                FieldLogContents& out) {
    struct Segment {
        std::size_t begin;
        std::size_t size;
        bool terminated;
    };
    std::vector<Segment> segments;
    std::size_t pos = 0;
    while (pos < text.size()) {
        const std::size_t nl = text.find('\n', pos);
        if (nl == std::string_view::npos) {
            segments.push_back({pos, text.size() - pos, false});
            break;
        }
        segments.push_back({pos, nl - pos, true});
        pos = nl + 1;
    }
    const std::string_view all = text;
    std::size_t last = segments.size();
    for (std::size_t i = segments.size(); i > 0; --i) {
        if (!isBlank(all.substr(segments[i - 1].begin, segments[i - 1].size))) {
            last = i - 1;
            break;
        }
    }
    for (std::size_t i = 0; i < segments.size(); ++i) {
        const std::string_view line = all.substr(segments[i].begin, segments[i].size);
        if (isBlank(line)) {
            continue;
        }
        const bool valid = segments[i].terminated && isJsonObjectLine(line);
        if (valid) {
            out.lines.push_back(FieldLogLine{std::string(line), file_index, i + 1});
        } else if (i == last) {
            ++out.partial_lines;
            note(out, file, i + 1,
                 segments[i].terminated ? "last line is not a JSON object (skipped as partial)"
                                        : "last line has no newline (skipped as partial)");
        } else {
            ++out.corrupt_lines;
            note(out, file, i + 1, "not a JSON object (skipped)");
        }
    }
}

}  // namespace

std::string fieldLogFileName(std::int64_t utc_s, std::uint64_t sequence) {
    const auto t = static_cast<std::time_t>(utc_s);
    std::tm tm{};
    gmtime_r(&t, &tm);
    std::array<char, 64> buf{};
    // NOLINTNEXTLINE(cppcoreguidelines-pro-type-vararg)
    std::snprintf(buf.data(), buf.size(), "scaled-%04d%02d%02dT%02d%02d%02dZ-%06llu.jsonl",
                  tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                  static_cast<unsigned long long>(sequence));
    return buf.data();
}

std::vector<FieldLogFile> listFieldLogFiles(const std::filesystem::path& dir) {
    std::vector<FieldLogFile> files;
    std::error_code ec;
    std::filesystem::directory_iterator it(dir, ec);
    if (ec) {
        return files;
    }
    for (const auto& entry : it) {
        FieldLogFile f;
        if (!parseName(entry.path().filename().string(), f.sequence)) {
            continue;
        }
        f.path = entry.path();
        std::error_code size_ec;
        const auto size = std::filesystem::file_size(entry.path(), size_ec);
        f.bytes = size_ec ? 0 : static_cast<std::uint64_t>(size);
        files.push_back(std::move(f));
    }
    std::sort(files.begin(), files.end(), [](const FieldLogFile& a, const FieldLogFile& b) {
        return a.sequence != b.sequence ? a.sequence < b.sequence : a.path < b.path;
    });
    return files;
}

// ---------------------------------------------------------------------------

FieldLogWriter::FieldLogWriter(FieldLogWriterOptions options) : options_(std::move(options)) {
    if (!options_.utc_now_s) {
        options_.utc_now_s = defaultUtcNow;
    }
    if (!options_.open_file) {
        options_.open_file = defaultOpen;
    }
}

FieldLogWriter::~FieldLogWriter() = default;

Result<std::unique_ptr<FieldLogWriter>> FieldLogWriter::open(FieldLogWriterOptions options) {
    const std::filesystem::path dir = options.dir;
    if (dir.empty()) {
        return makeError(ErrorCode::kInvalidArgument, "field log: no directory given");
    }
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
        return makeError(ErrorCode::kIo,
                         dir.string() + ": cannot create the log directory: " + ec.message());
    }
    if (!std::filesystem::is_directory(dir, ec)) {
        return makeError(ErrorCode::kIo, dir.string() + ": not a directory");
    }
    std::unique_ptr<FieldLogWriter> w(new FieldLogWriter(std::move(options)));
    w->closed_ = listFieldLogFiles(dir);
    if (auto ok = w->openNext(); !ok) {
        return ok.error();
    }
    if (auto ok = w->enforceTotal(); !ok) {
        return ok.error();
    }
    return w;
}

core::Error FieldLogWriter::setFault(const std::filesystem::path& path, const char* what, int err) {
    fault_ = path.string() + ": " + what + ": " + errnoText(err);
    return makeError(ErrorCode::kIo, fault_);
}

Status FieldLogWriter::openNext() {
    const std::uint64_t seq = (closed_.empty() ? 0 : closed_.back().sequence) + 1;
    FieldLogFile next;
    next.sequence = seq;
    next.path = options_.dir / fieldLogFileName(options_.utc_now_s(), seq);
    const int fd = options_.open_file(next.path);
    if (fd < 0) {
        return setFault(next.path, "cannot open", errno);
    }
    struct stat st = {};
    if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
        next.bytes = static_cast<std::uint64_t>(st.st_size);
    }
    fd_.reset(fd);
    current_ = std::move(next);
    return {};
}

Status FieldLogWriter::rotate() {
    if (::fdatasync(fd_.get()) != 0) {
        return setFault(current_.path, "fdatasync failed", errno);
    }
    if (const int err = fd_.close(); err != 0) {
        return setFault(current_.path, "close failed", err);
    }
    closed_.push_back(current_);
    current_ = FieldLogFile{};
    if (auto ok = openNext(); !ok) {
        return ok;
    }
    return enforceTotal();
}

Status FieldLogWriter::writeAll(std::string_view bytes) {
    const std::uint64_t before = current_.bytes;
    std::size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(fd_.get(), bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) {
            continue;
        }
        if (n <= 0) {
            const int err = n < 0 ? errno : EIO;
            if (done > 0) {
                // Keep whole lines only: drop the part of this batch that made it.
                (void)::ftruncate(fd_.get(), static_cast<off_t>(before));
            }
            return setFault(current_.path, "write failed", err);
        }
        done += static_cast<std::size_t>(n);
    }
    current_.bytes += bytes.size();
    bytes_written_ += bytes.size();
    return {};
}

Status FieldLogWriter::enforceTotal() {
    std::uint64_t total = totalBytes();
    while (total > options_.max_total_bytes && !closed_.empty()) {
        const FieldLogFile& oldest = closed_.front();
        if (::unlink(oldest.path.c_str()) != 0 && errno != ENOENT) {
            return setFault(oldest.path, "cannot delete (total size cap)", errno);
        }
        total -= oldest.bytes;
        closed_.erase(closed_.begin());
        ++files_deleted_;
    }
    return {};
}

std::uint64_t FieldLogWriter::totalBytes() const {
    std::uint64_t total = current_.bytes;
    for (const auto& f : closed_) {
        total += f.bytes;
    }
    return total;
}

Status FieldLogWriter::write(std::string_view lines) {
    if (faulted()) {
        return makeError(ErrorCode::kIo, fault_);
    }
    if (lines.empty()) {
        return {};
    }
    if (lines.back() != '\n') {
        return makeError(ErrorCode::kInvalidArgument,
                         "field log: a batch must end with a newline (whole lines only)");
    }
    std::string_view rest = lines;
    while (!rest.empty()) {
        const std::uint64_t room =
            options_.max_file_bytes > current_.bytes ? options_.max_file_bytes - current_.bytes : 0;
        if (rest.size() <= room) {
            if (auto ok = writeAll(rest); !ok) {
                return ok;
            }
            break;
        }
        // The longest run of whole lines that still fits.
        std::size_t cut = room > 0 ? rest.rfind('\n', static_cast<std::size_t>(room - 1))
                                   : std::string_view::npos;
        if (cut == std::string_view::npos) {
            if (current_.bytes > 0) {
                if (auto ok = rotate(); !ok) {
                    return ok;
                }
                continue;
            }
            cut = rest.find('\n');  // one line longer than a file: it gets one of its own
        }
        if (auto ok = writeAll(rest.substr(0, cut + 1)); !ok) {
            return ok;
        }
        rest.remove_prefix(cut + 1);
        if (!rest.empty()) {
            if (auto ok = rotate(); !ok) {
                return ok;
            }
        }
    }
    return enforceTotal();
}

Status FieldLogWriter::sync() {
    if (faulted()) {
        return makeError(ErrorCode::kIo, fault_);
    }
    if (::fdatasync(fd_.get()) != 0) {
        return setFault(current_.path, "fdatasync failed", errno);
    }
    return {};
}

// ---------------------------------------------------------------------------

bool isJsonObjectLine(std::string_view text) {
    const auto first = text.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || text[first] != '{') {
        return false;
    }
    return nlohmann::json::accept(text);
}

void readFieldLogText(std::string_view text, const std::filesystem::path& file,
                      FieldLogContents& out) {
    out.files.push_back(file);
    splitLines(text, out.files.size() - 1, file, out);
}

Result<FieldLogContents> readFieldLog(const std::filesystem::path& path) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kNotFound, path.string() + ": no such file or directory");
    }
    FieldLogContents out;
    if (std::filesystem::is_directory(status)) {
        for (auto& f : listFieldLogFiles(path)) {
            std::error_code type_ec;
            if (std::filesystem::is_regular_file(f.path, type_ec)) {  // not a device or fifo
                out.files.push_back(std::move(f.path));
            }
        }
        if (out.files.empty()) {
            return makeError(ErrorCode::kNotFound,
                             path.string() + ": no field log files (scaled-*.jsonl) in it");
        }
    } else {
        out.files.push_back(path);
    }
    for (std::size_t i = 0; i < out.files.size(); ++i) {
        auto text = readWhole(out.files[i]);
        if (!text) {
            return text.error();
        }
        splitLines(*text, i, out.files[i], out);
    }
    return out;
}

}  // namespace scaled::drivers::fieldlog
