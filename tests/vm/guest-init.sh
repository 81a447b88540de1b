#!/.vm/bin/sh
# shellcheck disable=SC3040 # busybox ash has pipefail
# guest-init.sh: PID 1 of the scaled test VM (busybox ash, from the initramfs
# that mkinitramfs.sh builds; run-vm.sh boots it).
#
# Mounts the kernel filesystems, the host's /usr and /etc (9p, read-only, with
# a tmpfs overlay so the guest may write), the kernel modules root and every
# share the host asked for at its host path; loads the kernel's virtual
# devices (vivid, vimc, gpio-sim with a live chip "scaled-leds", gpio-mockup,
# iio_dummy with the sysfs and hrtimer IIO triggers);
# marks the video and media nodes as udev-initialised for libcamera; then runs
# the host's command file with stdout/stderr on the console, records its exit
# code in the control share and powers off.
#
# The host passes everything through the 9p share tagged "vmctl" (mounted at
# /.vm/ctl): a `config` file with lines
#   CWD <path>                    the command's working directory
#   MODROOT <path>                the unpacked kernel root (modprobe -d)
#   SHARE <tag> <ro|rw|overlay> <path>   a 9p share to mount at <path>
# and `cmd.sh`, the command. The guest writes `started` (when the command
# starts), `rc` (its exit code) or `setup-failed` (the setup step that broke).
# A setup failure is printed as "scaled-vm: setup failed: STEP" and leaves no
# rc, so the host tells "VM setup broke" (exit 125) from "test failed".
set -euo pipefail
export PATH=/.vm/bin
ctl=/.vm/ctl
ctl_mounted=0

say() { echo "scaled-vm: $*"; }
off() {
  sync
  poweroff -f
  # Not reached unless the power-off failed; PID 1 must not exit.
  while :; do sleep 3600; done
}
fail() {
  trap - EXIT
  say "setup failed: $1" >&2
  if [ "$ctl_mounted" = 1 ]; then
    echo "$1" >"$ctl/setup-failed" || true
  fi
  off
}
trap 'fail "guest-init.sh exited early (line $LINENO)"' EXIT
verbose=0
step() { # step NAME CMD...: run CMD, fail the setup as NAME if it fails
  _name=$1
  shift
  if [ "$verbose" = 1 ]; then
    read -r _up _ </proc/uptime
    say "[$_up] $_name"
  fi
  "$@" || fail "$_name"
}

put() { echo "$2" >"$1"; } # put FILE VALUE, without a fork

# 9p: large messages for throughput; page cache for the read-only trees;
# cache=mmap (no caching, but shared mmap works) where the host reads results.
p9_opts="trans=virtio,version=9p2000.L,msize=262144"
mount9p() { # mount9p TAG MODE PATH
  case $2 in
    ro) mount -t 9p -o "$p9_opts,cache=loose,ro" "$1" "$3" ;;
    rw) mount -t 9p -o "$p9_opts,cache=mmap" "$1" "$3" ;;
    overlay)
      mkdir -p "/.vm/lower/$1" "/.vm/rw/$1/upper" "/.vm/rw/$1/work" &&
        mount -t 9p -o "$p9_opts,cache=loose,ro" "$1" "/.vm/lower/$1" &&
        mount -t overlay -o "lowerdir=/.vm/lower/$1,upperdir=/.vm/rw/$1/upper,workdir=/.vm/rw/$1/work" \
          "overlay-$1" "$3"
      ;;
    *) return 1 ;;
  esac
}

step "mount /proc" mount -t proc proc /proc
step "mount /sys" mount -t sysfs sysfs /sys
case " $(cat /proc/cmdline) " in
  *" scaled_vm.verbose=1 "*) verbose=1 ;;
