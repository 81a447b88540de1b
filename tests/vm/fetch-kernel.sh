#!/usr/bin/env bash
# fetch-kernel.sh CACHE_DIR
#
# Gets Debian's own kernel for the VM tests, without installing anything on
# the host: downloads (apt-get download) the kernel image, headers and kbuild
# of the ABI that linux-image-amd64 depends on, unpacks them with dpkg -x into
# CACHE_DIR/root, builds the test drivers Debian does not ship (vimc, gpio-sim,
# gpio-mockup and the irq-sim they need; the IIO dummy device with its buffer,
# patched into a 3-axis accelerometer (iio_dummy_accel_xyz.patch), the IIO
# configfs, software-device and software-trigger cores and the sysfs
# and hrtimer triggers) out of tree from the same version's linux-source-6.1,
# installs them into ROOT/lib/modules/VER/extra and runs depmod so that
# `modprobe -d ROOT` works in the guest.
#
# Idempotent: returns at once when CACHE_DIR/ready exists and was made by this
# version of the script (FORMAT below; an older cache is rebuilt from its
# downloaded packages, without downloading again). Exit codes: 0 ready,
# 77 something cannot be had here (no apt, no network, no linux-source, no
# compiler: one line on stderr), 1 any other failure (names the command).
set -euo pipefail

