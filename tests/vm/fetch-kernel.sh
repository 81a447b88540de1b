#!/usr/bin/env bash
# fetch-kernel.sh CACHE_DIR
#
# Gets Debian's own kernel for the VM tests, without installing anything on
# the host: downloads (apt-get download) the kernel image, headers and kbuild
# of the ABI that linux-image-amd64 depends on, unpacks them with dpkg -x into
# CACHE_DIR/root, builds the test drivers the kernel's config lacks (on
# Debian: vimc, gpio-sim, gpio-mockup and the irq-sim they need; the IIO dummy
# device with its buffer, patched into a 3-axis accelerometer
# (iio_dummy_accel_xyz.patch, or iio_dummy_accel_xyz-MAJOR.MINOR.patch when
# there is one for the kernel's version), the IIO configfs, software-device
# and software-trigger cores and the sysfs and hrtimer triggers) out of tree
# from the same version's linux-source-MAJOR.MINOR with the compiler the
# kernel was built with (CONFIG_CC_VERSION_TEXT), installs them into
# ROOT/lib/modules/VER/extra and runs depmod so that `modprobe -d ROOT` works
# in the guest. Works for whichever kernel the release's linux-image-amd64
# depends on: bookworm's 6.1 (gcc-12), trixie's 6.12 (gcc-14).
#
# Idempotent: returns at once when CACHE_DIR/ready exists and was made by this
# version of the script (FORMAT below; an older cache is rebuilt from its
# downloaded packages, without downloading again). Exit codes: 0 ready,
# 77 something cannot be had here (no apt, no network, no linux-source, no
# compiler, a source patch that does not apply to this kernel: one line on
# stderr), 1 any other failure (names the command).
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

# What the cache holds; bump it when the set of modules built here (or their
# content) changes, not for changes that leave a bookworm cache as it was.
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
# The compiler is checked once the kernel's config says which one it needs.
for tool in make tar xz patch depmod; do
  command -v "$tool" >/dev/null || skip "$tool not found (needed to build the test modules)"
done

# The kernel ABI is the one the meta-package depends on, e.g. 6.1.0-56
# (bookworm) or 6.12.118+deb13 (trixie).
image_pkg=$(apt-cache depends linux-image-amd64 2>/dev/null |
  sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n 1)
[[ -n $image_pkg ]] || skip "apt-cache knows no linux-image-amd64 dependency (run apt-get update)"
krel=${image_pkg#linux-image-}
abi=${krel%-amd64}
version=$(apt-cache show --no-all-versions "$image_pkg" 2>/dev/null | sed -n 's/^Version: //p' | head -n 1)
[[ -n $version ]] || skip "apt-cache has no version of $image_pkg (run apt-get update)"
# The kernel's major.minor (6.1, 6.12) names its source package.
[[ $version =~ ^([0-9]+\.[0-9]+)\. && $abi == "${BASH_REMATCH[1]}".* ]] ||
  die "cannot tell the kernel's major.minor from $image_pkg $version"
mm=${BASH_REMATCH[1]}
# The kbuild package is whatever the headers depend on: named by major.minor
# on bookworm (linux-kbuild-6.1), by ABI on trixie
# (linux-kbuild-6.12.118+deb13). It comes from the same source package, so
# it has the kernel's version (or, once the archive has moved on, another
# revision of the same upstream release: version_of below).
kbuild_pkg=$(apt-cache depends "linux-headers-$krel" 2>/dev/null |
  sed -n 's/^ *Depends: \(linux-kbuild-[0-9][^ ]*\)$/\1/p' | head -n 1)
[[ -n $kbuild_pkg ]] || skip "apt-cache knows no linux-kbuild dependency of linux-headers-$krel (run apt-get update)"
packages=("$image_pkg" "linux-headers-$krel" "linux-headers-$abi-common" "$kbuild_pkg")

# apt-get download as root: download unsandboxed (the _apt user may not be
# able to write the cache), which is what apt would do anyway, minus the
# warning.
debs=$cache/debs
mkdir -p "$debs"
deb_of() { # the .deb file of package $1 at version $2 (default: the kernel's), or nothing
  local f
  for f in "$debs/$1_${2:-$version}_"*.deb; do
    [[ -f $f ]] && echo "$f" && return 0
  done
  return 0
}
# The version of package $1 that is (or will be) in $debs: the kernel's
# version; for the build tools and the module sources (kbuild, linux-source)
# when the archive no longer has that exact revision, the newest one of the
# same upstream release. A security pocket keeps only the newest upload of
# each binary package: bookworm-security once had linux-kbuild-6.1 at
# 6.1.192-3 beside the kernel at 6.1.192-2. The same upstream release means
# the same kernel tree (SUBLEVEL, checked below) and the same build tools; the
# modules take their version magic from the headers, which match the image.
versions_of() { # the versions of package $1 the archive has, newest first
  apt-cache madison "$1" 2>/dev/null | awk -F'|' '{ gsub(/ /, "", $2); print $2 }'
}
version_of() {
  local v
  if [[ -n $(deb_of "$1") ]] || versions_of "$1" | grep -xF "$version" >/dev/null; then
    echo "$version"
    return 0
  fi
  case $1 in
    linux-kbuild-* | linux-source-*)
      v=$(versions_of "$1" | awk -v u="${version%-*}-" 'index($0, u) == 1 { print; exit }')
      echo "${v:-$version}"
      ;;
    *) echo "$version" ;;
  esac
}
# The version each package was downloaded at (download), for unpacking it.
declare -A got_version
download() { # download package $1 (at version_of $1) into $debs, or skip
  local v
  v=$(version_of "$1")
  got_version[$1]=$v
  if [[ -z $(deb_of "$1" "$v") ]]; then
    echo "fetch-kernel: downloading $1 $v" >&2
    if ! (cd "$debs" && apt-get -q -o APT::Sandbox::User=root download "$1=$v") >>"$log" 2>&1; then
      tail -n 5 "$log" >&2 || true
      skip "apt-get download $1=$v failed (no network or mirror?)"
    fi
  fi
}
for p in "${packages[@]}"; do download "$p"; done

