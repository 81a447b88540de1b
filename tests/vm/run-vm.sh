#!/usr/bin/env bash
# run-vm.sh [--cache DIR] [--share PATH]... [--share-ro PATH]... [--env NAME=VALUE]...
#           [--mem MB] [--timeout S] [--verbose] -- COMMAND [ARGS...]
#
# Runs COMMAND inside a QEMU VM (TCG, no KVM) that boots Debian's own kernel
# with the kernel's virtual devices loaded: vivid (V4L2 capture), vimc (media
# controller camera, for libcamera), gpio-sim (a live chip labelled
# scaled-leds, 8 lines) and gpio-mockup. The guest sees the host's /usr and
# /etc (read-only, writes go to a tmpfs overlay), the source tree, the current
# directory and every --share (read-write; --share-ro: read-only) at their
# host paths, so host-built binaries run unchanged; COMMAND runs in the host's
# current directory with SCALED_VM=1 in its environment. The guest console
# streams to stdout.
#
# Exit code: COMMAND's; 77 (skip, one line on stderr) when qemu-system-x86_64
# is missing or the kernel cannot be had (fetch-kernel.sh); 124 when the
# host-side timeout (default 900 s) killed the VM; 125 when the VM setup broke
# (the guest prints "scaled-vm: setup failed: STEP") or the VM stopped without
# running the command. --verbose shows the kernel log and times each setup
# step of the guest.
#
# The kernel, its modules and the initramfs are cached in --cache (default
# ${SCALED_VM_CACHE:-/tmp/scaled-vm-cache}); the first call fills it (about
# half a minute plus the download).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd -P)
repo=$(cd "$here/../.." && pwd -P)

usage() {
  sed -n '2,3p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}/usage: /;2s/^usage: /       /' >&2
  exit 2
}
die() {
  echo "run-vm: error: $*" >&2
  exit 1
}

