#!/usr/bin/env python3
"""Compares a float build of core with a double build on the same data.

Runs the double and the float build's tools on the same inputs and prints a
markdown table of what each gives and their relative difference:

  synthetic  slam-run on a rendered textured room (synth-render, double build):
             ATE RMSE and the Sim(3) scale; scale-sim's three experiments:
             final scale estimate and median relative error
  real       slam-run and scale-eval on 7-Scenes redkitchen (when present):
             ATE RMSE, Sim(3) scale, scale estimate, its 95% interval and
             median relative error

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
    ap.add_argument("--tolerance", type=float, default=0.01)
    ap.add_argument("--work", default="", help="scratch directory (default: a temporary one)")
    args = ap.parse_args()

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
            runs = [run_json([tool(b, "slam-run"), "--dataset", kitchen, "--json"] + extra)
                    for b in builds]
            compare("redkitchen (slam-run)", runs,
                    [("ATE RMSE (m)", "ate_rmse_m"), ("Sim(3) scale", "scale_to_gt")])
            if os.path.isfile(model):
                runs = [run_json([tool(b, "scale-eval"), "--dataset", kitchen, "--json",
                                  "--set", f"detector.model={model}"] + extra)
                        for b in builds]
                compare("redkitchen (scale-eval)", runs,
                        # The final posterior: scale_est is given only after
                        # convergence (rel. 95% width < 10%), a threshold a 0.1%
                        # change can cross.
                        [("scale estimate (final MAP)", "posterior_final.map"),
                         ("95% lo", "posterior_final.ci95.0"),
                         ("95% hi", "posterior_final.ci95.1"),
                         ("true scale", "scale_true")])
                rows.append(("redkitchen (scale-eval)", "observations (not bounded)",
                             get(runs[0], "posterior_final.observations"),
                             get(runs[1], "posterior_final.observations")))
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
        print(f"| {data} | {label} | {d if d is not None else '-'} | "
              f"{f if f is not None else '-'} | {text} |")
        if "not bounded" in label:
            continue
        if rel is None:
            worst = float("inf")
        else:
            worst = max(worst, rel)
    ok = worst <= args.tolerance
    print(f"\nlargest difference {100 * worst:.3f}% (bound {100 * args.tolerance:g}%): "
          f"{'within' if ok else 'OUTSIDE'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
