#!/usr/bin/env bash
# field-log end to end: usage errors, a small hand-written log with a corrupt
# line and a partial last line (a crash), the CSV files in scale-eval's shape,
# objects.csv from OBJECT lines, poses.csv and the metric trajectories (TUM)
# from POSE lines (a malformed one named) and, with matplotlib, the figures.
#   tests/cli/field_log_cli.sh PATH/TO/field-log
set -euo pipefail
fl=$1
source "$(dirname "${BASH_SOURCE[0]}")/cli_lib.sh"

"$fl" --help > "$tmp/help.txt" || fail "--help failed"  # a file: no SIGPIPE from grep -q
grep -q '^usage: field-log' "$tmp/help.txt" || fail "--help does not print usage"
expect 64 "a log directory or file is required" -- "$fl"
expect 64 "unknown option --bogus" -- "$fl" x --bogus
expect 64 "--out needs a value" -- "$fl" x --out
expect 66 "$tmp/none: no such file or directory" -- "$fl" "$tmp/none"
mkdir "$tmp/empty"
expect 66 "no field log files" -- "$fl" "$tmp/empty"
printf 'garbage\n{"class":"FR' > "$tmp/junk.jsonl"
expect 65 "no readable line" -- "$fl" "$tmp/junk.jsonl"

