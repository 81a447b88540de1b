#!/usr/bin/env bash
# synth-render: writes a TUM-like sequence; bad usage exits 64, an unwritable
# output directory exits 73.
#   synth_render_cli.sh PATH/TO/synth-render
set -euo pipefail
bin=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$bin" --out "$tmp/seq" --frames 4 --seed 3 --width 160 --height 120 --fx 131 >/dev/null
for f in rgb.txt groundtruth.txt camera.txt gravity.txt rgb/000000.png rgb/000003.png; do
  [[ -s $tmp/seq/$f ]] || fail "missing $f"
done
[[ $(grep -vc '^#' "$tmp/seq/rgb.txt") == 4 ]] || fail "rgb.txt should list 4 frames"
[[ $(grep -vc '^#' "$tmp/seq/groundtruth.txt") == 4 ]] || fail "groundtruth.txt should have 4 poses"
[[ $(grep -v '^#' "$tmp/seq/groundtruth.txt" | head -1 | wc -w) == 8 ]] || fail "TUM pose has 8 fields"
grep -q '^0.033333333 rgb/000001.png$' "$tmp/seq/rgb.txt" || fail "rgb.txt line format"
grep -q '^0.033333333 ' "$tmp/seq/groundtruth.txt" || fail "groundtruth.txt timestamps"
[[ ! -e $tmp/seq/depth.txt ]] || fail "depth.txt without --depth"
[[ $(grep -v '^#' "$tmp/seq/camera.txt") == "160 120 131 131 80 60" ]] || fail "camera.txt"
[[ $(grep -v '^#' "$tmp/seq/gravity.txt") == "0 0 -1" ]] || fail "gravity.txt"

# Depth maps and radial distortion on request.
"$bin" --out "$tmp/dist" --frames 2 --width 64 --height 48 --fx 50 --k1 -0.1 --k2 0.01 \
  --depth --noise 0 --no-aa >/dev/null
[[ $(grep -v '^#' "$tmp/dist/camera.txt") == "64 48 50 50 32 24 -0.1 0.01" ]] || fail "camera.txt k1 k2"
[[ $(grep -vc '^#' "$tmp/dist/depth.txt") == 2 && -s $tmp/dist/depth/000001.png ]] || fail "depth"

# The same seed gives the same images.
"$bin" --out "$tmp/again" --frames 2 --seed 3 --width 160 --height 120 --fx 131 >/dev/null
cmp -s "$tmp/seq/rgb/000001.png" "$tmp/again/rgb/000001.png" || fail "not deterministic"

expect() {  # expect CODE ARGS...
  local want=$1; shift
  local got=0
  "$bin" "$@" >/dev/null 2>"$tmp/err" || got=$?
  [[ $got == "$want" ]] || fail "synth-render $* exited $got, expected $want"
  [[ $want == 0 || -s $tmp/err ]] || fail "synth-render $* printed no error"
}
expect 64
expect 64 --out "$tmp/x" --frames 0
expect 64 --out "$tmp/x" --frames abc
expect 64 --out "$tmp/x" --width
expect 64 --out "$tmp/x" --fx -5
expect 64 --out "$tmp/x" --bogus 1
expect 0 --help
touch "$tmp/file"
expect 73 --out "$tmp/file/sub" --frames 1 --width 32 --height 32 --fx 30
echo "synth-render CLI: ok"
