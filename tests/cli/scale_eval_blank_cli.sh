#!/usr/bin/env bash
# Issue 21's relocalisation test, as scale-eval measures it: redkitchen with
# frames 300-319 black (a covered lens, 0.67 s) keeps its map and its scale
# evidence (one epoch, one relocalisation after the outage) and ends within 2%
# of the scale of the unbroken run, on the default seed, on seed 7 (whose first
# PnP pose after the outage is too weak and is verified, docs/slam.md
# "Relocalisation") and on seeds 5 and 6 (which also relocalise at frame 48,
# after a near-loss, in both runs). The detector's schedule keeps its phase
# through a relocalisation, so both runs detect the same frames (it used to
# shift by the frames spent relocalising: seeds 4-6 were 2.4-4.7% apart).
# The interval holds the truth in at least 90% of the updates. Skips without
# ../shared. SEEDS="1 2 3 4 5 6 7 8" runs issue 21's eight (docs/accuracy.md).
#   tests/cli/scale_eval_blank_cli.sh PATH/TO/scale-eval SHARED_DIR
set -euo pipefail
ev=$1
shared=${SCALED_SHARED_DIR:-$2}
source "$(dirname "${BASH_SOURCE[0]}")/cli_lib.sh"

model="$shared/models/yolox_nano.onnx"
rk="$shared/data/redkitchen"
if [[ ! -f "$model" || ! -d "$rk" ]]; then
    echo "SKIP: $model or $rk not found (set SCALED_SHARED_DIR)"
    exit 0
fi
py=/usr/bin/python3
[[ -x $py ]] || py=python3

seeds=${SEEDS:-1 5 6 7}
for seed in $seeds; do
    for run in unbroken blank; do
        extra=()
        [[ $run == blank ]] && extra=(--blank 300:320)
        "$ev" --dataset "$rk" --json --set "tracker.seed=$seed" "${extra[@]}" \
            > "$tmp/$run$seed.json" 2> "$tmp/$run$seed.err" || fail "seed $seed $run: $(tail -3 "$tmp/$run$seed.err")"
    done
done

"$py" - "$tmp" $seeds <<'PY' || fail "relocalisation checks failed"
import json, sys
d = sys.argv[1]
for seed in map(int, sys.argv[2:]):
    u = json.loads(open("%s/unbroken%d.json" % (d, seed)).read())
    b = json.loads(open("%s/blank%d.json" % (d, seed)).read())
    mu, mb = u["posterior_final"]["map"], b["posterior_final"]["map"]
    print("seed %d: blanked %d epoch(s), %d relocalisation(s), final MAP %.4f against %.4f unbroken "
          "(%+.2f%%), coverage %.3f" % (seed, b["epochs"], b["relocalisations"], mb, mu,
                                        100 * (mb / mu - 1), b["ci95_coverage"]))
    assert u["epochs"] == 1, (seed, u["epochs"])
    assert b["epochs"] == 1 and b["relocalisations"] == u["relocalisations"] + 1, (
        seed, b["epochs"], b["relocalisations"], u["relocalisations"])
    assert abs(mb / mu - 1) <= 0.02, (seed, mb, mu)
    assert b["ci95_coverage"] >= 0.9, (seed, b["ci95_coverage"])
    assert b["wrong_converged_updates"] == 0, (seed, b["wrong_converged_updates"])
PY
echo "scale-eval relocalisation: all checks passed"
