// scaled: the metric-scale daemon. Everything is in scaled_daemon (app.h).
#include <scaled/daemon/app.h>

int main(int argc, char** argv) {
    return scaled::daemon::runMain(argc, argv);
}