if [[ $# -ne 1 ]]; then
  echo "usage: $0 CACHE_DIR" >&2
  exit 2
fi

here=$(cd "$(dirname "$0")" && pwd)

skip() {
  echo "fetch-kernel: skip: $*" >&2
  exit 77
}
die() {
  echo "fetch-kernel: error: $*" >&2
  exit 1
}
# run CMD...: runs a command, its output into the log; on failure prints the
# command and the log's tail.
run() {
  if ! "$@" >>"$log" 2>&1; then
    echo "fetch-kernel: error: command failed: $*" >&2
    tail -n 30 "$log" >&2 || true
    exit 1
  fi
}

# What the cache holds; bump it when the set of modules built here changes.
# 2: the IIO modules (iio_dummy and friends) added.
# 3: iio_dummy patched into a 3-axis accelerometer (iio_dummy_accel_xyz.patch).
format=3

mkdir -p "$1" || die "cannot create cache directory $1"
cache=$(cd "$1" && pwd -P)
ready=$cache/ready
if [[ -f $ready ]]; then
  vmlinuz=$(sed -n 's/^VMLINUZ=//p' "$ready")
  if [[ -n $vmlinuz && -f $vmlinuz && $(sed -n 's/^FORMAT=//p' "$ready") == "$format" ]]; then
    exit 0
  fi
  rm -f "$ready"
fi

log=$cache/fetch-kernel.log
: >"$log"
start_s=$(date +%s)

for tool in apt-get apt-cache dpkg dpkg-query; do
  command -v "$tool" >/dev/null || skip "$tool not found (not a Debian host)"
done
for tool in make gcc-12 tar xz depmod; do
  command -v "$tool" >/dev/null || skip "$tool not found (needed to build the test modules)"
done

# The kernel ABI is the one the meta-package depends on, e.g. 6.1.0-56.
image_pkg=$(apt-cache depends linux-image-amd64 2>/dev/null |
  sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n 1)
[[ -n $image_pkg ]] || skip "apt-cache knows no linux-image-amd64 dependency (run apt-get update)"
krel=${image_pkg#linux-image-}
abi=${krel%-amd64}
version=$(apt-cache show --no-all-versions "$image_pkg" 2>/dev/null | sed -n 's/^Version: //p' | head -n 1)
[[ -n $version ]] || skip "apt-cache has no version of $image_pkg (run apt-get update)"
packages=("$image_pkg" "linux-headers-$krel" "linux-headers-$abi-common" "linux-kbuild-6.1")

# apt-get download as root: download unsandboxed (the _apt user may not be
# able to write the cache), which is what apt would do anyway, minus the
# warning.
debs=$cache/debs
mkdir -p "$debs"
deb_of() { # the .deb file of package $1 at $version, or nothing
  local f
  for f in "$debs/$1_${version}_"*.deb; do
    [[ -f $f ]] && echo "$f" && return 0
  done
  return 0
}
download() { # download package=version into $debs, or skip
  if [[ -z $(deb_of "$1") ]]; then
    echo "fetch-kernel: downloading $1 $version" >&2
    if ! (cd "$debs" && apt-get -q -o APT::Sandbox::User=root download "$1=$version") >>"$log" 2>&1; then
      tail -n 5 "$log" >&2 || true
      skip "apt-get download $1=$version failed (no network or mirror?)"
    fi
  fi
}
for p in "${packages[@]}"; do download "$p"; done

# The sources: the installed linux-source-6.1 when it is the same version,
# else that version's linux-source package, downloaded and unpacked here.
src_tar=/usr/src/linux-source-6.1.tar.xz
src_version=$(dpkg-query -W -f '${Version}' linux-source-6.1 2>/dev/null || true)
if [[ ! -f $src_tar || $src_version != "$version" ]]; then
  download linux-source-6.1
  rm -rf "$cache/srcpkg"
  run dpkg -x "$(deb_of linux-source-6.1)" "$cache/srcpkg"
  src_tar=$cache/srcpkg/usr/src/linux-source-6.1.tar.xz
  [[ -f $src_tar ]] || die "linux-source-6.1 $version has no $src_tar"
fi

# Unpack (never install) into one root, then make the absolute paths in the
# headers point inside it.
root=$cache/root
rm -rf "$root"
mkdir -p "$root"
for p in "${packages[@]}"; do run dpkg -x "$(deb_of "$p")" "$root"; done
headers=$root/usr/src/linux-headers-$krel
vmlinuz=$root/boot/vmlinuz-$krel
[[ -f $vmlinuz ]] || die "$image_pkg has no /boot/vmlinuz-$krel"
[[ -f $headers/Makefile ]] || die "linux-headers-$krel has no Makefile"
run sed -i "s#^include /usr/src/#include $root/usr/src/#" "$headers/Makefile"
moddir=$root/lib/modules/$krel
run ln -sfn "../../../usr/src/linux-headers-$krel" "$moddir/build"
run ln -sfn "../../../usr/src/linux-headers-$abi-common" "$moddir/source"

# The kernel config decides what must be built here: the drivers must be
# absent, their dependencies present (modules or built in).
config=$root/boot/config-$krel
has() { grep -Eq "^CONFIG_$1=[ym]" "$config"; }
for opt in CONFIGFS_FS GPIOLIB GPIO_CDEV IRQ_DOMAIN VIDEO_DEV MEDIA_CONTROLLER \
  VIDEO_V4L2_SUBDEV_API V4L2_FWNODE VIDEO_V4L2_TPG VIDEOBUF2_VMALLOC \
  VIDEOBUF2_DMA_CONTIG VIDEO_VIVID NET_9P_VIRTIO 9P_FS OVERLAY_FS VIRTIO_PCI \
  IIO IIO_BUFFER IIO_TRIGGER IIO_TRIGGERED_BUFFER IIO_KFIFO_BUF IRQ_WORK; do
  has "$opt" || die "kernel $krel lacks CONFIG_$opt, which the VM tests need"
done
want=()
has VIDEO_VIMC || want+=(vimc)
has GPIO_SIM || want+=(gpio-sim)
has GPIO_MOCKUP || want+=(gpio-mockup)
has IRQ_SIM || want+=(irq_sim)
# IIO (the imu VM test): Debian 6.1 has the IIO core and triggered buffers as
# modules but none of these. iio_dummy is built with its buffer
# (CONFIG_IIO_SIMPLE_DUMMY_BUFFER) and without its events (they need the
# iio_dummy_evgen irq chip, which nothing here uses).
has IIO_CONFIGFS || want+=(industrialio-configfs)
has IIO_SW_DEVICE || want+=(industrialio-sw-device)
has IIO_SW_TRIGGER || want+=(industrialio-sw-trigger)
has IIO_SIMPLE_DUMMY_BUFFER || want+=(iio_dummy)
has IIO_SYSFS_TRIGGER || want+=(iio-trig-sysfs)
has IIO_HRTIMER_TRIGGER || want+=(iio-trig-hrtimer)

build=$cache/build
rm -rf "$build" "$cache/src"
mkdir -p "$build/vimc" "$build/iio" "$cache/src"
if [[ ${#want[@]} -gt 0 ]]; then
  s=linux-source-6.1
  run tar -xJf "$src_tar" -C "$cache/src" "$s/drivers/media/test-drivers/vimc" \
    "$s/drivers/gpio/gpio-sim.c" "$s/drivers/gpio/gpio-mockup.c" "$s/drivers/gpio/gpiolib.h" \
    "$s/kernel/irq/irq_sim.c" "$s/drivers/iio/dummy" "$s/drivers/iio/industrialio-configfs.c" \
    "$s/drivers/iio/industrialio-sw-device.c" "$s/drivers/iio/industrialio-sw-trigger.c" \
    "$s/drivers/iio/trigger/iio-trig-sysfs.c" "$s/drivers/iio/trigger/iio-trig-hrtimer.c" \
    "$s/Makefile"
  s=$cache/src/$s
  # The source must be the headers' version (same SUBLEVEL).
  sub=$(sed -n 's/^SUBLEVEL = //p' "$s/Makefile")
  [[ $version == 6.1.$sub-* ]] || die "linux-source is 6.1.$sub but the kernel is $version"
  kbuild=""
  iio_kbuild=""
  for m in "${want[@]}"; do
    case $m in
      vimc)
        run cp "$s"/drivers/media/test-drivers/vimc/*.[ch] "$s/drivers/media/test-drivers/vimc/Makefile" "$build/vimc/"
        kbuild+="obj-m += vimc/"$'\n'
        ;;
      gpio-sim | gpio-mockup)
        run cp "$s/drivers/gpio/$m.c" "$s/drivers/gpio/gpiolib.h" "$build/"
        kbuild+="obj-m += $m.o"$'\n'
        ;;
      irq_sim)
        run cp "$s/kernel/irq/irq_sim.c" "$build/"
        # irq_to_desc is not exported to modules; generic_handle_irq looks
        # the descriptor up and calls its handler, which irq_sim sets to
        # handle_simple_irq: the same thing. Built-in code needs no
        # MODULE_LICENSE, a module using GPL symbols does.
        grep -q 'handle_simple_irq(irq_to_desc(irqnum));' "$build/irq_sim.c" ||
          die "irq_sim.c changed: the irq_to_desc patch does not apply"
        run sed -i 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' "$build/irq_sim.c"
        printf '\nMODULE_DESCRIPTION("Interrupt simulator, built out of tree for the scaled VM tests");\nMODULE_LICENSE("GPL");\n' >>"$build/irq_sim.c"
        kbuild+="obj-m += irq_sim.o"$'\n'
        ;;
      industrialio-configfs | industrialio-sw-device | industrialio-sw-trigger)
        run cp "$s/drivers/iio/$m.c" "$build/iio/"
        iio_kbuild+="obj-m += $m.o"$'\n'
        ;;
      iio-trig-sysfs | iio-trig-hrtimer)
        run cp "$s/drivers/iio/trigger/$m.c" "$build/iio/"
        iio_kbuild+="obj-m += $m.o"$'\n'
        ;;
      iio_dummy)
        run cp "$s"/drivers/iio/dummy/iio_simple_dummy.[ch] \
          "$s/drivers/iio/dummy/iio_simple_dummy_buffer.c" "$build/iio/"
        # A 3-axis accelerometer whose axes the tests set (the daemon's
        # [imu] in vm.daemon): in_accel_{y,z}_raw, writable raw values and
        # in_accel_scale. The patch names what it changes.
        run patch -p1 --forward -d "$build/iio" -i "$here/iio_dummy_accel_xyz.patch"
        # The buffer part is compiled in only when its Kconfig symbol is
        # defined (iio_simple_dummy.h); out of tree, define it by hand.
        iio_kbuild+="CFLAGS_iio_simple_dummy.o += -DCONFIG_IIO_SIMPLE_DUMMY_BUFFER"$'\n'
        iio_kbuild+="CFLAGS_iio_simple_dummy_buffer.o += -DCONFIG_IIO_SIMPLE_DUMMY_BUFFER"$'\n'
        iio_kbuild+="obj-m += iio_dummy.o"$'\n'
        iio_kbuild+="iio_dummy-y := iio_simple_dummy.o iio_simple_dummy_buffer.o"$'\n'
        ;;
    esac
  done
  if [[ -n $iio_kbuild ]]; then
    printf '%s' "$iio_kbuild" >"$build/iio/Kbuild"
    kbuild+="obj-m += iio/"$'\n'
  fi
  printf '%s' "$kbuild" >"$build/Kbuild"
  echo "fetch-kernel: building ${want[*]} for $krel" >&2
  run nice make -C "$headers" M="$build" CONFIG_VIDEO_VIMC=m -j2 modules
  extra=$moddir/extra
  mkdir -p "$extra"
  while IFS= read -r ko; do
    run cp "$ko" "$extra/"
    run strip --strip-debug "$extra/$(basename "$ko")"
  done < <(find "$build" -name '*.ko')
fi
run depmod -b "$root" "$krel"
for m in vivid "${want[@]}"; do
  run modprobe -d "$root" -S "$krel" --show-depends "$m"
done

{
  echo "KREL=$krel"
  echo "VERSION=$version"
  echo "ROOT=$root"
  echo "VMLINUZ=$vmlinuz"
  echo "BUILT=${want[*]}"
  echo "FORMAT=$format"
} >"$ready.tmp"
mv "$ready.tmp" "$ready"
echo "fetch-kernel: $krel ($version) ready in $cache, $(($(date +%s) - start_s)) s" >&2