cache=${SCALED_VM_CACHE:-/tmp/scaled-vm-cache}
mem_mb=1024
timeout_s=900
extra_shares=()
envs=()
kernel_args="quiet"
while [[ $# -gt 0 ]]; do
  case $1 in
    --cache) [[ $# -ge 2 ]] || usage; cache=$2; shift 2 ;;
    --share) [[ $# -ge 2 ]] || usage; extra_shares+=("rw $2"); shift 2 ;;
    --share-ro) [[ $# -ge 2 ]] || usage; extra_shares+=("ro $2"); shift 2 ;;
    --env) [[ $# -ge 2 && $2 == [A-Za-z_]*=* ]] || usage; envs+=("$2"); shift 2 ;;
    --mem) [[ $# -ge 2 && $2 =~ ^[0-9]+$ ]] || usage; mem_mb=$2; shift 2 ;;
    --timeout) [[ $# -ge 2 && $2 =~ ^[0-9]+$ ]] || usage; timeout_s=$2; shift 2 ;;
    --verbose) kernel_args="scaled_vm.verbose=1"; shift ;;
    --) shift; break ;;
    *) usage ;;
  esac
done
[[ $# -ge 1 ]] || usage

qemu=$(command -v qemu-system-x86_64 || true)
if [[ -z $qemu ]]; then
  echo "run-vm: skip: qemu-system-x86_64 not found (install qemu-system-x86)" >&2
  exit 77
fi

# The kernel and initramfs, made once per cache; the lock keeps concurrent
# callers from building into the same directory.
mkdir -p "$cache" || die "cannot create the cache $cache"
cache=$(cd "$cache" && pwd -P)
prepare_rc=0
(
  flock 9
  "$here/fetch-kernel.sh" "$cache" || exit $?
  initrd=$cache/initramfs.cpio.gz
  if [[ ! -f $initrd || $here/guest-init.sh -nt $initrd || $here/mkinitramfs.sh -nt $initrd ||
    $cache/ready -nt $initrd ]]; then
    "$here/mkinitramfs.sh" "$cache" || exit $?
  fi
) 9>"$cache/.lock" || prepare_rc=$?
if [[ $prepare_rc -eq 77 ]]; then
  echo "run-vm: skip: the VM kernel cannot be had here (see above)" >&2
  exit 77
elif [[ $prepare_rc -ne 0 ]]; then
  die "preparing the VM kernel in $cache failed (exit $prepare_rc)"
fi
vmlinuz=$(sed -n 's/^VMLINUZ=//p' "$cache/ready")
modroot=$(sed -n 's/^ROOT=//p' "$cache/ready")

# The control share (config and command in, results out) and the host's own
# files of this run.
tmp=$(mktemp -d "${TMPDIR:-/tmp}/scaled-vm.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
ctl=$tmp/ctl
mkdir "$ctl"

# The shares: MODE PATH, mounted at PATH in the guest. A path inside a share
# that already exposes it (read-write, or read-only for a read-only one) is
# not shared again.
cwd=$(pwd -P)
candidates=("overlay /usr" "overlay /etc" "ro $modroot" "rw $repo" "rw $cwd")
for s in "${extra_shares[@]}"; do
  [[ -d ${s#* } ]] || die "share ${s#* }: not a directory"
  candidates+=("${s%% *} $(cd "${s#* }" && pwd -P)")
done
accepted=()
while IFS= read -r cand; do
  mode=${cand%% *}
  path=${cand#* }
  [[ $path == / ]] && die "cannot share / with the guest"
  [[ $path == *$'\n'* ]] && die "cannot share a path with a newline: $path"
  keep=1
  for a in "${accepted[@]}"; do
    amode=${a%% *}
    apath=${a#* }
    if [[ $path == "$apath" || $path == "$apath"/* ]]; then
      if [[ $amode == rw || ($amode == ro && $mode == ro) || $path == "$apath" ]]; then
        keep=0
      fi
    fi
  done
  [[ $keep -eq 1 ]] && accepted+=("$cand")
done < <(printf '%s\n' "${candidates[@]}" | LC_ALL=C sort -t ' ' -k2 -k1,1r)

qemu_args=(-accel tcg -cpu max -smp 2 -m "$mem_mb" -no-reboot -nodefaults -no-user-config
  -display none -monitor none -serial stdio
  -kernel "$vmlinuz" -initrd "$cache/initramfs.cpio.gz"
  -append "console=ttyS0 panic=-1 mitigations=off $kernel_args")
add_share() { # add_share TAG PATH READONLY(on|off)
  qemu_args+=(-fsdev "local,id=$1,path=$2,security_model=none,multidevs=remap,readonly=$3"
    -device "virtio-9p-pci,fsdev=$1,mount_tag=$1")
}
add_share vmctl "$ctl" off
{
  echo "CWD $cwd"
  echo "MODROOT $modroot"
} >"$ctl/config"
i=0
for a in "${accepted[@]}"; do
  mode=${a%% *}
  path=${a#* }
  # A qemu option value cannot hold a comma unless doubled.
  add_share "s$i" "${path//,/,,}" "$([[ $mode == rw ]] && echo off || echo on)"
  echo "SHARE s$i $mode $path" >>"$ctl/config"
  i=$((i + 1))
done

quote() { printf "'%s'" "${1//\'/\'\\\'\'}"; }
{
  for e in "${envs[@]}"; do
    echo "export ${e%%=*}=$(quote "${e#*=}")"
  done
  printf 'exec'
  for arg in "$@"; do printf ' %s' "$(quote "$arg")"; done
  printf '\n'
} >"$ctl/cmd.sh"

# The guest console: serial on stdio, carriage returns dropped so logs read
# as plain text. timeout(1) puts qemu in a process group of its own, so a
# signal to this script would not reach it: the trap stops the VM by pid.
t0=$(date +%s.%N)
{
  timeout -k 10 "$timeout_s" "$qemu" "${qemu_args[@]}" </dev/null 2>&1 &
  echo $! >"$tmp/timeout.pid"
  rc=0
  wait $! || rc=$?
  echo "$rc" >"$tmp/qemu.rc"
} | stdbuf -o0 tr -d '\r' &
vm_pid=$!
# shellcheck disable=SC2317 # called by the trap
stop_vm() {
  trap '' INT TERM HUP
  if [[ -f $tmp/timeout.pid ]]; then kill -TERM "$(cat "$tmp/timeout.pid")" 2>/dev/null || true; fi
  wait "$vm_pid" || true
  echo "run-vm: interrupted; the VM was stopped" >&2
  exit 130
}
trap stop_vm INT TERM HUP
wait "$vm_pid" || true
trap - INT TERM HUP
t1=$(date +%s.%N)
qemu_rc=$(cat "$tmp/qemu.rc" 2>/dev/null || echo "unknown")

elapsed() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }
if [[ -f $ctl/started ]]; then
  echo "run-vm: qemu start to command: $(elapsed "$t0" "$(stat -c %.9Y "$ctl/started")") s"
fi
echo "run-vm: total: $(elapsed "$t0" "$t1") s"
if [[ $qemu_rc == 124 || $qemu_rc == 137 ]]; then
  echo "run-vm: error: timed out after $timeout_s s; the VM was killed" >&2
  exit 124
fi
if [[ -f $ctl/rc ]]; then
  exit "$(cat "$ctl/rc")"
fi
if [[ -f $ctl/setup-failed ]]; then
  echo "run-vm: error: VM setup failed: $(cat "$ctl/setup-failed")" >&2
else
  echo "run-vm: error: the VM stopped without running the command (qemu exit $qemu_rc)" >&2
fi
exit 125
