#!/usr/bin/env bash
# synth-render: writes a TUM-like sequence, also along a recorded trajectory;
# bad usage exits 64, a malformed recording 65 (66 missing), an unwritable
# output directory 73.
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

# A recorded trajectory (the sequence above as the recording): the same motion,
# upright and centred in the room, at the recording's times.
"$bin" --out "$tmp/rec" --frames 4 --width 64 --height 48 --fx 50 --trajectory "$tmp/seq" \
  --rolling-shutter 0.03 --exposure 0.01 >/dev/null
[[ $(grep -vc '^#' "$tmp/rec/groundtruth.txt") == 4 ]] || fail "--trajectory: 4 poses"
grep -q '^0.066666667 rgb/000002.png$' "$tmp/rec/rgb.txt" || fail "--trajectory: the recording's times"
python3 - "$tmp/seq/groundtruth.txt" "$tmp/rec/groundtruth.txt" <<'PY' || fail "--trajectory: motion"
import math, sys
def poses(path):
    return [list(map(float, l.split())) for l in open(path) if l.strip() and not l.startswith("#")]
a, b = poses(sys.argv[1]), poses(sys.argv[2])
for i in (1, 2, 3):
    da = math.dist(a[i][1:4], a[i - 1][1:4]); db = math.dist(b[i][1:4], b[i - 1][1:4])
    assert abs(da - db) < 1e-6, (i, da, db)
assert abs(sum(p[3] for p in b) / 4 - 1.45) < 1e-6   # mean height
PY
# Still frames (every pose the same) with a shutter and an exposure: the noise
# is added once per frame, fresh (frame-to-frame differences of sigma sqrt(2)).
printf '# t tx ty tz qx qy qz qw\n0 0 0 0 0 0 0 1\n0.033 0 0 0 0 0 0 1\n0.067 0 0 0 0 0 0 1\n' \
  > "$tmp/seq/groundtruth.txt"
"$bin" --out "$tmp/still" --frames 3 --width 64 --height 48 --fx 50 --trajectory "$tmp/seq" \
  --rolling-shutter 0.03 --exposure 0.01 --noise 4 >/dev/null
"$bin" --out "$tmp/still0" --frames 3 --width 64 --height 48 --fx 50 --trajectory "$tmp/seq" \
  --rolling-shutter 0.03 --noise 0 >/dev/null
python3 - "$tmp/still" "$tmp/still0" <<'PY' || fail "--rolling-shutter: the noise is not one fresh draw a frame"
import struct, sys, zlib
def grey(path):  # an 8-bit grey PNG without interlacing, as cv::imwrite writes it
    data = open(path, "rb").read()
    w, h = struct.unpack(">II", data[16:24])
    idat, pos = b"", 8
    while pos < len(data):
        n = struct.unpack(">I", data[pos:pos + 4])[0]
        if data[pos + 4:pos + 8] == b"IDAT":
            idat += data[pos + 8:pos + 8 + n]
        pos += 12 + n
    raw, rows, prev = zlib.decompress(idat), [], [0] * w
    for r in range(h):
        f, line = raw[r * (w + 1)], list(raw[r * (w + 1) + 1:(r + 1) * (w + 1)])
        for c in range(w):
            a = line[c - 1] if c else 0
            b, cc = prev[c], (prev[c - 1] if c else 0)
            if f == 1: line[c] = (line[c] + a) & 255
            elif f == 2: line[c] = (line[c] + b) & 255
            elif f == 3: line[c] = (line[c] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - cc; pa, pb, pc = abs(p - a), abs(p - b), abs(p - cc)
                line[c] = (line[c] + (a if pa <= pb and pa <= pc else b if pb <= pc else cc)) & 255
        rows.append(line); prev = line
    return [v for row in rows for v in row]
def sd(x): m = sum(x) / len(x); return (sum((v - m) ** 2 for v in x) / len(x)) ** 0.5
f0, f1 = grey(sys.argv[1] + "/rgb/000000.png"), grey(sys.argv[1] + "/rgb/000001.png")
c0 = grey(sys.argv[2] + "/rgb/000000.png")
between = sd([a - b for a, b in zip(f0, f1)])      # fresh noise each frame: 4 sqrt(2)
against = sd([a - b for a, b in zip(f0, c0)])      # one frame's noise: 4
assert 4.6 < between < 6.8, between
assert 3.3 < against < 4.8, against
PY
printf '# t tx ty tz qx qy qz qw\n0 0 0 0 0 0 0 1\n0.1 0 0 oops 0 0 0 1\n' > "$tmp/seq/groundtruth.txt"
got=0; "$bin" --out "$tmp/bad" --frames 3 --trajectory "$tmp/seq" 2>"$tmp/err" >/dev/null || got=$?
[[ $got == 65 ]] || fail "a malformed groundtruth.txt exited $got, expected 65"
grep -q 'groundtruth.txt:3' "$tmp/err" || fail "the bad line is not named: $(cat "$tmp/err")"
[[ ! -e $tmp/bad ]] || fail "a refused trajectory created its output"
# A recording that leaves the room: the pose and its line named.
printf '# t tx ty tz qx qy qz qw\n0 0 0 0 0 0 0 1\n0.1 9 0 0 0 0 0 1\n' > "$tmp/seq/groundtruth.txt"
got=0; "$bin" --out "$tmp/bad" --frames 2 --trajectory "$tmp/seq" 2>"$tmp/err" >/dev/null || got=$?
[[ $got == 65 ]] || fail "a recording that leaves the room exited $got, expected 65"
grep -q 'groundtruth.txt: .*pose 0 (line 2)' "$tmp/err" || fail "the pose's line is not named: $(cat "$tmp/err")"

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
expect 64 --out "$tmp/x" --trajectory "$tmp/seq" --shake 0.01
expect 64 --out "$tmp/x" --trajectory "$tmp/seq" --fps 10
expect 64 --out "$tmp/x" --rolling-shutter 0.5
expect 64 --out "$tmp/x" --texture 0
expect 66 --out "$tmp/x" --trajectory "$tmp/nowhere"
touch "$tmp/file"
expect 73 --out "$tmp/file/sub" --frames 1 --width 32 --height 32 --fx 30
echo "synth-render CLI: ok"
