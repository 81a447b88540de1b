#pragma once

// Output files of the tools.

#include <string>

#include <scaled/core/result.h>

namespace scaled::tools {

// Creates the directory `out_dir` (and its parents); a kIo error naming it
// when that fails.
core::Status createOutputDir(const std::string& out_dir);

}  // namespace scaled::tools
