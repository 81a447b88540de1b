#pragma once

// Height priors that know the sim's objects (drivers/sim, docs/sim.md
// "Objects"): each of the four upright classes of the sim room with its
// object's exact height as the mean and a spread of 1% of it (truncated at
// +-4%). config/priors.toml's generic classes spread 8-11%, so that with a
// handful of objects the object model's honest 95% interval stays 40-70% wide
// and never reaches "converged"; tests that need the converged state take these
// priors instead (together with objects.map_rel_sigma = 0, see where they are
// used). sim_source_tests checks that the means are simObjects()' heights.

#include <string_view>

namespace scaled::test {

inline constexpr std::string_view kSimExactPriorsToml = R"(# The sim room's objects, 1% spread.
version = 1

[histogram]
bins = 24

[classes.refrigerator]
upright = true
mean_m = 1.75
std_m = 0.0175
min_m = 1.68
max_m = 1.82
source = "the sim's refrigerator (drivers/sim), 1% spread"

[classes.couch]
upright = true
mean_m = 0.85
std_m = 0.0085
min_m = 0.816
max_m = 0.884
source = "the sim's couch (drivers/sim), 1% spread"

[classes.chair]
upright = true
mean_m = 0.90
std_m = 0.009
min_m = 0.864
max_m = 0.936
source = "the sim's chair (drivers/sim), 1% spread"

[classes.suitcase]
upright = true
mean_m = 0.62
std_m = 0.0062
min_m = 0.5952
max_m = 0.6448
source = "the sim's suitcase (drivers/sim), 1% spread"
)";

}  // namespace scaled::test
