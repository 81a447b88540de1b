#!/usr/bin/env python3
"""The object-model ablation over RANSAC seeds 1-8 and each half of a sequence run alone.

Usage (from the project root, after a release build):
    tools/scale_ablation.py [--bin build/release/bin] [--data ../shared/data/redkitchen]
                            [--jobs 2] [--row NAME=K=V,K=V]... [--per-run] [--set K=V]...
                            [--wide | --phases]

Every row is scale-eval with the given --set overrides (on top of --set, which applies to all
rows) over the ten runs of ../shared/tools/generality.py (tracker.seed 1..8, --frames 0:300,
--frames 300:600). It prints one markdown table: per row the median of the seeds' median
relative errors 5 s after the map started and the worst seed's, each half's median, the
smallest ci95 coverage of the ten runs, the converged updates whose interval excludes the truth
(summed), the observations per 100 frames (median) and the final 95% width against the
information limit (medians). With --per-run, one table per row with every run as well.
Without --row, the rows of docs/accuracy.md's ablation. Nothing here knows a bound.

With --wide, 26 runs instead of ten: tracker.seed 1..16, and five 300-frame windows
(--frames 0:300, 100:400, 150:450, 200:500, 300:600) each with seeds 1 and 2; per row the
median and worst (and how many runs are at most 10%) of the error 5 s after the map started
against the whole-run truth and against the sliding-window truth, over the seeds and over the
windows; how many runs keep the window truth within 8% of the run's own (the map's drift);
metric ATE; the smallest ci95 coverage.

With --phases, the ten runs at each of the detector's ten phases (detection.phase_frames 0..9:
which frame of every ten the detector sees; 100 runs a row): per row the issue 18 figures at
each phase (median and worst of the seeds' medians 5 s after the map started, each half), how
many phases are within 5% / 10% / 10% / 10%, the seeds' median against the window truth and the
smallest ci95 coverage. The phase is a lottery like the seed: which views the estimator gets.
"""
import argparse
import concurrent.futures as cf
import json
import os
import statistics
import subprocess
import sys

RUNS = [("seed %d" % s, ["--set", "tracker.seed=%d" % s]) for s in range(1, 9)] + [
    ("frames 0:300", ["--frames", "0:300"]),
    ("frames 300:600", ["--frames", "300:600"]),
]

WIDE_RUNS = [("seed %d" % s, ["--set", "tracker.seed=%d" % s]) for s in range(1, 17)] + [
    ("frames %s seed %d" % (w, s), ["--frames", w, "--set", "tracker.seed=%d" % s])
    for w in ("0:300", "100:400", "150:450", "200:500", "300:600") for s in (1, 2)]

DEFAULT_ROWS = [
    ("paper model (issue 5 defaults)", ["estimator.model=paper"]),
    ("object model (defaults)", []),
    ("object, width model on", ["objects.width_model=true"]),
    ("object, independent heights per view", ["objects.one_height=false"]),
    ("object, no outlier term", ["estimator.robust=false"]),
    ("object, no partial visibility", ["estimator.partial_visibility=false"]),
]


def run(exe, data, args):
    p = subprocess.run([exe, "--dataset", data, "--json"] + args, capture_output=True, text=True)
    lines = [l for l in p.stdout.splitlines() if l.startswith("{")]
    if p.returncode != 0 or not lines:
        return {"_error": (p.stderr.strip().splitlines() or ["exit %d" % p.returncode])[-1]}
    return json.loads(lines[-1])


def row_results(name, jobs):
    """The row's results by run name; None (the row printed as its first error) if a run failed."""
    res = {rn: f.result() for (n, rn), f in jobs.items() if n == name}
    errs = [d for d in res.values() if "_error" in d]
    if errs:
        print("| %s | error: %s |" % (name, errs[0]["_error"][:80]))
        return None
    return res


def err(d):
    """The run's median relative error 5 s or more after the map started (whole-run truth)."""
    return d["rel_error_after_5s"]["median"]


def werr(d):
    """The same against the sliding-window truth."""
    return d["rel_error_after_5s_window"]["median"]


