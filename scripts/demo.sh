#!/usr/bin/env bash
# The main job: installs dependencies, builds the release preset, then runs the
# daemon `scaled` on 7-Scenes redkitchen from ../shared ($SCALED_SHARED_DIR),
# replayed at its recorded 30 fps, with YOLOX-Nano detecting objects every 10
# frames. On a terminal it prints a live status line (frame/total, fps,
# scale ± 95% half-width, state). In another terminal,
#
#     build/bin/scalectl --socket "$XDG_RUNTIME_DIR/scaled-demo/scaled.sock" watch
#
# (the exact command is printed at start) shows the stream of scale reports.
# Without the data or the model it says so and runs the built-in `sim`
# source instead (a rendered room with objects of known height).
# The field log goes to build/demo-log. The daemon stops at the end of the
# sequence (sim: after 60 s), or on Ctrl-C.
#   scripts/demo.sh [extra scaled options, e.g. --pacing fast]
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)" --target scaled scalectl
ln -sfn release/bin build/bin

shared=${SCALED_SHARED_DIR:-../shared}
data=$shared/data/redkitchen
model=$shared/models/yolox_nano.onnx
run_dir=${XDG_RUNTIME_DIR:-/tmp}/scaled-demo
mkdir -p "$run_dir" build/demo-log
sock=$run_dir/scaled.sock

args=(--config config/scaled.toml --socket "$sock" --log-dir build/demo-log
      --set source.at_end=exit)
if [[ -d $data && -f $model ]]; then
  echo "demo: scaled on $data (real-time replay), YOLOX-Nano $model"
  args+=(--source "replay:$data" --set "detector.model=$model")
else
  [[ -d $data ]] || echo "demo: $data not found (set SCALED_SHARED_DIR)"
  [[ -f $model ]] || echo "demo: $model not found (set SCALED_SHARED_DIR)"
  echo "demo: running the built-in sim source instead (60 s)"
  args+=(--source sim --set source.max_frames=1800)
fi
echo "demo: in another terminal: build/bin/scalectl --socket $sock watch"
exec build/bin/scaled "${args[@]}" "$@"
