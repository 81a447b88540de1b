#!/usr/bin/env bash
# Installs dependencies, builds and runs every test: the release preset, then the
# asan preset (AddressSanitizer + UndefinedBehaviorSanitizer).
#   scripts/test.sh              # both presets
#   scripts/test.sh release      # only the presets named
# In CI (CI=true) warnings are errors.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh

presets=("$@")
((${#presets[@]})) || presets=(release asan)

werror=OFF
[[ -n ${CI:-} ]] && werror=ON

jobs=$(nproc)
for preset in "${presets[@]}"; do
  echo "=== preset ${preset}"
  cmake --preset "${preset}" -DSCALED_WERROR="${werror}" >/dev/null
  cmake --build --preset "${preset}" -j "${jobs}"
  ctest --preset "${preset}" -j "${jobs}"
done
ln -sfn release/bin build/bin 2>/dev/null || true