def fmt(v, pct=False):
    if v is None:
        return "-"
    return ("%.1f%%" % (100 * v)) if pct else ("%.3g" % v)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="build/release/bin")
    ap.add_argument("--data", default=os.path.join(os.environ.get("SCALED_SHARED_DIR", "../shared"),
                                                   "data/redkitchen"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--row", action="append", default=[], help="NAME=K=V,K=V")
    ap.add_argument("--set", action="append", default=[], help="K=V for every row")
    ap.add_argument("--flag", action="append", default=[], help="a scale-eval flag for every row")
    ap.add_argument("--per-run", action="store_true")
    matrix = ap.add_mutually_exclusive_group()
    matrix.add_argument("--wide", action="store_true", help="26 runs (seeds 1-16, five windows)")
    matrix.add_argument("--phases", action="store_true",
                    help="the ten runs at each detection.phase_frames 0..9 (100 runs)")
    a = ap.parse_args()
    runs = WIDE_RUNS if a.wide else RUNS
    if a.phases:
        runs = [("%s phase %d" % (rn, ph), args + ["--set", "detection.phase_frames=%d" % ph])
                for ph in PHASES for rn, args in RUNS]
    exe = os.path.join(a.bin, "scale-eval")
    if not os.access(exe, os.X_OK):
        sys.exit("scale_ablation: %s not found (build the release preset first)" % exe)
    rows = DEFAULT_ROWS
    if a.row:
        rows = []
        for r in a.row:
            name, _, sets = r.partition("=")
            rows.append((name, [s for s in sets.split(",") if s]))
    common = [x for kv in a.set for x in ("--set", kv)] + a.flag
    jobs = {}
    with cf.ThreadPoolExecutor(a.jobs) as pool:
        for name, sets in rows:
            extra = [x for kv in sets for x in ("--set", kv)]
            for run_name, args in runs:
                jobs[(name, run_name)] = pool.submit(run, exe, a.data, args + common + extra)
    if a.wide:
        print_wide(rows, jobs, a.per_run)
        return
    if a.phases:
        print_phases(rows, jobs, a.per_run)
        return
    print("| row | seeds: median / worst of the medians | 0:300 | 300:600 | min ci95 coverage |"
          " wrong converged | obs / 100 frames | final 95% width / limit |")
    print("|---|---|---|---|---|---|---|---|")
    for name, _ in rows:
        res = row_results(name, jobs)
        if res is None:
            continue
        seeds = [err(res["seed %d" % s]) for s in range(1, 9)]
        seeds_ok = [x for x in seeds if x is not None]
        cov = [res[rn]["ci95_coverage"] for rn, _ in RUNS if res[rn]["ci95_coverage"] is not None]
        wrong = sum(res[rn]["wrong_converged_updates"] for rn, _ in RUNS)
        obs = statistics.median(res[rn]["observations_per_100_frames"] for rn, _ in RUNS)
        widths = [res[rn]["posterior_final"]["rel_width95"] for rn, _ in RUNS
                  if res[rn]["posterior_final"]["rel_width95"] is not None]
        limits = [res[rn]["information_limit"]["rel_width95_final"] for rn, _ in RUNS
                  if res[rn]["information_limit"]["rel_width95_final"] is not None]
        print("| %s | %s / %s%s | %s | %s | %s | %d | %s | %s / %s |" % (
            name,
            fmt(statistics.median(seeds_ok) if seeds_ok else None, True),
            fmt(max(seeds_ok) if seeds_ok else None, True),
            "" if len(seeds_ok) == 8 else " (%d none)" % (8 - len(seeds_ok)),
            fmt(err(res["frames 0:300"]), True), fmt(err(res["frames 300:600"]), True),
            fmt(min(cov) if cov else None, True), wrong, fmt(obs),
            fmt(statistics.median(widths) if widths else None, True),
            fmt(statistics.median(limits) if limits else None, True)))
        if a.per_run:
            for rn, _ in RUNS:
                d = res[rn]
                e = d["rel_error_after_5s"]
                print("|   %s | median %s, max %s | | | %s | %d | %s | %s / %s |" % (
                    rn, fmt(e["median"], True), fmt(e["max"], True), fmt(d["ci95_coverage"], True),
                    d["wrong_converged_updates"], fmt(d["observations_per_100_frames"]),
                    fmt(d["posterior_final"]["rel_width95"], True),
                    fmt(d["information_limit"]["rel_width95_final"], True)))


def stat(values, bound):
    """'median / worst (n of m at most bound)' of relative errors, in %."""
    v = [x for x in values if x is not None]
    if not v:
        return "-"
    return "%s / %s (%d/%d)" % (fmt(statistics.median(v), True), fmt(max(v), True),
                                sum(1 for x in v if x <= bound), len(values))


PHASES = range(10)


def print_phases(rows, jobs, per_run):
    print("| row | seeds: median of the medians, per phase | median / worst over phases (<= 5%) |"
          " worst seed, median / worst over phases (<= 10%) | 0:300 (<= 10%) | 300:600 (<= 10%) |"
          " vs window truth, seeds: median / worst over phases | min ci95 coverage |")
    print("|---|---|---|---|---|---|---|---|")
    for name, _ in rows:
        res = row_results(name, jobs)
        if res is None:
            continue
        med, worst, first, second, window = [], [], [], [], []
        for ph in PHASES:
            seeds = [err(res["seed %d phase %d" % (s, ph)]) for s in range(1, 9)]
            seeds = [x if x is not None else float("inf") for x in seeds]
            med.append(statistics.median(seeds))
            worst.append(max(seeds))
            first.append(err(res["frames 0:300 phase %d" % ph]))
            second.append(err(res["frames 300:600 phase %d" % ph]))
            w = [werr(res["seed %d phase %d" % (s, ph)]) for s in range(1, 9)]
            window.append(statistics.median(x for x in w if x is not None))
        cov = [d["ci95_coverage"] for d in res.values() if d["ci95_coverage"] is not None]

        def over(v, bound):
            v = [x if x is not None else float("inf") for x in v]
            return "%s / %s (%d/%d)" % (fmt(statistics.median(v), True), fmt(max(v), True),
                                        sum(1 for x in v if x <= bound), len(v))
        print("| %s | %s | %s | %s | %s | %s | %s / %s | %s |" % (
            name, " ".join("%.1f" % (100 * x) for x in med), over(med, 0.05), over(worst, 0.10),
            over(first, 0.10), over(second, 0.10), fmt(statistics.median(window), True),
            fmt(max(window), True), fmt(min(cov) if cov else None, True)))
        if per_run:
            for ph in PHASES:
                print("|   phase %d | seeds %s | | | %s | %s | | |" % (
                    ph, " ".join("%.1f" % (100 * err(res["seed %d phase %d" % (s, ph)]))
                                 if err(res["seed %d phase %d" % (s, ph)]) is not None else "-"
                                 for s in range(1, 9)),
                    fmt(first[ph], True), fmt(second[ph], True)))


def print_wide(rows, jobs, per_run):
    print("| row | after 5 s, seeds 1-16 | after 5 s, 5 windows x 2 seeds | vs window truth, seeds |"
          " vs window truth, windows | window truth within 8% | metric ATE % of path |"
          " min ci95 coverage |")
    print("|---|---|---|---|---|---|---|---|")
    for name, _ in rows:
        res = row_results(name, jobs)
        if res is None:
            continue
        seeds = [res[rn] for rn, _ in WIDE_RUNS if rn.startswith("seed")]
        wins = [res[rn] for rn, _ in WIDE_RUNS if rn.startswith("frames")]
        dev = [d["scale_true_window_max_dev"] for d in seeds + wins]
        ate = [d["metric_trajectory"]["ate_percent_of_path"] for d in seeds + wins]
        ate = [x for x in ate if x is not None]
        cov = [d["ci95_coverage"] for d in seeds + wins if d["ci95_coverage"] is not None]
        print("| %s | %s | %s | %s | %s | %d/%d | %s / %s | %s |" % (
            name, stat([err(d) for d in seeds], 0.10), stat([err(d) for d in wins], 0.10),
            stat([werr(d) for d in seeds], 0.10), stat([werr(d) for d in wins], 0.10),
            sum(1 for x in dev if x is not None and x <= 0.08), len(dev),
            fmt(statistics.median(ate)) if ate else "-", fmt(max(ate)) if ate else "-",
            fmt(min(cov) if cov else None, True)))
        if per_run:
            for rn, _ in WIDE_RUNS:
                d = res[rn]
                print("|   %s | %s | | %s | | %s | %s | %s |" % (
                    rn, fmt(err(d), True), fmt(werr(d), True),
                    fmt(d["scale_true_window_max_dev"], True),
                    fmt(d["metric_trajectory"]["ate_percent_of_path"]),
                    fmt(d["ci95_coverage"], True)))


if __name__ == "__main__":
    main()
