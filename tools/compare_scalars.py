#!/usr/bin/env python3
"""Compares a float build of core with a double build on the same data.

Runs the double and the float build's tools on the same inputs and prints a
markdown table of what each gives and their relative difference:

  synthetic  slam-run on a rendered textured room (synth-render, double build):
             ATE RMSE and the Sim(3) scale; scale-sim's three experiments:
             final scale estimate and median relative error
  real       slam-run and scale-eval on 7-Scenes redkitchen (when present),
             once per RANSAC seed 1..--seeds and build: ATE RMSE, and the final
             scale estimate and its 95% interval as fractions of the true
             scale; each seed's pair is printed, the means over the seeds are
             bounded (one run of the filter on real data is one sample of a
             process that amplifies any perturbation: docs/numerics.md)

Exit status: 0 when every compared quantity of the float build is within
--tolerance (relative, default 1%) of the double build's, 1 otherwise, 2 on
a usage or run error. Standard library only.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile


def run_json(cmd):
    """Runs cmd, returns its stdout parsed as JSON (the last JSON line)."""
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}:\n{proc.stderr[-2000:]}")
    lines = [l for l in proc.stdout.splitlines() if l.startswith("{")]
    if not lines:
        raise RuntimeError(f"{' '.join(cmd)} printed no JSON")
    return json.loads(lines[-1])


def shown(value):
    if value is None:
        return "-"
    return f"{value:.7g}" if isinstance(value, float) else str(value)


def mean(values):
    return sum(values) / len(values)


def get(obj, path):
    for key in path.split("."):
        if obj is None:
            return None
        if key.isdigit():
            obj = obj[int(key)]
        else:
            obj = obj.get(key)
    return obj


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--double", required=True, help="bin directory of the double build")
    ap.add_argument("--float", required=True, dest="flt", help="bin directory of the float build")
    ap.add_argument("--shared", default=os.environ.get("SCALED_SHARED_DIR", "../shared"))
    ap.add_argument("--frames", default="", help="redkitchen frame range A:B (default: all)")
    ap.add_argument("--seeds", type=int, default=8,
                    help="redkitchen: RANSAC seeds 1..N per build (default 8)")
    ap.add_argument("--tolerance", type=float, default=0.01)
    ap.add_argument("--work", default="", help="scratch directory (default: a temporary one)")
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error(f"--seeds must be at least 1 (got {args.seeds})")

    work = args.work or tempfile.mkdtemp(prefix="scaled-scalars-")
    rows = []  # (data, quantity, double, float)

    def tool(build, name):
        path = os.path.join(build, name)
        if not os.access(path, os.X_OK):
            raise RuntimeError(f"{path}: not found (build the tools of both builds first)")
        return path

    def compare(data, runs, quantities):
        for label, path in quantities:
            rows.append((data, label, get(runs[0], path), get(runs[1], path)))

    builds = (args.double, args.flt)
    try:
        # Synthetic images: one rendering (double build), tracked by both.
        synth = os.path.join(work, "synth")
        if not os.path.isdir(os.path.join(synth, "rgb")):
            subprocess.run([tool(args.double, "synth-render"), "--out", synth, "--frames", "300"],
                           check=True, stdout=subprocess.DEVNULL)
        runs = [run_json([tool(b, "slam-run"), "--dataset", synth, "--json"]) for b in builds]
        compare("synthetic room (slam-run, 300 frames)", runs,
                [("ATE RMSE (m)", "ate_rmse_m"), ("ATE / path (%)", "ate_percent_of_path"),
                 ("Sim(3) scale", "scale_to_gt")])

        # The paper's experiments in simulation.
        runs = [run_json([tool(b, "scale-sim"), "--json"]) for b in builds]
        for i, exp in enumerate(runs[0]["experiments"]):
            compare(f"scale-sim {exp['name']}", runs,
                    [("final scale", f"experiments.{i}.final_scale"),
                     ("95% lo", f"experiments.{i}.final_ci95.0"),
                     ("95% hi", f"experiments.{i}.final_ci95.1")])

        kitchen = os.path.join(args.shared, "data", "redkitchen")
        model = os.path.join(args.shared, "models", "yolox_nano.onnx")
        if os.path.isdir(kitchen):
            extra = ["--frames", args.frames] if args.frames else []
            seeds = range(1, args.seeds + 1)
            # One run per RANSAC seed and build. A single run of the filter on
            # real data is one sample of a process that amplifies any
            # perturbation (a seed, a rounding), so the bounded quantities are
            # means over the seeds; each seed's pair is listed, not bounded.
            slam = {b: [] for b in builds}
            for seed in seeds:
                for b in builds:
                    slam[b].append(run_json([tool(b, "slam-run"), "--dataset", kitchen, "--json",
                                             "--seed", str(seed)] + extra))
                rows.append(("redkitchen (slam-run)", f"seed {seed}: ATE RMSE (m), paired, not bounded",
                             slam[builds[0]][-1]["ate_rmse_m"], slam[builds[1]][-1]["ate_rmse_m"]))
            for label, key in (("ATE RMSE (m)", "ate_rmse_m"), ("ATE / path (%)", "ate_percent_of_path")):
                rows.append(("redkitchen (slam-run)", f"{label}, mean of {len(seeds)} seeds",
                             mean([r[key] for r in slam[builds[0]]]),
                             mean([r[key] for r in slam[builds[1]]])))
            if os.path.isfile(model):
                # The SLAM scale differs from seed to seed (each map has its own
                # unit): the estimate is compared as a fraction of each run's
                # true scale, i.e. its metric accuracy.
                ratios = {b: {"map": [], "lo": [], "hi": []} for b in builds}
                for seed in seeds:
                    for b in builds:
                        r = run_json([tool(b, "scale-eval"), "--dataset", kitchen, "--json",
                                      "--set", f"detector.model={model}",
                                      "--set", f"tracker.seed={seed}"] + extra)
                        true = r["scale_true"]
                        ratios[b]["map"].append(get(r, "posterior_final.map") / true)
                        ratios[b]["lo"].append(get(r, "posterior_final.ci95.0") / true)
                        ratios[b]["hi"].append(get(r, "posterior_final.ci95.1") / true)
                    rows.append(("redkitchen (scale-eval)",
                                 f"seed {seed}: final MAP / true scale, paired, not bounded",
                                 ratios[builds[0]]["map"][-1], ratios[builds[1]]["map"][-1]))
                # The final posterior: scale_est is given only after convergence
                # (rel. 95% width < 10%), a threshold a 0.1% change can cross.
                for label, key in (("final MAP / true scale", "map"), ("95% lo / true scale", "lo"),
                                   ("95% hi / true scale", "hi")):
                    rows.append(("redkitchen (scale-eval)", f"{label}, mean of {len(seeds)} seeds",
                                 mean(ratios[builds[0]][key]), mean(ratios[builds[1]][key])))
            else:
                print(f"note: {model} absent: scale-eval on redkitchen skipped", file=sys.stderr)
        else:
            print(f"note: {kitchen} absent: real-data comparison skipped", file=sys.stderr)
    except (RuntimeError, subprocess.CalledProcessError, KeyError, IndexError, TypeError) as e:
        print(f"compare_scalars: {e}", file=sys.stderr)
        return 2

    worst = 0.0
    print("| data | quantity | double | float | relative difference |")
    print("|---|---|---|---|---|")
    for data, label, d, f in rows:
        if d is None or f is None:
            rel = None
            text = "n/a (one build gave none)"
        else:
            rel = abs(f - d) / abs(d) if d != 0 else abs(f - d)
            text = f"{100 * rel:.3f}%"
        # Error figures are compared as fractions of the path/estimate, not relative to
        # themselves (a 0.2% error becoming 0.21% is not a 5% change of the estimate).
        if label == "median rel. error" and d is not None and f is not None:
            rel = abs(f - d)
            text = f"{100 * rel:.3f} points"
        print(f"| {data} | {label} | {shown(d)} | {shown(f)} | {text} |")
        if "not bounded" in label:
            continue
        if rel is None:
            worst = float("inf")
        else:
            worst = max(worst, rel)
    # Paired runs (same seed, double and float): is there a systematic
    # difference, beyond the run-to-run amplification of rounding?
    groups = {}
    for data, label, d, f in rows:
        if label.startswith("seed ") and d is not None and f is not None and d != 0:
            groups.setdefault((data, label.split(": ", 1)[1]), []).append((f - d) / d)
    for (data, label), diffs in groups.items():
        n = len(diffs)
        m = mean(diffs)
        se = (sum((x - m) ** 2 for x in diffs) / (n - 1) / n) ** 0.5 if n > 1 else float("nan")
        print(f"\n{data}, {label.replace(', paired, not bounded', '')}: float - double over "
              f"{n} seeds, mean {100 * m:+.3f}% (standard error {100 * se:.3f}%), "
              f"largest {100 * max(diffs, key=abs):+.3f}%")
    ok = worst <= args.tolerance
    print(f"\nlargest difference {100 * worst:.3f}% (bound {100 * args.tolerance:g}%): "
          f"{'within' if ok else 'OUTSIDE'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
