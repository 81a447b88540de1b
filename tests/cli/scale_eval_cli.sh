#!/usr/bin/env bash
# scale-eval end to end: sysexits codes and messages for bad input (runs
# anywhere), and with ../shared present: redkitchen frames 0-199 (clean JSON
# on stdout, the CSV files and, with matplotlib, the figures) and TUM fr3
# office (16 nearly static frames: no convergence, no scale claimed).
#   tests/cli/scale_eval_cli.sh PATH/TO/scale-eval SHARED_DIR
set -euo pipefail
ev=$1
shared=${SCALED_SHARED_DIR:-$2}
source "$(dirname "${BASH_SOURCE[0]}")/cli_lib.sh"

# Into a file: grep -q would close the pipe before a long help ends (SIGPIPE).
"$ev" --help > "$tmp/help.txt" || fail "--help failed"
grep -q '^usage: scale-eval' "$tmp/help.txt" || fail "--help does not print usage"
expect 64 "--dataset is required" -- "$ev"
expect 64 "unknown option --bogus" -- "$ev" --bogus 1
expect 64 "bad value for --frames: '9:3'" -- "$ev" --dataset x --frames 9:3
expect 64 "bad value for --format: 'avi'" -- "$ev" --dataset x --format avi
printf '[estimator]\nrobust = true\nvariance = "exact"\n' > "$tmp/bad.toml"
expect 78 "$tmp/bad.toml:3: estimator.variance: must be one of \"paper\", \"propagated\" (got \"exact\")" \
    -- "$ev" --dataset x --config "$tmp/bad.toml"
expect 66 "$tmp/none.toml: cannot read configuration: no such file" -- "$ev" --dataset x --config "$tmp/none.toml"
expect 78 "--set detection.every_frames=0: detection.every_frames: must be an integer in [1, 100000] (got 0)" \
    -- "$ev" --dataset x --set detection.every_frames=0
expect 66 "$tmp/p.toml: cannot open priors file" -- "$ev" --dataset x --set "estimator.priors=$tmp/p.toml"
printf 'version = 1\n[classes.cup]\nupright = true\nsource = "x"\nmean_m = 0.1\nstd_m = 0.02\nmin_m = 0.05\nmax_m = 0.2\npartial_probability = 1.5\n' > "$tmp/p.toml"
expect 78 "$tmp/p.toml:9: classes.cup.partial_probability: must be in [0, 1) (got 1.5)" \
    -- "$ev" --dataset x --set "estimator.priors=$tmp/p.toml"
expect 66 "$tmp/none" -- "$ev" --dataset "$tmp/none"
# --camera: a missing file, one that does not parse, and with --intrinsics.
expect 66 "scale-eval: --camera: $tmp/nocam.txt" -- "$ev" --dataset x --camera "$tmp/nocam.txt"
printf '640 480 500\n' > "$tmp/short.txt"
expect 65 "$tmp/short.txt:1:" -- "$ev" --dataset x --camera "$tmp/short.txt"
expect 64 "give --camera or --intrinsics, not both" -- "$ev" --dataset x --camera "$tmp/short.txt" --intrinsics 1,1,1,1
model="$shared/models/yolox_nano.onnx"
rk="$shared/data/redkitchen"
tum="$shared/data/tum-fr3-office"
# Images that do not match camera.txt: the reason and the file, not only "no
# frame could be read" (issue 22). scale-eval loads the model first, so this
# needs the model (without it: exit 66, model not found).
if [[ -f "$model" ]]; then
    mkdir -p "$tmp/mismatch"
    printf '# width height fx fy cx cy\n640 480 500 500 320 240\n' > "$tmp/mismatch/camera.txt"
    for k in 0 1 2; do
        { printf 'P5\n32 24\n255\n'; head -c 768 /dev/zero; } > "$tmp/mismatch/$k.pgm"
    done
    expect 65 "no frame could be read (3 unreadable; the first: $tmp/mismatch/0.pgm: image is 32x24 but the intrinsics are for 640x480)" \
        -- "$ev" --dataset "$tmp/mismatch"
    # --camera overrides the dataset's camera.txt (with distortion): the same
    # frames are read.
    printf '32 24 30 30 16 12 -0.1 0.03\n' > "$tmp/small.txt"
    "$ev" --dataset "$tmp/mismatch" --camera "$tmp/small.txt" --json > "$tmp/small.json" 2> "$tmp/small.err" \
        || fail "--camera run failed: $(cat "$tmp/small.err")"
    grep -q '"frames":3,' "$tmp/small.json" || fail "--camera run: not 3 frames: $(head -c 300 "$tmp/small.json")"
else
    echo "SKIP unreadable-frames part: $model not found (set SCALED_SHARED_DIR)"
fi
if [[ ! -f "$model" || ! -d "$rk" || ! -d "$tum" ]]; then
    echo "SKIP real-data part: $model, $rk or $tum not found (set SCALED_SHARED_DIR)"
    exit 0
fi
py=/usr/bin/python3
[[ -x $py ]] || py=python3

# redkitchen, 200 frames: one clean JSON object on stdout, files in --out
# (the paper model: it has observations this early; the object model's
# outputs are checked by scale_eval_objects_cli.sh).
paper=(--set estimator.model=paper)
"$ev" --dataset "$rk" --frames 0:200 "${paper[@]}" --json --out "$tmp/rk" --no-plots > "$tmp/rk.json" 2> "$tmp/rk.err" \
    || fail "redkitchen run failed: $(cat "$tmp/rk.err")"
