#!/usr/bin/env python3
"""Plot the map's sliding-window scale of one or more runs
(``slam-run --window-out CSV``) into one PNG.

Usage:
    tools/plot_window_scale.py OUT.png CSV [CSV ...] [--title TEXT]

Each CSV (columns t_s,scale) becomes one line labelled by its file name,
each normalised by its own median so that runs with different map units
share the axis: a flat line at 1 is a map whose scale held. Needs
python3-matplotlib. Exit codes: 0 ok, 65 malformed CSV (file and line
named), 66 a CSV missing, 69 matplotlib cannot be imported.
"""
import argparse
import csv
import os
import statistics
import sys

EX_DATAERR, EX_NOINPUT, EX_UNAVAILABLE = 65, 66, 69


def read(path):
    t, s = [], []
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows, None)
        if header != ["t_s", "scale"]:
            raise ValueError(f"{path}:1: expected the header t_s,scale, got {header}")
        for n, row in enumerate(rows, start=2):
            if len(row) != 2:
                raise ValueError(f"{path}:{n}: expected 2 fields, got {len(row)}")
            try:
                t.append(float(row[0]))
                s.append(float(row[1]) if row[1] else float("nan"))
            except ValueError:
                raise ValueError(f"{path}:{n}: not a number: {row}") from None
    return t, s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", metavar="OUT.png")
    ap.add_argument("csv", nargs="+")
    ap.add_argument("--title", default="sliding-window Sim(3) scale / its median")
    a = ap.parse_args(argv)
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        print(f"plot_window_scale: cannot import matplotlib ({e}); install python3-matplotlib",
              file=sys.stderr)
        return EX_UNAVAILABLE
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=120)
    for path in a.csv:
        if not os.path.isfile(path):
            print(f"plot_window_scale: {path}: no such file", file=sys.stderr)
            return EX_NOINPUT
        try:
            t, s = read(path)
        except ValueError as e:
            print(f"plot_window_scale: {e}", file=sys.stderr)
            return EX_DATAERR
        valid = [x for x in s if x == x]
        if not valid:
            continue
        med = statistics.median(valid)
        ax.plot(t, [x / med for x in s], lw=1.2,
                label=f"{os.path.basename(path)} (max/min {max(valid) / min(valid):.3f})")
    ax.axhline(1, color="0.4", lw=0.8)
    ax.set_xlabel("time of the window's last frame (s)")
    ax.set_ylabel("window scale / median")
    ax.set_title(a.title)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(a.out)
    print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
