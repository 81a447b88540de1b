#pragma once

// The figures of scale-eval and field-log: tools/scale_eval_plot.py run on an
// output directory.

#include <string>
#include <string_view>
#include <vector>

namespace scaled::tools {

// Runs `python3 tools/scale_eval_plot.py OUT_DIR EXTRA_ARGS...` (the script's
// output goes to stderr: stdout may carry --json). The interpreter is
// $SCALED_PYTHON, else /usr/bin/python3, else python3 on PATH. Returns 0 when
// the figures are drawn; otherwise says so on stderr as `TOOL: figures not
// drawn ...` and returns kExUnavailable (69).
int drawFigures(std::string_view tool, const std::string& out_dir,
                const std::vector<std::string>& extra_args = {});

}  // namespace scaled::tools
