#!/usr/bin/env bash
# Runs inside the test VM (tests/vm): the `scaled` daemon with the kernel's
# vivid camera as its V4L2 source and the gpio-sim chip "scaled-leds" as its
# status LEDs, queried over its socket with scalectl:
#   1. it starts, streams from vivid (STATUS names the card and the mode) and
#      the heartbeat LED blinks; its map's vertical comes from the kernel's
#      iio_dummy (patched into a 3-axis accelerometer) set to a known tilt;
#   2. vivid is unbound (the device disappears): SCALE says "fault" naming the
#      camera, the status LED blinks fast;
#   3. vivid is bound again: the daemon reopens it by card name, without a
#      restart (same pid), frames flow, STATUS counts one reconnect;
#   4. SIGTERM: exit 0 and the LED lines are released.
# Usage: daemon_vm_test.sh SCALED SCALECTL
# Waits are bounded polls of a condition (the daemon's replies, sysfs), each
# with a deadline; a failed wait prints what it saw.
set -euo pipefail

scaled=${1:?usage: daemon_vm_test.sh SCALED SCALECTL}
scalectl=${2:?usage: daemon_vm_test.sh SCALED SCALECTL}
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
shared=${SCALED_SHARED_DIR:-$repo/../shared}
model=$shared/models/yolox_nano.onnx

if [[ -z ${SCALED_VM:-} ]]; then
  echo "daemon_vm_test: not in the test VM (SCALED_VM unset); run it through tests/vm/run-vm.sh" >&2
  exit 77
fi
if [[ ! -f $model ]]; then
  # The detector runs the real network; without the model there is no daemon
  # to test (the harness shares ../shared when it exists).
  echo "daemon_vm_test: SKIP: $model is missing (set SCALED_SHARED_DIR)" >&2
  exit 77
fi

fail() {
  echo "daemon_vm_test: FAIL: $*" >&2
  [[ -f $work/scaled.err ]] && { echo "--- scaled's stderr:" >&2; tail -n 40 "$work/scaled.err" >&2; }
  exit 1
}

. "$here/daemon_lib.sh"

work=$(mktemp -d /tmp/daemon-vm.XXXXXX)
sock=$work/scaled.sock
export SCALED_SOCKET=$sock

# The gpio-sim chip: its sysfs values show what the daemon drives.
# gpiodetect prints `gpiochip0 [scaled-leds] (8 lines)`.
chip_dev=$(gpiodetect | awk '$2 == "[scaled-leds]" { print $1 }')
[[ -n $chip_dev ]] || fail "no gpio-sim chip labelled scaled-leds (the VM setup is broken)"
sim_dir=$(dirname "$(ls -d /sys/devices/platform/gpio-sim.*/"$chip_dev"/sim_gpio0)")
# Both levels of a blinking line within a window (bounded sampling). The
# value is read with a builtin (no fork: fast even under emulation), and the
# pause is not a divisor of the blink periods (200 ms, 1 s), so a loaded guest
# cannot alias the samples onto one level.
saw_both() { # saw_both LINE WINDOW_S
  local file=$sim_dir/sim_gpio$1/value end=$((SECONDS + $2)) seen0=0 seen1=0 v
  while ((SECONDS <= end)); do
    read -r v < "$file"
    if [[ $v == 1 ]]; then seen1=1; else seen0=1; fi
    ((seen0 && seen1)) && return 0
    sleep 0.037
  done
  return 1
}

# The IMU: the kernel's iio_dummy as fetch-kernel.sh patches it (a 3-axis
# accelerometer whose axes are written in mm/s^2), made through configfs
# (imu_vm_test may have made it in this boot already), reading what a camera
# pitched 30 degrees down measures with the IMU's axes on the camera's:
# f = -g (0, cos 30, sin 30) = (0, -8.493, -4.903) m/s^2.
scaled_imu 0 -8493 -4903

