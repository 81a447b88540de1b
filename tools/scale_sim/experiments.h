#pragma once

// The paper's three experiments (Sucar & Hayet 2017, section 5), simulated.

#include <vector>

#include "simulation.h"

namespace scaled::papersim {

// (1) four bottles of the same known height, (2) one microwave of known height,
// (3) four bottles of four heights with a uniform prior over the four.
std::vector<ExperimentSpec> paperExperiments(std::uint32_t seed,
                                             const core::EstimatorConfig& estimator);

// The default estimator configuration used by scale-sim.
core::EstimatorConfig defaultSimEstimatorConfig();

}  // namespace scaled::papersim
