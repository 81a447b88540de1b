#!/usr/bin/env bash
# Runs inside the test VM (tests/vm): the whole product on real kernel drivers
# with real pixels. vivid_feed plays the first FRAMES frames of redkitchen
# (../shared) into vivid's HDMI output, looped to its HDMI capture; the
# `scaled` daemon captures them through its V4L2 source, takes its map's
# vertical from the kernel's iio_dummy (a 3-axis accelerometer, set to the
# dataset's gravity at the first frame), detects with the real YOLOX-Nano and
# serves its scale over the socket. Then the same frames are replayed from
# disk by the same daemon (fast, lossless) for the bound.
#   1. the feeder holds the first frame (a camera at rest) until the daemon
#      captures, then plays every frame once at FPS (the emulated CPU cannot
#      track 30 per second: the motion between frames is the sequence's, the
#      time between them longer);
#   2. the map starts with the accelerometer's vertical; the daemon reaches
#      at least one scale update and serves it (scalectl get);
#   3. frames played, captured, tracked and dropped are printed;
#   4. the looped run's scale (MAP) lies inside the replay run's 95% interval
#      at the same frame count, and the replay's inside the looped run's.
# Usage: daemon_loop_vm_test.sh SCALED SCALECTL VIVID_FEED
# Waits are bounded polls of a condition, each with a deadline.
set -euo pipefail

scaled=${1:?usage: daemon_loop_vm_test.sh SCALED SCALECTL VIVID_FEED}
scalectl=${2:?usage}
feed=${3:?usage}
frames=${SCALED_LOOP_FRAMES:-300}
fps=${SCALED_LOOP_FPS:-5}
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
shared=${SCALED_SHARED_DIR:-$repo/../shared}
model=$shared/models/yolox_nano.onnx
data=$shared/data/redkitchen

if [[ -z ${SCALED_VM:-} ]]; then
  echo "daemon_loop_vm_test: not in the test VM (SCALED_VM unset); run it through tests/vm/run-vm.sh" >&2
  exit 77
fi
for f in "$model" "$data/rgb.txt"; do
  if [[ ! -f $f ]]; then
    echo "daemon_loop_vm_test: SKIP: $f is missing (set SCALED_SHARED_DIR)" >&2
    exit 77
  fi
done

work=$(mktemp -d /tmp/daemon-loop.XXXXXX)
pid=""
feed_pid=""
fail() {
  echo "daemon_loop_vm_test: FAIL: $*" >&2
  for f in scaled.err feed.out feed.err replay.err; do
    [[ -s $work/$f ]] && { echo "--- $f:" >&2; tail -n 30 "$work/$f" >&2; }
  done
  exit 1
}
cleanup() {
  [[ -n $pid ]] && kill "$pid" 2>/dev/null
  [[ -n $feed_pid ]] && kill "$feed_pid" 2>/dev/null
  return 0
}
trap cleanup EXIT

# python3 reads the JSON replies (the guest runs the host's /usr).
field() { # field JSON_LINE EXPR  -> prints j[EXPR...], e.g. field "$line" frames.captured
  /usr/bin/python3 -c '
import json, sys
v = json.loads(sys.argv[1])
for k in sys.argv[2].split("."):
    v = v.get(k) if isinstance(v, dict) else None
print("" if v is None else v)' "$1" "$2"
}
# Polls `scalectl CMD --json` on SOCKET until the python condition on its
# reply (j) holds; the process PID must stay alive.
wait_reply() { # wait_reply SECONDS SOCKET PID CMD CONDITION
  local end=$((SECONDS + $1)) line=""
  while ((SECONDS <= end)); do
    kill -0 "$3" 2>/dev/null || fail "scaled exited while waiting for: $5"
    if line=$("$scalectl" --socket "$2" --json --timeout 5 "$4" 2>/dev/null | head -n 1) &&
      [[ -n $line ]] &&
      /usr/bin/python3 -c 'import json,sys; j=json.loads(sys.argv[1]); sys.exit(0 if ('"$5"') else 1)' "$line"; then
      reply=$line
      return 0
    fi
    sleep 0.5
  done
  fail "no $4 reply with $5 within $1 s (last: ${line:-none})"
}

