#!/usr/bin/env bash
# Builds and tests scaled inside a Debian chroot of another release, as a
# fresh machine of that release would: a minimal system (mmdebstrap, variant
# apt) in which scripts/test.sh installs its own dependencies with
# scripts/install-deps.sh, then builds and runs the presets named.
#   scripts/test-in-chroot.sh SUITE [PRESET...]      # default preset: asan
#   scripts/test-in-chroot.sh trixie                 # what CI runs
#   scripts/test-in-chroot.sh trixie release
#   scripts/test-in-chroot.sh trixie -- COMMAND...   # any command, in the source tree
#
# The chroot is build/chroot/SUITE/root (cached: made once, reused while it
# holds the marker .scaled-chroot of this script's FORMAT; delete the folder
# to start again). The source tree is bind-mounted at /scaled, with
# build/chroot/SUITE/build over /scaled/build, so the presets' build trees
# (build/asan, ...) never mix with the host's; ../shared (SCALED_SHARED_DIR),
# when there is one, is bind-mounted read-only at /shared. The mounts live in a private mount
# namespace (unshare) and vanish with it: nothing is left mounted whatever
# happens. Runs as root, or through sudo (mmdebstrap root mode, chroot).
#
# Environment: SCALED_DEBIAN_MIRROR (default: mmdebstrap's, deb.debian.org
# with updates and security), CI and SCALED_FUZZ_SECONDS (passed through),
# SCALED_VM_CACHE (a VM kernel cache made on the host, bind-mounted at the
# same path so the vm tests boot it; docs/vm-tests.md).
# Exit codes: the command's; 64 usage; 77 (skip, one line on stderr) no root
# or no mount namespace to be had.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() {
  echo "usage: scripts/test-in-chroot.sh SUITE [PRESET... | -- COMMAND...]" >&2
  exit 64
}
(($# >= 1)) || usage
suite=$1
shift
[[ $suite =~ ^[a-z]+$ ]] || usage

# What the cached root holds; bump it when the way it is made changes.
format=1

src=$PWD
top=$src/build/chroot/$suite
root=$top/root
marker=$root/.scaled-chroot

sudo=()
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "test-in-chroot: need root or sudo (mmdebstrap root mode, mounts, chroot)" >&2; exit 77; }
  sudo=(sudo)
fi

# A chroot with /proc, /dev and the source tree needs a mount namespace:
# root with CAP_SYS_ADMIN (not granted in every container).
if ! "${sudo[@]}" unshare --mount --fork true 2>/dev/null; then
  echo "test-in-chroot: skip: cannot make a mount namespace here (unshare --mount failed: not privileged enough)" >&2
  exit 77
fi

if [[ ! -f $marker || $(sed -n 's/^format=//p' "$marker") != "$format" ]]; then
  if ! command -v mmdebstrap >/dev/null; then
    echo "test-in-chroot: installing mmdebstrap"
    export DEBIAN_FRONTEND=noninteractive
    "${sudo[@]}" apt-get update -qq
    "${sudo[@]}" apt-get install -y -qq --no-install-recommends mmdebstrap
  fi
  mirror=()
  [[ -n ${SCALED_DEBIAN_MIRROR:-} ]] && mirror=("$SCALED_DEBIAN_MIRROR")
  echo "test-in-chroot: making a minimal $suite in $root"
  start=$SECONDS
  "${sudo[@]}" rm -rf "$root.partial" "$root"
  mkdir -p "$top"
  # variant apt: Essential packages and apt, nothing else; install-deps.sh
  # must bring the rest, as on a fresh machine. ca-certificates for https
  # mirrors; sudo is not needed (the tests run as root).
  "${sudo[@]}" mmdebstrap --variant=apt --mode=root --include=ca-certificates \
    "$suite" "$root.partial" "${mirror[@]}"
  printf 'format=%s\nsuite=%s\ndate=%s\n' "$format" "$suite" "$(date -u +%FT%TZ)" |
    "${sudo[@]}" tee "$root.partial/.scaled-chroot" >/dev/null
  "${sudo[@]}" mv -T "$root.partial" "$root"
  echo "test-in-chroot: made in $((SECONDS - start)) s ($(du -sh "$root" | cut -f1))"
fi

command=()
if (($# >= 1)) && [[ $1 == -- ]]; then
  shift
  (($# >= 1)) || usage
  command=("$@")
else
  presets=("$@")
  ((${#presets[@]})) || presets=(asan)
  command=(scripts/test.sh "${presets[@]}")
fi

shared=${SCALED_SHARED_DIR:-$src/../shared}
mkdir -p "$top/build"
# The steps run as root in the private mount namespace before the chroot.
setup=(
  "mount --make-rprivate /"
  "mount -t proc proc '$root/proc'"
  "mount --rbind /sys '$root/sys'"
  "mount --rbind /dev '$root/dev'"
  "mount -t tmpfs -o mode=1777 tmpfs '$root/tmp'"
  "mount -t tmpfs -o mode=755 tmpfs '$root/run'"
  "mkdir -p '$root/scaled'"
  "mount --bind '$src' '$root/scaled'"
  "mount --bind '$top/build' '$root/scaled/build'"
)
# ../shared of /scaled is /shared: there when the host has the data, else
# absent (not an empty folder, which tests would take for the data).
shared_env=()
if [[ -d $shared ]]; then
  setup+=("mkdir -p '$root/shared'" "mount --bind '$(cd "$shared" && pwd -P)' '$root/shared'"
    "mount -o remount,bind,ro '$root/shared'")
  shared_env=(SCALED_SHARED_DIR=/shared)
else
  setup+=("rmdir '$root/shared' 2>/dev/null || true")
fi
if [[ -n ${SCALED_VM_CACHE:-} && -d ${SCALED_VM_CACHE} ]]; then
  vmc=$(cd "$SCALED_VM_CACHE" && pwd -P)
  setup+=("mkdir -p '$root$vmc'" "mount --bind '$vmc' '$root$vmc'")
fi
# The mirrors' names resolve as on the host.
setup+=("cp -L /etc/resolv.conf '$root/etc/resolv.conf'")

env=(
  PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
  HOME=/root LANG=C.UTF-8 TERM="${TERM:-dumb}"
  "${shared_env[@]}"
)
for name in CI SCALED_FUZZ_SECONDS SCALED_VM_CACHE; do
  [[ -n ${!name:-} ]] && env+=("$name=${!name}")
done

# git refuses a repository owned by another user (the host's checkout seen
# by root in the chroot) unless told it is safe.
setup+=("printf '[safe]\n\tdirectory = /scaled\n' >'$root/root/.gitconfig'")

# The command goes through as arguments, never re-parsed by a shell.
script="set -e; $(printf '%s; ' "${setup[@]}")
exec chroot '$root' /usr/bin/env -i ${env[*]@Q} /bin/bash -c 'cd /scaled && exec \"\$@\"' bash \"\$@\""

echo "test-in-chroot: $suite: ${command[*]}"
"${sudo[@]}" unshare --mount --fork /bin/bash -c "$script" bash "${command[@]}"