cat > "$work/scaled.toml" <<EOF
[source]
kind = "v4l2"
device = "vivid"
[camera]
width_px = 640
height_px = 480
fps = 30
pixel_format = "YUYV"
frame_timeout_s = 2
retry_initial_s = 0.2
retry_max_s = 1
fx_px = 525
fy_px = 525
cx_px = 319.5
cy_px = 239.5
[gpio]
chip = "scaled-leds"
status_line = 0
heartbeat_line = 1
[imu]
device = "scaled-imu"
rate_hz = 50
[detector]
model = "$model"
[detection]
period_s = 2
[estimator]
priors = "$repo/config/priors.toml"
[socket]
path = "$sock"
[log]
dir = "$work/log"
EOF

"$scaled" --config "$work/scaled.toml" --no-tty 2> "$work/scaled.err" &
pid=$!
trap 'kill "$pid" 2>/dev/null || true' EXIT

# 1. Streaming from vivid.
wait_reply 120 status 'j["frames"]["captured"] >= 10'
[[ $(field "$reply" source) == v4l2:vivid ]] || fail "source: $(field "$reply" source)"
[[ $(field "$reply" camera.device) == *vivid* ]] || fail "camera.device: $(field "$reply" camera.device)"
[[ $(field "$reply" camera.mode) == "YUYV 640x480"* ]] || fail "camera.mode: $(field "$reply" camera.mode)"
captured=$(field "$reply" frames.captured)
wait_reply 60 status "j['frames']['captured'] > $captured"
saw_both 1 8 || fail "the heartbeat LED (line 1) does not blink"
echo "daemon_vm_test: streaming: $(field "$reply" camera.device), $(field "$reply" camera.mode), $(field "$reply" frames.captured) frames"

# 1b. The map's vertical came from the IIO accelerometer.
wait_reply 60 status '"gravity_source" in j and j["imu"]["samples"] > 0'
[[ $(field "$reply" gravity_source) == "accelerometer (iio:device"*" [scaled-imu], "* ]] ||
  fail "gravity_source: $(field "$reply" gravity_source) (imu: $(field "$reply" imu))"
/usr/bin/python3 -c '
import json, math, sys
g = json.loads(sys.argv[1])["gravity_down_C"]
want = (0.0, math.cos(math.radians(30)), 0.5)
sys.exit(0 if max(abs(a - b) for a, b in zip(g, want)) < 1e-3 else 1)' "$reply" ||
  fail "gravity_down_C $(field "$reply" gravity_down_C), want (0, 0.866, 0.5)"
[[ -z $(field "$reply" imu.error) ]] || fail "imu.error: $(field "$reply" imu.error)"
echo "daemon_vm_test: imu: $(field "$reply" imu.device), $(field "$reply" imu.samples) samples; gravity $(field "$reply" gravity_down_C) from $(field "$reply" gravity_source)"

# 2. The camera disappears.
vivid_dev=$(basename "$(readlink -f /sys/bus/platform/drivers/vivid/vivid.0)")
echo "$vivid_dev" > /sys/bus/platform/drivers/vivid/unbind
wait_reply 30 get 'j["state"] == "fault" and "vivid" in j.get("fault", "")'
echo "daemon_vm_test: lost: $(field "$reply" fault)"
saw_both 0 6 || fail "the status LED (line 0) does not blink in the fault state"
kill -0 "$pid" || fail "scaled exited when the camera went away"

# 3. The camera returns: reopened by card name, same process.
echo "$vivid_dev" > /sys/bus/platform/drivers/vivid/bind
wait_reply 60 status 'j["camera"]["reconnects"] == 1 and not j["camera"]["lost"]'
captured=$(field "$reply" frames.captured)
wait_reply 60 status "j['frames']['captured'] > $captured + 5"
wait_reply 30 get 'j["state"] != "fault"'
echo "daemon_vm_test: back: state $(field "$reply" state), epoch $(field "$reply" epoch)"
kill -0 "$pid" || fail "scaled is not the same process"

# 4. A clean stop releases the lines.
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
trap - EXIT
((rc == 0)) || fail "scaled exited with $rc after SIGTERM"
grep -q "gpio: status LEDs on" "$work/scaled.err" || fail "no 'gpio: status LEDs on' line"
echo "daemon_vm_test: PASS"
