#!/usr/bin/env bash
# What an executable is linked with: no shared library and no code of the
# subsystems it must not carry (issue 24: scale-eval without GPIO, libcamera
# or the socket).
#   tests/cli/link_line.sh BINARY SUBSYSTEM...   (e.g. gpio libcam ipc)
# A subsystem is absent when the binary needs none of its shared libraries
# (readelf -d NEEDED) and defines no symbol of its namespace
# scaled::drivers::<subsystem> (nm -C).
set -euo pipefail
bin=$1
shift
fail() { echo "FAIL: $*" >&2; exit 1; }
[[ -x $bin ]] || fail "$bin: not an executable"
command -v readelf > /dev/null || fail "readelf not found (binutils)"
command -v nm > /dev/null || fail "nm not found (binutils)"

needed=$(readelf -d "$bin" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
symbols=$(nm -C --defined-only "$bin")
for sub in "$@"; do
  case $sub in
    gpio) libs='^libgpiod' ;;
    libcam) libs='^libcamera' ;;
    ipc) libs='' ;;  # the socket is libc's: only its code is checked
    *) fail "unknown subsystem '$sub' (gpio, libcam, ipc)" ;;
  esac
  if [[ -n $libs ]] && lib=$(grep -E "$libs" <<< "$needed"); then
    fail "$bin needs $lib (subsystem $sub)"
  fi
  if hits=$(grep -F "scaled::drivers::$sub::" <<< "$symbols" | head -3); [[ -n $hits ]]; then
    fail "$bin carries code of scaled::drivers::$sub:"$'\n'"$hits"
  fi
  echo "ok: $(basename "$bin") has no $sub"
done
