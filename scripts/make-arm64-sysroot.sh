#!/usr/bin/env bash
# Builds an arm64 (aarch64) Debian sysroot for cross-building the whole of
# scaled (daemon, drivers, tools, tests) with cmake/toolchains/aarch64-linux-gnu.cmake.
#   scripts/make-arm64-sysroot.sh DIR [SUITE]
# DIR must not exist yet (or be empty); the sysroot is built next to it and
# moved into place when complete, so an existing DIR is always a whole sysroot.
# SUITE: bookworm (Debian 12) or trixie (Debian 13); default
# $SCALED_DEBIAN_SUITE, else this machine's release when it is one of those
# (the sysroot's libstdc++ must be the one of the cross compiler that links
# against it: GCC 12 on bookworm, GCC 14 on trixie), else bookworm.
# Environment: SCALED_DEBIAN_MIRROR (default: mmdebstrap's, deb.debian.org
# with updates and security).
#
# mmdebstrap's "extract" variant unpacks the packages and their hard
# dependencies without running maintainer scripts, so no arm64 emulation is
# needed: a sysroot only has to hold headers, libraries and CMake/pkg-config
# files. Runs as root or through sudo (mmdebstrap's root mode keeps ownership).
# docs/arm.md has the measured time and size.
set -euo pipefail

