#pragma once

// The configuration field registry shared by pipeline_config.cpp and
// daemon_config.cpp (private to scaled_daemon: it includes toml++).
//
// A Field is one `section.key`, bound to a member of a configuration object:
// `set` checks a TOML node and stores it (nullopt = accepted, else what is
// wrong, with the allowed range and the value), `value` prints the member as
// TOML. A configuration is a list of fields bound to a working copy; applying
// a document or an override checks every key against the list, then the
// caller runs its cross-field checks and commits the copy.

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <toml++/toml.h>

#include <scaled/core/param_limits.h>
#include <scaled/core/result.h>
#include <scaled/daemon/pipeline_config.h>
#include <scaled/drivers/priors/toml_read.h>

namespace scaled::daemon::config_detail {

using SetFn =
    std::function<std::optional<std::string>(const toml::node&, const std::filesystem::path&)>;

struct Field {
    std::string section;
    std::string key;
    SetFn set;
    std::function<std::string()> value;
};

std::string tomlQuote(const std::string& s);

enum class Bound : std::uint8_t { kClosed, kOpen };

// A number within limits core (or a driver) owns (scaled/core/param_limits.h).
template <typename T>
Field real(const char* section, const char* key, T* target, core::ParamLimits limits) {
    using drivers::priors::tomlread::num;
    using drivers::priors::tomlread::show;
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                const auto v = drivers::priors::tomlread::asNumber(n);
                if (!v || !limits.contains(*v)) {
                    return std::string("must be a number in ") + (limits.lo_open ? "(" : "[") +
                           num(limits.lo) + ", " + num(limits.hi) + (limits.hi_open ? ")" : "]") +
                           " (got " + show(n) + ")";
                }
                *target = static_cast<T>(*v);
                return std::nullopt;
            },
            [=] { return num(static_cast<double>(*target)); }};
}

template <typename T>
Field real(const char* section, const char* key, T* target, double lo, double hi,
           Bound lo_bound = Bound::kClosed) {
    return real(section, key, target, core::ParamLimits{lo, hi, lo_bound == Bound::kOpen, false});
}

template <typename T>
Field integer(const char* section, const char* key, T* target, std::int64_t lo, std::int64_t hi) {
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                const auto* i = n.as_integer();
                if (i == nullptr || i->get() < lo || i->get() > hi) {
                    return "must be an integer in [" + std::to_string(lo) + ", " +
                           std::to_string(hi) + "] (got " + drivers::priors::tomlread::show(n) +
                           ")";
                }
                *target = static_cast<T>(i->get());
                return std::nullopt;
            },
            [=] { return std::to_string(*target); }};
}

// An integer within limits core (or a driver) owns; open bounds exclude
// the bound itself.
template <typename T>
Field integer(const char* section, const char* key, T* target, const core::ParamLimits& limits) {
    // Whole bounds inside what int64 holds: the smallest and largest integer
    // the limits contain.
    const auto bound = [](double v) {
        if (!(v > -9.2e18)) {
            return std::numeric_limits<std::int64_t>::min();
        }
        if (!(v < 9.2e18)) {
            return std::numeric_limits<std::int64_t>::max();
        }
        return static_cast<std::int64_t>(v);
    };
    const double lo = limits.lo_open ? std::floor(limits.lo) + 1 : std::ceil(limits.lo);
    const double hi = limits.hi_open ? std::ceil(limits.hi) - 1 : std::floor(limits.hi);
    return integer(section, key, target, bound(lo), bound(hi));
}

template <typename E>
Field choice(const char* section, const char* key, E* target,
             std::vector<std::pair<std::string, E>> names) {
    std::string allowed;
    for (const auto& [name, value] : names) {
        allowed += (allowed.empty() ? "" : ", ") + tomlQuote(name);
    }
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                if (n.is_string()) {
                    for (const auto& [name, value] : names) {
                        if (n.as_string()->get() == name) {
                            *target = value;
                            return std::nullopt;
                        }
                    }
                }
                return "must be one of " + allowed + " (got " + drivers::priors::tomlread::show(n) +
                       ")";
            },
            [=] {
                for (const auto& [name, value] : names) {
                    if (*target == value) {
                        return tomlQuote(name);
                    }
                }
                return std::string("\"?\"");
            }};
}

