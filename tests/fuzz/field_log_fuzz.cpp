// The field log's reader (readFieldLogText, drivers/src/field_log.cpp) and
// field-log's analysis of what it read (tools/field_log/field_log_report.cpp)
// on any file content: every kept line is one line opening a JSON object,
// each line is counted once, summary.json is valid JSON and every CSV row is
// one record (a line break only inside a quoted field, RFC 4180).

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/drivers/fieldlog/field_log.h>

#include "field_log_report.h"
#include "fuzz_support.h"

using scaled::fuzz::check;

namespace {

// One CSV record: quotes balanced, line breaks only between quotes.
bool isOneRecord(const std::string& row) {
    bool quoted = false;
    for (const char c : row) {
        if (c == '"') {
            quoted = !quoted;
        } else if ((c == '\n' || c == '\r') && !quoted) {
            return false;
        }
    }
    return !quoted;
}

void checkRows(const std::vector<std::string>& rows, const char* what) {
    for (const std::string& row : rows) {
        check(isOneRecord(row), what);
    }
}

}  // namespace

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view text = scaled::fuzz::asText(data, size);
    scaled::drivers::fieldlog::FieldLogContents contents;
    scaled::drivers::fieldlog::readFieldLogText(text, "log/scaled-fuzz.jsonl", contents);
    check(contents.files.size() == 1, "one file read");
    std::size_t newlines = 0;
    for (const char c : text) {
        newlines += c == '\n' ? 1 : 0;
    }
    check(contents.lines.size() + contents.partial_lines + contents.corrupt_lines <= newlines + 1,
          "each line counted at most once");
    check(contents.partial_lines <= 1, "only the last line of a file is partial");
    for (const auto& line : contents.lines) {
        // (Whether it is a JSON object is the reader's own isJsonObjectLine:
        // not checked again here, it would double the cost of a run.)
        check(line.text.find_first_not_of(" \t\r") != std::string::npos &&
                  line.text[line.text.find_first_not_of(" \t\r")] == '{',
              "a kept line starts with '{'");
        check(line.text.find('\n') == std::string::npos, "a kept line is one line");
    }

    const scaled::tools::FieldLogAnalysis a = scaled::tools::analyseFieldLog(contents, "log");
    check(a.lines == contents.lines.size(), "the analysis counts the lines read");
    check(nlohmann::json::accept(scaled::tools::toJson(a)), "summary.json is valid JSON");
    (void)scaled::tools::toText(a);
    checkRows(a.frame_rows, "frames.csv rows are one record");
    checkRows(a.update_rows, "updates.csv rows are one record");
    checkRows(a.observation_rows, "observations.csv rows are one record");
    checkRows(a.object_rows, "objects.csv rows are one record");
    checkRows(a.pose_rows, "poses.csv rows are one record");
    checkRows(a.window_rows, "windows.csv rows are one record");
    return 0;
}
