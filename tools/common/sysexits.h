#pragma once

// Exit codes of the command-line tools, from BSD sysexits(3).

namespace scaled::tools {

inline constexpr int kExUsage = 64;        // bad command line
inline constexpr int kExDataErr = 65;      // input data malformed
inline constexpr int kExNoInput = 66;      // an input file does not exist
inline constexpr int kExUnavailable = 69;  // a service or helper program is unavailable
inline constexpr int kExSoftware = 70;     // internal error
inline constexpr int kExCantCreat = 73;    // cannot create an output file
inline constexpr int kExIoErr = 74;        // I/O error
inline constexpr int kExTempFail = 75;     // temporary failure: try again later
inline constexpr int kExProtocol = 76;     // the remote side broke the protocol
inline constexpr int kExConfig = 78;       // bad configuration

}  // namespace scaled::tools
