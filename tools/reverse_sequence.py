#!/usr/bin/env python3
"""A sequence played backwards: a second test sequence from one with ground truth.

Usage (from the project root):
    tools/reverse_sequence.py ../shared/data/redkitchen /tmp/redkitchen-reversed
    build/release/bin/slam-run --dataset /tmp/redkitchen-reversed --json
    tools/scale_ablation.py --data /tmp/redkitchen-reversed --row "defaults="

SRC is a dataset folder in the TUM RGB-D layout the project reads (rgb.txt, optional
depth.txt, groundtruth.txt, camera.txt, optional gravity.txt). DST gets the same files with
the frames listed last to first: frame i of DST is frame n-1-i of SRC, stamped with the
source's i-th time stamp (so the frame times stay the source's), its ground-truth pose and
depth image the source frame's own. The image
folders are symbolic links to the source's (nothing is copied; the data stay where their
licence allows them), camera.txt and gravity.txt are copied as they are (the world frame of
the ground truth does not change).

Why (docs/accuracy.md, "Redkitchen played backwards"): the same scenes and camera, another
motion. Played backwards the first frame is one where the camera is already moving, as after
a tracking loss; defaults tuned on the forward run alone failed there.
"""
import argparse
import os
import shutil
import sys


def read_list(path):
    header, rows = [], []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            if line.startswith("#") or not line.strip():
                header.append(line.rstrip("\n"))
                continue
            fields = line.split()
            try:
                t = float(fields[0])
            except ValueError:
                sys.exit("%s:%d: not a timestamp: %r" % (path, number, fields[0]))
            rows.append((t, fields[1:]))
    return header, rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src")
    ap.add_argument("dst")
    a = ap.parse_args()
    src = os.path.abspath(a.src)
    if not os.path.isfile(os.path.join(src, "rgb.txt")):
        sys.exit("%s: no rgb.txt (not a dataset folder in the TUM layout)" % src)
    if os.path.exists(a.dst) and os.listdir(a.dst):
        sys.exit("%s: exists and is not empty" % a.dst)
    os.makedirs(a.dst, exist_ok=True)

    _, rgb = read_list(os.path.join(src, "rgb.txt"))
    if len(rgb) < 2:
        sys.exit("%s/rgb.txt: fewer than 2 frames" % src)
    times = sorted(t for t, _ in rgb)
    # The source's i-th stamp goes to its (n-1-i)-th frame; a stamp of another
    # list that is no image's is mirrored about the middle of the run.
    mirror = {t: u for t, u in zip(times, reversed(times))}

    def reversed_time(t):
        return mirror.get(t, times[0] + times[-1] - t)

    for name in ("rgb.txt", "depth.txt", "groundtruth.txt"):
        path = os.path.join(src, name)
        if not os.path.isfile(path):
            continue
        header, rows = read_list(path)
        rows = sorted(((reversed_time(t), fields) for t, fields in rows), key=lambda r: r[0])
        with open(os.path.join(a.dst, name), "w") as f:
            for line in header:
                f.write(line + "\n")
            for t, fields in rows:
                f.write("%.6f %s\n" % (t, " ".join(fields)))
    for name in ("camera.txt", "gravity.txt", "calib.txt"):
        if os.path.isfile(os.path.join(src, name)):
            shutil.copy(os.path.join(src, name), os.path.join(a.dst, name))
    for entry in sorted(os.listdir(src)):
        if os.path.isdir(os.path.join(src, entry)):
            os.symlink(os.path.join(src, entry), os.path.join(a.dst, entry))
    print("%s: %d frames reversed" % (a.dst, len(rgb)))


if __name__ == "__main__":
    main()
