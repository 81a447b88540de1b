#!/bin/sh
# The redkitchen experiments of docs/accuracy.md, issue 5 (the paper model:
# every run adds --set estimator.model=paper): experiment 1 (COCO priors),
# experiment 2 (scene priors) and the ablation table. The object model's
# ablation is tools/scale_ablation.py. Prints one line per run:
#   name  converged_at_frame  median  std  final_map  scale_true  observations
# Usage: scripts/accuracy-redkitchen.sh [BUILD_BIN_DIR]   (default build/release/bin)
set -eu
bin=${1:-build/release/bin}
shared=${SCALED_SHARED_DIR:-../shared}
data="$shared/data/redkitchen"
run() {
    name=$1
    shift
    "$bin/scale-eval" --dataset "$data" --json --set estimator.model=paper "$@" 2>/dev/null | /usr/bin/python3 -c "
import json, sys
j = json.loads(sys.stdin.read())
e = j['rel_error'] or j['rel_error_unconverged'] or {}
f = lambda v, s='%.2f%%': (s % (100 * v)) if v is not None else '-'
print('%-34s conv@%-5s median %-7s std %-7s map %.4f truth %.4f obs %d' % (
    sys.argv[1], j['converged_at_frame'], f(e.get('median')) + ('' if j['converged'] else '*'),
    f(e.get('std')), j['posterior_final']['map'] or 0, j['scale_true'] or 0, j['observations']))
" "$name"
}
echo "# * = not converged: error over all updates"
run "1 default (COCO priors)"
run "2 scene priors" --set estimator.priors=config/priors-redkitchen.toml
run "paper (literal)" --set estimator.variance=paper --set estimator.robust=false \
    --set estimator.compensate_roll=false --set estimator.partial_visibility=false
run "variance=paper" --set estimator.variance=paper
run "robust off" --set estimator.robust=false
run "robust w=0.02" --set estimator.outlier_weight=0.02
run "robust w=0.1" --set estimator.outlier_weight=0.1
run "partial visibility off" --set estimator.partial_visibility=false
run "weighting=box" --set estimator.weighting=box
run "roll compensation off" --set estimator.compensate_roll=false
run "all classes (use_non_upright)" --set estimator.use_non_upright=true
run "detection every 5" --set detection.every_frames=5
run "detection every 30" --set detection.every_frames=30
run "Yolo-Fastest 416" --set detector.family=darknet \
    --set "detector.model=$shared/models/yolo-fastest-1.1-xl.cfg"
run "seed 2" --set tracker.seed=2
run "seed 3" --set tracker.seed=3
run "seed 4" --set tracker.seed=4