"$py" - "$tmp/rk.json" "$tmp/rk" <<'PY' || fail "redkitchen JSON or CSV check failed"
import csv, json, sys
lines = open(sys.argv[1]).read().splitlines()
assert len(lines) == 1, "stdout must be one JSON line, got %d lines" % len(lines)
j = json.loads(lines[0])
for key in ("scale_true", "scale_est", "rel_error", "converged_at_frame", "distance_errors",
            "baselines", "updates", "frames", "tracking_lost_frames", "ms_per_frame",
            "scale_true_window", "depth_check"):
    assert key in j, key
assert j["frames"] == 200 and j["tracking_lost_frames"] == 0, j
assert j["updates"] == 14, j["updates"]  # frames 60, 70, ..., 190 (none in the map's first 2 s)
assert 0.5 < j["scale_true"] < 2, j["scale_true"]
assert j["baselines"]["constant"]["scale"] is not None
assert j["baselines"]["single_detection"]["scale"] is not None
frames = list(csv.DictReader(open(sys.argv[2] + "/frames.csv")))
updates = list(csv.DictReader(open(sys.argv[2] + "/updates.csv")))
obs = list(csv.DictReader(open(sys.argv[2] + "/observations.csv")))
assert len(frames) == 200 and len(updates) == 14, (len(frames), len(updates))
assert len(obs) == j["observations"] > 0
post = open(sys.argv[2] + "/posterior.csv").read().splitlines()
assert len(post) == 15 and len(post[0].split(",")) == 2 + 256, (len(post), len(post[0].split(",")))
assert "[estimator]" in open(sys.argv[2] + "/config.toml").read()
json.loads(open(sys.argv[2] + "/summary.json").read())
PY
# Deterministic: a second run gives the same estimates, also while it reads
# the depth images for the map's geometric unit (--depth-unit).
"$ev" --dataset "$rk" --frames 0:200 "${paper[@]}" --out "$tmp/rk2" --no-plots --depth-unit --json \
    > "$tmp/rk2.json" 2> /dev/null || fail "the --depth-unit run failed"
cmp -s "$tmp/rk/updates.csv" "$tmp/rk2/updates.csv" || fail "two runs gave different updates.csv"
"$py" - "$tmp/rk2.json" "$tmp/rk2" "$tmp/rk.json" <<'PY' || fail "--depth-unit check failed"
import csv, json, sys
j = json.loads(open(sys.argv[1]).read())
assert "map_unit_depth" not in json.loads(open(sys.argv[3]).read())  # only when asked
g = j["map_unit_depth"]
# Every tracked frame after the first has measured features over the depth image.
assert g["frames"] >= 190, g
# The geometry's unit and the motion's agree within a factor of two.
assert 0.5 < g["median"] / j["scale_true"] < 2, (g, j["scale_true"])
assert g["window_range"] >= 1 and g["motion_over_geometry_range"] >= 1, g
frames = list(csv.DictReader(open(sys.argv[2] + "/frames.csv")))
values = [float(f["map_unit_depth"]) for f in frames if f["map_unit_depth"]]
assert len(values) == g["frames"] and all(v > 0 for v in values), (len(values), g)
PY

# The figures, where matplotlib is installed.
if "$py" -c 'import matplotlib, numpy' 2> /dev/null; then
    PATH="$(dirname "$py"):$PATH" "$ev" --dataset "$rk" --frames 0:200 "${paper[@]}" --out "$tmp/fig" --json \
        > "$tmp/fig.json" 2> "$tmp/fig.err" || fail "figures: $(cat "$tmp/fig.err")"
    for f in fig_a_likelihoods fig_b_posterior fig_c_estimates fig_d_rel_error; do
        head -c 8 "$tmp/fig/$f.png" | od -An -tx1 | grep -q '89 50 4e 47' || fail "$f.png is not a PNG"
    done
    [[ $(wc -l < "$tmp/fig.json") -eq 1 ]] || fail "the plotting script wrote to stdout"
else
    echo "SKIP figures: python3-matplotlib not installed"
fi

# Experiment 1 of docs/accuracy.md (issue 5): the whole sequence with the
# paper model, its issue-5 defaults and the COCO priors converges, with a
# median relative error of at most 3% (on this seed; issue 18's ablation
# shows its intervals excluding the truth on others). Measured in the
# filter's map, as then (in the served map its 95% width ends at 10.6%, just
# short of "converged", 1.0% off).
"$ev" --dataset "$rk" "${paper[@]}" --set estimator.map=filter --json > "$tmp/exp1.json" 2> "$tmp/exp1.err" || fail "experiment 1: $(cat "$tmp/exp1.err")"
"$py" - "$tmp/exp1.json" <<'PY' || fail "experiment 1 check failed"
import json, sys
j = json.loads(open(sys.argv[1]).read())
assert j["frames"] == 600 and j["converged"], j
print("experiment 1: converged at frame %d, median %.2f%%" % (j["converged_at_frame"], 100 * j["rel_error"]["median"]))
assert j["rel_error"]["median"] <= 0.03, j["rel_error"]
PY

# TUM fr3 office: 16 frames, nearly static. Runs, no convergence, no scale.
"$ev" --dataset "$tum" --intrinsics 535.4,539.2,320.1,247.6 --json > "$tmp/tum.json" 2> "$tmp/tum.err" \
    || fail "TUM run failed: $(cat "$tmp/tum.err")"
"$py" - "$tmp/tum.json" <<'PY' || fail "TUM check failed"
import json, sys
j = json.loads(open(sys.argv[1]).read())
assert j["frames"] == 16, j["frames"]
assert j["converged"] is False and j["converged_at_frame"] is None, j
assert j["scale_est"] is None and j["rel_error"] is None, j
PY
echo "scale-eval CLI: all checks passed"
