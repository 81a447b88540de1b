#!/usr/bin/env bash
# The daemon benchmark of docs/benchmarks.md: `scaled` as a whole process under
# load, measured by daemon_bench (tests/bench/daemon_bench.cpp) with 16 watchers
# and a poller every 20 ms:
#   1. 7-Scenes redkitchen replayed at real time (30 fps), YOLOX-Nano at 416 px
#      every 10 frames;
#   2. the simulated source (sim room, simulated detector), 900 frames.
# Both with source.at_end=stay: daemon_bench sees source_finished in STATUS,
# takes one more STATUS (final counters) and stops the daemon with SIGTERM.
# (With at_end=exit the daemon exits within 0.1 s of the last frame and the last
# STATUS the bench has can be up to a second old: the last frames are missing.)
# Builds nothing: build first (cmake --build --preset release --target scaled daemon_bench).
#   scripts/bench-daemon.sh [BUILD_DIR]      (default build/release)
# Environment: SCALED_SHARED_DIR (default ../shared; redkitchen is skipped with
# a message when the data or the model is absent), WATCHERS (16),
# POLL_INTERVAL_MS (20), BENCH_OUT (JSON summaries, default BUILD_DIR/bench-daemon),
# POSE=1 (the watchers also stream POSE lines, socket.pose_rate_hz = 30),
# EXTRA_SET="section.key=value ..." (more --set options for both runs, e.g.
# EXTRA_SET=detector.nice=0 for the detector at the daemon's own priority).
# Prints the machine, each run's markdown table row and per-stage timing table
# (STATUS.timing: predict, search, match, update, map, tracking, detect_*,
# scale_*; docs/benchmarks.md "Per-stage timing"), and the JSON file names.
# Measure on an idle machine: it warns when the 1-minute load average is above 0.5.
set -euo pipefail
cd "$(dirname "$0")/.."

build=${1:-build/release}
bench="$build/bin/daemon_bench"
scaled="$build/bin/scaled"
for exe in "$bench" "$scaled"; do
    [[ -x $exe ]] || { echo "bench-daemon: $exe not found: build the targets scaled and daemon_bench first" >&2; exit 66; }
done
shared=${SCALED_SHARED_DIR:-../shared}
watchers=${WATCHERS:-16}
interval=${POLL_INTERVAL_MS:-20}
pose=()
if [[ ${POSE:-0} == 1 ]]; then
    pose=(--pose)
fi
extra=()
for assignment in ${EXTRA_SET:-}; do
    extra+=(--set "$assignment")
done
out=${BENCH_OUT:-$build/bench-daemon}
mkdir -p "$out"
priors="$PWD/config/priors.toml"

load=$(cut -d' ' -f1 /proc/loadavg)
echo "# $(date -u +%Y-%m-%dT%H:%MZ), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //'), $(nproc) cores, load average $load"
if awk -v l="$load" 'BEGIN { exit !(l > 0.5) }'; then
    echo "# WARNING: load average $load > 0.5: the machine is busy, figures will be pessimistic" >&2
fi

run() {
    local name=$1
    shift
    echo "# $name: $bench --scaled $scaled --watchers $watchers --poll-interval-ms $interval ${pose[*]} --label $name -- $*" >&2
    local status=0
    "$bench" --scaled "$scaled" --watchers "$watchers" --poll-interval-ms "$interval" \
        "${pose[@]}" --label "$name" -- "$@" >"$out/$name.json" || status=$?
    echo "# $name: $out/$name.json (exit $status)" >&2
    return $status
}

failed=0
data="$shared/data/redkitchen"
model="$shared/models/yolox_nano.onnx"
if [[ -d $data && -f $model ]]; then
    run redkitchen --source "replay:$(realpath "$data")" --pacing realtime \
        --set "detector.model=$(realpath "$model")" --set detection.every_frames=10 \
        --set detector.input_size_px=416 --set source.at_end=stay \
        --set "estimator.priors=$priors" "${extra[@]}" --no-tty || failed=1
else
    echo "# redkitchen: skipped ($data or $model not found; set SCALED_SHARED_DIR)" >&2
fi

run sim --source sim --set source.max_frames=900 --set source.at_end=stay \
    --set "estimator.priors=$priors" "${extra[@]}" --no-tty || failed=1
exit $failed
