#!/usr/bin/env bash
# Installs dependencies, builds the release preset and runs the main job.
# For now the main job is scale-sim: the paper's three experiments in simulation.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
ln -sfn release/bin build/bin
build/bin/scale-sim "$@"
