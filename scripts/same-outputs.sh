#!/usr/bin/env bash
# Behaviour unchanged across a restructuring: scale-eval, slam-run and the
# daemon built at two revisions give byte-identical outputs on redkitchen.
# Behaviour added since BASE on purpose is turned off for HEAD's run (the
# window bundle adjustment: head_off below), and keys added since BASE are
# left out of config.toml.
#
#   scripts/same-outputs.sh BASE [HEAD] [--frames N] [--head-build DIR]
#
# BASE and HEAD are git revisions (HEAD defaults to the working tree as it is,
# built in build/release, or the existing build DIR given by --head-build: the
# ctest tools.same_outputs passes its own). Each revision is built (release preset, only the
# three programs) in build/same-outputs/<rev>, then over the first N frames
# (default 300):
#   - slam-run --out: the trajectory file;
#   - scale-eval --out --no-plots: frames.csv, updates.csv, observations.csv,
#     posterior.csv, likelihoods.csv, objects.csv, config.toml (less the keys
#     added since BASE, at their defaults), and
#     summary.json without its timings (keys ending in ms_per_frame or
#     ms_per_update);
#   - scaled --source replay:... --pacing fast (lossless) until the replay ends:
#     the field log's DETECTION, SCALE, OBJECT, POSE and STATE lines without
#     their clock readings (mono_ns, ms, latency_ms), POSE lines without the
#     members they take from the latest SCALE (thread timing decides which).
# Exit 0 when every output is the same to the byte, 1 with the differing files
# named otherwise, 66 without the dataset or model, 77 outside a git checkout
# with BASE in its history, 64 on bad arguments.
# Needs ../shared (SCALED_SHARED_DIR): data/redkitchen and models/yolox_nano.onnx.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

