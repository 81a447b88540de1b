#!/usr/bin/env bash
# Installs dependencies, builds the release preset and runs the main job:
#  1. scale-sim: the paper's three experiments in simulation (arguments go to it);
#  2. without arguments, also slam-run: the EKF MonoSLAM tracker on 7-Scenes redkitchen
#     from ../shared (or $SCALED_SHARED_DIR), or on a rendered synthetic room if absent;
#  3. and scaled-detect: YOLOX-Nano on redkitchen frame 0 (when the model and data exist),
#     drawn to build/redkitchen_000000_detections.png.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
ln -sfn release/bin build/bin
build/bin/scale-sim "$@"
(($# == 0)) || exit 0

shared=${SCALED_SHARED_DIR:-../shared}
echo
if [[ -d $shared/data/redkitchen ]]; then
  echo "=== slam-run on $shared/data/redkitchen (600 frames)"
  build/bin/slam-run --dataset "$shared/data/redkitchen" --out build/redkitchen_traj.txt
  echo "trajectory: build/redkitchen_traj.txt"
else
  echo "=== slam-run on a synthetic room ($shared/data/redkitchen not found)"
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  build/bin/synth-render --out "$tmp/room" --frames 150 >/dev/null
  build/bin/slam-run --dataset "$tmp/room"
fi

model=$shared/models/yolox_nano.onnx
frame=$shared/data/redkitchen/rgb/000000.jpg
echo
if [[ -f $model && -f $frame ]]; then
  echo "=== scaled-detect on $frame (YOLOX-Nano, 416)"
  build/bin/scaled-detect --image "$frame" --model "$model" --draw build/redkitchen_000000_detections.png
  echo "drawn: build/redkitchen_000000_detections.png"
else
  echo "=== scaled-detect skipped: $model or $frame not found (set SCALED_SHARED_DIR)"
fi
