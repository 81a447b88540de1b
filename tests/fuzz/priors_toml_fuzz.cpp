// The height priors loader (parsePriors, drivers/src/priors_toml.cpp) on any
// text: what it accepts is a valid table of normalised histograms, what it
// refuses is an error naming the source.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include <scaled/core/scale/height_prior.h>
#include <scaled/drivers/priors/priors_toml.h>

#include "fuzz_support.h"

using scaled::fuzz::check;
using scaled::fuzz::isFinite;

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto table =
        scaled::drivers::priors::parsePriors(scaled::fuzz::asText(data, size), "fuzz.toml");
    if (!table) {
        check(scaled::fuzz::startsWith(table.error().message, "fuzz.toml"),
              "an error names the source");
        return 0;
    }
    for (const scaled::core::HeightPrior& p : table->priors()) {
        check(!p.className().empty(), "a prior has a class name");
        check(table->find(p.className()) == &p, "a class is in the table once");
        check(p.size() >= 1 && p.size() <= scaled::core::HeightPrior::kMaxBins,
              "a prior has 1 to kMaxBins bins");
        double sum = 0;
        double previous = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
            const double h = p.heights()[i];
            const double pr = p.probabilities()[i];
            check(isFinite(h) && h > 0, "heights are finite and positive");
            check(h >= previous, "heights are sorted");
            check(isFinite(pr) && pr > 0 && pr <= 1, "probabilities are in (0, 1]");
            check(isFinite(p.logProbabilities()[i]), "log probabilities are finite");
            previous = h;
            sum += pr;
        }
        check(std::abs(sum - 1) < 1e-6, "probabilities sum to 1");
        check(isFinite(p.mean()) && p.mean() > 0, "the mean height is finite and positive");
        check(isFinite(p.widthMean()) && isFinite(p.widthStd()) && p.widthMean() >= 0 &&
                  p.widthStd() >= 0,
              "the width prior is finite and not negative");
    }
    return 0;
}
