#include "files.h"

#include <filesystem>
#include <system_error>

namespace scaled::tools {

core::Status createOutputDir(const std::string& out_dir) {
    std::error_code ec;
    std::filesystem::create_directories(out_dir, ec);
    if (ec) {
        return core::makeError(core::ErrorCode::kIo,
                               out_dir + ": cannot create the output directory: " + ec.message());
    }
    return {};
}

}  // namespace scaled::tools
