#!/usr/bin/env bash
# slam-run end to end on a synthetic sequence written by synth-render (so it
# runs without ../shared): trajectory file, JSON summary with ground-truth
# metrics, the same frames as a plain image folder (--camera, --fps), sysexits
# codes.
#   tests/cli/slam_run_cli.sh PATH/TO/slam-run PATH/TO/synth-render
set -euo pipefail
run=$1
render=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$render" --out "$tmp/seq" --frames 90 --seed 1 >/dev/null
json=$("$run" --dataset "$tmp/seq" --out "$tmp/traj.txt" --json --window 30 \
  --window-out "$tmp/window.csv")
python3 - "$json" "$tmp/traj.txt" "$tmp/window.csv" <<'PY' || fail "summary or trajectory does not meet the contract: $json"
import json, sys
d = json.loads(sys.argv[1])
for key in ("frames", "tracked_frames", "reinitialisations", "mean_features_measured",
            "ms_per_frame", "ate_rmse_m", "scale_to_gt", "scale_drift_thirds"):
    assert key in d, key
assert d["frames"] == 90 and d["tracked_frames"] == 90 and d["reinitialisations"] == 0, d
assert d["mean_features_measured"] > 20, d
assert d["ate_rmse_m"] < 0.01 * d["path_length_m"], d
rows = [l.split() for l in open(sys.argv[2]) if l.strip() and not l.startswith("#")]
assert len(rows) == 90 and all(len(r) == 8 for r in rows), len(rows)
# The map's scale over every window of 30 frames: 61 windows, the range is
# max/min of what the CSV holds, and a rendered room's map barely drifts.
w = d["window_scale"]
assert w["frames"] == 30 and w["windows"] == 61, w
lines = open(sys.argv[3]).read().splitlines()
assert lines[0] == "t_s,scale" and len(lines) == 62, lines[:3]
scales = [float(l.split(",")[1]) for l in lines[1:]]
assert abs(max(scales) / min(scales) - w["range"]) < 1e-3 * w["range"], (w, max(scales), min(scales))
assert 1 <= w["range"] < 1.2, w
nis = d["nis_by_feature_age"]
assert sum(nis["matches"]) > 1000 and all(0 < m < 9.21 for m in nis["mean"] if m), nis
# The filter's attitude against the truth: within 2 degrees on the rendered
# room (1.0 measured), its vertical (synth-render writes gravity.txt) within 1.
a = d["attitude_error_deg"]
assert 0 < a["final"] <= a["max"] < 2 and 0 < a["tilt_final"] <= a["tilt_max"] < 1, a
PY
set +e
err=$("$run" --dataset "$tmp/seq" --window 2 2>&1 >/dev/null); rc=$?
set -e
[[ $rc -eq 64 ]] || fail "--window 2: exit $rc ($err)"

# The window bundle adjustment (--set window_ba=true), with a window of 20
# keyframes (every 3rd frame), 10 fixed, an optimisation every 5 once 15 are
# in: 4 optimisations in 90 frames, reported, and the served trajectory stays
# as good as the filter's; a window with no free keyframe is refused.
json=$("$run" --dataset "$tmp/seq" --json --set window_ba=true --set window_ba_window_keyframes=20 \
  --set window_ba_fixed_keyframes=10 --set window_ba_step_keyframes=5)
python3 - "$json" <<'PY' || fail "--set window_ba=true does not adjust the window: $json"
import json, sys
d = json.loads(sys.argv[1])
ba = d["window_ba"]
assert ba["optimisations"] == 4 and ba["mean_points"] > 30 and ba["mean_rms_after_px"] < 1, ba
assert d["tracked_frames"] == 90 and d["ate_rmse_m"] < 0.01 * d["path_length_m"], d
PY
set +e
err=$("$run" --dataset "$tmp/seq" --set window_ba=true --set window_ba_fixed_keyframes=66 2>&1 >/dev/null); rc=$?
set -e
[[ $rc -ne 0 && $err == *"window_ba.fixed_keyframes"* ]] || fail "a window with no free keyframe: exit $rc ($err)"

# The gyro prior: nothing feeds it on a sequence without an IMU log; with
# --gyro-sim a gyro simulated from the ground truth feeds every frame but the
# map's first, and the bias estimate stays near the drawn bias's size.
python3 - "$json" <<'PY' || fail "no gyro expected: $json"
import json, sys
d = json.loads(sys.argv[1])
assert d["gyro_source"] == "none" and d["gyro_frames"] == 0, d
PY
json=$("$run" --dataset "$tmp/seq" --json --gyro-sim 2e-4:0.01 --frames 0:60)
python3 - "$json" <<'PY' || fail "--gyro-sim does not feed the gyro prior: $json"
import json, sys
d = json.loads(sys.argv[1])
assert d["gyro_source"].startswith("simulated gyro from ground truth (200 Hz"), d
assert d["gyro_frames"] == 59 and d["tracked_frames"] == 60 and d["reinitialisations"] == 0, d
assert len(d["gyro_bias_C_radps"]) == 3 and all(abs(b) < 0.05 for b in d["gyro_bias_C_radps"]), d
assert d["ate_rmse_m"] < 0.01 * d["path_length_m"], d
PY
for bad in x 1e-4 -1:0.01 1e-4:nan 5:0.01 1e-4:11; do
  set +e
  err=$("$run" --dataset "$tmp/seq" --gyro-sim "$bad" 2>&1 >/dev/null); rc=$?
  set -e
  [[ $rc -eq 64 && $err == *"--gyro-sim"* ]] || fail "--gyro-sim $bad: exit $rc ($err)"
