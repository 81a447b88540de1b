#include <cmath>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <toml++/toml.h>

#include <scaled/drivers/priors/priors_toml.h>
#include <scaled/drivers/priors/toml_read.h>

namespace scaled::drivers::priors {

using core::Error;
using core::ErrorCode;
using core::HeightPrior;
using core::makeError;
using core::PriorTable;
using core::Result;
using core::Scalar;
using drivers::priors::tomlread::num;
using drivers::priors::tomlread::show;

namespace {

constexpr int kFormatVersion = 1;
constexpr int kDefaultBins = 24;

class Reporter {
public:
    explicit Reporter(std::string_view source) : source_(source) {}

    [[nodiscard]] Error at(const toml::node* node, const std::string& key,
                           const std::string& what) const {
        return drivers::priors::tomlread::errorAt(ErrorCode::kParse, source_, node, key, what);
    }

private:
    std::string source_;
};

std::optional<Scalar> number(const toml::node& n) {
    const auto v = drivers::priors::tomlread::asNumber(n);
    return v ? std::optional<Scalar>(static_cast<Scalar>(*v)) : std::nullopt;
}

// A value read from the file with the node it stands at, so that a range error
// names the value's own line.
template <typename T>
struct Located {
    std::optional<T> value;
    const toml::node* node = nullptr;

    explicit operator bool() const { return value.has_value(); }
    const T& operator*() const { return *value; }
    const T* operator->() const { return &*value; }
    void set(T v, const toml::node& n) {
        value = std::move(v);
        node = &n;
    }
};

struct ClassSpec {
    std::optional<bool> upright;
    std::optional<std::string> source;
    std::optional<int> bins;
    Located<Scalar> mean_m, std_m, min_m, max_m, bin_width_m, partial_probability, width_mean_m,
        width_std_m;
    Located<std::vector<Scalar>> heights_m, probabilities;

