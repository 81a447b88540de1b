#include <algorithm>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <random>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <scaled/core/result.h>
#include <scaled/core/scale/height_prior.h>
#include <scaled/drivers/priors/priors_toml.h>

#include "temp_dir.h"

namespace scaled::drivers::priors {
namespace {

using core::ErrorCode;
using core::HeightPrior;
using core::PriorTable;
using core::Scalar;

constexpr std::string_view kName = "prio.toml";

std::string shippedPath() {
    return std::string(SCALED_SOURCE_DIR) + "/config/priors.toml";
}

std::string redkitchenPath() {
    return std::string(SCALED_SOURCE_DIR) + "/config/priors-redkitchen.toml";
}

std::string readFile(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    EXPECT_TRUE(in.good()) << "cannot open " << path;
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

bool writeFile(const std::filesystem::path& path, std::string_view content) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << content;
    return out.good();
}

// One TOML line per element, so line N of the text is element N-1.
std::string lines(std::initializer_list<std::string_view> ls) {
    std::string out;
    for (const auto l : ls) {
        out += l;
        out += '\n';
    }
    return out;
}

std::vector<std::string> splitLines(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string l; std::getline(in, l);) {
        out.push_back(l);
    }
    return out;
}

// A one-class file: lines 1-5 are fixed, `body` starts at line 6.
//   1 version = 1
//   2
//   3 [classes.cup]
//   4 upright = true
//   5 source = "test"
std::string cupWith(std::initializer_list<std::string_view> body) {
    std::string out =
        lines({"version = 1", "", "[classes.cup]", "upright = true", R"(source = "test")"});
    for (const auto l : body) {
        out += l;
        out += '\n';
    }
    return out;
}

// The prefix every located error message has: "prio.toml:7: classes.cup.std_m: ".
// line 0 means the message carries no line number ("prio.toml: version: ").
std::string where(int line, std::string_view key, std::string_view source = kName) {
    std::string s(source);
    if (line > 0) {
        s += ":" + std::to_string(line);
    }
    s += ": ";
    s += key;
    s += ": ";
    return s;
}

::testing::AssertionResult startsWith(const std::string& msg, const std::string& prefix) {
    if (msg.starts_with(prefix)) {
        return ::testing::AssertionSuccess();
    }
    return ::testing::AssertionFailure()
           << "message\n  \"" << msg << "\"\ndoes not start with\n  \"" << prefix << "\"";
}

::testing::AssertionResult contains(const std::string& msg, std::string_view part) {
    if (msg.find(part) != std::string::npos) {
        return ::testing::AssertionSuccess();
    }
    return ::testing::AssertionFailure()
           << "message\n  \"" << msg << "\"\ndoes not contain\n  \"" << part << "\"";
}

// Parses text that must fail; returns the message (empty, with a failure, if it parsed).
std::string parseError(const std::string& text) {
    const auto r = parsePriors(text, kName);
    if (r.ok()) {
        ADD_FAILURE() << "parsed OK, expected an error; text:\n" << text;
        return {};
    }
    EXPECT_EQ(r.error().code, ErrorCode::kParse) << r.error().message;
    return r.error().message;
}

Scalar sum(std::span<const Scalar> v) {
    Scalar s = 0;
    for (const Scalar x : v) {
        s += x;
    }
    return s;
}

Scalar normalCdf(Scalar x) {
    return Scalar(0.5) * std::erfc(-x / std::sqrt(Scalar(2)));
}

// ---------------------------------------------------------------------------
// The shipped config/priors.toml
// ---------------------------------------------------------------------------

// (class name, line of its [classes.X] header) for every class table in the raw text.
std::vector<std::pair<std::string, int>> classHeaders(const std::string& text) {
    std::vector<std::pair<std::string, int>> out;
    const auto ls = splitLines(text);
    for (std::size_t i = 0; i < ls.size(); ++i) {
        const std::string_view l = ls[i];
        constexpr std::string_view kPrefix = "[classes.";
        if (!l.starts_with(kPrefix) || !l.ends_with("]")) {
            continue;
        }
        std::string name(l.substr(kPrefix.size(), l.size() - kPrefix.size() - 1));
        if (name.size() >= 2 && name.front() == '"' && name.back() == '"') {
            name = name.substr(1, name.size() - 2);
        }
        out.emplace_back(name, static_cast<int>(i + 1));
    }
    return out;
}

TEST(ShippedPriors, LoadsWithTheCocoClassesAndSaneHistograms) {
    const auto r = loadPriorsFile(shippedPath());
    ASSERT_TRUE(r.ok()) << r.error().message;
    const PriorTable& table = r.value();

    for (const char* name :
         {"person",    "bicycle",       "car",          "motorcycle", "bus",
          "truck",     "traffic light", "fire hydrant", "stop sign",  "parking meter",
          "bench",     "bottle",        "wine glass",   "cup",        "chair",
          "couch",     "potted plant",  "toilet",       "tv",         "laptop",
          "microwave", "oven",          "refrigerator", "book",       "clock",
          "vase",      "teddy bear",    "suitcase",     "sink",       "dining table",
          "keyboard"}) {
        const HeightPrior* p = table.find(name);
        ASSERT_NE(p, nullptr) << "missing class '" << name << "'";
        EXPECT_EQ(p->className(), name);
    }

    for (const char* name : {"dining table", "keyboard", "book", "sink"}) {
        EXPECT_FALSE(table.find(name)->upright()) << name;
    }
    for (const char* name : {"bottle", "chair", "person", "car", "tv"}) {
        EXPECT_TRUE(table.find(name)->upright()) << name;
    }

    for (const HeightPrior& p : table.priors()) {
        SCOPED_TRACE(p.className());
        ASSERT_GT(p.size(), 0u);
        ASSERT_EQ(p.heights().size(), p.probabilities().size());
        EXPECT_NEAR(sum(p.probabilities()), 1.0, 1e-9);
        EXPECT_GT(p.heights().front(), 0.0);
        const auto h = p.heights();
        EXPECT_EQ(std::adjacent_find(h.begin(), h.end(), [](Scalar a, Scalar b) { return a >= b; }),
                  h.end())
            << "heights not strictly ascending";
        for (const Scalar q : p.probabilities()) {
            EXPECT_GT(q, 0.0);
        }
        EXPECT_GT(p.binWidth(), 0.0);
    }

    const auto meanOf = [&](const char* name) { return table.find(name)->mean(); };
    EXPECT_GE(meanOf("person"), 1.5);
    EXPECT_LE(meanOf("person"), 1.85);
    EXPECT_GE(meanOf("cup"), 0.06);
    EXPECT_LE(meanOf("cup"), 0.16);
    EXPECT_GE(meanOf("chair"), 0.7);
    EXPECT_LE(meanOf("chair"), 1.1);
    EXPECT_GE(meanOf("car"), 1.3);
    EXPECT_LE(meanOf("car"), 1.8);
    EXPECT_GE(meanOf("bottle"), 0.15);
    EXPECT_LE(meanOf("bottle"), 0.4);
}

TEST(ShippedPriors, EveryClassTableHasANonEmptySource) {
    const std::string text = readFile(shippedPath());
    const auto headers = classHeaders(text);
    const auto r = parsePriors(text, "priors.toml");
    ASSERT_TRUE(r.ok()) << r.error().message;
    // The raw scan sees exactly the classes the loader loaded.
    ASSERT_EQ(headers.size(), r.value().priors().size());

    const auto ls = splitLines(text);
    for (std::size_t h = 0; h < headers.size(); ++h) {
        const auto& [name, header_line] = headers[h];
        SCOPED_TRACE(name);
        EXPECT_NE(r.value().find(name), nullptr);
        const std::size_t begin = static_cast<std::size_t>(header_line);  // first line after header
        const std::size_t end = h + 1 < headers.size()
                                    ? static_cast<std::size_t>(headers[h + 1].second - 1)
                                    : ls.size();

        // Find `source = "..."` in this table and check it is non-empty.
        std::size_t source_index = end;
        for (std::size_t i = begin; i < end; ++i) {
            if (ls[i].starts_with("source")) {
                source_index = i;
            }
        }
        ASSERT_LT(source_index, end) << "no source line";
        const std::string& src = ls[source_index];
        const auto quote = src.find('"');
        ASSERT_NE(quote, std::string::npos) << src;
        EXPECT_NE(src.substr(quote), "\"\"") << src;
        EXPECT_GT(src.size(), quote + 2) << src;

        // Without its source line the file is rejected, naming this class's source key
        // at the line of its table header.
        std::string without;
        for (std::size_t i = 0; i < ls.size(); ++i) {
            if (i != source_index) {
                without += ls[i];
                without += '\n';
            }
        }
        const std::string msg = parseError(without);
        EXPECT_TRUE(startsWith(msg, where(header_line, "classes." + name + ".source")));
        EXPECT_TRUE(contains(msg, "missing"));
    }
}

// Every class with upright = true has a width prior (the object model needs
// one), with a real spread, and its source names where the width comes from.
// Fails when someone adds an upright class without width_mean_m/width_std_m.
void expectWidthForEveryUprightClass(const std::string& path) {
    SCOPED_TRACE(path);
    const std::string text = readFile(path);
    const auto r = parsePriors(text, path);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const auto headers = classHeaders(text);
    const auto ls = splitLines(text);
    int upright = 0;
    for (std::size_t h = 0; h < headers.size(); ++h) {
        const auto& [name, header_line] = headers[h];
        SCOPED_TRACE(name);
        const HeightPrior* p = r.value().find(name);
        ASSERT_NE(p, nullptr);
        if (!p->upright()) {
            continue;
        }
        ++upright;
        EXPECT_TRUE(p->hasWidth()) << "upright class without width_mean_m/width_std_m";
        EXPECT_GT(p->widthMean(), 0.0);
        // A population spread, not an exact width.
        EXPECT_GT(p->widthStd(), 0.0);
        EXPECT_LE(p->widthStd(), p->widthMean());
        const std::size_t end = h + 1 < headers.size()
                                    ? static_cast<std::size_t>(headers[h + 1].second - 1)
                                    : ls.size();
        bool source_names_width = false;
        for (auto i = static_cast<std::size_t>(header_line); i < end; ++i) {
            source_names_width = source_names_width || (ls[i].starts_with("source") &&
                                                        ls[i].find("width:") != std::string::npos);
        }
        EXPECT_TRUE(source_names_width) << "source does not say where the width comes from";
    }
    EXPECT_GT(upright, 0);
}

TEST(ShippedPriors, EveryUprightClassHasAWidth) {
    expectWidthForEveryUprightClass(shippedPath());

    const auto r = loadPriorsFile(shippedPath());
    ASSERT_TRUE(r.ok()) << r.error().message;
    const auto widthOf = [&](const char* name) { return r.value().find(name)->widthMean(); };
    // A few against the product ranges the file cites.
    EXPECT_GE(widthOf("cup"), 0.06);
    EXPECT_LE(widthOf("cup"), 0.10);
    EXPECT_GE(widthOf("person"), 0.2);
    EXPECT_LE(widthOf("person"), 0.5);
    EXPECT_GE(widthOf("microwave"), 0.3);
    EXPECT_LE(widthOf("microwave"), 0.5);
    EXPECT_GE(widthOf("car"), 1.7);
    EXPECT_LE(widthOf("car"), 5.0);
    // The chair's box top is its backrest: less than the seat depth.
    EXPECT_LT(widthOf("chair"), 0.40);
}

TEST(ShippedPriors, RedkitchenChairAndCupHaveWidths) {
    expectWidthForEveryUprightClass(redkitchenPath());

    const auto r = loadPriorsFile(redkitchenPath());
    ASSERT_TRUE(r.ok()) << r.error().message;
    const HeightPrior* cup = r.value().find("cup");
    const HeightPrior* chair = r.value().find("chair");
    ASSERT_NE(cup, nullptr);
    ASSERT_NE(chair, nullptr);
    EXPECT_DOUBLE_EQ(cup->widthMean(), 0.08);
    EXPECT_DOUBLE_EQ(cup->widthStd(), 0.01);
    EXPECT_DOUBLE_EQ(chair->widthMean(), 0.25);
    EXPECT_DOUBLE_EQ(chair->widthStd(), 0.15);
    EXPECT_FALSE(r.value().find("dining table")->hasWidth());
}

// ---------------------------------------------------------------------------
// Valid input
// ---------------------------------------------------------------------------

TEST(ParsePriors, ReadsBothFormsWithCorrectHistograms) {
    const std::string text = lines({
        "version = 1",
        "[classes.box]",
        "upright = false",
        R"(source = "explicit")",
        "heights_m = [0.3, 0.1, 0.2, 0.4]",
        "probabilities = [2, 1, 0, 1.0]",
        "bin_width_m = 0.05",
        "",
        "[classes.\"tall thing\"]",
        "upright = true",
        R"(source = "normal")",
        "mean_m = 1",
        "std_m = 0.2",
        "min_m = 0.5",
        "max_m = 1.5",
        "bins = 10",
    });
    const auto r = parsePriors(text, kName);
    ASSERT_TRUE(r.ok()) << r.error().message;
    ASSERT_EQ(r.value().priors().size(), 2u);

    // Explicit form: zero bin dropped, sorted by height, normalised.
    const HeightPrior* box = r.value().find("box");
    ASSERT_NE(box, nullptr);
    EXPECT_FALSE(box->upright());
    EXPECT_DOUBLE_EQ(box->binWidth(), 0.05);
    ASSERT_EQ(box->size(), 3u);
    const Scalar want_h[] = {0.1, 0.3, 0.4};
    const Scalar want_p[] = {0.25, 0.5, 0.25};
    for (std::size_t i = 0; i < 3; ++i) {
        EXPECT_DOUBLE_EQ(box->heights()[i], want_h[i]) << i;
        EXPECT_NEAR(box->probabilities()[i], want_p[i], 1e-12) << i;
        EXPECT_NEAR(box->logProbabilities()[i], std::log(want_p[i]), 1e-12) << i;
    }

    // Normal form: 10 equal bins over [0.5, 1.5], truncated-normal masses.
    const HeightPrior* tall = r.value().find("tall thing");
    ASSERT_NE(tall, nullptr);
    EXPECT_TRUE(tall->upright());
    ASSERT_EQ(tall->size(), 10u);
    EXPECT_NEAR(tall->binWidth(), 0.1, 1e-12);
    EXPECT_NEAR(sum(tall->probabilities()), 1.0, 1e-12);
    for (std::size_t i = 0; i < 10; ++i) {
        EXPECT_NEAR(tall->heights()[i], 0.55 + 0.1 * static_cast<Scalar>(i), 1e-12) << i;
        EXPECT_NEAR(tall->probabilities()[i], tall->probabilities()[9 - i], 1e-12) << i;
    }
    EXPECT_NEAR(tall->mean(), 1.0, 1e-12);
    // Bin [0.9, 1.0]: (Phi(0) - Phi(-0.5)) / (Phi(2.5) - Phi(-2.5)).
    const Scalar z = normalCdf(2.5) - normalCdf(-2.5);
    EXPECT_NEAR(tall->probabilities()[4], (normalCdf(0) - normalCdf(-0.5)) / z, 1e-12);
    EXPECT_GT(tall->probabilities()[4], tall->probabilities()[3]);
    EXPECT_GT(tall->probabilities()[3], tall->probabilities()[0]);
}

TEST(ParsePriors, HistogramBinsIsTheDefaultAndClassBinsOverridesIt) {
    // [histogram] deliberately comes after the classes: TOML order must not matter.
    const std::string text = lines({
        "version = 1",
        "[classes.a]",
        "upright = true",
        R"(source = "s")",
        "mean_m = 1.0",
        "std_m = 0.3",
        "min_m = 0.4",
        "max_m = 1.8",
        "[classes.b]",
        "upright = true",
        R"(source = "s")",
        "mean_m = 1.0",
        "std_m = 0.3",
        "min_m = 0.4",
        "max_m = 1.8",
        "bins = 3",
        "[histogram]",
        "bins = 7",
    });
    const auto r = parsePriors(text, kName);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const HeightPrior* a = r.value().find("a");
    const HeightPrior* b = r.value().find("b");
    ASSERT_NE(a, nullptr);
    ASSERT_NE(b, nullptr);
    EXPECT_EQ(a->size(), 7u);
    EXPECT_NEAR(a->binWidth(), 1.4 / 7, 1e-12);
    EXPECT_EQ(b->size(), 3u);
    EXPECT_NEAR(b->binWidth(), 1.4 / 3, 1e-12);

    // A different [histogram].bins changes only the class without its own bins.
    std::string text9 = text;
    text9.replace(text9.rfind("bins = 7"), 8, "bins = 9");
    const auto r9 = parsePriors(text9, kName);
    ASSERT_TRUE(r9.ok()) << r9.error().message;
    EXPECT_EQ(r9.value().find("a")->size(), 9u);
    EXPECT_EQ(r9.value().find("b")->size(), 3u);
}

TEST(ParsePriors, ReadsTheOptionalWidthInBothForms) {
    const std::string text = lines({
        "version = 1",
        "[classes.cup]",
        "upright = true",
        R"(source = "s")",
        "heights_m = [0.09, 0.1]",
        "probabilities = [1, 1]",
        "width_mean_m = 0.08",
        "width_std_m = 0.01",
        "[classes.chair]",
        "width_std_m = 0.15",
        "width_mean_m = 0.25",
        "upright = true",
        R"(source = "s")",
        "mean_m = 0.9",
        "std_m = 0.1",
        "min_m = 0.6",
        "max_m = 1.3",
        "[classes.tv]",
        "upright = true",
        R"(source = "s")",
        "heights_m = [0.5]",
        "probabilities = [1]",
        "width_mean_m = 1",
        "width_std_m = 0",
        "[classes.book]",
        "upright = false",
        R"(source = "s")",
        "heights_m = [0.2]",
        "probabilities = [1]",
    });
    const auto r = parsePriors(text, kName);
    ASSERT_TRUE(r.ok()) << r.error().message;
    const HeightPrior* cup = r.value().find("cup");
    const HeightPrior* chair = r.value().find("chair");
    const HeightPrior* tv = r.value().find("tv");
    const HeightPrior* book = r.value().find("book");
    ASSERT_TRUE(cup != nullptr && chair != nullptr && tv != nullptr && book != nullptr);
    EXPECT_TRUE(cup->hasWidth());
    EXPECT_DOUBLE_EQ(cup->widthMean(), 0.08);
    EXPECT_DOUBLE_EQ(cup->widthStd(), 0.01);
    EXPECT_TRUE(chair->hasWidth());
    EXPECT_DOUBLE_EQ(chair->widthMean(), 0.25);
    EXPECT_DOUBLE_EQ(chair->widthStd(), 0.15);
    // Integers are numbers; std 0 is an exact width.
    EXPECT_TRUE(tv->hasWidth());
    EXPECT_DOUBLE_EQ(tv->widthMean(), 1.0);
    EXPECT_DOUBLE_EQ(tv->widthStd(), 0.0);
    // Without the keys: no width model.
    EXPECT_FALSE(book->hasWidth());
    EXPECT_DOUBLE_EQ(book->widthMean(), 0.0);
    EXPECT_DOUBLE_EQ(book->widthStd(), 0.0);
    // The width does not change the height histogram.
    const auto plain = HeightPrior::fromNormal("chair", 0.9, 0.1, 0.6, 1.3, 24, true);
    ASSERT_TRUE(plain.ok()) << plain.error().message;
    ASSERT_EQ(chair->size(), plain->size());
    for (std::size_t i = 0; i < plain->size(); ++i) {
        EXPECT_DOUBLE_EQ(chair->heights()[i], plain->heights()[i]) << i;
        EXPECT_DOUBLE_EQ(chair->probabilities()[i], plain->probabilities()[i]) << i;
    }
}

// ---------------------------------------------------------------------------
// Errors: file name, line, full key and offending value
// ---------------------------------------------------------------------------

TEST(ParsePriorsErrors, NegativeStd) {
    const std::string msg =
        parseError(cupWith({"mean_m = 0.10", "std_m = -0.1", "min_m = 0.05", "max_m = 0.18"}));
    EXPECT_TRUE(contains(msg, "std_m"));
    EXPECT_TRUE(contains(msg, "-0.1"));
    EXPECT_TRUE(startsWith(msg, where(7, "classes.cup.std_m")));
}

TEST(ParsePriorsErrors, MinNotBelowMax) {
    const std::string msg =
        parseError(cupWith({"mean_m = 0.10", "std_m = 0.02", "min_m = 0.2", "max_m = 0.2"}));
    EXPECT_TRUE(contains(msg, "0.2"));
    // Either of the two keys involved, at its own line.
    EXPECT_TRUE(startsWith(msg, where(8, "classes.cup.min_m")) ||
                startsWith(msg, where(9, "classes.cup.max_m")))
        << msg;
}

TEST(ParsePriorsErrors, MeanOutsideRange) {
    const std::string msg =
        parseError(cupWith({"mean_m = 0.5", "std_m = 0.02", "min_m = 0.05", "max_m = 0.18"}));
    EXPECT_TRUE(contains(msg, "0.5"));
    EXPECT_TRUE(startsWith(msg, where(6, "classes.cup.mean_m")));
}

TEST(ParsePriorsErrors, UnknownKeyInClass) {
    const std::string msg = parseError(cupWith(
        {"mean_m = 0.10", "std_m = 0.02", "min_m = 0.05", "max_m = 0.18", R"(colour = "red")"}));
    EXPECT_TRUE(startsWith(msg, where(10, "classes.cup.colour")));
    EXPECT_TRUE(contains(msg, "unknown key"));
}

TEST(ParsePriorsErrors, UnknownTopLevelKey) {
    const std::string msg =
        parseError(lines({"version = 1", "flavour = 3", "[classes.cup]", "upright = true",
                          R"(source = "s")", "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(2, "flavour")));
    EXPECT_TRUE(contains(msg, "unknown key"));
}

TEST(ParsePriorsErrors, UnknownKeyInHistogram) {
    const std::string msg = parseError(
        lines({"version = 1", "[histogram]", "bins = 8", "width = 0.1", "[classes.cup]",
               "upright = true", R"(source = "s")", "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(4, "histogram.width")));
    EXPECT_TRUE(contains(msg, "unknown key"));
}

TEST(ParsePriorsErrors, MissingVersion) {
    const std::string msg = parseError(lines({"[classes.cup]", "upright = true", R"(source = "s")",
                                              "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(0, "version")));
    EXPECT_TRUE(contains(msg, "missing"));
}

TEST(ParsePriorsErrors, UnsupportedVersion) {
    const std::string msg =
        parseError(lines({"", "version = 2", "[classes.cup]", "upright = true", R"(source = "s")",
                          "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(2, "version")));
    EXPECT_TRUE(contains(msg, "version 2"));
}

TEST(ParsePriorsErrors, MissingUpright) {
    const std::string msg = parseError(lines({"version = 1", "", "[classes.cup]", R"(source = "s")",
                                              "heights_m = [0.1]", "probabilities = [1]"}));
    // Nothing to point at but the class table itself.
    EXPECT_TRUE(startsWith(msg, where(3, "classes.cup.upright")));
    EXPECT_TRUE(contains(msg, "missing"));
}

TEST(ParsePriorsErrors, UprightOfWrongType) {
    const std::string msg =
        parseError(lines({"version = 1", "", "[classes.cup]", R"(source = "s")",
                          R"(upright = "yes")", "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(5, "classes.cup.upright")));
    EXPECT_TRUE(contains(msg, R"("yes")"));
}

TEST(ParsePriorsErrors, NumberOfWrongType) {
    const std::string msg =
        parseError(cupWith({"mean_m = 0.10", R"(std_m = "wide")", "min_m = 0.05", "max_m = 0.18"}));
    EXPECT_TRUE(startsWith(msg, where(7, "classes.cup.std_m")));
    EXPECT_TRUE(contains(msg, R"("wide")"));
}

TEST(ParsePriorsErrors, BothForms) {
    const std::string msg =
        parseError(cupWith({"mean_m = 0.10", "std_m = 0.02", "min_m = 0.05", "max_m = 0.18",
                            "heights_m = [0.1]", "probabilities = [1]"}));
    EXPECT_TRUE(startsWith(msg, where(3, "classes.cup")));
    EXPECT_TRUE(contains(msg, "exactly one form"));
}

TEST(ParsePriorsErrors, NeitherForm) {
    const std::string msg = parseError(cupWith({}));
    EXPECT_TRUE(startsWith(msg, where(3, "classes.cup")));
    EXPECT_TRUE(contains(msg, "exactly one form"));
}

TEST(ParsePriorsErrors, IncompleteNormalForm) {
    const std::string msg = parseError(cupWith({"mean_m = 0.10", "min_m = 0.05", "max_m = 0.18"}));
    EXPECT_TRUE(startsWith(msg, where(3, "classes.cup.std_m")));
    EXPECT_TRUE(contains(msg, "missing"));
}

// Lines 6-7 of cupWith: the explicit form; the width keys follow from line 8.
std::string cupWidthError(std::initializer_list<std::string_view> width_lines) {
    std::string text = cupWith({"heights_m = [0.1]", "probabilities = [1]"});
    for (const auto l : width_lines) {
        text += l;
        text += '\n';
    }
    return parseError(text);
}

TEST(ParsePriorsErrors, WidthMeanNotPositive) {
    for (const std::string_view value : {"0", "-0.05", "nan", "inf"}) {
        SCOPED_TRACE(value);
        const std::string line = "width_mean_m = " + std::string(value);
        const std::string msg = cupWidthError({line, "width_std_m = 0.01"});
        EXPECT_TRUE(startsWith(msg, where(8, "classes.cup.width_mean_m")));
        EXPECT_TRUE(contains(msg, "must be > 0"));
        EXPECT_TRUE(contains(msg, "(got " + std::string(value) + ")"));
    }
}

TEST(ParsePriorsErrors, WidthStdNegative) {
    for (const std::string_view value : {"-0.01", "-1", "nan"}) {
        SCOPED_TRACE(value);
        const std::string line = "width_std_m = " + std::string(value);
        const std::string msg = cupWidthError({"width_mean_m = 0.08", line});
        EXPECT_TRUE(startsWith(msg, where(9, "classes.cup.width_std_m")));
        EXPECT_TRUE(contains(msg, "must be >= 0"));
        EXPECT_TRUE(contains(msg, "(got " + std::string(value) + ")"));
    }
}

TEST(ParsePriorsErrors, WidthMeanWithoutStdAndStdWithoutMean) {
    const std::string mean_only = cupWidthError({"width_mean_m = 0.08"});
    EXPECT_TRUE(startsWith(mean_only, where(8, "classes.cup.width_mean_m")));
    EXPECT_TRUE(contains(mean_only, "width_std_m"));

    const std::string std_only = cupWidthError({"", "width_std_m = 0.01"});
    EXPECT_TRUE(startsWith(std_only, where(9, "classes.cup.width_std_m")));
    EXPECT_TRUE(contains(std_only, "width_mean_m"));

    // Also in the mean/std form of the heights.
    const std::string normal = parseError(cupWith(
        {"mean_m = 0.10", "std_m = 0.02", "min_m = 0.05", "max_m = 0.18", "width_std_m = 0.01"}));
    EXPECT_TRUE(startsWith(normal, where(10, "classes.cup.width_std_m")));
    EXPECT_TRUE(contains(normal, "width_mean_m"));
}

TEST(ParsePriorsErrors, WidthOfWrongType) {
    const std::string mean = cupWidthError({R"(width_mean_m = "wide")", "width_std_m = 0.01"});
    EXPECT_TRUE(startsWith(mean, where(8, "classes.cup.width_mean_m")));
    EXPECT_TRUE(contains(mean, "must be a number"));
    EXPECT_TRUE(contains(mean, R"("wide")"));

    const std::string std_m = cupWidthError({"width_mean_m = 0.08", "width_std_m = [0.01]"});
    EXPECT_TRUE(startsWith(std_m, where(9, "classes.cup.width_std_m")));
    EXPECT_TRUE(contains(std_m, "must be a number"));
    EXPECT_TRUE(contains(std_m, "an array"));

    const std::string boolean = cupWidthError({"width_mean_m = true", "width_std_m = 0.01"});
    EXPECT_TRUE(startsWith(boolean, where(8, "classes.cup.width_mean_m")));
    EXPECT_TRUE(contains(boolean, "(got true)"));
}

TEST(ParsePriorsErrors, UnknownKeyListsTheWidthKeys) {
    const std::string msg = cupWidthError({"width_m = 0.08"});
    EXPECT_TRUE(startsWith(msg, where(8, "classes.cup.width_m")));
    EXPECT_TRUE(contains(msg, "unknown key"));
    EXPECT_TRUE(contains(msg, "width_mean_m, width_std_m"));
}

TEST(ParsePriorsErrors, HeightsAndProbabilitiesOfDifferentLengths) {
    const std::string msg =
        parseError(cupWith({"heights_m = [0.08, 0.10, 0.12]", "probabilities = [0.5, 0.5]"}));
    EXPECT_TRUE(contains(msg, "3"));
    EXPECT_TRUE(contains(msg, "2"));
    EXPECT_TRUE(startsWith(msg, where(7, "classes.cup.probabilities")) ||
                startsWith(msg, where(6, "classes.cup.heights_m")))
        << msg;
}

TEST(ParsePriorsErrors, NonNumberInsideHeights) {
    const std::string msg =
        parseError(cupWith({R"(heights_m = [0.08, "tall", 0.12])", "probabilities = [1, 1, 1]"}));
    EXPECT_TRUE(startsWith(msg, where(6, "classes.cup.heights_m[1]")));
    EXPECT_TRUE(contains(msg, R"("tall")"));
}

TEST(ParsePriorsErrors, AllZeroProbabilities) {
    const std::string msg =
        parseError(cupWith({"heights_m = [0.08, 0.10]", "probabilities = [0, 0.0]"}));
    EXPECT_TRUE(contains(msg, "zero"));
    EXPECT_TRUE(startsWith(msg, where(7, "classes.cup.probabilities")));
}

TEST(ParsePriorsErrors, BinsOutOfRange) {
    for (const std::string_view bins : {"0", "100000", "-3"}) {
        SCOPED_TRACE(bins);
        const std::string line = "bins = " + std::string(bins);
        const std::string msg = parseError(
            cupWith({"mean_m = 0.10", "std_m = 0.02", "min_m = 0.05", "max_m = 0.18", line}));
        EXPECT_TRUE(startsWith(msg, where(10, "classes.cup.bins")));
        EXPECT_TRUE(contains(msg, "(got " + std::string(bins) + ")"));

        // The same limits hold for the [histogram] default.
        const std::string hmsg =
            parseError(lines({"version = 1", "[histogram]", line, "[classes.cup]", "upright = true",
                              R"(source = "s")", "heights_m = [0.1]", "probabilities = [1]"}));
        EXPECT_TRUE(startsWith(hmsg, where(3, "histogram.bins")));
        EXPECT_TRUE(contains(hmsg, "(got " + std::string(bins) + ")"));
    }
}

TEST(ParsePriorsErrors, TomlSyntaxErrorHasLineAndColumn) {
    const std::string msg =
        parseError(lines({"version = 1", "", "[classes.cup", "upright = true"}));
    const std::string prefix = std::string(kName) + ":3:";
    ASSERT_TRUE(startsWith(msg, prefix));
    // Then a positive column number and ": ".
    const std::size_t colon = msg.find(':', prefix.size());
    ASSERT_NE(colon, std::string::npos) << msg;
    const std::string column = msg.substr(prefix.size(), colon - prefix.size());
    ASSERT_FALSE(column.empty()) << msg;
    EXPECT_TRUE(std::all_of(column.begin(), column.end(), [](char c) {
        return c >= '0' && c <= '9';
    })) << msg;
    EXPECT_GT(std::stoi(column), 0) << msg;
    EXPECT_EQ(msg.substr(colon, 2), ": ") << msg;
}

TEST(ParsePriorsErrors, NoClasses) {
    for (const std::string& text : {lines({"version = 1", "[classes]"}), lines({"version = 1"})}) {
        SCOPED_TRACE(text);
        const std::string msg = parseError(text);
        EXPECT_TRUE(startsWith(msg, std::string(kName) + ":"));
        EXPECT_TRUE(contains(msg, "classes: "));
        EXPECT_TRUE(contains(msg, "no classes"));
    }
}

TEST(ParsePriorsErrors, ClassThatIsNotATable) {
    const std::string msg = parseError(lines({"version = 1", "[classes]", "cup = 3"}));
    EXPECT_TRUE(startsWith(msg, where(3, "classes.cup")));
    EXPECT_TRUE(contains(msg, "table"));
}

// ---------------------------------------------------------------------------
// loadPriorsFile
// ---------------------------------------------------------------------------

TEST(LoadPriorsFile, MissingFileIsAnIoErrorNamingThePath) {
    const test::TempDir dir("priors_toml");
    const auto path = dir.path() / "does_not_exist.toml";
    const auto r = loadPriorsFile(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kIo);
    EXPECT_TRUE(contains(r.error().message, path.string()));
}

TEST(LoadPriorsFile, ParseErrorNamesTheFile) {
    const test::TempDir tmp("priors_toml");
    const auto& dir = tmp.path();
    const auto path = dir / "bad.toml";
    ASSERT_TRUE(writeFile(
        path, cupWith({"mean_m = 0.10", R"(std_m = "wide")", "min_m = 0.05", "max_m = 0.18"})));
    const auto r = loadPriorsFile(path);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kParse);
    EXPECT_TRUE(startsWith(r.error().message, where(7, "classes.cup.std_m", path.string())));

    const auto syntax = dir / "syntax.toml";
    ASSERT_TRUE(writeFile(syntax, "version = 1\nversion = \n"));
    const auto rs = loadPriorsFile(syntax);
    ASSERT_FALSE(rs.ok());
    EXPECT_EQ(rs.error().code, ErrorCode::kParse);
    EXPECT_TRUE(startsWith(rs.error().message, syntax.string() + ":2:"));

    const auto good = dir / "good.toml";
    ASSERT_TRUE(writeFile(good, cupWith({"heights_m = [0.1]", "probabilities = [1]"})));
    const auto rg = loadPriorsFile(good);
    ASSERT_TRUE(rg.ok()) << rg.error().message;
    EXPECT_NE(rg.value().find("cup"), nullptr);
}

TEST(LoadPriorsFile, DirectoryIsAnIoError) {
    const test::TempDir tmp("priors_toml");
    const auto& dir = tmp.path();
    const auto r = loadPriorsFile(dir);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().code, ErrorCode::kIo) << r.error().message;
    EXPECT_TRUE(contains(r.error().message, dir.string()));
}

// ---------------------------------------------------------------------------
// Robustness: mutated versions of the shipped file never crash the loader
// ---------------------------------------------------------------------------

TEST(ParsePriorsFuzz, MutatedShippedFileGivesOkOrALocatedError) {
    const std::string original = readFile(shippedPath());
    ASSERT_FALSE(original.empty());
    constexpr std::string_view kSource = "mutant.toml";
    constexpr std::string_view kChars = "=[]\"#.0-\n";

    // Raw mt19937 output (fully specified by the standard) so the variants are the
    // same on every platform; std::uniform_int_distribution is not.
    std::mt19937 rng(20170721u);
    const auto pick = [&](std::size_t n) { return static_cast<std::size_t>(rng() % n); };

    int n_ok = 0;
    int n_error = 0;
    for (int variant = 0; variant < 300; ++variant) {
        std::string text = original;
        const std::size_t n_mutations = 1 + pick(3);
        for (std::size_t m = 0; m < n_mutations && !text.empty(); ++m) {
            switch (pick(4)) {
                case 0:  // delete a character
                    text.erase(pick(text.size()), 1);
                    break;
                case 1: {  // duplicate a line
                    const std::size_t at = pick(text.size());
                    const std::size_t nl = text.rfind('\n', at);
                    const std::size_t begin = nl == std::string::npos ? 0 : nl + 1;
                    std::size_t end = text.find('\n', begin);
                    end = end == std::string::npos ? text.size() : end + 1;
                    const std::string line = text.substr(begin, end - begin);
                    text.insert(end, line.ends_with('\n') ? line : "\n" + line);
                    break;
                }
                case 2:  // replace a character
                    text[pick(text.size())] = kChars[pick(kChars.size())];
                    break;
                default:  // truncate
                    text.resize(pick(text.size() + 1));
                    break;
            }
        }

        const auto r = parsePriors(text, kSource);
        if (!r.ok()) {
            ++n_error;
            EXPECT_EQ(r.error().code, ErrorCode::kParse) << r.error().message;
            EXPECT_TRUE(startsWith(r.error().message, std::string(kSource) + ":"))
                << "variant " << variant;
            continue;
        }
        ++n_ok;
        ASSERT_FALSE(r.value().empty()) << "variant " << variant;
        for (const HeightPrior& p : r.value().priors()) {
            ASSERT_GT(p.size(), 0u) << "variant " << variant << " class " << p.className();
            EXPECT_NEAR(sum(p.probabilities()), 1.0, 1e-9) << "variant " << variant;
            EXPECT_TRUE(std::is_sorted(p.heights().begin(), p.heights().end()))
                << "variant " << variant;
            EXPECT_GT(p.heights().front(), 0.0) << "variant " << variant;
        }
    }
    // Both outcomes occur, so the test exercises the error paths and the success path.
    EXPECT_GT(n_ok, 30);
    EXPECT_GT(n_error, 30);
}

// The daemon's fallback when /etc/scaled/priors.toml is missing: exactly the
// repository's config/priors.toml of this build, and it parses to the same table.
TEST(BuiltinPriors, AreTheShippedFileAndParse) {
    const std::string shipped = readFile(shippedPath());
    EXPECT_EQ(builtinPriorsToml(), shipped);
    const auto builtin = parsePriors(builtinPriorsToml(), "built-in config/priors.toml");
    const auto file = loadPriorsFile(shippedPath());
    ASSERT_TRUE(builtin) << builtin.error().message;
    ASSERT_TRUE(file) << file.error().message;
    ASSERT_EQ(builtin->priors().size(), file->priors().size());
    for (std::size_t i = 0; i < file->priors().size(); ++i) {
        EXPECT_EQ(builtin->priors()[i].className(), file->priors()[i].className());
        EXPECT_EQ(builtin->priors()[i].mean(), file->priors()[i].mean());
    }
}

}  // namespace
}  // namespace scaled::drivers::priors