# Two runs in two files; the second was killed in the middle of a line.
mkdir "$tmp/log"
f1="$tmp/log/scaled-20240101T000000Z-000001.jsonl"
f2="$tmp/log/scaled-20240101T001000Z-000002.jsonl"
cat > "$f1" <<'EOF'
{"class":"START","mono_ns":1000000000,"release":"0.1.0","source":"sim","config":"[log]\nenabled = true\n"}
{"class":"FRAME","mono_ns":1100000000,"frame_id":0,"t_ns":0,"epoch":0,"health":"ok","features":30,"tracked":20,"ms":3.5,"dropped":0}
{"class":"DETECTION","mono_ns":1200000000,"frame_id":0,"t_ns":0,"epoch":0,"latency_ms":80.5,"boxes":[{"class":"chair","score":0.9,"box":[1,2,3,4]}]}
{"class":"SCALE","mono_ns":1300000000,"frame_id":0,"t_ns":0,"epoch":0,"state":"tracking","scale":null,"mean":null,"ci68":null,"ci95":null,"observations":0,"new_observations":0,"detections":1,"obs":[]}
{"class":"SCALE","mono_ns":1400000000,"frame_id":5,"t_ns":166666666,"epoch":0,"state":"converging","scale":1.2,"mean":1.25,"ci68":[1.1,1.3],"ci95":[1.0,1.5],"observations":3,"new_observations":3,"detections":2,"obs":[{"class":"chair","D":0.5,"sigma_D":0.05,"local":1.2,"weight":1},{"class":"cup","D":0.08,"sigma_D":0.01,"local":1.1,"weight":0.5}]}
{"class":"OBJECT","mono_ns":1400000100,"frame_id":5,"t_ns":166666666,"epoch":0,"id":1,"object_class":"chair","state":"used","anchor":[0.5,-0.25,2],"anchor_rel_sigma":0.04,"detections":4,"views":4,"views_used":3,"first_frame":0,"last_frame":5,"local_estimate":1.2,"height_m":0.875,"height_ci95_m":[0.8,0.95]}
{"class":"OBJECT","mono_ns":1400000200,"frame_id":5,"t_ns":166666666,"epoch":0,"id":2,"object_class":"dining table, \"big\"","state":"tentative","anchor":null,"anchor_rel_sigma":null,"detections":1,"views":1,"views_used":0,"first_frame":5,"last_frame":5,"local_estimate":null,"height_m":null,"height_ci95_m":null}
this line is not JSON
{"class":"FRAME","mono_ns":1500000000,"frame_id":30,"t_ns":1000000000,"epoch":0,"health":"ok","features":35,"tracked":22,"ms":3.1,"dropped":0}
{"class":"POSE","mono_ns":1500000100,"frame_id":3,"t_ns":100000000,"epoch":0,"state":"tracking","scale":null,"scale_sigma":null,"position":null,"velocity":null,"position_cov":null,"orientation":[1,0,0,0],"position_map":[0.1,0,0],"attitude_cov":[[1e-05,0,0],[0,1e-05,0],[0,0,1e-05]],"velocity_map":[0,0,0],"position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]}
{"class":"POSE","mono_ns":1500000200,"frame_id":6,"t_ns":200000000,"epoch":0,"state":"converging","scale":1.2,"scale_sigma":0.1,"position":[0.24,0.12,-0.06],"velocity":[0,0,0],"position_cov":[[0.0004,0,0],[0,0.0009,0],[0,0,0.0016]],"orientation":[0.5,-0.5,0.5,-0.5],"position_map":[0.2,0.1,-0.05],"attitude_cov":[[1e-05,0,0],[0,1e-05,0],[0,0,1e-05]],"velocity_map":[0,0,0],"position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]}
{"class":"POSE","mono_ns":1500000300,"frame_id":9,"t_ns":300000000,"epoch":0,"state":"converging","scale":1.2,"scale_sigma":0.1,"position":[0.36,0.12,-0.06],"velocity":[0,0,0],"position_cov":[[0.0004,0,0],[0,0.0009,0],[0,0,0.0016]],"orientation":[1,0,0,0],"position_map":[0.3,0.1,-0.05],"attitude_cov":[[1e-05,0,0],[0,1e-05,0],[0,0,1e-05]],"velocity_map":[0,0,0],"position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]}
{"class":"POSE","mono_ns":1500000400,"frame_id":12,"t_ns":400000000,"epoch":0,"state":"converging","scale":1.2,"position":[0.36,0.12],"orientation":[1,0,0,0],"position_map":[0.3,0.1,-0.05]}
{"class":"STOP","mono_ns":1600000000,"reason":"SIGTERM"}
EOF
cat > "$f2" <<'EOF'
{"class":"START","mono_ns":5000000000,"release":"0.1.0","source":"sim","config":""}
{"class":"STATE","mono_ns":5100000000,"from":"initialising","to":"tracking","epoch":0,"frame_id":0,"reason":"map"}
{"class":"SCALE","mono_ns":5200000000,"frame_id":45,"t_ns":1500000000,"epoch":0,"state":"converged","scale":1.21,"mean":1.22,"ci68":[1.18,1.24],"ci95":[1.15,1.27],"observations":9,"new_observations":6,"detections":2,"obs":[{"class":"chair","D":0.5,"sigma_D":0.05,"local":1.2,"weight":1}]}
{"class":"OBJECT","mono_ns":5200000100,"frame_id":45,"t_ns":1500000000,"epoch":0,"id":1,"object_class":"chair","state":"anchored","anchor":[1,2,3],"anchor_rel_sigma":0.3,"detections":2,"views":2,"views_used":0,"first_frame":30,"last_frame":45,"local_estimate":null,"height_m":null,"height_ci95_m":null}
{"class":"OBJECT","mono_ns":5200000200,"frame_id":46,"t_ns":1533333333,"epoch":0,"id":2,"object_class":"cup","state":"tentative","anchor":null,"anchor_rel_sigma":null,"detections":1,"views":1,"views_used":0,"first_frame":46,"last_frame":46,"local_estimate":null,"height_m":null,"height_ci95_m":null}
{"class":"ERROR","mono_ns":5300000000,"where":"detector","message":"slow"}
{"class":"POSE","mono_ns":5300000100,"frame_id":50,"t_ns":1666666667,"epoch":0,"state":"converged","scale":1.21,"scale_sigma":0.03,"position":[1,2,0.5],"velocity":[0,0,0],"position_cov":[[0.0004,0,0],[0,0.0009,0],[0,0,0.0016]],"orientation":[1,0,0,0],"position_map":[0.8264463,1.652893,0.4132231],"attitude_cov":[[1e-05,0,0],[0,1e-05,0],[0,0,1e-05]],"velocity_map":[0,0,0],"position_map_cov":[[1e-06,0,0],[0,1e-06,0],[0,0,1e-06]]}
{"class":"FRAME","mono_ns":5400000000,"frame_id":60,"t_ns":2000000000,"epoch":0,"health":"lost","features":35,"tracked":0,"ms":3.1,"dropped":1}
EOF
printf '{"class":"SCALE","mono_ns":55000' >> "$f2"

"$fl" "$tmp/log" --json --out "$tmp/out" --no-plots > "$tmp/s.json" 2> "$tmp/s.err" \
    || fail "field-log failed: $(cat "$tmp/s.err")"
grep -q "$f1:8: not a JSON object" "$tmp/s.err" || fail "corrupt line not reported: $(cat "$tmp/s.err")"
grep -q "$f2:9: last line has no newline" "$tmp/s.err" || fail "partial line not reported"
grep -q "$f1:13: POSE position is neither null nor \[x,y,z\] (skipped)" "$tmp/s.err" \
    || fail "malformed POSE line not reported: $(cat "$tmp/s.err")"
py=/usr/bin/python3
[[ -x $py ]] || py=python3
"$py" - "$tmp/s.json" "$tmp/out" <<'PY' || fail "summary or CSV check failed"
import csv, json, os, sys
lines = open(sys.argv[1]).read().splitlines()
assert len(lines) == 1, "stdout must be one JSON line"
j = json.loads(lines[0])
assert j == json.load(open(os.path.join(sys.argv[2], "summary.json"))), "summary.json differs"
assert j["files"] == 2 and j["lines"] == 21, j
assert j["corrupt_lines"] == 1 and j["partial_lines"] == 1, j
assert j["runs"] == 2 and j["stops"] == 1 and j["last_stop_reason"] == "SIGTERM", j
assert j["epochs"] == 2 and j["updates"] == 3 and j["frames_logged"] == 3, j
assert j["errors"] == 1 and j["last_error"] == "detector: slow", j
assert j["classes"]["SCALE"] == 3 and j["boxes"] == 1, j
assert j["classes"]["OBJECT"] == 4 and j["objects_logged"] == 4, j
assert j["classes"]["POSE"] == 5 and j["poses_logged"] == 4 and j["metric_poses_logged"] == 3, j
assert j["bad_fields"] == 1, j
assert j["trajectory_metric"] == "trajectory_metric_run1_epoch0.tum", j
assert [(t["file"], t["poses"]) for t in j["trajectories"]] == [
    ("trajectory_metric_run1_epoch0.tum", 2), ("trajectory_metric_run2_epoch0.tum", 1)], j
assert abs(j["time_span_s"] - 0.6 - 0.4) < 1e-9, j["time_span_s"]
ls = j["last_scale"]
assert ls["scale"] == 1.21 and ls["ci95"] == [1.15, 1.27] and ls["state"] == "converged", ls
def rows(name):
    with open(os.path.join(sys.argv[2], name), newline="") as f:
        r = list(csv.reader(f))
    assert all(len(x) == len(r[0]) for x in r), name + ": ragged rows"
    return [dict(zip(r[0], x)) for x in r[1:]]
u = rows("updates.csv")
assert [x["frame"] for x in u] == ["0", "5", "45"], u
assert u[0]["scale_est"] == "" and u[1]["scale_est"] == "1.2" and u[2]["converged"] == "1", u
assert u[1]["ci95_lo"] == "1" and u[1]["ci95_hi"] == "1.5" and u[2]["total_observations"] == "9", u
assert all(x["scale_true"] == "" and x["rel_error"] == "" for x in u), "truth columns must be empty"
fr = rows("frames.csv")
assert [x["frame"] for x in fr] == ["0", "30", "60"], fr
assert fr[1]["scale_est"] == "1.2" and fr[1]["state"] == "converging", fr[1]
assert fr[2]["tracked"] == "0" and fr[2]["scale_est"] == "1.21", fr[2]
o = rows("observations.csv")
assert [x["class"] for x in o] == ["chair", "cup", "chair"] and o[1]["D"] == "0.08", o
ob = rows("objects.csv")
assert [(x["update"], x["frame"], x["id"], x["run"]) for x in ob] == [
    ("1", "5", "1", "1"), ("1", "5", "2", "1"), ("2", "45", "1", "2"), ("", "46", "2", "2")], ob
assert ob[0]["class"] == "chair" and ob[0]["state"] == "used" and ob[0]["views_used"] == "3", ob[0]
assert ob[0]["local_estimate"] == "1.2" and ob[0]["height_m"] == "0.875", ob[0]
assert ob[0]["height_ci95_lo_m"] == "0.8" and ob[0]["height_ci95_hi_m"] == "0.95", ob[0]
assert (ob[0]["anchor_x"], ob[0]["anchor_y"], ob[0]["anchor_z"]) == ("0.5", "-0.25", "2"), ob[0]
assert ob[0]["anchor_rel_sigma"] == "0.04" and ob[0]["t_s"] == "0.166666666", ob[0]
assert ob[1]["class"] == 'dining table, "big"' and ob[1]["state"] == "tentative", ob[1]
assert ob[1]["anchor_x"] == "" and ob[1]["height_m"] == "" and ob[1]["local_estimate"] == "", ob[1]
assert ob[2]["state"] == "anchored" and ob[2]["anchor_z"] == "3" and ob[2]["epoch"] == "0", ob[2]
p = rows("poses.csv")
assert [(x["frame"], x["epoch"], x["run"]) for x in p] == [
    ("3", "0", "1"), ("6", "0", "1"), ("9", "0", "1"), ("50", "0", "2")], p
assert p[0]["x_m"] == "" and p[0]["sigma_x_m"] == "" and p[0]["scale"] == "", p[0]
assert p[0]["x_map"] == "0.1" and p[0]["state"] == "tracking", p[0]
assert (p[1]["t_s"], p[1]["x_m"], p[1]["y_m"], p[1]["z_m"]) == ("0.2", "0.24", "0.12", "-0.06"), p[1]
assert (p[1]["sigma_x_m"], p[1]["sigma_y_m"], p[1]["sigma_z_m"]) == ("0.02", "0.03", "0.04"), p[1]
assert p[1]["scale"] == "1.2" and p[3]["scale"] == "1.21", p
def tum(name):
    with open(os.path.join(sys.argv[2], name)) as f:
        return [l.split() for l in f if not l.startswith("#")]
t1 = tum("trajectory_metric_run1_epoch0.tum")
assert t1 == [["0.200000", "0.240000000", "0.120000000", "-0.060000000",
               "-0.500000000", "0.500000000", "-0.500000000", "0.500000000"],
              ["0.300000", "0.360000000", "0.120000000", "-0.060000000",
               "0.000000000", "0.000000000", "0.000000000", "1.000000000"]], t1
assert tum("trajectory_metric.tum") == t1
assert tum("trajectory_metric_run2_epoch0.tum")[0][:4] == [
    "1.666667", "1.000000000", "2.000000000", "0.500000000"]
for c in ("frame", "t_s", "tracked", "epoch", "features_measured", "scale_est", "ci95_lo",
          "ci95_hi", "state", "scale_true", "rel_error", "baseline_single_rel_error"):
    assert c in fr[0], c
PY

# Text summary on stdout without --json.
"$fl" "$f1" 2>/dev/null | grep -q "last scale 1.2 m/unit" || fail "text summary"
"$fl" "$f1" 2>/dev/null | grep -q "2 scale updates, 2 object lines, 3 pose lines (2 metric), 0 errors" \
    || fail "text: objects and poses"

# The figures (figures (c) and (d): a field log has no posterior curves).
if "$py" -c 'import matplotlib, numpy' 2>/dev/null; then
    SCALED_PYTHON=$py "$fl" "$tmp/log" --out "$tmp/fig" > /dev/null 2> "$tmp/fig.err" \
        || fail "field-log with figures failed: $(cat "$tmp/fig.err")"
    for f in fig_c_estimates.png fig_d_rel_error.png fig_g_trajectory.png; do
        [[ -s "$tmp/fig/$f" ]] || fail "$f not written"
    done
else
    echo "SKIP figures: python3 matplotlib/numpy not installed"
fi
# A python that cannot run: exit 69, CSV files kept.
set +e
SCALED_PYTHON=/nonexistent/python "$fl" "$tmp/log" --out "$tmp/nopy" > /dev/null 2> "$tmp/nopy.err"
rc=$?
set -e
[[ $rc -eq 69 ]] || fail "missing python: exit $rc, expected 69"
[[ -s "$tmp/nopy/updates.csv" ]] || fail "CSV files not kept when plotting fails"
echo "field-log CLI: ok"
