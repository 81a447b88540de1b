#!/usr/bin/env bash
# scaled-detect end to end: sysexits codes and messages for bad input (runs
# anywhere), and with ../shared present the real model on redkitchen frame 0
# as text, JSON and a drawn PNG.
#   tests/cli/scaled_detect_cli.sh PATH/TO/scaled-detect SHARED_DIR
set -euo pipefail
det=$1
shared=${SCALED_SHARED_DIR:-$2}
source "$(dirname "${BASH_SOURCE[0]}")/cli_lib.sh"

"$det" --help > "$tmp/help.txt" || fail "--help failed"  # a file: no SIGPIPE from grep -q
grep -q '^usage: scaled-detect' "$tmp/help.txt" || fail "--help does not print usage"
expect 64 "--image FILE is required" -- "$det"
expect 64 "unknown option --bogus" -- "$det" --bogus 1
expect 64 "--size needs a value" -- "$det" --image x.png --size
expect 64 "input_size_px = 100" -- "$det" --image x.png --size 100
expect 64 "not a number: 'abc'" -- "$det" --image x.png --score abc
expect 64 "unknown model family 'yolov8'" -- "$det" --image x.png --family yolov8
expect 66 "$tmp/none.png: image file not found" -- "$det" --image "$tmp/none.png"
printf 'not a png' > "$tmp/bad.png"
expect 65 "$tmp/bad.png: cannot decode" -- "$det" --image "$tmp/bad.png"
python3 -c "
import zlib, struct, sys
# a 64x48 gray PNG, written without any imaging library
w, h = 64, 48
raw = b''.join(b'\x00' + bytes((x * 4) % 256 for x in range(w)) for _ in range(h))
def chunk(t, d): return struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d))
open(sys.argv[1], 'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 0, 0, 0, 0))
    + chunk(b'IDAT', zlib.compress(raw)) + chunk(b'IEND', b''))
" "$tmp/gray.png"
expect 66 "$tmp/none.onnx: ONNX model not found" -- "$det" --image "$tmp/gray.png" --model "$tmp/none.onnx"
printf 'person\ncar\n' > "$tmp/coco.names"
printf 'garbage' > "$tmp/garbage.onnx"
expect 65 "$tmp/garbage.onnx: cannot load the yolox model" -- "$det" --image "$tmp/gray.png" --model "$tmp/garbage.onnx"
printf '[net]\n' > "$tmp/net.cfg"
expect 66 "$tmp/net.weights: Darknet weights file not found" -- "$det" --image "$tmp/gray.png" --model "$tmp/net.cfg"

models="$shared/models"
frame="$shared/data/redkitchen/rgb/000000.jpg"
if [[ ! -f "$models/yolox_nano.onnx" || ! -f "$frame" ]]; then
    echo "SKIP real-model part: $models/yolox_nano.onnx or $frame not found (set SCALED_SHARED_DIR)"
    exit 0
fi
text=$("$det" --image "$frame" --model "$models/yolox_nano.onnx")
grep -q '^chair 0\.[0-9]* ' <<<"$text" || fail "no chair line in: $text"
grep -q '^dining table ' <<<"$text" || fail "no dining table line in: $text"
json=$("$det" --image "$frame" --model "$models/yolox_nano.onnx" --size 320 --json --classes chair --draw "$tmp/out.png")
python3 - "$json" "$tmp/out.png" <<'PY' || fail "JSON or drawing does not meet the contract: $json"
import json, sys
d = json.loads(sys.argv[1])
assert d["class"] == "DETECTIONS" and d["family"] == "yolox" and d["input_size"] == 320, d
assert d["width"] == 640 and d["height"] == 480, d
assert d["detections"] and all(x["class_name"] == "chair" for x in d["detections"]), d
for x in d["detections"]:
    x0, y0, x1, y1 = x["box"]
    assert 0 <= x0 < x1 <= 639 and 0 <= y0 < y1 <= 479, x
assert d["timing_ms"]["forward"] > 0, d
png = open(sys.argv[2], "rb").read()
assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10000, len(png)
PY
expect 73 "cannot write the image" -- "$det" --image "$frame" --model "$models/yolox_nano.onnx" --draw "$tmp/no/such/dir/out.png"
# The default model comes from SCALED_SHARED_DIR.
SCALED_SHARED_DIR="$shared" "$det" --image "$frame" --json | grep -q '"family":"yolox"' || fail "default model"
if [[ -f "$models/yolo-fastest-1.1-xl.cfg" ]]; then
    out=$("$det" --image "$shared/data/redkitchen/rgb/000080.jpg" --model "$models/yolo-fastest-1.1-xl.cfg" --size 320)
    grep -q '^chair ' <<<"$out" || fail "Yolo-Fastest finds no chair on frame 80: $out"
fi
echo "scaled-detect CLI: ok"
