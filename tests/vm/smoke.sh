#!/usr/bin/env bash
# smoke.sh: the guest test that proves the VM harness itself (ctest vm.smoke;
# by hand: tests/vm/run-vm.sh -- tests/vm/smoke.sh). Asserts what the other
# guest tests rely on: the guest marker, vivid's capture node, vimc's media
# device, the gpio-sim chip "scaled-leds" with 8 lines, the udev markers
# libcamera needs, and that v4l2-ctl and cam see the devices. Devices are
# found by name, never by number. Exits 77 outside the VM.
set -euo pipefail

if [[ ${SCALED_VM:-} != 1 ]]; then
  echo "smoke.sh: skip: not inside the VM (run it through tests/vm/run-vm.sh)" >&2
  exit 77
fi

failures=0
ok() { echo "ok: $*"; }
bad() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}

# video4linux node whose sysfs name is $1, as /dev/NAME, or nothing
v4l_node() {
  local f
  for f in /sys/class/video4linux/*/name; do
    [[ -f $f && $(<"$f") == "$1" ]] && echo "/dev/$(basename "$(dirname "$f")")" && return 0
  done
  return 0
}
# media device whose model is $1, as /dev/mediaN, or nothing
media_node() {
  local f
  for f in /sys/bus/media/devices/*/model; do
    [[ -f $f && $(<"$f") == "$1" ]] && echo "/dev/$(basename "$(dirname "$f")")" && return 0
  done
  return 0
}

vivid=$(v4l_node vivid-000-vid-cap)
if [[ -n $vivid && -c $vivid ]]; then ok "vivid capture node $vivid"; else bad "no vivid capture node (vivid-000-vid-cap)"; fi

vimc=$(media_node "VIMC MDEV")
if [[ -n $vimc && -c $vimc ]]; then ok "vimc media device $vimc"; else bad "no vimc media device (model VIMC MDEV)"; fi
for name in "Sensor B" "Raw Capture 1"; do
  node=$(v4l_node "$name")
  if [[ -n $node && -c $node ]]; then ok "vimc node '$name' $node"; else bad "no vimc node '$name'"; fi
done

# gpio-sim: the chip by label (legacy sysfs class and the character device,
# whose chip gpiodetect names), and its per-line sysfs attributes (where a
# held line's value reads back).
chip=""
for c in /sys/class/gpio/gpiochip*; do
  if [[ -f $c/label && $(<"$c/label") == scaled-leds ]]; then
    chip=$c
    break
  fi
done
if [[ -z $chip ]]; then
  bad "no gpio chip labelled scaled-leds in /sys/class/gpio"
else
  ngpio=$(<"$chip/ngpio")
  if [[ $ngpio == 8 ]]; then ok "scaled-leds has 8 lines"; else bad "scaled-leds has $ngpio lines, not 8"; fi
fi
if ! command -v gpiodetect >/dev/null; then
  bad "gpiodetect not found (install gpiod)"
else
  dev=$(gpiodetect | sed -n 's/^\(gpiochip[0-9]*\) \[scaled-leds\] (8 lines)$/\1/p')
  if [[ -n $dev && -c /dev/$dev ]]; then
    ok "gpiodetect: scaled-leds is /dev/$dev"
    if [[ -f /sys/bus/gpio/devices/$dev/sim_gpio7/value && -f /sys/bus/gpio/devices/$dev/sim_gpio0/pull ]]; then
      ok "gpio-sim line attributes in /sys/bus/gpio/devices/$dev"
    else
      bad "no sim_gpioN attributes in /sys/bus/gpio/devices/$dev"
    fi
  else
    bad "gpiodetect does not list scaled-leds with 8 lines"
  fi
fi

# Every video and media node is marked initialised for libudev.
marked=0
for f in /sys/class/video4linux/*/dev /sys/bus/media/devices/*/dev; do
  [[ -f $f ]] || continue
  marker=/run/udev/data/c$(<"$f")
  if [[ -f $marker && $(<"$marker") == I:1 ]]; then
    marked=$((marked + 1))
  else
    bad "no udev marker $marker for $f"
  fi
done
if [[ $marked -gt 0 ]]; then ok "$marked udev markers"; else bad "no udev markers at all"; fi

if command -v v4l2-ctl >/dev/null; then
  devices=$(v4l2-ctl --list-devices 2>&1 || true)
  for want in "platform:vivid-000" "platform:vimc"; do
    if grep -q "$want" <<<"$devices"; then ok "v4l2-ctl lists $want"; else bad "v4l2-ctl does not list $want"; fi
  done
fi
if command -v cam >/dev/null; then
  cameras=$(cam -l 2>/dev/null || true)
  if grep -q "Sensor B" <<<"$cameras"; then ok "libcamera (cam -l) lists vimc's Sensor B"; else bad "cam -l does not list vimc: $cameras"; fi
fi

if [[ $failures -gt 0 ]]; then
  echo "smoke.sh: $failures check(s) failed"
  exit 1
fi
echo "smoke.sh: all checks passed"