esac
step "mount /dev" mount -t devtmpfs devtmpfs /dev
step "mkdir /dev/pts /dev/shm" mkdir -p /dev/pts /dev/shm
step "mount /dev/pts" mount -t devpts -o gid=5,mode=620 devpts /dev/pts
step "mount /dev/shm" mount -t tmpfs -o mode=1777 shm /dev/shm
step "mount /run" mount -t tmpfs -o mode=755 run /run
step "mount /tmp" mount -t tmpfs -o mode=1777 tmp /tmp
step "mount /.vm/rw" mount -t tmpfs -o mode=755 vmrw /.vm/rw
ln -sf /proc/self/fd /dev/fd
ln -sf /proc/self/fd/0 /dev/stdin
ln -sf /proc/self/fd/1 /dev/stdout
ln -sf /proc/self/fd/2 /dev/stderr

while read -r mod; do
  step "insmod $mod" insmod "/.vm/modules/$mod"
done </.vm/modules/order

step "mount the control share (9p tag vmctl)" mount9p vmctl rw "$ctl"
ctl_mounted=1
[ -f "$ctl/config" ] || fail "no $ctl/config"
[ -f "$ctl/cmd.sh" ] || fail "no $ctl/cmd.sh"

cwd=/
modroot=""
while read -r key rest; do
  case $key in
    CWD) cwd=$rest ;;
    MODROOT) modroot=$rest ;;
    SHARE)
      # SHARE <tag> <mode> <path>; the path may contain spaces.
      tag=${rest%% *}
      rest=${rest#* }
      mode=${rest%% *}
      path=${rest#* }
      step "mkdir $path" mkdir -p "$path"
      step "mount share $path ($mode, 9p tag $tag)" mount9p "$tag" "$mode" "$path"
      ;;
    "") ;;
    *) fail "unknown config line: $key" ;;
  esac
done <"$ctl/config"
[ -n "$modroot" ] || fail "no MODROOT in $ctl/config"
[ -x /usr/sbin/modprobe ] || fail "the host's /usr is not mounted (no /usr/sbin/modprobe)"

export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin:/.vm/bin
export HOME=/root SCALED_VM=1 TERM=dumb
hostname scaled-vm
step "mount configfs" mount -t configfs configfs /sys/kernel/config
mount -t debugfs debugfs /sys/kernel/debug || say "no debugfs (gpio-mockup values unavailable)"

mp() { /usr/sbin/modprobe -d "$modroot" "$@"; }
step "modprobe vivid" mp vivid n_devs=1
step "modprobe vimc" mp vimc
step "modprobe gpio-sim" mp gpio-sim
# gpio-sim: one live chip, one bank of 8 lines labelled scaled-leds.
sim=/sys/kernel/config/gpio-sim/scaled
step "gpio-sim: create chip" mkdir -p "$sim/bank0"
step "gpio-sim: num_lines" put "$sim/bank0/num_lines" 8
step "gpio-sim: label" put "$sim/bank0/label" scaled-leds
step "gpio-sim: live" put "$sim/live" 1
# A second, independent chip; nothing needs it yet, so it is not fatal.
mp gpio-mockup gpio_mockup_ranges=-1,4 gpio_mockup_named_lines=1 || say "gpio-mockup not loaded"
# IIO: the dummy device (made through configfs by the imu test itself) and the
# software triggers; only that test needs them, so not fatal here.
mp iio_dummy || say "iio_dummy not loaded"
mp iio-trig-sysfs || say "iio-trig-sysfs not loaded"
mp iio-trig-hrtimer || say "iio-trig-hrtimer not loaded"

# libcamera only lists devices that udev has initialised; there is no udevd.
step "mkdir /run/udev/data" mkdir -p /run/udev/data
for f in /sys/class/video4linux/*/dev /sys/bus/media/devices/*/dev; do
  [ -f "$f" ] || continue
  read -r devnum <"$f"
  put "/run/udev/data/c$devnum" I:1 || fail "udev marker for $f"
done

step "cd $cwd" cd "$cwd"
trap - EXIT
set +e
read -r up _ </proc/uptime
say "running the command (guest uptime ${up} s)"
echo "$up" >"$ctl/started"
sh "$ctl/cmd.sh" </dev/null
rc=$?
echo "$rc" >"$ctl/rc"
off
