#!/usr/bin/env bash
# Cross-builds the whole of scaled (daemon, drivers, tools, tests, benchmarks)
# for arm64 against a Debian arm64 sysroot, then runs a few of the programs
# under qemu-aarch64-static as a smoke test. Not part of scripts/test.sh (CI):
# docs/arm.md has the times.
#   scripts/cross-build-arm64.sh
# Environment:
#   SCALED_ARM64_SYSROOT    the sysroot; made by scripts/make-arm64-sysroot.sh when
#                           absent (default build/arm64-sysroot, ignored by git)
#   SCALED_ARM64_BUILD_DIR  the build tree (default build/aarch64-sysroot, the preset's)
# In CI (CI=true) warnings are errors, as in scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."

for tool in aarch64-linux-gnu-g++ qemu-aarch64-static cmake ninja pkg-config; do
  command -v "$tool" >/dev/null || {
    echo "cross-build-arm64: $tool not found: run scripts/install-deps.sh (g++-aarch64-linux-gnu, qemu-user-static)" >&2
    exit 69
  }
done

sysroot=${SCALED_ARM64_SYSROOT:-$PWD/build/arm64-sysroot}
[[ $sysroot == /* ]] || sysroot=$PWD/$sysroot
if [[ ! -f $sysroot/.scaled-arm64-sysroot ]]; then
  if [[ -e $sysroot ]] && [[ -n $(ls -A "$sysroot" 2>/dev/null) ]]; then
    echo "cross-build-arm64: $sysroot is not a sysroot made by scripts/make-arm64-sysroot.sh" >&2
    exit 66
  fi
  echo "=== making the arm64 sysroot in $sysroot"
  scripts/make-arm64-sysroot.sh "$sysroot"
fi
export SCALED_ARM64_SYSROOT=$sysroot

# The sysroot's libstdc++ and the cross compiler's must be one GCC: a trixie
# sysroot (GCC 14's libraries) wants trixie's cross compiler, so cross-build
# for trixie inside a trixie system (scripts/test-in-chroot.sh trixie --
# scripts/cross-build-arm64.sh; docs/arm.md).
sysroot_suite=$(sed -n 's/^suite=//p' "$sysroot/.scaled-arm64-sysroot")
host_suite=$(sed -n 's/^VERSION_CODENAME=//p' /etc/os-release 2>/dev/null || true)
if [[ -n $host_suite && -n $sysroot_suite && $host_suite != "$sysroot_suite" ]]; then
  echo "cross-build-arm64: the sysroot $sysroot is Debian $sysroot_suite but this machine is $host_suite:" \
    "its cross compiler ($(aarch64-linux-gnu-g++ -dumpversion)) does not match the sysroot's libstdc++;" \
    "use a $host_suite sysroot, or build inside $sysroot_suite (scripts/test-in-chroot.sh $sysroot_suite -- scripts/cross-build-arm64.sh)" >&2
  exit 78
fi

werror=OFF
[[ -n ${CI:-} ]] && werror=ON

build=${SCALED_ARM64_BUILD_DIR:-build/aarch64-sysroot}
jobs=$(nproc)
echo "=== configure and build ($build, sysroot $sysroot)"
cmake --preset aarch64-sysroot -B "$build" -DSCALED_WERROR="${werror}" >/dev/null
cmake --build "$build" -j "${jobs}"

# Smoke test under the emulator, with the sysroot's loader and libraries.
run() {
  echo "--- qemu-aarch64-static: $*"
  qemu-aarch64-static -L "$sysroot" "$@"
}
bin=$build/bin
file -L "$bin/scaled" | grep -q 'ARM aarch64' || { echo "cross-build-arm64: $bin/scaled is not an aarch64 program" >&2; exit 70; }
run "$bin/scaled" --version
run "$bin/scaled" --help >/dev/null
run "$bin/scaled" --check-config config/scaled.toml
run "$bin/scalectl" --help >/dev/null
run "$bin/core_tests" --gtest_brief=1
run "$bin/drivers_tests" --gtest_brief=1
run "$bin/daemon_tests" --gtest_brief=1
echo "cross-build-arm64: arm64 build in $build; the programs above ran under qemu-aarch64-static"
