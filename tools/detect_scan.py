#!/usr/bin/env python3
"""In how many frames of a sequence does each class appear? Runs scaled-detect
(--json) on every Nth image of a folder for one or more models and prints a
table: class, then per model the number of frames with at least one box of it.

  tools/detect_scan.py --bin build/bin/scaled-detect --images ../shared/data/redkitchen/rgb \\
      --every 10 --model ../shared/models/yolox_nano.onnx:416 \\
      --model ../shared/models/yolo-fastest-1.1-xl.cfg:320
"""
import argparse
import collections
import json
import pathlib
import subprocess
import sys

IMAGE_EXT = {".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".bmp"}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", required=True, help="path to scaled-detect")
    ap.add_argument("--images", required=True, help="folder of images")
    ap.add_argument("--every", type=int, default=10, help="use every Nth image (default 10)")
    ap.add_argument("--model", action="append", required=True, help="MODEL_PATH:INPUT_SIZE")
    ap.add_argument("--score", default="0.3", help="score threshold (default 0.3)")
    args = ap.parse_args()

    images = sorted(p for p in pathlib.Path(args.images).iterdir() if p.suffix.lower() in IMAGE_EXT)
    images = images[:: max(args.every, 1)]
    if not images:
        sys.exit(f"{args.images}: no images")
    counts = []
    for spec in args.model:
        path, _, size = spec.rpartition(":")
        if not path:
            path, size = spec, "416"
        seen = collections.Counter()
        for img in images:
            out = subprocess.run([args.bin, "--image", str(img), "--model", path, "--size", size,
                                  "--score", args.score, "--json"],
                                 capture_output=True, text=True)
            if out.returncode != 0:
                sys.exit(f"scaled-detect failed on {img}: {out.stderr.strip()}")
            seen.update({d["class_name"] for d in json.loads(out.stdout)["detections"]})
        counts.append(seen)
    classes = sorted(set().union(*counts), key=lambda c: -max(s[c] for s in counts))
    print(f"{len(images)} frames (every {args.every}th of {args.images}), score >= {args.score}")
    print("| class | " + " | ".join(pathlib.Path(m).name for m in args.model) + " |")
    print("|---|" + "---|" * len(args.model))
    for c in classes:
        print(f"| {c} | " + " | ".join(str(s[c]) for s in counts) + " |")


if __name__ == "__main__":
    main()
