// The image folder reader's text and name handling
// (drivers/src/dataset_folder.cpp): times.txt (read as KITTI's), which names
// are images, and the natural order of names, which must be a strict weak
// ordering for std::sort. Each input line is a file name.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <scaled/drivers/dataset/dataset_folder.h>
#include <scaled/drivers/dataset/dataset_kitti.h>

#include "fuzz_support.h"

using scaled::drivers::dataset::naturalLess;
using scaled::fuzz::check;

// NOLINTNEXTLINE(readability-identifier-naming): the name libFuzzer calls
extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string_view text = scaled::fuzz::asText(data, size);

    const auto times = scaled::drivers::dataset::parseKittiTimes(text, "f/times.txt");
    if (!times) {
        check(scaled::fuzz::startsWith(times.error().message, "f/times.txt:"),
              "an error names the file");
    }

    std::vector<std::string_view> names;
    for (std::size_t pos = 0; pos <= text.size();) {
        std::size_t end = text.find('\n', pos);
        if (end == std::string_view::npos) {
            end = text.size();
        }
        names.push_back(text.substr(pos, end - pos));
        pos = end + 1;
    }
    for (const std::string_view a : names) {
        (void)scaled::drivers::dataset::isImageFileName(std::string(a));
        check(!naturalLess(a, a), "natural order is irreflexive");
    }
    // Every pair and (for small inputs) every triple: asymmetric, transitive,
    // and "neither less" (equivalence) transitive.
    const std::size_t n = std::min<std::size_t>(names.size(), 6);
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t j = 0; j < n; ++j) {
            const bool ij = naturalLess(names[i], names[j]);
            check(!(ij && naturalLess(names[j], names[i])), "natural order is asymmetric");
            for (std::size_t k = 0; k < n; ++k) {
                const bool jk = naturalLess(names[j], names[k]);
                if (ij && jk) {
                    check(naturalLess(names[i], names[k]), "natural order is transitive");
                }
                const bool ji = naturalLess(names[j], names[i]);
                const bool kj = naturalLess(names[k], names[j]);
                if (!ij && !ji && !jk && !kj) {
                    check(!naturalLess(names[i], names[k]) && !naturalLess(names[k], names[i]),
                          "equivalence under natural order is transitive");
                }
            }
        }
    }
    std::sort(names.begin(), names.end(), naturalLess);
    check(std::is_sorted(names.begin(), names.end(), naturalLess), "sorted in natural order");
    return 0;
}
