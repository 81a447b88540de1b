#pragma once

// The text of an errno value, for error messages ("Permission denied").
// Thread-safe (strerror_r), unlike std::strerror.

#include <string>

namespace scaled::drivers::base {

[[nodiscard]] std::string errnoText(int err);

}  // namespace scaled::drivers::base
