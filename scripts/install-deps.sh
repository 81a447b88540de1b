#!/usr/bin/env bash
# Installs every Debian package scaled needs to build, test and run its tools.
# Idempotent: packages already present are left alone and nothing is fetched.
# Works on Debian 12 bookworm and 13 trixie and on Raspberry Pi OS of both
# (amd64, arm64, armhf): every name below exists in both releases, and the
# versioned ones are reached through Debian's meta-packages (linux-source:
# 6.1 on bookworm, 6.12 on trixie; libclang-rt-dev: 14 or 19).
set -euo pipefail

packages=(
  # build
  build-essential cmake ninja-build pkg-config git
  # the DEB package (cpack's DEB generator needs file; cli.package)
  file
  # core
  libeigen3-dev
  # config files
  libtomlplusplus-dev
  # daemon and tools: JSON protocol and field log, command lines
  nlohmann-json3-dev libcli11-dev
  # live drivers: GPIO status LEDs (libgpiod 1.6 on bookworm, 2.2 on trixie),
  # libcamera capture
  libgpiod-dev libcamera-dev
  # image front end, detector, dataset readers (OpenCV 4.6 on bookworm, 4.10 on trixie)
  libopencv-dev
  # tests and benchmarks (googletest: the sources, for the aarch64 cross build)
  libgtest-dev libgmock-dev libbenchmark-dev googletest
  # style checks
  clang-format clang-tidy
  # libFuzzer targets (preset fuzz, tests/fuzz): clang and its runtimes
  # (libclang-rt-dev: libFuzzer and the sanitizers, Debian 12 and 13)
  clang libclang-rt-dev
  # scripts in tools/: plots, the depth-model render (tools/render_depth_model.py)
  python3 python3-matplotlib python3-numpy python3-opencv
  # real-kernel driver tests (tests/vm, ctest label vm): QEMU, a busybox initramfs,
  # the kernel source for vimc/gpio-sim/gpio-mockup/irq-sim, libcamera's IPA and
  # tools, V4L2 and GPIO command-line tools. No kernel is installed on the host:
  # tests/vm/fetch-kernel.sh unpacks Debian's kernel package into the build tree.
  qemu-system-x86 busybox-static linux-source bc flex bison libelf-dev libssl-dev
  xz-utils patch kmod libcamera-ipa libcamera-tools v4l-utils gpiod
)

# aarch64 cross build of core and its tests, run under qemu-user (presets
# aarch64 and aarch64-float, docs/arm.md), from an x86-64 host.
if [[ $(dpkg --print-architecture) == amd64 ]]; then
  packages+=(g++-aarch64-linux-gnu qemu-user-static)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]} == 0)); then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

sudo=()
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to install: ${missing[*]}" >&2; exit 77; }
  sudo=(sudo)
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