# The sources: the installed linux-source-MAJOR.MINOR when it is the same
# version, else that version's linux-source package, downloaded and unpacked
# here.
src_pkg=linux-source-$mm
src_tar=/usr/src/$src_pkg.tar.xz
src_version=$(dpkg-query -W -f '${Version}' "$src_pkg" 2>/dev/null || true)
if [[ ! -f $src_tar || $src_version != "$version" ]]; then
  download "$src_pkg"
  rm -rf "$cache/srcpkg"
  run dpkg -x "$(deb_of "$src_pkg" "${got_version[$src_pkg]}")" "$cache/srcpkg"
  src_tar=$cache/srcpkg/usr/src/$src_pkg.tar.xz
  [[ -f $src_tar ]] || die "$src_pkg $version has no $src_tar"
fi

# Unpack (never install) into one root, then make the absolute paths in the
# headers point inside it.
root=$cache/root
rm -rf "$root"
mkdir -p "$root"
for p in "${packages[@]}"; do run dpkg -x "$(deb_of "$p" "${got_version[$p]}")" "$root"; done
# Trixie's packages ship the modules in /usr/lib/modules (merged /usr), where
# bookworm's ship /lib/modules: make the root a merged-/usr one too, so that
# ROOT/lib/modules is the place for both here and for modprobe -d/depmod -b
# (whichever of the two directories the host's kmod looks in).
if [[ ! -e $root/lib && -d $root/usr/lib/modules ]]; then
  run ln -s usr/lib "$root/lib"
