#!/usr/bin/env bash
# mkinitramfs.sh CACHE_DIR
#
# Builds CACHE_DIR/initramfs.cpio.gz for the VM tests: busybox-static, the
# modules needed to reach the host's files (virtio-pci, 9p, overlayfs,
# configfs; everything else is loaded later with the host's modprobe from the
# 9p-mounted modules root), and tests/vm/guest-init.sh as /init. The guest's
# /bin, /sbin, /lib, /lib64 are symlinks into /usr, as on bookworm, so the
# host's /usr mounted over 9p runs unchanged.
#
# Needs CACHE_DIR/ready (fetch-kernel.sh). Exit 77 when busybox-static is
# missing, 1 on any other failure.
set -euo pipefail

if [[ $# -ne 1 ]]; then
  echo "usage: $0 CACHE_DIR" >&2
  exit 2
fi
die() {
  echo "mkinitramfs: error: $*" >&2
  exit 1
}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd -P)
cache=$(cd "$1" && pwd -P) || die "no cache directory $1"
[[ -f $cache/ready ]] || die "$cache/ready is missing: run fetch-kernel.sh first"
krel=$(sed -n 's/^KREL=//p' "$cache/ready")
root=$(sed -n 's/^ROOT=//p' "$cache/ready")

busybox=""
for b in /bin/busybox /usr/bin/busybox; do
  # The guest has no libc before /usr is mounted: only a static busybox will do.
  if [[ -x $b ]] && ! ldd "$b" >/dev/null 2>&1; then
    busybox=$b
    break
  fi
done
if [[ -z $busybox ]]; then
  echo "mkinitramfs: skip: no static busybox (install busybox-static)" >&2
  exit 77
fi

stage=$(mktemp -d "$cache/initramfs.XXXXXX")
trap 'rm -rf "$stage"' EXIT
cd "$stage"
mkdir -p .vm/bin .vm/modules .vm/ctl .vm/lower .vm/rw proc sys dev run tmp usr etc root home \
  mnt var/tmp
chmod 1777 tmp var/tmp
for d in bin sbin lib lib64; do ln -s "usr/$d" "$d"; done
cp "$busybox" .vm/bin/busybox
for applet in $("$busybox" --list); do
  [[ $applet == busybox ]] || ln -s busybox ".vm/bin/$applet"
done
# The kernel opens /dev/console for init before anything is mounted.
mknod -m 600 dev/console c 5 1 || die "cannot create dev/console (needs root)"
mknod -m 666 dev/null c 1 3 || die "cannot create dev/null (needs root)"

# The early modules, in load order (modprobe resolves the dependencies),
# plain: busybox's insmod loads them, and trixie's kernel ships its modules
# compressed (NAME.ko.xz; bookworm's are plain).
: >.vm/modules/order
while read -r kind path _; do
  [[ $kind == insmod ]] || continue
  name=$(basename "$path")
  name=${name%.xz}
  name=${name%.zst}
  name=${name%.gz}
  if ! grep -qx "$name" .vm/modules/order; then
    case $path in
      *.ko.xz) xz -dc "$path" >".vm/modules/$name" ;;
      *.ko.zst) zstd -qdc "$path" >".vm/modules/$name" ;;
      *.ko.gz) gzip -dc "$path" >".vm/modules/$name" ;;
      *) cp "$path" ".vm/modules/$name" ;;
    esac || die "cannot copy the module $path"
    echo "$name" >>.vm/modules/order
  fi
done < <(modprobe -d "$root" -S "$krel" --show-depends -a virtio_pci 9pnet_virtio 9p overlay configfs ||
  die "modprobe --show-depends failed for the early modules")
grep -qx 9p.ko .vm/modules/order || die "no 9p.ko among the early modules"

install -m 755 "$here/guest-init.sh" init

out=$cache/initramfs.cpio.gz
find . -mindepth 1 -printf '%P\n' | LC_ALL=C sort | "$busybox" cpio -o -H newc 2>/dev/null | gzip -1 >"$out.tmp" ||
  die "cpio/gzip failed"
mv "$out.tmp" "$out"
