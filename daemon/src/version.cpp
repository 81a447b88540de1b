#include <scaled/daemon/version.h>

namespace scaled::daemon {

const char* version() {
    return SCALED_VERSION;
}

}  // namespace scaled::daemon