// Exactly N numbers in [lo, hi], e.g. a row-major 3x3 matrix.
template <std::size_t N>
Field realArray(const char* section, const char* key, std::array<double, N>* target, double lo,
                double hi) {
    using drivers::priors::tomlread::num;
    using drivers::priors::tomlread::show;
    return {section, key,
            [=](const toml::node& n, const std::filesystem::path&) -> std::optional<std::string> {
                const auto* arr = n.as_array();
                const std::string expected = "must be an array of " + std::to_string(N) +
                                             " numbers in [" + num(lo) + ", " + num(hi) + "]";
                if (arr == nullptr) {
                    return expected + " (got " + show(n) + ")";
                }
                if (arr->size() != N) {
                    return expected + " (got an array of " + std::to_string(arr->size()) + ")";
                }
                std::array<double, N> out{};
                for (std::size_t i = 0; i < N; ++i) {
                    const toml::node& e = (*arr)[i];
                    const auto v = drivers::priors::tomlread::asNumber(e);
                    if (!v || !std::isfinite(*v) || *v < lo || *v > hi) {
                        return expected + ": entry " + std::to_string(i) + " (got " + show(e) + ")";
                    }
                    out[i] = *v;
                }
                *target = out;
                return std::nullopt;
            },
            [=] {
                std::string s = "[";
                for (std::size_t i = 0; i < N; ++i) {
                    s += (i > 0 ? ", " : "") + num((*target)[i]);
                }
                return s + "]";
            }};
}

Field boolean(const char* section, const char* key, bool* target);
// A path; a relative one resolves against the base directory (the file's,
// or the working directory for overrides). "" stays empty.
Field path(const char* section, const char* key, std::filesystem::path* target);
// Any string (empty allowed).
Field text(const char* section, const char* key, std::string* target);
Field stringList(const char* section, const char* key, std::vector<std::string>* target);

// Moves the fields of `more` to the end of `out` (one section's table after
// another, in file order).
void appendFields(std::vector<Field>& out, std::vector<Field> more);

// The pipeline's sections ([tracker] [detector] [detection] [estimator]) in
// file order, bound to `c`.
std::vector<Field> pipelineFields(PipelineConfig& c);

// Where a key stands, for cross-field errors: `SOURCE[:LINE]` of the first
// of `keys` (`section.key`) that the input set, else of the input as a whole.
using Locator = std::function<std::string(const std::vector<std::string>& keys)>;

// A Locator over a parsed document: the line of the key, else of its section.
Locator documentLocator(const toml::table& root, std::string_view source);

// `WHERE: KEY: WHAT` (kInvalidArgument).
core::Error checkError(const Locator& where, const std::vector<std::string>& keys,
                       const std::string& what);

// Whether a problem about `problem_key` (`section.key`, or a section) is about
// `key`: the same key, or a key of that section.
bool keyCovers(std::string_view problem_key, std::string_view key);

// Every problem a check found, each with the key it is about (`section.key`,
// or a section). Loading stops at the first problem; `scaled --check-config`
// passes a ProblemList to the same checks, which then go on to the end.
struct ProblemList {
    std::vector<core::Error> errors;
    std::vector<std::string> keys;

    void add(core::Error e, std::string key);
    // Whether a problem about `key` was found (a section counts for its keys).
    [[nodiscard]] bool about(std::string_view key) const;
};

// One check's problems: fail() reports one and answers whether the check
// must stop there (true without a ProblemList), result() is the first.
class Checker {
public:
    Checker(const Locator& where, ProblemList* all) : where_(where), all_(all) {}
    bool fail(const std::vector<std::string>& keys, const std::string& what);
    bool fail(core::Error e, std::string key);
    // A nested check's outcome (already in the ProblemList when there is one).
    bool failed(const core::Status& nested);
    [[nodiscard]] core::Status result() const;

private:
    const Locator& where_;
    ProblemList* all_;
    std::optional<core::Error> first_;
};

// The pipeline's cross-field checks, each reported at the later key of a pair.
core::Status checkPipeline(const PipelineConfig& c, const Locator& where,
                           ProblemList* all = nullptr);

// Checks every section and key of `root` against `fields` and sets them
// (unknown sections and keys, types and ranges; no cross-field checks). On
// error the bound object may be partly set: callers bind a working copy.
// With `all`, every problem is kept and the valid keys are still set.
core::Status applyFields(const toml::table& root, std::string_view source,
                         const std::filesystem::path& base_dir, const std::vector<Field>& fields,
                         ProblemList* all = nullptr);

// `section.key=value` assignments, each checked as applyFields does (paths
// against the working directory; a bare word is a string). `set_by` records,
// for each `section.key`, the assignment that set it (for a Locator).
core::Status applyAssignments(const std::vector<std::string>& assignments,
                              const std::vector<Field>& fields,
                              std::vector<std::pair<std::string, std::string>>& set_by,
                              ProblemList* all = nullptr);

// A Locator over assignments recorded by applyAssignments; keys not set by
// them are attributed to `fallback`.
Locator assignmentLocator(std::vector<std::pair<std::string, std::string>> set_by,
                          std::string fallback);

// `section.key` of every field, in order.
std::vector<std::string> fieldKeys(const std::vector<Field>& fields);
// The fields as TOML, one [section] after another.
std::string fieldsToToml(const std::vector<Field>& fields);

// A configuration file's text; kIo errors read `PATH: cannot read configuration: why`.
core::Result<std::string> readConfigFile(const std::filesystem::path& path);

}  // namespace scaled::daemon::config_detail
