# Sourced by the daemon's guest tests (daemon_vm_test.sh, daemon_loop_vm_test.sh):
# what they share. They define fail() (prints why, exits 1), $scalectl, and,
# before wait_reply, $sock (the daemon's socket) and $pid (the daemon).

# python3 reads the JSON replies (the guest runs the host's /usr).
field() { # field JSON_LINE EXPR  -> prints j[EXPR...], e.g. field "$line" camera.mode
  /usr/bin/python3 -c '
import json, sys
v = json.loads(sys.argv[1])
for k in sys.argv[2].split("."):
    v = v.get(k) if isinstance(v, dict) else None
print("" if v is None else v)' "$1" "$2"
}

# Polls `scalectl CMD --json` until the python condition on its reply (j)
# holds, within SECONDS; the daemon must stay alive. The reply: $reply.
wait_reply() { # wait_reply SECONDS CMD CONDITION
  local end=$((SECONDS + $1)) line=""
  while ((SECONDS <= end)); do
    kill -0 "$pid" 2>/dev/null || fail "scaled exited while waiting for: $3"
    if line=$("$scalectl" --socket "$sock" --json --timeout 5 "$2" 2>/dev/null | head -n 1) &&
      [[ -n $line ]] &&
      /usr/bin/python3 -c 'import json,sys; j=json.loads(sys.argv[1]); sys.exit(0 if ('"$3"') else 1)' "$line"; then
      reply=$line
      return 0
    fi
    sleep 0.2
  done
  fail "no $2 reply with $3 within $1 s (last: ${line:-none})"
}

# The IMU: the kernel's iio_dummy as fetch-kernel.sh patches it (a 3-axis
# accelerometer whose axes are written in mm/s^2), made through configfs as
# "scaled-imu" (an earlier test of this boot may have made it already), set
# to read X Y Z (mm/s^2). Sets $imu_dir.
scaled_imu() { # scaled_imu X Y Z
  local cfg=/sys/kernel/config/iio/devices/dummy name
  [[ -d $cfg ]] || fail "no $cfg (iio_dummy not loaded: the VM setup is broken)"
  [[ -d $cfg/scaled-imu ]] || mkdir "$cfg/scaled-imu"
  name=$(grep -lx scaled-imu /sys/bus/iio/devices/iio:device*/name 2>/dev/null | head -n 1 || true)
  [[ -n $name ]] || fail "no IIO device named scaled-imu (iio_dummy's configfs made none)"
  imu_dir=$(dirname "$name")
  echo "$1" > "$imu_dir/in_accel_x_raw"
  echo "$2" > "$imu_dir/in_accel_y_raw"
  echo "$3" > "$imu_dir/in_accel_z_raw"
}
