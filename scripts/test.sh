#!/usr/bin/env bash
# Installs dependencies, builds and runs every test. On a Debian 12 bookworm
# x86-64 host (CI) that is: the release preset; core and its tests
# cross-built for aarch64 with the float scalar and run under qemu-user
# (preset aarch64-float, about 5 min; the double one, aarch64, is left to
# `scripts/test.sh aarch64`: docs/arm.md); the daemon's tests under
# ThreadSanitizer (preset tsan); the libFuzzer targets, each fuzzing for
# SCALED_FUZZ_SECONDS (default 20; preset fuzz, clang); then, in a fresh
# Debian 13 trixie chroot (scripts/test-in-chroot.sh: GCC 14, OpenCV 4.10,
# libgpiod 2), the asan preset (AddressSanitizer + UndefinedBehaviorSanitizer)
# and the GPIO VM test through libgpiod 2 (stage chroot-trixie). On any other
# host (trixie, arm64 boards) the asan preset runs on the host instead of the
# chroot stage; tsan and fuzz run by default only on x86-64 hosts, where they
# are measured. tsan and fuzz build only the targets their build presets name
# (docs/fuzzing.md).
#   scripts/test.sh                      # all of the above
#   scripts/test.sh release              # only the presets (or stages) named
#   scripts/test.sh chroot-trixie        # the trixie stage alone
#   SCALED_FUZZ_SECONDS=300 scripts/test.sh fuzz
# In CI (CI=true) warnings are errors, in the chroot too. Each stage's time is
# printed at its end.
set -euo pipefail
cd "$(dirname "$0")/.."

scripts/install-deps.sh

presets=("$@")
if ((${#presets[@]} == 0)); then
  x86=$([[ $(uname -m) == x86_64 ]] && echo yes || true)
  release=$(sed -n 's/^VERSION_CODENAME=//p' /etc/os-release 2>/dev/null || true)
  # ASan/UBSan: in the trixie chroot (last) on a bookworm x86-64 host (CI:
  # both releases in one run, docs/deploy.md), else on the host. tsan and fuzz
  # are measured and run on x86-64 hosts (CI); on an arm64 board (untested
  # there, and they would add most of an hour on a Raspberry Pi)
  # `scripts/test.sh tsan fuzz` asks for them.
  asan=asan
  [[ $x86 && $release == bookworm ]] && asan=chroot-trixie
  presets=(release)
  [[ $asan == asan ]] && presets+=(asan)
  [[ $x86 ]] && presets+=(aarch64-float tsan fuzz)
  [[ $asan == chroot-trixie ]] && presets+=(chroot-trixie)
fi

werror=OFF
[[ -n ${CI:-} ]] && werror=ON

jobs=$(nproc)

# A chroot-SUITE stage that comes after other presets has its chroot made and
# its packages installed in the background while they build and test: that
# part waits on the mirror and the disk more than on the CPU (docs/benchmarks.md).
# Only where no password can be asked for (root, or sudo -n). Whatever it
# leaves undone, the stage itself does (test-in-chroot.sh makes a missing
# chroot, test.sh installs what is missing).
declare -A prepared=()
prepareLog() { echo "build/chroot/$1-prepare.log"; }
prepareChroot() {
  local suite=$1
  [[ $(id -u) -eq 0 ]] || sudo -n true 2>/dev/null || return 0
  mkdir -p build/chroot
  local log
  log=$(prepareLog "$suite")
  echo "=== chroot-$suite: made in the background (log: $log)"
  # Its own process group (setsid), stopped with the script if still running.
  setsid -w bash -c 'start=$SECONDS; rc=0
    scripts/test-in-chroot.sh "$1" -- scripts/install-deps.sh || rc=$?
    echo "=== chroot-$1 prepared in $((SECONDS - start)) s, exit status $rc"' \
    bash "$suite" >"$log" 2>&1 </dev/null &
  prepared[$suite]=$!
}
stopPreparations() {
  local pid
  for pid in "${prepared[@]}"; do
    kill -- "-$pid" 2>/dev/null || true
  done
}
trap stopPreparations EXIT
if ((${#presets[@]} > 1)); then
  for preset in "${presets[@]:1}"; do
    if [[ $preset == chroot-* ]]; then
      prepareChroot "${preset#chroot-}"
    fi
  done
fi

# chroot-SUITE: the asan preset in a fresh chroot of SUITE, then the GPIO
# VM test (smoke and gpio_patterns) there, booting the kernel that the
# release preset's vm tests fetched when it ran first (else the chroot's own).
chrootStage() {
  local suite=$1
  local cache=${SCALED_VM_CACHE:-$PWD/build/release/vm-cache}
  local vm_env=()
  [[ -f $cache/ready ]] && vm_env=(SCALED_VM_CACHE="$cache")
  if [[ -n ${prepared[$suite]:-} ]]; then
    wait "${prepared[$suite]}" || true
    unset "prepared[$suite]"
    tail -n 1 "$(prepareLog "$suite")" || true
  fi
  local rc=0
  scripts/test-in-chroot.sh "$suite" asan || rc=$?
  if ((rc == 77)); then
    echo "=== SKIPPED: the $suite chroot cannot be made on this machine (see above)" >&2
    return 0
  fi
  ((rc == 0)) || return "$rc"
  env "${vm_env[@]}" scripts/test-in-chroot.sh "$suite" -- \
    env SCALED_VM_TESTS='^(smoke|gpio_patterns)$' ctest --test-dir build/asan -L vm -j 1 --output-on-failure
}

for preset in "${presets[@]}"; do
  echo "=== preset ${preset}"
  start=${SECONDS}
  if [[ ${preset} == chroot-* ]]; then
    chrootStage "${preset#chroot-}"
    echo "=== preset ${preset}: $((SECONDS - start)) s"
    continue
  fi
  extra=()
  [[ ${preset} == fuzz ]] && extra+=(-DSCALED_FUZZ_SECONDS="${SCALED_FUZZ_SECONDS:-20}")
  # The configure output but for the lines that say what the build uses
  # (compiler, OpenCV, libgpiod API, libcamera); errors and warnings go to stderr.
  cmake --preset "${preset}" -DSCALED_WERROR="${werror}" "${extra[@]}" | { grep -E '^-- scaled' || true; }
  cmake --build --preset "${preset}" -j "${jobs}"
  ctest --preset "${preset}" -j "${jobs}"
  echo "=== preset ${preset}: $((SECONDS - start)) s"
done
ln -sfn release/bin build/bin 2>/dev/null || true
