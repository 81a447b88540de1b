#pragma once

namespace scaled::daemon {

// The release string, e.g. "0.1.0".
const char* version();

}  // namespace scaled::daemon