    // The number-valued and array-valued keys by name; nullptr for others.
    Located<Scalar>* numberKey(std::string_view key) {
        const std::pair<std::string_view, Located<Scalar>*> keys[] = {
            {"mean_m", &mean_m},
            {"std_m", &std_m},
            {"min_m", &min_m},
            {"max_m", &max_m},
            {"bin_width_m", &bin_width_m},
            {"partial_probability", &partial_probability},
            {"width_mean_m", &width_mean_m},
            {"width_std_m", &width_std_m}};
        for (const auto& [name, field] : keys) {
            if (name == key) {
                return field;
            }
        }
        return nullptr;
    }
    Located<std::vector<Scalar>>* arrayKey(std::string_view key) {
        if (key == "heights_m") {
            return &heights_m;
        }
        return key == "probabilities" ? &probabilities : nullptr;
    }
};

// Range checks of one class, each reported at the offending key's line. The
// core constructors check the same again; these exist for the message.
std::optional<Error> checkRanges(const Reporter& rep, const std::string& base, const ClassSpec& s) {
    if (s.std_m && !(*s.std_m > 0 && std::isfinite(*s.std_m))) {
        return rep.at(s.std_m.node, base + ".std_m", "must be > 0 (got " + num(*s.std_m) + ")");
    }
    if (s.min_m && !(*s.min_m > 0 && std::isfinite(*s.min_m))) {
        return rep.at(s.min_m.node, base + ".min_m", "must be > 0 (got " + num(*s.min_m) + ")");
    }
    if (s.min_m && s.max_m && !(*s.max_m > *s.min_m && std::isfinite(*s.max_m))) {
        return rep.at(
            s.max_m.node, base + ".max_m",
            "must be greater than min_m = " + num(*s.min_m) + " (got " + num(*s.max_m) + ")");
    }
    if (s.mean_m && s.min_m && s.max_m && !(*s.mean_m >= *s.min_m && *s.mean_m <= *s.max_m)) {
        return rep.at(s.mean_m.node, base + ".mean_m",
                      "must lie in [min_m, max_m] = [" + num(*s.min_m) + ", " + num(*s.max_m) +
                          "] (got " + num(*s.mean_m) + ")");
    }
    if (s.bin_width_m && !(*s.bin_width_m >= 0 && std::isfinite(*s.bin_width_m))) {
        return rep.at(s.bin_width_m.node, base + ".bin_width_m",
                      "must be >= 0 (got " + num(*s.bin_width_m) + ")");
    }
    if (s.partial_probability && !(*s.partial_probability >= 0 && *s.partial_probability < 1)) {
        return rep.at(s.partial_probability.node, base + ".partial_probability",
                      "must be in [0, 1) (got " + num(*s.partial_probability) + ")");
    }
    if (s.width_mean_m && !(*s.width_mean_m > 0 && std::isfinite(*s.width_mean_m))) {
        return rep.at(s.width_mean_m.node, base + ".width_mean_m",
                      "must be > 0 (got " + num(*s.width_mean_m) + ")");
    }
    if (s.width_std_m && !(*s.width_std_m >= 0 && std::isfinite(*s.width_std_m))) {
        return rep.at(s.width_std_m.node, base + ".width_std_m",
                      "must be >= 0 (got " + num(*s.width_std_m) + ")");
    }
    if (s.width_std_m && !s.width_mean_m) {
        return rep.at(s.width_std_m.node, base + ".width_std_m", "needs width_mean_m beside it");
    }
    if (s.width_mean_m && !s.width_std_m) {
        return rep.at(s.width_mean_m.node, base + ".width_mean_m", "needs width_std_m beside it");
    }
    if (s.heights_m) {
        const auto& h = *s.heights_m;
        if (h.empty()) {
            return rep.at(s.heights_m.node, base + ".heights_m", "must not be empty");
        }
        if (h.size() > static_cast<std::size_t>(HeightPrior::kMaxBins)) {
            return rep.at(s.heights_m.node, base + ".heights_m",
                          "at most " + std::to_string(HeightPrior::kMaxBins) + " entries (got " +
                              std::to_string(h.size()) + ")");
        }
        for (std::size_t i = 0; i < h.size(); ++i) {
            if (!(h[i] > 0 && std::isfinite(h[i]))) {
                return rep.at(s.heights_m.node, base + ".heights_m[" + std::to_string(i) + "]",
                              "must be > 0 (got " + num(h[i]) + ")");
            }
        }
    }
    if (s.probabilities) {
        const auto& p = *s.probabilities;
        Scalar total = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
            if (!(p[i] >= 0 && std::isfinite(p[i]))) {
                return rep.at(s.probabilities.node,
                              base + ".probabilities[" + std::to_string(i) + "]",
                              "must be >= 0 (got " + num(p[i]) + ")");
            }
            total += p[i];
        }
        if (s.heights_m && p.size() != s.heights_m->size()) {
            return rep.at(s.probabilities.node, base + ".probabilities",
                          "has " + std::to_string(p.size()) + " entries but heights_m has " +
                              std::to_string(s.heights_m->size()));
        }
        if (!(total > 0)) {
            return rep.at(s.probabilities.node, base + ".probabilities",
                          "all zero: they must sum to > 0");
        }
    }
    return std::nullopt;
}

Result<std::vector<Scalar>> numberArray(const Reporter& rep, const toml::node& n,
                                        const std::string& key) {
    const auto* arr = n.as_array();
    if (arr == nullptr) {
        return rep.at(&n, key, "must be an array of numbers (got " + show(n) + ")");
    }
    std::vector<Scalar> out;
    for (std::size_t i = 0; i < arr->size(); ++i) {
        const auto v = number(*arr->get(i));
        if (!v) {
            return rep.at(arr->get(i), key + "[" + std::to_string(i) + "]",
                          "must be a number (got " + show(*arr->get(i)) + ")");
        }
        out.push_back(*v);
    }
    return out;
}

// One key of a class table into `spec` (full: its dotted name, for messages).
core::Status readClassKey(const Reporter& rep, const std::string& key, const std::string& full,
                          const toml::node& node, ClassSpec& spec) {
    if (key == "upright") {
        if (!node.is_boolean()) {
            return rep.at(&node, full, "must be true or false (got " + show(node) + ")");
        }
        spec.upright = node.as_boolean()->get();
    } else if (key == "source") {
        if (!node.is_string() || node.as_string()->get().empty()) {
            return rep.at(&node, full, "must be a non-empty string (got " + show(node) + ")");
        }
        spec.source = node.as_string()->get();
    } else if (key == "bins") {
        const auto* i = node.as_integer();
        if (i == nullptr || i->get() < 1 || i->get() > HeightPrior::kMaxBins) {
            return rep.at(&node, full,
                          "must be an integer in [1, " + std::to_string(HeightPrior::kMaxBins) +
                              "] (got " + show(node) + ")");
        }
        spec.bins = static_cast<int>(i->get());
    } else if (auto* array = spec.arrayKey(key)) {
        auto arr = numberArray(rep, node, full);
        if (!arr) {
            return arr.error();
        }
        array->set(std::move(arr.value()), node);
    } else if (auto* field = spec.numberKey(key)) {
        const auto v = number(node);
        if (!v) {
            return rep.at(&node, full, "must be a number (got " + show(node) + ")");
        }
        field->set(*v, node);
    } else {
        return rep.at(&node, full,
                      "unknown key (allowed: upright, source, mean_m, std_m, min_m, max_m, "
                      "bins, heights_m, probabilities, bin_width_m, partial_probability, "
                      "width_mean_m, width_std_m)");
    }
    return {};
}

// The class's height prior in the form its keys give (normal_form: mean/std,
// otherwise the explicit histogram).
Result<HeightPrior> makeClassPrior(const Reporter& rep, const std::string& name,
                                   const std::string& base, const toml::table& t,
                                   const ClassSpec& spec, bool normal_form, int default_bins) {
    Result<HeightPrior> prior = makeError(ErrorCode::kParse, "");
    if (normal_form) {
        for (const auto& [key, v] : {std::pair{"mean_m", spec.mean_m},
                                     {"std_m", spec.std_m},
                                     {"min_m", spec.min_m},
                                     {"max_m", spec.max_m}}) {
            if (!v) {
                return rep.at(&t, base + "." + key,
                              "missing (the mean/std form needs mean_m, "
                              "std_m, min_m and max_m)");
            }
        }
        prior = HeightPrior::fromNormal(name, *spec.mean_m, *spec.std_m, *spec.min_m, *spec.max_m,
                                        spec.bins.value_or(default_bins), *spec.upright);
    } else {
        if (!spec.heights_m || !spec.probabilities) {
            return rep.at(&t, base, "the explicit form needs both heights_m and probabilities");
        }
        prior = HeightPrior::fromHistogram(name, *spec.heights_m, *spec.probabilities,
                                           spec.bin_width_m.value.value_or(0), *spec.upright);
    }
    if (!prior) {
        return rep.at(&t, base, prior.error().message);
    }
    return prior;
}

// The optional partial probability and width of the class, set on `prior`.
core::Status setClassExtras(const Reporter& rep, const std::string& base, const ClassSpec& spec,
                            HeightPrior& prior) {
    if (spec.partial_probability) {
        if (auto set = prior.setPartialProbability(*spec.partial_probability); !set) {
            return rep.at(spec.partial_probability.node, base + ".partial_probability",
                          set.error().message);
        }
    }
    if (spec.width_mean_m) {
        if (auto set = prior.setWidth(*spec.width_mean_m, *spec.width_std_m); !set) {
            return rep.at(spec.width_mean_m.node, base + ".width_mean_m", set.error().message);
        }
    }
    return {};
}

Result<HeightPrior> parseClass(const Reporter& rep, const std::string& name, const toml::table& t,
                               int default_bins) {
    const std::string base = "classes." + name;
    ClassSpec spec;
    for (const auto& [k, node] : t) {
        const std::string key(k.str());
        std::string full = base;
        full += '.';
        full += key;
        if (auto ok = readClassKey(rep, key, full, node, spec); !ok) {
            return ok.error();
        }
    }
    if (!spec.upright) {
        return rep.at(&t, base + ".upright", "missing (true or false is required)");
    }
    if (!spec.source) {
        return rep.at(&t, base + ".source", "missing (say where the numbers come from)");
    }
    const bool normal_form = spec.mean_m || spec.std_m || spec.min_m || spec.max_m || spec.bins;
    const bool explicit_form = spec.heights_m || spec.probabilities || spec.bin_width_m;
    if (normal_form == explicit_form) {
        return rep.at(&t, base,
                      "give exactly one form: mean_m/std_m/min_m/max_m[/bins] or "
                      "heights_m/probabilities[/bin_width_m]");
    }
    if (auto err = checkRanges(rep, base, spec)) {
        return *err;
    }
    auto prior = makeClassPrior(rep, name, base, t, spec, normal_form, default_bins);
    if (!prior) {
        return prior;
    }
    if (auto ok = setClassExtras(rep, base, spec, *prior); !ok) {
        return ok.error();
    }
    return prior;
}

}  // namespace