# The IMU: iio_dummy (fetch-kernel.sh's 3-axis patch) reading what the
# camera's accelerometer reads at the first frame, IMU axes on the camera's:
# f = -g down_C, in mm/s^2.
dummy_cfg=/sys/kernel/config/iio/devices/dummy
[[ -d $dummy_cfg ]] || fail "no $dummy_cfg (iio_dummy not loaded: the VM setup is broken)"
[[ -d $dummy_cfg/scaled-imu ]] || mkdir "$dummy_cfg/scaled-imu"
imu_dir=$(dirname "$(grep -lx scaled-imu /sys/bus/iio/devices/iio:device*/name | head -n 1)")
[[ -d $imu_dir ]] || fail "no IIO device named scaled-imu"
read -r _ gx gy gz < <("$feed" gravity "$data") || fail "vivid_feed gravity $data"
raw() { /usr/bin/python3 -c "print(round(-9806.65 * $1))"; }
echo "$(raw "$gx")" > "$imu_dir/in_accel_x_raw"
echo "$(raw "$gy")" > "$imu_dir/in_accel_y_raw"
echo "$(raw "$gz")" > "$imu_dir/in_accel_z_raw"
echo "daemon_loop_vm_test: dataset gravity at frame 0: $gx $gy $gz"

# The sequence plays 30/FPS times slower than it was recorded, and the
# tracker's motion model is in seconds: its accelerations, scaled by
# (FPS/30)^2, make the slow playback the same process as the recording
# (measured on the host: redkitchen's first 150 frames stamped 0.25 s apart
# track 60 of 150 frames with 6 new maps at the default noise, all 150 in one
# map with it scaled). The replay run below uses the recording's own times
# and the default noise.
read -r sigma_a sigma_alpha < <(/usr/bin/python3 -c "
k = ($fps / 30.0) ** 2
print('%.6g %.6g' % (8 * k, 1 * k))")

# One configuration for both runs; the source differs.
write_config() { # write_config FILE SOCKET LOGDIR
  cat > "$1" <<EOF
[source]
kind = "v4l2"
device = "vivid"
[camera]
width_px = 640
height_px = 480
fps = 60
pixel_format = "YUYV"
frame_timeout_s = 10
retry_initial_s = 0.5
retry_max_s = 2
fx_px = 585
fy_px = 585
cx_px = 320
cy_px = 240
[tracker]
sigma_a = $sigma_a
sigma_alpha = $sigma_alpha
[imu]
device = "scaled-imu"
rate_hz = 50
[detector]
model = "$model"
[estimator]
priors = "$repo/config/priors.toml"
[socket]
path = "$2"
[log]
dir = "$3"
EOF
}

# 1. The feeder sets both sides up and holds the first frame; then the daemon.
hold=$work/hold
"$feed" play "$data" "$frames" "$fps" "$hold" "$work/stop" > "$work/feed.out" 2> "$work/feed.err" &
feed_pid=$!
end=$((SECONDS + 120))
until grep -q '^streaming' "$work/feed.out"; do
  kill -0 "$feed_pid" 2>/dev/null || fail "vivid_feed exited before streaming"
  ((SECONDS <= end)) || fail "vivid_feed is not streaming after 120 s"
  sleep 0.2
done
write_config "$work/loop.toml" "$work/loop.sock" "$work/loop-log"
"$scaled" --config "$work/loop.toml" --no-tty 2> "$work/scaled.err" &
pid=$!
wait_reply 180 "$work/loop.sock" "$pid" status 'j["frames"]["captured"] >= 10'
[[ $(field "$reply" camera.mode) == "YUYV 640x480"* ]] || fail "camera.mode: $(field "$reply" camera.mode)"
touch "$hold"
echo "daemon_loop_vm_test: playing: $(field "$reply" camera.device), $(field "$reply" camera.mode)"

# 2. The map's vertical is the accelerometer's.
wait_reply 60 "$work/loop.sock" "$pid" status '"gravity_source" in j'
[[ $(field "$reply" gravity_source) == "accelerometer (iio:device"*"[scaled-imu]"* ]] ||
  fail "gravity_source: $(field "$reply" gravity_source)"

# The whole sequence played (the feeder paces itself: FRAMES / FPS seconds).
end=$((SECONDS + frames / fps * 4 + 120))
until grep -q '^played' "$work/feed.out"; do
  kill -0 "$feed_pid" 2>/dev/null || fail "vivid_feed exited while playing"
  ((SECONDS <= end)) || fail "vivid_feed still playing after $((frames / fps * 4 + 120)) s: $(tail -n 1 "$work/feed.out")"
  sleep 0.5
done
echo "daemon_loop_vm_test: $(grep '^played' "$work/feed.out")"
# The daemon works through what it captured (its queue), then reports.
wait_reply 300 "$work/loop.sock" "$pid" status \
  'j["frames"]["captured"] == j["frames"]["tracked"] + j["frames"]["dropped"] and j["detector"]["runs"] > 0'
status=$reply
"$scalectl" --socket "$work/loop.sock" --json get > "$work/loop.scale" ||
  fail "scalectl get failed"
loop=$(head -n 1 "$work/loop.scale")
echo "daemon_loop_vm_test: looped: captured $(field "$status" frames.captured), tracked $(field "$status" frames.tracked), dropped $(field "$status" frames.dropped), epoch $(field "$status" epoch), updates $(field "$status" scale_updates), detector $(field "$status" detector.runs) runs, $(field "$status" fps) fps"
echo "daemon_loop_vm_test: looped scale: $loop"
[[ $(field "$loop" observations) -ge 1 ]] || fail "no scale update served: $loop"
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
pid=""
((rc == 0)) || fail "scaled exited with $rc after SIGTERM"
touch "$work/stop"
feed_rc=0
wait "$feed_pid" || feed_rc=$?
feed_pid=""
((feed_rc == 0)) || fail "vivid_feed exited with $feed_rc"

# 4. The same frames replayed from disk by the same daemon (lossless), up to
#    the frames the loop tracked in its last epoch.
write_config "$work/replay.toml" "$work/replay.sock" "$work/replay-log"
"$scaled" --config "$work/replay.toml" --no-tty --source "replay:$data" --pacing fast \
  --set source.at_end=\"stay\" --set "source.max_frames=$frames" --set imu.device=\"\" \
  --set tracker.sigma_a=8 --set tracker.sigma_alpha=1 \
  2> "$work/replay.err" &
pid=$!
wait_reply 900 "$work/replay.sock" "$pid" status 'j["source_finished"] and j["frames"]["tracked"] > 0'
"$scalectl" --socket "$work/replay.sock" --json get > "$work/replay.scale" || fail "scalectl get (replay)"
replay=$(head -n 1 "$work/replay.scale")
echo "daemon_loop_vm_test: replayed scale: $replay"
kill -TERM "$pid"
wait "$pid" || true
pid=""
/usr/bin/python3 - "$loop" "$replay" <<'EOF' || fail "the looped scale is not the replay's (see above)"
import json, sys
loop, replay = (json.loads(a) for a in sys.argv[1:3])
def inside(a, b):  # a's MAP inside b's 95% interval
    return a.get("scale") is not None and b.get("ci95") is not None and \
        b["ci95"][0] <= a["scale"] <= b["ci95"][1]
print("looped %s %s (%s obs), replayed %s %s (%s obs)" % (
    loop.get("scale"), loop.get("ci95"), loop.get("observations"),
    replay.get("scale"), replay.get("ci95"), replay.get("observations")))
sys.exit(0 if inside(loop, replay) and inside(replay, loop) else 1)
EOF
echo "daemon_loop_vm_test: PASS"
