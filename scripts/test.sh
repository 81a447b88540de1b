#!/usr/bin/env bash
# Installs dependencies, builds and runs every test: the release preset, then the
# asan preset (AddressSanitizer + UndefinedBehaviorSanitizer), then, on an x86-64
# host, core and its tests cross-built for aarch64 with the float scalar and run
# under qemu-user (preset aarch64-float, about 5 min; the double one, aarch64,
# is left to `scripts/test.sh aarch64` to keep CI within its time: docs/arm.md),
# then the daemon's tests under ThreadSanitizer (preset tsan) and the libFuzzer
# targets, each fuzzing for SCALED_FUZZ_SECONDS (default 20; preset fuzz,
# clang). tsan and fuzz build only the targets their build presets name
# (docs/fuzzing.md).
#   scripts/test.sh              # all those presets
#   scripts/test.sh release      # only the presets named
#   SCALED_FUZZ_SECONDS=300 scripts/test.sh fuzz
# In CI (CI=true) warnings are errors. Each preset's time is printed at its end.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh

presets=("$@")
if ((${#presets[@]} == 0)); then
  presets=(release asan)
  [[ $(uname -m) == x86_64 ]] && presets+=(aarch64-float)
  # The two sanitizer stages are measured and run on x86-64 hosts (CI); on an
  # arm64 board (untested there, and they would add most of an hour on a
  # Raspberry Pi) `scripts/test.sh tsan fuzz` asks for them.
  [[ $(uname -m) == x86_64 ]] && presets+=(tsan fuzz)
fi

werror=OFF
[[ -n ${CI:-} ]] && werror=ON

jobs=$(nproc)
for preset in "${presets[@]}"; do
  echo "=== preset ${preset}"
  start=${SECONDS}
  extra=()
  [[ ${preset} == fuzz ]] && extra+=(-DSCALED_FUZZ_SECONDS="${SCALED_FUZZ_SECONDS:-20}")
  cmake --preset "${preset}" -DSCALED_WERROR="${werror}" "${extra[@]}" >/dev/null
  cmake --build --preset "${preset}" -j "${jobs}"
  ctest --preset "${preset}" -j "${jobs}"
  echo "=== preset ${preset}: $((SECONDS - start)) s"
done
ln -sfn release/bin build/bin 2>/dev/null || true