done

# The first 30 rendered frames as a plain image folder: no index, no intrinsics.
mkdir "$tmp/folder"
cp "$tmp"/seq/rgb/0000[0-2][0-9].png "$tmp/folder/"
set +e
err=$("$run" --dataset "$tmp/folder" 2>&1 >/dev/null); rc=$?
set -e
[[ $rc -eq 65 && $err == *"$tmp/folder"* && $err == *"--camera FILE"* ]] ||
  fail "folder without intrinsics: exit $rc, message: $err"
json=$("$run" --dataset "$tmp/folder" --camera "$tmp/seq/camera.txt" --out "$tmp/folder.txt" --json)
python3 - "$json" "$tmp/folder.txt" <<'PY' || fail "folder run does not meet the contract: $json"
import json, sys
d = json.loads(sys.argv[1])
assert d["frames"] == 30 and d["tracked_frames"] == 30 and d["reinitialisations"] == 0, d
assert d["mean_features_measured"] > 20, d
assert "ate_rmse_m" not in d, d  # no ground truth in a plain folder
rows = [l.split() for l in open(sys.argv[2]) if l.strip() and not l.startswith("#")]
assert len(rows) == 30, len(rows)
assert abs(float(rows[1][0]) - 1 / 30) < 1e-6, rows[1]  # default 30 Hz
PY
# --fps times the frames; a camera.txt in the folder is found without --camera.
cp "$tmp/seq/camera.txt" "$tmp/folder/"
"$run" --dataset "$tmp/folder" --fps 15 --frames 0:10 --out "$tmp/folder15.txt" >/dev/null ||
  fail "folder with camera.txt and --fps 15"
python3 - "$tmp/folder15.txt" <<'PY' || fail "--fps 15 does not time the frames at 15 Hz"
import sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip() and not l.startswith("#")]
assert len(rows) == 10 and abs(float(rows[1][0]) - 1 / 15) < 1e-6, rows[:2]
PY

"$run" --help > "$tmp/help.txt" || fail "--help failed"  # a file: no SIGPIPE from grep -q
grep -q '^usage: slam-run' "$tmp/help.txt" || fail "--help does not print usage"
set +e
"$run" >/dev/null 2>&1; rc=$?
[[ $rc -eq 64 ]] || fail "no --dataset: exit $rc, expected 64"
err=$("$run" --dataset "$tmp/seq" --frames 5:x 2>&1 >/dev/null); rc=$?
[[ $rc -eq 64 && $err == *"5:x"* ]] || fail "--frames 5:x: exit $rc, message: $err"
err=$("$run" --dataset "$tmp/seq" --set no_such_key=1 2>&1 >/dev/null); rc=$?
[[ $rc -eq 64 && $err == *"no_such_key"* ]] || fail "--set unknown key: exit $rc, message: $err"
"$run" --dataset "$tmp/missing" >/dev/null 2>&1; rc=$?
[[ $rc -eq 66 ]] || fail "missing dataset: exit $rc, expected 66"
err=$("$run" --dataset "$tmp/folder" --camera "$tmp/none.txt" 2>&1 >/dev/null); rc=$?
[[ $rc -eq 66 && $err == *"none.txt"* ]] || fail "missing --camera file: exit $rc, message: $err"
echo "640 480 525" > "$tmp/short.txt"
err=$("$run" --dataset "$tmp/folder" --camera "$tmp/short.txt" 2>&1 >/dev/null); rc=$?
[[ $rc -eq 65 && $err == *"short.txt:1:"* ]] || fail "bad --camera file: exit $rc, message: $err"
err=$("$run" --dataset "$tmp/folder" --camera "$tmp/seq/camera.txt" --intrinsics 1,1,1,1 2>&1 >/dev/null); rc=$?
[[ $rc -eq 64 ]] || fail "--camera with --intrinsics: exit $rc, message: $err"
err=$("$run" --dataset "$tmp/folder" --fps 0 2>&1 >/dev/null); rc=$?
[[ $rc -eq 64 && $err == *"--fps"* ]] || fail "--fps 0: exit $rc, message: $err"
echo "bad line" >> "$tmp/seq/rgb.txt"
err=$("$run" --dataset "$tmp/seq" 2>&1 >/dev/null); rc=$?
[[ $rc -eq 65 && $err == *"rgb.txt:"* ]] || fail "malformed rgb.txt: exit $rc, message: $err"
set -e
echo "slam-run CLI ok"
