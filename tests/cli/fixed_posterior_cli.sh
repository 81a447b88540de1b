#!/usr/bin/env bash
# The fixed-point posterior against the floating one (docs/numerics.md):
# final MAP within one grid bin, 95% interval bounds within 1%.
#   tests/cli/fixed_posterior_cli.sh sim PATH/TO/scale-sim
#       the paper's three experiments, seeds 1-3, both variance models
#   tests/cli/fixed_posterior_cli.sh redkitchen PATH/TO/scale-eval SHARED_DIR
#       7-Scenes redkitchen, frames 0:600; exit 77 (skipped) without the data
set -euo pipefail
mode=$1
tool=$2
py=/usr/bin/python3
[[ -x $py ]] || py=python3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# The default grid: 0.01 .. 100 m per unit in 1024 log-spaced bins.
compare='
import json, math, sys
delta = math.log(100 / 0.01) / 1023
def check(name, a, b):
    bins = abs(math.log(a["map"] / b["map"])) / delta
    lo = abs(a["lo"] / b["lo"] - 1)
    hi = abs(a["hi"] / b["hi"] - 1)
    print("%-40s MAP %.5g vs %.5g (%.2f bins)  ci95 [%.5g, %.5g] vs [%.5g, %.5g] (%.3f%%, %.3f%%)"
          % (name, a["map"], b["map"], bins, a["lo"], a["hi"], b["lo"], b["hi"], 100 * lo, 100 * hi))
    return bins <= 1 and lo <= 0.01 and hi <= 0.01
'

case $mode in
sim)
    ok=1
    for variance in propagated paper; do
        for seed in 1 2 3; do
            "$tool" --json --seed "$seed" --variance "$variance" > "$tmp/float.json"
            "$tool" --json --seed "$seed" --variance "$variance" --arithmetic fixed > "$tmp/fixed.json"
            "$py" -c "$compare"'
a, b = (json.load(open(f))["experiments"] for f in sys.argv[1:3])
ok = True
for x, y in zip(a, b):
    p = lambda e: {"map": e["final_scale"], "lo": e["final_ci95"][0], "hi": e["final_ci95"][1]}
    ok &= check(sys.argv[3] + " " + x["name"], p(y), p(x))
sys.exit(0 if ok else 1)' "$tmp/float.json" "$tmp/fixed.json" "$variance seed $seed" || ok=0
        done
    done
    [[ $ok -eq 1 ]] || fail "fixed and floating posteriors disagree (fixed first, floating second)"
    ;;
redkitchen)
    shared=${SCALED_SHARED_DIR:-$3}
    rk="$shared/data/redkitchen"
    if [[ ! -f "$shared/models/yolox_nano.onnx" || ! -d "$rk" ]]; then
        echo "SKIP: $shared/models/yolox_nano.onnx or $rk not found (set SCALED_SHARED_DIR)"
        exit 77
    fi
    "$tool" --dataset "$rk" --json --out "$tmp/float" --no-plots > "$tmp/float.json" 2> "$tmp/err" \
        || fail "$(cat "$tmp/err")"
    "$tool" --dataset "$rk" --json --out "$tmp/fixed" --no-plots \
        --set estimator.posterior_arithmetic=fixed > "$tmp/fixed.json" 2> "$tmp/err" \
        || fail "$(cat "$tmp/err")"
    "$py" -c "$compare"'
import csv
a, b = (json.load(open(f)) for f in sys.argv[1:3])
assert a["updates"] == b["updates"] and a["observations"] == b["observations"], "different evidence"
p = lambda j: {"map": j["posterior_final"]["map"], "lo": j["posterior_final"]["ci95"][0],
               "hi": j["posterior_final"]["ci95"][1]}
ok = check("redkitchen 0:600 posterior_final", p(b), p(a))
# Every update with a posterior, not only the last.
ua, ub = (list(csv.DictReader(open(d + "/updates.csv"))) for d in sys.argv[3:5])
assert len(ua) == len(ub)
q = lambda r: {"map": float(r["scale_est"]), "lo": float(r["ci95_lo"]), "hi": float(r["ci95_hi"])}
for x, y in zip(ua, ub):
    if x["scale_est"] and int(x["total_observations"]) > 0:
        ok &= check("update %s (frame %s)" % (x["update"], x["frame"]), q(y), q(x))
sys.exit(0 if ok else 1)' \
        "$tmp/float.json" "$tmp/fixed.json" "$tmp/float" "$tmp/fixed" \
        || fail "fixed and floating posteriors disagree on redkitchen"
    ;;
*)
    fail "unknown mode $mode"
    ;;
esac