usage() { echo "usage: scripts/same-outputs.sh BASE [HEAD] [--frames N] [--head-build DIR]" >&2; exit 64; }
base=""
head=""
head_dir=""
frames=300
while [[ $# -gt 0 ]]; do
  case $1 in
    --frames) [[ $# -ge 2 && $2 =~ ^[1-9][0-9]*$ ]] || usage; frames=$2; shift 2 ;;
    --head-build) [[ $# -ge 2 && -d $2 ]] || usage; head_dir=$(cd "$2" && pwd); shift 2 ;;
    -*) usage ;;
    *) if [[ -z $base ]]; then base=$1; elif [[ -z $head ]]; then head=$1; else usage; fi; shift ;;
  esac
done
[[ -n $base ]] || usage

shared=${SCALED_SHARED_DIR:-$root/../shared}
dataset=$shared/data/redkitchen
model=$shared/models/yolox_nano.onnx
if [[ ! -d $dataset || ! -f $model ]]; then
  echo "same-outputs: needs $dataset and $model (SCALED_SHARED_DIR)" >&2
  exit 66
fi

if ! git rev-parse --verify --quiet "$base^{commit}" > /dev/null 2>&1; then
  echo "same-outputs: $base is not a revision of this checkout (a git clone with its history is needed)" >&2
  exit 77
fi
[[ -z $head_dir || -z $head ]] || usage

targets=(scale-eval slam-run scaled)
jobs=${SCALED_JOBS:-$(nproc)}

# build REV -> prints the build directory holding bin/
build() {
  local rev=$1
  if [[ -z $rev && -n $head_dir ]]; then
    cmake --build "$head_dir" -j "$jobs" --target "${targets[@]}" > /dev/null
    echo "$head_dir"
    return
  fi
  if [[ -z $rev ]]; then
    cmake --preset release > /dev/null
    cmake --build build/release -j "$jobs" --target "${targets[@]}" > /dev/null
    echo "$root/build/release"
    return
  fi
  local sha
  sha=$(git rev-parse --verify "$rev^{commit}") || { echo "same-outputs: no revision '$rev'" >&2; exit 64; }
  local tree=$root/build/same-outputs/$sha
  if [[ ! -d $tree/src ]]; then
    mkdir -p "$tree"
    git worktree add --detach "$tree/src" "$sha" > /dev/null 2>&1
  fi
  (cd "$tree/src" && cmake --preset release -B "$tree/build" > /dev/null &&
     cmake --build "$tree/build" -j "$jobs" --target "${targets[@]}" > /dev/null)
  echo "$tree/build"
}

# Behaviour added since the restructuring, on by default and off for HEAD's
# run: the window bundle adjustment (tracker.window_ba, docs/slam.md), and
# poses in metres only from a narrow enough scale (estimator.pose_max_rel_width95,
# scale-eval's metric_trajectory; docs/protocol.md), and the velocity's noise as
# a random walk (tracker.sigma_a_reference_hz; at 30 Hz the same to rounding),
# and a run of near-losses counted as a loss (tracker.near_loss_ratio).
head_slam_off=(--set window_ba=false --set sigma_a_reference_hz=0 --set near_loss_ratio=0)
head_off=(--set tracker.window_ba=false --set estimator.pose_max_rel_width95=1000
          --set tracker.sigma_a_reference_hz=0 --set tracker.near_loss_ratio=0)

# run BUILD_DIR OUT_DIR [head]
run() {
  local bin=$1/bin out=$2
  local slam_off=() off=()
  if [[ ${3:-} == head ]]; then
    slam_off=("${head_slam_off[@]}")
    off=("${head_off[@]}")
  fi
  rm -rf "$out"
  mkdir -p "$out/eval" "$out/daemon/log"
  "$bin/slam-run" --dataset "$dataset" --frames "0:$frames" --out "$out/trajectory.txt" \
    "${slam_off[@]}" > /dev/null 2>&1
  SCALED_SHARED_DIR=$shared "$bin/scale-eval" --dataset "$dataset" --frames "0:$frames" \
    --set "estimator.priors=$work/priors.toml" --set "detector.model=$model" \
    --out "$out/eval" --no-plots "${off[@]}" > /dev/null 2>&1
  python3 - "$out/eval/summary.json" <<'PY'
import json, sys
p = sys.argv[1]
doc = json.load(open(p))
def strip(x):
    if isinstance(x, dict):
        return {k: strip(v) for k, v in x.items() if not k.endswith(("ms_per_frame", "ms_per_update"))}
    if isinstance(x, list):
        return [strip(v) for v in x]
    return x
json.dump(strip(doc), open(p, "w"), indent=1, sort_keys=True)
PY
  # The daemon: lossless replay of the same frames, exits at the end.
  cat > "$out/daemon/scaled.toml" <<EOF
[estimator]
priors = "$work/priors.toml"

[detector]
model = "$model"

[socket]
path = "$out/daemon/scaled.sock"

[log]
dir = "$out/daemon/log"
EOF
  "$bin/scaled" --config "$out/daemon/scaled.toml" --no-tty \
    --source "replay:$dataset" --pacing fast --set source.at_end=exit \
    --set "source.max_frames=$frames" "${off[@]}" > /dev/null 2> "$out/daemon/stderr.txt" || true
  python3 - "$out/daemon/log" "$out/daemon/lines.json" <<'PY'
import json, os, sys
src, dst = sys.argv[1], sys.argv[2]
wall = {"mono_ns", "ms", "latency_ms"}  # clock readings and durations
metric = {"state", "scale", "scale_sigma", "position", "velocity", "position_cov"}
keep = []
for name in sorted(os.listdir(src)):
    for line in open(os.path.join(src, name)):
        try:
            doc = json.loads(line)
        except ValueError:
            continue
        if doc.get("class") not in ("DETECTION", "SCALE", "OBJECT", "POSE", "STATE"):
            continue
        if doc["class"] == "POSE":
            # A POSE carries the latest SCALE the server had when it was
            # written: which one depends on how the two threads ran. Its map
            # units are the tracker's alone.
            doc = {k: v for k, v in doc.items() if k not in metric}
        keep.append({k: v for k, v in doc.items() if k not in wall and not k.endswith("_us")})
# Each class in the order its thread wrote it: DETECTION lines (detection
# thread) and POSE lines (tracking thread) interleave as the threads ran.
keep.sort(key=lambda d: d["class"])
json.dump(keep, open(dst, "w"), indent=0, sort_keys=True)
PY
  rm -rf "$out/daemon/log" "$out/daemon/scaled.toml" "$out/daemon/scaled.sock"
}

echo "same-outputs: building ${base} and ${head:-the working tree}"
base_build=$(build "$base")
head_build=$(build "$head")

work=$root/build/same-outputs/runs
# Both runs read the same priors (BASE's), at the same path: the path is part
# of scale-eval's config.toml.
mkdir -p "$work"
git show "$(git rev-parse "$base^{commit}"):config/priors.toml" > "$work/priors.toml"
echo "same-outputs: running both over the first $frames frames of redkitchen"
run "$base_build" "$work/base"
run "$head_build" "$work/head" head

# Keys added after BASE (additive configuration) are left out of HEAD's
# config.toml: a new key at its default changes no output, which the other
# files show.
python3 - "$work/base/eval/config.toml" "$work/head/eval/config.toml" <<'PY'
import re, sys
base_path, head_path = sys.argv[1], sys.argv[2]
def keys(path):
    section, out = "", set()
    for line in open(path):
        m = re.match(r"\s*\[([^\]]+)\]", line)
        if m:
            section = m.group(1)
        m = re.match(r"\s*([A-Za-z0-9_]+)\s*=", line)
        if m:
            out.add((section, m.group(1)))
    return out
known = keys(base_path)
section, kept = "", []
for line in open(head_path):
    m = re.match(r"\s*\[([^\]]+)\]", line)
    if m:
        section = m.group(1)
    m = re.match(r"\s*([A-Za-z0-9_]+)\s*=", line)
    if m and (section, m.group(1)) not in known:
        continue
    kept.append(line)
open(head_path, "w").writelines(kept)
PY

status=0
compared=0
while IFS= read -r f; do
  rel=${f#"$work/base/"}
  [[ $rel == daemon/stderr.txt ]] && continue
  compared=$((compared + 1))
  if ! cmp -s "$f" "$work/head/$rel"; then
    echo "DIFFERS: $rel" >&2
    status=1
  fi
done < <(find "$work/base" -type f | sort)
for f in eval/frames.csv eval/updates.csv eval/summary.json trajectory.txt daemon/lines.json; do
  if [[ ! -s $work/base/$f ]]; then
    echo "same-outputs: $f is missing or empty (see $work/base)" >&2
    status=1
  fi
done
if [[ $status -eq 0 ]]; then
  echo "same-outputs: $compared files identical ($work/base vs $work/head)"
fi
exit $status
