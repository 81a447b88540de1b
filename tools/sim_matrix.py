#!/usr/bin/env python3
"""Runs scale-sim over seeds and configurations and prints a Markdown table of
median relative error after convergence (mean and worst over seeds), as
recorded in docs/method.md.

    tools/sim_matrix.py [--bin build/bin/scale-sim] [--seeds 20]
"""
import argparse
import json
import statistics
import subprocess
import sys

PAPER = ["--variance", "paper", "--roll-compensation", "off", "--weighting", "feature"]
CONFIGS = [
    ("paper (literal): paper variance, axis-aligned box, per-feature", PAPER),
    ("paper + roll compensation", PAPER[:2] + ["--roll-compensation", "on", "--weighting", "feature"]),
    ("paper + per-box weighting", PAPER[:4] + ["--weighting", "box"]),
    ("propagated variance, roll compensation, per-feature", ["--weighting", "feature"]),
    ("propagated variance, per-box, no roll compensation", ["--roll-compensation", "off"]),
    ("**scale-sim default**: propagated, roll compensation, per-box", []),
    ("default + robust likelihood", ["--robust"]),
    ("default + drift 0.002 per update", ["--drift", "0.002"]),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="build/bin/scale-sim")
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    names = None
    print(f"seeds 1..{args.seeds}; each cell: mean / worst median_rel_error over seeds / "
          "mean 95% interval coverage after convergence (never-converged runs count as 100% "
          "error, 0% coverage)\n")
    rows = []
    for label, flags in CONFIGS:
        per_exp = {}
        for seed in range(1, args.seeds + 1):
            out = subprocess.run([args.bin, "--json", "--seed", str(seed), *flags],
                                 check=True, capture_output=True, text=True).stdout
            for e in json.loads(out)["experiments"]:
                conv = e["converged_at_update"] is not None
                err = e["median_rel_error"] if conv else 1.0
                cov = e["ci95_coverage"] if conv else 0.0
                per_exp.setdefault(e["name"], []).append((err, cov))
        names = list(per_exp)
        cells = [f"{100 * statistics.mean(x[0] for x in v):.2f}% / "
                 f"{100 * max(x[0] for x in v):.2f}% / {100 * statistics.mean(x[1] for x in v):.0f}%"
                 for v in per_exp.values()]
        rows.append((label, cells))
    print("| configuration | " + " | ".join(names) + " |")
    print("|---|" + "---|" * len(names))
    for label, cells in rows:
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    sys.exit(main())