fi
headers=$root/usr/src/linux-headers-$krel
vmlinuz=$root/boot/vmlinuz-$krel
[[ -f $vmlinuz ]] || die "$image_pkg has no /boot/vmlinuz-$krel"
[[ -f $headers/Makefile ]] || die "linux-headers-$krel has no Makefile"
run sed -i "s#^include /usr/src/#include $root/usr/src/#" "$headers/Makefile"
moddir=$root/lib/modules/$krel
up=../../..
[[ -L $root/lib ]] && up=../../../.. # moddir is really ROOT/usr/lib/modules/VER
run ln -sfn "$up/usr/src/linux-headers-$krel" "$moddir/build"
run ln -sfn "$up/usr/src/linux-headers-$abi-common" "$moddir/source"

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
  # The compiler the kernel was built with (the headers' Makefile calls it
  # by that name: gcc-12 on bookworm, x86_64-linux-gnu-gcc-14 on trixie);
  # modules built with another one may not load.
  cc_text=$(sed -n 's/^CONFIG_CC_VERSION_TEXT="\(.*\)"$/\1/p' "$config")
  cc=${cc_text%% *}
  [[ -n $cc ]] || die "kernel $krel's config has no CONFIG_CC_VERSION_TEXT"
  command -v "$cc" >/dev/null ||
    skip "$cc not found (kernel $krel was built with '$cc_text'; install ${cc##*-linux-gnu-}, needed to build the test modules)"
  s=$src_pkg
  run tar -xJf "$src_tar" -C "$cache/src" "$s/drivers/media/test-drivers/vimc" \
    "$s/drivers/gpio/gpio-sim.c" "$s/drivers/gpio/gpio-mockup.c" "$s/drivers/gpio/gpiolib.h" \
    "$s/kernel/irq/irq_sim.c" "$s/drivers/iio/dummy" "$s/drivers/iio/industrialio-configfs.c" \
    "$s/drivers/iio/industrialio-sw-device.c" "$s/drivers/iio/industrialio-sw-trigger.c" \
    "$s/drivers/iio/trigger/iio-trig-sysfs.c" "$s/drivers/iio/trigger/iio-trig-hrtimer.c" \
    "$s/Makefile"
  s=$cache/src/$s
  # The source must be the headers' version (same SUBLEVEL).
  sub=$(sed -n 's/^SUBLEVEL = //p' "$s/Makefile")
  [[ $version == "$mm.$sub"-* ]] || die "linux-source is $mm.$sub but the kernel is $version"
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
        # handle_simple_irq: the same thing (6.1 and 6.12 have the same
        # line). Built-in code needs no MODULE_LICENSE, a module using GPL
        # symbols does. A source that no longer calls irq_to_desc needs
        # neither change; one that calls it elsewhere cannot be built.
        if grep -q 'handle_simple_irq(irq_to_desc(irqnum));' "$build/irq_sim.c"; then
          run sed -i 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' "$build/irq_sim.c"
        fi
        if grep -q 'irq_to_desc' "$build/irq_sim.c"; then
          skip "kernel/irq/irq_sim.c of $src_pkg $version calls irq_to_desc (not exported) in a way the generic_handle_irq change does not cover: irq_sim cannot be built as a module"
        fi
        if ! grep -q '^MODULE_LICENSE' "$build/irq_sim.c"; then
          printf '\nMODULE_DESCRIPTION("Interrupt simulator, built out of tree for the scaled VM tests");\nMODULE_LICENSE("GPL");\n' >>"$build/irq_sim.c"
        fi
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
        # in_accel_scale. The patch names what it changes. The driver was
        # rewritten between 6.1 and 6.12 (guards, early returns), so each
        # version has its own patch: iio_dummy_accel_xyz-MAJOR.MINOR.patch
        # when it exists, else iio_dummy_accel_xyz.patch (made on 6.1).
        # Without fuzz: a hunk placed by guesswork would compile and
        # misbehave.
        xyz_patch=$here/iio_dummy_accel_xyz.patch
        [[ -f $here/iio_dummy_accel_xyz-$mm.patch ]] && xyz_patch=$here/iio_dummy_accel_xyz-$mm.patch
        if patch -p1 --dry-run --reverse --force --fuzz=0 -d "$build/iio" -i "$xyz_patch" >/dev/null 2>&1; then
          echo "fetch-kernel: iio_dummy of $src_pkg $version already has $(basename "$xyz_patch"), not patching" >&2
        elif patch -p1 --dry-run --forward --fuzz=0 -d "$build/iio" -i "$xyz_patch" >>"$log" 2>&1; then
          run patch -p1 --forward --fuzz=0 -d "$build/iio" -i "$xyz_patch"
        else
          skip "$(basename "$xyz_patch") does not apply to drivers/iio/dummy of $src_pkg $version (patch's output in $log; make an iio_dummy_accel_xyz-$mm.patch for it)"
        fi
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
  make_vars=(CONFIG_VIDEO_VIMC=m)
  # Trixie's headers ship vmlinux, so with CONFIG_DEBUG_INFO_BTF_MODULES
  # kbuild would give each module BTF with pahole (dwarves), which nothing
  # else here needs; the test modules need no BTF (it only describes their
  # types to BPF) and load without it. Bookworm's headers have no vmlinux
  # and kbuild skips BTF by itself there.
  if [[ -f $headers/vmlinux ]] && has DEBUG_INFO_BTF_MODULES; then
    make_vars+=(CONFIG_DEBUG_INFO_BTF_MODULES=)
  fi
  echo "fetch-kernel: building ${want[*]} for $krel" >&2
  run nice make -C "$headers" M="$build" "${make_vars[@]}" -j2 modules
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
