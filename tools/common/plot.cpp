#include "plot.h"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include "sysexits.h"

namespace scaled::tools {

namespace {

// Runs the plotting script; its exit code (or 69 when it cannot start).
int runPlotScript(const std::string& out_dir, const std::vector<std::string>& extra_args) {
    const std::string script = std::string(SCALED_SOURCE_DIR) + "/tools/scale_eval_plot.py";
    // Debian's interpreter is where python3-matplotlib installs; a python3
    // earlier on PATH (pyenv, a venv) may not have it. SCALED_PYTHON wins.
    std::string python =
        std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    if (const char* env = std::getenv("SCALED_PYTHON"); env != nullptr && *env != '\0') {
        python = env;
    }
    std::vector<std::string> args = {python, script, out_dir};
    args.insert(args.end(), extra_args.begin(), extra_args.end());
    std::vector<char*> argv;
    argv.reserve(args.size() + 1);
    for (auto& a : args) {
        argv.push_back(a.data());
    }
    argv.push_back(nullptr);
    // The script's messages go to stderr: stdout may carry --json.
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, STDERR_FILENO, STDOUT_FILENO);
    pid_t pid = 0;
    const int spawned = posix_spawnp(&pid, python.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) {
        return kExUnavailable;
    }
    int status = 0;
    if (waitpid(pid, &status, 0) < 0 || !WIFEXITED(status)) {
        return kExSoftware;
    }
    return WEXITSTATUS(status);
}

}  // namespace

int drawFigures(std::string_view tool, const std::string& out_dir,
                const std::vector<std::string>& extra_args) {
    const int rc = runPlotScript(out_dir, extra_args);
    if (rc == 0) {
        return 0;
    }
    std::fprintf(stderr,
                 "%.*s: figures not drawn (tools/scale_eval_plot.py exit %d%s); "
                 "the CSV files are in %s\n",
                 static_cast<int>(tool.size()), tool.data(), rc,
                 rc == kExUnavailable ? ": python3 with matplotlib and numpy is needed "
                                        "(apt install python3-matplotlib python3-numpy)"
                                      : "",
                 out_dir.c_str());
    return kExUnavailable;
}

}  // namespace scaled::tools