Result<PriorTable> parsePriors(std::string_view text, std::string_view source_name) {
    const Reporter rep(source_name);
    auto parsed = drivers::priors::tomlread::parse(text, source_name);
    if (!parsed) {
        return parsed.error();
    }
    const toml::table& root = *parsed;

    int default_bins = kDefaultBins;
    const toml::table* classes = nullptr;
    bool have_version = false;
    for (const auto& [k, node] : root) {
        const std::string key(k.str());
        if (key == "version") {
            const auto* v = node.as_integer();
            if (v == nullptr || v->get() != kFormatVersion) {
                return rep.at(&node, key,
                              "unsupported format version " + show(node) + " (this build reads " +
                                  std::to_string(kFormatVersion) + ")");
            }
            have_version = true;
        } else if (key == "histogram") {
            const auto* t = node.as_table();
            if (t == nullptr) {
                return rep.at(&node, key, "must be a table");
            }
            for (const auto& [hk, hn] : *t) {
                const std::string hkey = "histogram." + std::string(hk.str());
                if (hk.str() != "bins") {
                    return rep.at(&hn, hkey, "unknown key (allowed: bins)");
                }
                const auto* i = hn.as_integer();
                if (i == nullptr || i->get() < 1 || i->get() > HeightPrior::kMaxBins) {
                    return rep.at(&hn, hkey,
                                  "must be an integer in [1, " +
                                      std::to_string(HeightPrior::kMaxBins) + "] (got " + show(hn) +
                                      ")");
                }
                default_bins = static_cast<int>(i->get());
            }
        } else if (key == "classes") {
            classes = node.as_table();
            if (classes == nullptr) {
                return rep.at(&node, key, "must be a table of classes");
            }
        } else {
            return rep.at(&node, key, "unknown key (allowed: version, histogram, classes)");
        }
    }
    if (!have_version) {
        return rep.at(nullptr, "version", "missing (expected version = 1)");
    }
    if (classes == nullptr || classes->empty()) {
        return rep.at(classes, "classes", "no classes defined");
    }
    PriorTable table;
    for (const auto& [k, node] : *classes) {
        const std::string name(k.str());
        const auto* t = node.as_table();
        if (t == nullptr) {
            return rep.at(&node, "classes." + name, "must be a table");
        }
        auto prior = parseClass(rep, name, *t, default_bins);
        if (!prior) {
            return prior.error();
        }
        table.add(std::move(prior.value()));
    }
    return table;
}

Result<PriorTable> loadPriorsFile(const std::filesystem::path& path) {
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (ec || !std::filesystem::exists(status)) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot open priors file: " +
                                             (ec ? ec.message() : "no such file"));
    }
    if (!std::filesystem::is_regular_file(status)) {
        return makeError(ErrorCode::kIo, path.string() + ": not a regular file");
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        return makeError(ErrorCode::kIo, path.string() + ": cannot open priors file");
    }
    std::string text;
    char buf[4096];
    while (in.read(buf, sizeof buf) || in.gcount() > 0) {
        text.append(buf, static_cast<std::size_t>(in.gcount()));
    }
    if (in.bad() || !in.eof()) {
        return makeError(ErrorCode::kIo, path.string() + ": read error");
    }
    return parsePriors(text, path.string());
}

}  // namespace scaled::drivers::priors
