#pragma once

// Loads class height priors (core::PriorTable) from TOML, e.g. config/priors.toml.
// Every problem is reported with file, line, key and the offending value;
// unknown keys are errors. The format is described at the top of config/priors.toml.

#include <filesystem>
#include <string_view>

#include <scaled/core/result.h>
#include <scaled/core/scale/height_prior.h>

namespace scaled::drivers::priors {

core::Result<core::PriorTable> loadPriorsFile(const std::filesystem::path& path);

// source_name is used in error messages in place of a file name.
core::Result<core::PriorTable> parsePriors(std::string_view toml_text,
                                           std::string_view source_name);

// The text of config/priors.toml in the source tree this binary was built
// from: what the daemon falls back to when the installed default
// (/etc/scaled/priors.toml) is missing, e.g. run from a build tree.
std::string_view builtinPriorsToml();

}  // namespace scaled::drivers::priors