usage() { echo "usage: scripts/make-arm64-sysroot.sh DIR [bookworm|trixie]" >&2; exit 64; }
(($# == 1 || $# == 2)) || usage
dir=$1
[[ $dir == /* ]] || dir=$PWD/$dir
host_suite=$(sed -n 's/^VERSION_CODENAME=//p' /etc/os-release 2>/dev/null || true)
[[ $host_suite == bookworm || $host_suite == trixie ]] || host_suite=bookworm
suite=${2:-${SCALED_DEBIAN_SUITE:-$host_suite}}
# The C++ library headers of the suite's default GCC.
case $suite in
  bookworm) gcc_major=12 ;;
  trixie) gcc_major=14 ;;
  *) echo "make-arm64-sysroot: suite '$suite' is not supported (bookworm or trixie)" >&2; exit 64 ;;
esac

if [[ -e $dir ]] && [[ -n $(ls -A "$dir" 2>/dev/null) ]]; then
  echo "make-arm64-sysroot: $dir exists and is not empty; remove it to rebuild" >&2
  exit 73
fi

sudo=()
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "make-arm64-sysroot: need root or sudo (mmdebstrap root mode, apt-get)" >&2; exit 77; }
  sudo=(sudo)
fi

if ! command -v mmdebstrap >/dev/null; then
  echo "make-arm64-sysroot: installing mmdebstrap"
  export DEBIAN_FRONTEND=noninteractive
  "${sudo[@]}" apt-get update -qq
  "${sudo[@]}" apt-get install -y -qq --no-install-recommends mmdebstrap
fi

# The -dev packages of every find_package / pkg_check_modules in the CMake files
# (scripts/install-deps.sh has the host's list). OpenCV: the modules scaled uses
# rather than the libopencv-dev metapackage, which would add VTK, Open MPI,
# Tesseract and 60 more packages (libopencv-features2d-dev still pulls
# highgui and Qt 5). libopencv-dev itself holds OpenCVConfig.cmake; it is
# unpacked alone below.
packages=(
  # C and C++ runtime and headers for the target
  libc6-dev "libstdc++-${gcc_major}-dev"
  # core
  libeigen3-dev
  # config files, daemon, tools
  libtomlplusplus-dev nlohmann-json3-dev libcli11-dev
  # live drivers
  libgpiod-dev libcamera-dev
  # image front end, detector, dataset readers
  libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev
  libopencv-features2d-dev libopencv-calib3d-dev libopencv-videoio-dev libopencv-dnn-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
)

tmp=$dir.partial
"${sudo[@]}" rm -rf "$tmp"
mkdir -p "$(dirname "$dir")"

mirror=()
[[ -n ${SCALED_DEBIAN_MIRROR:-} ]] && mirror=("$SCALED_DEBIAN_MIRROR")

echo "make-arm64-sysroot: $suite arm64 -> $dir"
# The extract hook (the only hook the extract variant runs) runs on the host
# with mmdebstrap's apt configuration (MMDEBSTRAP_APT_CONFIG: arm64, the suite's mirrors),
# so apt-get download fetches the arm64 libopencv-dev without its dependencies.
# shellcheck disable=SC2016 # $1 is the hook's argument, expanded by mmdebstrap's shell
"${sudo[@]}" mmdebstrap --variant=extract --architectures=arm64 --mode=root \
  --include="$(IFS=,; echo "${packages[*]}")" \
  --extract-hook='cd "$1/tmp" && APT_CONFIG="$MMDEBSTRAP_APT_CONFIG" apt-get download -q libopencv-dev:arm64 && dpkg-deb -x libopencv-dev_*_arm64.deb "$1" && rm -f libopencv-dev_*_arm64.deb' \
  "$suite" "$tmp" "${mirror[@]}"

# Merged /usr: trixie's packages ship everything under /usr, and the
# /bin, /sbin and /lib links that a normal install makes are not made by the
# extract variant; qemu -L looks for the loader at /lib/ld-linux-aarch64.so.1.
for d in bin sbin lib; do
  if [[ ! -e $tmp/$d && -d $tmp/usr/$d ]]; then
    "${sudo[@]}" ln -s "usr/$d" "$tmp/$d"
  fi
done

# Documentation, manuals and translations are of no use to a compiler.
"${sudo[@]}" rm -rf "$tmp"/usr/share/{doc,man,info,locale}

# Absolute symlinks (a few -dev packages link /usr/lib/...so to /lib/...) would
# point into the host once the sysroot is not /: make them relative.
fixed=0
while IFS= read -r -d '' link; do
  target=$(readlink "$link")
  rel=$(realpath -m --relative-to="$(dirname "$link")" "$tmp$target")
  "${sudo[@]}" ln -sfn "$rel" "$link"
  fixed=$((fixed + 1))
done < <(find "$tmp" -type l -lname '/*' -print0)
echo "make-arm64-sysroot: made $fixed absolute symlinks relative"

# The links update-alternatives would make in libblas3's and liblapack3's
# postinst (not run by the extract variant): OpenCV's core needs libblas.so.3
# and liblapack.so.3 under their plain names.
multiarch=$tmp/usr/lib/aarch64-linux-gnu
for alt in blas/libblas.so.3 lapack/liblapack.so.3; do
  if [[ -e $multiarch/$alt && ! -e $multiarch/${alt#*/} ]]; then
    "${sudo[@]}" ln -s "$alt" "$multiarch/${alt#*/}"
  fi
done

# Every library's DT_NEEDED must be found in the sysroot, or linking against it
# (and running under qemu -L) fails later with a less clear message.
if command -v aarch64-linux-gnu-readelf >/dev/null; then
  unresolved=()
  while read -r soname; do
    found=0
    for libdir in usr/lib/aarch64-linux-gnu lib/aarch64-linux-gnu usr/lib lib; do
      [[ -e $tmp/$libdir/$soname ]] && { found=1; break; }
    done
    ((found)) || unresolved+=("$soname")
  done < <(find "$tmp"/usr/lib/aarch64-linux-gnu "$tmp"/lib/aarch64-linux-gnu -maxdepth 1 -name '*.so*' -type f -print0 |
    xargs -0 aarch64-linux-gnu-readelf -d 2>/dev/null | sed -n 's/.*(NEEDED).*\[\(.*\)\]$/\1/p' | sort -u)
  if ((${#unresolved[@]})); then
    echo "make-arm64-sysroot: libraries needed but not in the sysroot: ${unresolved[*]}" >&2
    exit 70
  fi
fi

# OpenCVModules.cmake checks that the library of every OpenCV module exists.
# Drop the modules this sysroot leaves out (viz, stitching, ...) from that check;
# their imported targets stay defined, unused.
modules_cfg=$tmp/usr/lib/aarch64-linux-gnu/cmake/opencv4/OpenCVModules-release.cmake
[[ -f $modules_cfg ]] || { echo "make-arm64-sysroot: no $modules_cfg (libopencv-dev not unpacked)" >&2; exit 70; }
dropped=()
while read -r target lib; do
  if [[ ! -e $tmp/usr/${lib#\$\{_IMPORT_PREFIX\}/} ]]; then
    "${sudo[@]}" sed -i "/^list(APPEND _cmake_import_check_targets ${target} )$/d;/^list(APPEND _IMPORT_CHECK_TARGETS ${target} )$/d" "$modules_cfg"
    dropped+=("$target")
  fi
done < <(sed -n 's/^list(APPEND _\(cmake_import_check_files_for\|IMPORT_CHECK_FILES_FOR\)_\([a-z0-9_]*\) "\([^"]*\)" )$/\2 \3/p' "$modules_cfg")
echo "make-arm64-sysroot: OpenCV modules left out: ${dropped[*]:-none}"

printf 'suite=%s\ndate=%s\npackages=%s\n' "$suite" "$(date -u +%FT%TZ)" "${packages[*]} libopencv-dev(unpacked)" |
  "${sudo[@]}" tee "$tmp/.scaled-arm64-sysroot" >/dev/null
"${sudo[@]}" mv -T "$tmp" "$dir"
echo "make-arm64-sysroot: done: $dir ($(du -sh "$dir" | cut -f1))"
