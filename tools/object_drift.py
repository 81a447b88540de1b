#!/usr/bin/env python3
"""Can the objects see the map's drift? Each view's unit against the trajectory's window truth.

Usage (from the project root, after a release build):
    tools/object_drift.py [--bin build/release/bin] [--data ../shared/data/redkitchen]
                          [--seeds 1-8] [--set K=V]... [--flag=--camera=FILE]...
                          [--min-views 4] [--work DIR] [--reuse]

scale-eval --out writes observations.csv: one row per view of an object, with its frame and
its extent D (the box's top and bottom rays on the vertical line through the object's anchor),
and frames.csv: scale_true_window, the Sim(3) scale of the last 150 frames of the trajectory
against the ground truth (metres per map unit at that frame). The script runs scale-eval on
the tracker's map for each seed and once on the ground-truth geometry (--truth-geometry: the
same detections, metric poses), and pairs the views of the two (same frame, class and score).
For a view, D_truth / D_map is the metres per map unit of the map around that object at that
frame, whatever the object's height and however it is seen. An estimator could follow the
map's drift with its objects if that unit followed the window truth over each object's views:
a correlation near 1 and a slope of 1 between the two logs, each centred on the object's own
mean.

Printed per object (at least --min-views paired views): the span in frames; the standard
deviation over its views of log(D_truth / D_map) and of log(window truth); their correlation
and the least-squares slope; then the same pooled over every object of every seed, and the
correlation of the window truth with -log D_truth alone (how much of the metric extent's own
change, the viewpoint, moves with the window truth). Nothing here knows a bound.
"""
import argparse
import csv
import math
import os
import statistics as st
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor


def parse_seeds(text):
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def run(a, out, extra):
    if a.reuse and os.path.exists(os.path.join(out, "observations.csv")):
        return out
    cmd = [os.path.join(a.bin, "scale-eval"), "--dataset", a.data, "--json", "--no-plots",
           "--out", out] + extra
    for s in a.set:
        cmd += ["--set", s]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def views_of(out):
    """(frame, class, score) -> (object id, D) for every view with an extent."""
    views = {}
    with open(os.path.join(out, "observations.csv")) as f:
        for r in csv.DictReader(f):
            if r["D"] and r["object_id"] and float(r["D"]) > 0:
                key = (int(r["frame"]), r["class"], r["score"])
                views[key] = (int(r["object_id"]), r["class"], float(r["D"]))
    return views


def window_of(out):
    with open(os.path.join(out, "frames.csv")) as f:
        return {int(r["frame"]): float(r["scale_true_window"])
                for r in csv.DictReader(f) if r["scale_true_window"]}


def centred(values):
    m = st.mean(values)
    return [v - m for v in values]


def slope(xs, ys):
    """Least-squares slope of ys on xs."""
    sxx = sum(x * x for x in xs)
    return sum(x * y for x, y in zip(xs, ys)) / sxx if sxx > 0 else float("nan")


def corr(xs, ys):
    if len(xs) < 2 or st.pstdev(xs) == 0 or st.pstdev(ys) == 0:
        return float("nan")
    return st.correlation(xs, ys)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="build/release/bin")
    ap.add_argument("--data", default=os.path.join(
        os.environ.get("SCALED_SHARED_DIR", "../shared"), "data", "redkitchen"))
    ap.add_argument("--seeds", default="1-8")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--flag", action="append", default=[],
                    help="a scale-eval flag for the tracker's runs (e.g. --flag=--camera=FILE)")
    ap.add_argument("--min-views", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--work", default="")
    ap.add_argument("--reuse", action="store_true",
                    help="read the outputs already in --work instead of running scale-eval")
    a = ap.parse_args()
    if not os.path.isdir(a.data):
        print(f"object_drift: no dataset at {a.data}", file=sys.stderr)
        return 2
    work = a.work or tempfile.mkdtemp(prefix="object_drift.")
    seeds = parse_seeds(a.seeds)
    jobs = [(os.path.join(work, "truth"), ["--truth-geometry"])]
    jobs += [(os.path.join(work, f"seed{s}"), ["--set", f"tracker.seed={s}"] + a.flag)
             for s in seeds]
    with ThreadPoolExecutor(a.jobs) as pool:
        outs = list(pool.map(lambda j: run(a, j[0], j[1]), jobs))
    truth = views_of(outs[0])

    print("| seed | object | views | span (frames) | sd log(D_truth / D_map) | sd log window truth "
          "| correlation | slope |")
    print("|---|---|---|---|---|---|---|---|")
    pooled_unit, pooled_window, pooled_metric = [], [], []
    for seed, out in zip(seeds, outs[1:]):
        window = window_of(out)
        objects = {}
        for key, (oid, cls, D) in views_of(out).items():
            if key in truth and key[0] in window:
                objects.setdefault((oid, cls), []).append(
                    (key[0], math.log(truth[key][2] / D), math.log(window[key[0]]),
                     -math.log(truth[key][2])))
        for (oid, cls), v in sorted(objects.items()):
            if len(v) < a.min_views:
                continue
            unit = centred([x[1] for x in v])
            win = centred([x[2] for x in v])
            pooled_unit += unit
            pooled_window += win
            pooled_metric += centred([x[3] for x in v])
            span = max(x[0] for x in v) - min(x[0] for x in v)
            print(f"| {seed} | {oid} {cls} | {len(v)} | {span} | {st.pstdev(unit):.3f} | "
                  f"{st.pstdev(win):.3f} | {corr(win, unit):.2f} | {slope(win, unit):.2f} |")
    if pooled_unit:
        print(f"| all | pooled | {len(pooled_unit)} | | {st.pstdev(pooled_unit):.3f} | "
              f"{st.pstdev(pooled_window):.3f} | {corr(pooled_window, pooled_unit):.2f} | "
              f"{slope(pooled_window, pooled_unit):.2f} |")
        print(f"\nthe metric extent alone (-log D_truth, the viewpoint) against the window truth: "
              f"correlation {corr(pooled_window, pooled_metric):.2f}, "
              f"sd {st.pstdev(pooled_metric):.3f}")
    print(f"(scale-eval outputs in {work})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
