#!/usr/bin/env bash
# Builds the tools twice, with core in double and in float (SCALED_CORE_SCALAR),
# and compares what they give on the synthetic sequences and on redkitchen
# (tools/compare_scalars.py; docs/numerics.md records a run). Exit 0 when every
# compared quantity of the float build is within 1% of the double build's.
#   scripts/compare-scalars.sh [--frames A:B] [--seeds 8] [--tolerance 0.01]
# On redkitchen each build runs once per RANSAC seed 1..8; the means over the
# seeds are bounded, each seed's pair is printed (docs/numerics.md says why).
# Env: SCALED_SHARED_DIR (default ../shared): without redkitchen only the
# synthetic comparisons run.
set -euo pipefail
cd "$(dirname "$0")/.."

shared=${SCALED_SHARED_DIR:-../shared}
jobs=$(nproc)
targets=(slam-run scale-sim scale-eval synth-render)
for scalar in double float; do
  dir=build/compare-${scalar}
  echo "=== ${scalar} build (${dir})" >&2
  cmake -S . -B "${dir}" -G Ninja -DCMAKE_BUILD_TYPE=Release -DSCALED_CORE_SCALAR="${scalar}" \
    -DSCALED_BUILD_TESTS=OFF -DSCALED_BUILD_BENCHMARKS=OFF >/dev/null
  cmake --build "${dir}" -j "${jobs}" --target "${targets[@]}" >/dev/null
done
exec python3 tools/compare_scalars.py --double build/compare-double/bin \
  --float build/compare-float/bin --shared "${shared}" "$@"
