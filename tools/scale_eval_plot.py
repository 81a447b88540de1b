#!/usr/bin/env python3
"""Plot the output of ``scale-eval --out DIR`` as four paper-style figures
(after Sucar & Hayet, CVPR-W 2017: likelihoods, posterior, estimates, errors).

Usage:
    tools/scale_eval_plot.py OUT_DIR [--title TEXT] [--no-curves]

Reads frames.csv, updates.csv, observations.csv, posterior.csv,
likelihoods.csv and (if present) summary.json from OUT_DIR and writes
fig_a_likelihoods.png, fig_b_posterior.png, fig_c_estimates.png and
fig_d_rel_error.png into OUT_DIR (and fig_e_objects.png, each object's own
estimate over time, when objects.csv is there; fig_f_map_scale.png, the
map's ground-truth scale so far and over the sliding window;
fig_g_trajectory.png, the metric camera path from above and its height over
time, when poses.csv is there: field-log's POSE lines), printing one line per
written file.
With --no-curves (field-log output: no posterior curves are logged)
posterior.csv and likelihoods.csv are not read and only figures (c) and (d)
are drawn.
Empty CSV fields mean "not available". Needs python3-numpy and
python3-matplotlib (Agg backend, no display).

Exit codes: 0 ok, 65 malformed input (file, line and problem are named),
66 OUT_DIR or a CSV missing, 69 numpy/matplotlib cannot be imported.
"""
import argparse
import csv
import json
import math
import os
import sys
import warnings

try:
    import numpy as np
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize
    from matplotlib.cm import ScalarMappable
    from matplotlib.ticker import LogLocator, FormatStrFormatter, NullFormatter
    IMPORT_ERROR = None
except ImportError as exc:  # reported in main() so that --help still works
    IMPORT_ERROR = exc

EX_DATAERR, EX_NOINPUT, EX_UNAVAILABLE = 65, 66, 69
FRAMES_COLS = ("frame,t_s,tracked,epoch,features_measured,scale_est,ci95_lo,"
               "ci95_hi,state,scale_true,scale_true_window,rel_error,"
               "rel_error_window,baseline_constant_rel_error,"
               "baseline_single_rel_error").split(",")
UPDATES_COLS = ("update,frame,t_s,epoch,detections,observations,"
                "total_observations,scale_est,mean,ci68_lo,ci68_hi,ci95_lo,"
                "ci95_hi,rel_width95,state,converged,scale_true,"
                "scale_true_window,rel_error,rel_error_window").split(",")
OBS_COLS = ("update,frame,observation,class,score,D,sigma_D,local_estimate,"
            "weight").split(",")
# objects.csv (model object; optional): the columns figure (e) needs.
OBJ_COLS = "frame,id,class,state,local_estimate".split(",")
# poses.csv (field-log; optional): the columns figure (g) needs.
POSES_COLS = "t_s,epoch,x_m,y_m,z_m,run".split(",")
TEXT_COLS = {"state", "class"}
PAPER_REL_ERROR_PCT = 2.0


class InputError(Exception):
    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


def fail(path, line, problem):
    raise InputError(EX_DATAERR, f"{path}:{line}: {problem}")


def read_csv(path):
    """(header line, header, [(line, fields)]) with all rows checked for
    width; blank lines are skipped."""
    if not os.path.isfile(path):
        raise InputError(EX_NOINPUT, f"{path}: required file is missing")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        rows = [(reader.line_num, [t.strip() for t in fields])
                for fields in reader if any(t.strip() for t in fields)]
    if not rows:
        fail(path, 1, "empty file, no header line")
    (hline, header), body = rows[0], rows[1:]
    for line, fields in body:
        if len(fields) != len(header):
            fail(path, line, f"expected {len(header)} fields, "
                 f"got {len(fields)}")
    return hline, header, body


def to_float(text, path, line, col):
    if text == "":
        return math.nan
    try:
        return float(text)
    except ValueError:
        fail(path, line, f"column '{col}': non-numeric value '{text}'")


def read_table(path, required):
    """Read a CSV into {column: float array}; text columns stay lists."""
    hline, header, body = read_csv(path)
    missing = [c for c in required if c not in header]
    if missing:
        fail(path, hline, "missing column(s) " + ", ".join(missing))
    data = {c: [] for c in header}
    for line, fields in body:
        for col, text in zip(header, fields):
            data[col].append(text if col in TEXT_COLS
                             else to_float(text, path, line, col))
    return {c: (v if c in TEXT_COLS else np.array(v, dtype=float))
            for c, v in data.items()}


def read_grid(path, lead):
    """Read posterior.csv / likelihoods.csv: (d grid, lead cols, values)."""
    hline, header, body = read_csv(path)
    n = len(lead)
    if header[:n] != lead:
        fail(path, hline, f"header must start with {','.join(lead)}")
    d = np.array([to_float(t, path, hline, "grid") for t in header[n:]])
    if len(d) < 2 or not np.all(d > 0) or not np.all(np.diff(d) > 0):
        fail(path, hline, "grid d values must be at least 2 positive, "
             "increasing numbers")
    nums = np.array([[to_float(t, path, line, c) for t, c in
                      zip(fields, header)] for line, fields in body],
                    dtype=float).reshape(-1, len(header))
    return d, nums[:, :n], nums[:, n:]


def read_summary(path):
    if not os.path.isfile(path):
        print(f"scale_eval_plot: warning: {path} missing, using defaults",
              file=sys.stderr)
        return {}
    try:
        with open(path, encoding="utf-8") as f:
            summary = json.load(f)
    except json.JSONDecodeError as e:
        fail(path, e.lineno, f"invalid JSON: {e.msg}")
    if not isinstance(summary, dict):
        fail(path, 1, "not a JSON object")
    return summary


def number(value):
    """A finite float from a JSON value, else None."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    return float(value) if ok and math.isfinite(value) else None


def rownorm(logv):
    """exp(log values), each row normalised to max 1 (NaN stays NaN)."""
    return np.exp(logv - np.nanmax(logv, axis=1, keepdims=True))


def epochs(epoch):
    """Slices of consecutive rows that share an epoch."""
    e = np.nan_to_num(np.asarray(epoch, dtype=float), nan=-1.0)
    cuts = [0] + list(np.nonzero(np.diff(e))[0] + 1) + [len(e)]
    return [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]


def plot_epochs(ax, x, y, epoch, label, **kw):
    """Plot y(x) without joining points across SLAM epochs; skip if all NaN."""
    if not np.isfinite(y).any():
        return
    for i, s in enumerate(epochs(epoch)):
        lone = s.stop - s.start == 1  # a lone point needs a marker
        ax.plot(x[s], y[s], label=label if i == 0 else None,
                marker="o" if lone else None, ms=4, **kw)


def note(ax, text):
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center",
            va="center", fontsize=14, color="0.35",
            bbox=dict(facecolor="white", edgecolor="0.7", alpha=0.9))


def log_ticks(axis):
    """Label 1-2-5 ticks of a log axis as plain numbers."""
    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_formatter(NullFormatter())


def geometric_edges(d):
    mid = np.sqrt(d[1:] * d[:-1])
    return np.concatenate([[d[0] ** 2 / mid[0]], mid, [d[-1] ** 2 / mid[-1]]])


def linear_edges(x):
    return np.concatenate([[x[0] - 0.5], (x[1:] + x[:-1]) / 2, [x[-1] + 0.5]])


def support(d, dens, floor):
    """(lo, hi) of the d range where any row exceeds floor, padded."""
    idx = np.nonzero(np.nanmax(dens, axis=0) > floor)[0]
    if len(idx) == 0:
        return d[0], d[-1]
    return max(d[0], d[idx[0]] / 1.5), min(d[-1], d[idx[-1]] * 1.5)


def fig_likelihoods(ax, fig, lik, post, truth, n_updates):
    d, meta, logl = lik
    ax.set_xscale("log")
    log_ticks(ax.xaxis)
    ax.set_xlabel("scale d (m / SLAM unit)")
    ax.set_ylabel("likelihood (normalised to max 1)")
    ax.set_ylim(0, 1.05)
    if len(logl) == 0:
        ax.set_xlim(d[0], d[-1])
        note(ax, "no scale updates" if n_updates == 0 else "no observations")
    else:
        vals = rownorm(logl)
        upd = meta[:, 1]
        good = upd[np.isfinite(upd)]
        lo, hi = (good.min(), good.max()) if len(good) else (0.0, 1.0)
        norm = Normalize(lo, max(hi, lo + 1))
        alpha = float(np.clip(6.0 / math.sqrt(len(vals)), 0.04, 0.6))
        lc = LineCollection([np.column_stack([d, v]) for v in vals],
                            cmap="viridis", norm=norm, linewidths=0.7,
                            alpha=alpha)
        lc.set_array(upd)
        ax.add_collection(lc)
        fig.colorbar(ScalarMappable(norm=norm, cmap="viridis"), ax=ax,
                     label="update index")
        ax.set_xlim(*support(d, vals, 1e-3))
    pd, _, logp = post
    if len(logp) and np.any(np.isfinite(logp[-1])):
        ax.plot(pd, rownorm(logp[-1:])[0], color="black", lw=1.8,
                label="final posterior")
    if truth is not None:
        ax.axvline(truth, color="red", ls="--", lw=1.3,
                   label=f"scale_true = {truth:.4g}")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right")


def fig_posterior(ax, fig, post, upd):
    d, meta, logp = post
    ax.set_yscale("log")
    log_ticks(ax.yaxis)
    ax.set_xlabel("update index")
    ax.set_ylabel("scale d (m / SLAM unit)")
    if len(logp) == 0:
        ax.set_ylim(d[0], d[-1])
        note(ax, "no scale updates")
        return
    x = meta[:, 0]
    if not (np.all(np.isfinite(x)) and np.all(np.diff(x) > 0)):
        x = np.arange(len(logp), dtype=float)
    dens = rownorm(logp)
    mesh = ax.pcolormesh(linear_edges(x), geometric_edges(d), dens.T,
                         cmap="viridis", vmin=0, vmax=1, shading="flat")
    fig.colorbar(mesh, ax=ax, label="posterior density (normalised, max 1)")
    ax.set_ylim(*support(d, dens, 1e-4))
    ax.set_xlim(x[0] - 0.5, x[-1] + 0.5)
    plot_epochs(ax, upd["update"], upd["scale_est"], upd["epoch"], "MAP",
                color="white", lw=1.5)
    plot_epochs(ax, upd["update"], upd["scale_true"], upd["epoch"],
                "scale_true", color="red", ls="--", lw=1.3)
    ax.legend(loc="upper right", facecolor="0.85")


def fig_estimates(ax, upd, obs, conv_frame):
    ax.set_xlabel("update index")
    ax.set_ylabel("scale d (m / SLAM unit)")
    u, ep = upd["update"], upd["epoch"]
    if len(u) == 0:
        note(ax, "no scale updates")
        return
    for level, alpha in (("95", 0.18), ("68", 0.35)):
        for i, s in enumerate(epochs(ep)):
            xs, lo, hi = u[s], upd[f"ci{level}_lo"][s], upd[f"ci{level}_hi"][s]
            if len(xs) == 1:  # widen a lone update so its band is visible
                xs, lo, hi = xs + np.array([-0.2, 0.2]), lo.repeat(2), \
                    hi.repeat(2)
            ax.fill_between(xs, lo, hi, color="tab:blue", alpha=alpha, lw=0,
                            label=f"{level}% interval" if i == 0 else None)
    loc = obs["local_estimate"]
    ok = np.isfinite(loc) & np.isfinite(obs["update"])
    if ok.any():
        ax.scatter(obs["update"][ok], loc[ok], s=3, color="0.3", alpha=0.3,
                   lw=0, label="local estimates (per observation)")
    plot_epochs(ax, u, upd["scale_est"], ep, "MAP", color="tab:blue", lw=1.8)
    plot_epochs(ax, u, upd["scale_true"], ep, "scale_true (cumulative)",
                color="black", ls="--", lw=1.3)
    plot_epochs(ax, u, upd["scale_true_window"], ep, "scale_true (window)",
                color="tab:red", ls=":", lw=1.3)
    hit = np.nonzero(upd["frame"] >= (math.inf if conv_frame is None
                                      else conv_frame))[0]
    if len(hit):  # first update at or after the convergence frame
        ax.axvline(u[hit[0]], color="tab:green", ls="-.", lw=1.2,
                   label=f"converged (update {u[hit[0]]:g})")
    ranges = [upd[c] for c in ("scale_est", "scale_true",
                               "scale_true_window")]
    if ok.any():
        ranges.append(np.percentile(loc[ok], [1, 99]))
    vals = np.concatenate(ranges)
    vals = vals[np.isfinite(vals)]
    if len(vals):
        lo, hi = vals.min(), vals.max()
        pad = 0.05 * (hi - lo) if hi > lo else 0.05 * abs(hi) + 1e-9
        ax.set_ylim(max(0.0, lo - pad), hi + pad)
    ax.set_xlim(u[0] - 0.5, u[-1] + 0.5)
    ax.legend(loc="best", fontsize=8)


def fig_objects(ax, objs, upd):
    """(e) Each object's own scale estimate (the mode of its likelihood
    alone) over time, with the MAP and the truth."""
    ax.set_xlabel("frame index")
    ax.set_ylabel("scale d (m / SLAM unit)")
    ids = objs["id"]
    loc = objs["local_estimate"]
    ok = np.isfinite(loc) & np.isfinite(ids)
    if not ok.any():
        note(ax, "no object was used")
    cmap = plt.get_cmap("tab20")
    for k, i in enumerate(sorted(set(ids[ok].astype(int)))):
        sel = ok & (ids == i)
        cls = objs["class"][int(np.nonzero(sel)[0][0])]
        ax.plot(objs["frame"][sel], loc[sel], "o-", ms=2.5, lw=1,
                color=cmap(k % 20), label=f"{i} {cls}")
    plot_epochs(ax, upd["frame"], upd["scale_est"], upd["epoch"], "MAP",
                color="tab:blue", lw=2)
    plot_epochs(ax, upd["frame"], upd["scale_true"], upd["epoch"],
                "scale_true (cumulative)", color="black", ls="--", lw=1.3)
    vals = np.concatenate([loc[ok], upd["scale_est"], upd["scale_true"]])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    if len(vals):
        ax.set_yscale("log")
        lo, hi = np.percentile(vals, [1, 99])
        ax.set_ylim(lo / 1.3, hi * 1.3)
    ax.legend(loc="best", fontsize=7, ncol=2)


def fig_errors(ax, frames, n_updates, conv_frame):
    ax.set_xlabel("frame index")
    ax.set_ylabel("|relative error| (%)")
    x, ep = frames["frame"], frames["epoch"]
    series = [("rel_error_window", "MAP vs window truth", "tab:cyan", "-", 1),
              ("baseline_constant_rel_error", "baseline: constant scale",
               "tab:orange", "--", 1.3),
              ("baseline_single_rel_error", "baseline: single early "
               "detection", "tab:red", ":", 1.5),
              ("rel_error", "MAP vs cumulative truth", "tab:blue", "-", 2)]
    allv = []
    for col, label, color, ls, lw in series:
        y = 100.0 * np.abs(frames[col])
        plot_epochs(ax, x, y, ep, label, color=color, ls=ls, lw=lw)
        allv.append(y[np.isfinite(y)])
    allv = np.concatenate(allv)
    notes = (["no scale updates"] if n_updates == 0 else []) + \
        (["no ground truth"] if len(allv) == 0 else [])
    if notes:
        note(ax, "\n".join(notes))
    ax.axhline(PAPER_REL_ERROR_PCT, color="0.4", lw=1, ls="-.",
               label=f"paper: {PAPER_REL_ERROR_PCT:g}%")
    if conv_frame is not None:
        ax.axvline(conv_frame, color="tab:green", ls="-.", lw=1.2,
                   label=f"converged (frame {conv_frame:g})")
    top = 5.0
    if len(allv):
        top = max(top, 1.15 * float(np.percentile(allv, 99)))
    ax.set_ylim(0, min(50.0, top))
    if len(x) and np.isfinite(x).any():
        ax.set_xlim(np.nanmin(x), max(np.nanmax(x), np.nanmin(x) + 1))
    ax.legend(loc="best", fontsize=8)


def fig_map_scale(ax, frames, summary):
    """The map's own scale: the Sim(3) scale of the epoch so far and of the
    sliding window, per frame; where they part, the map drifts (issue 19)."""
    ax.set_xlabel("frame index")
    ax.set_ylabel("ground-truth scale (m per SLAM unit)")
    x, ep = frames["frame"], frames["epoch"]
    window = summary.get("window_frames")
    plot_epochs(ax, x, frames["scale_true"], ep, "epoch so far",
                color="tab:blue", lw=2)
    plot_epochs(ax, x, frames["scale_true_window"], ep,
                f"last {window} frames" if window else "sliding window",
                color="tab:cyan", lw=1.2)
    plot_epochs(ax, x, frames["scale_est"], ep, "served estimate (MAP)",
                color="0.4", lw=1, ls=":")
    if "map_unit_depth" in frames and np.isfinite(frames["map_unit_depth"]).any():
        # --depth-unit: the map's geometry by the depth images, per frame.
        plot_epochs(ax, x, frames["map_unit_depth"], ep,
                    "map geometry (depth images)", color="tab:orange", lw=0.8)
    if not np.isfinite(frames["scale_true"]).any():
        note(ax, "no ground truth")
        return
    rng = number(summary.get("scale_true_window_range"))
    dev = number(summary.get("scale_true_window_max_dev"))
    if rng is not None and dev is not None:
        ax.text(0.02, 0.97, f"window range (max/min) {rng:.3f}\n"
                f"window vs so far: at most {100 * dev:.1f}%",
                transform=ax.transAxes, va="top", fontsize=9,
                bbox=dict(facecolor="white", edgecolor="0.7", alpha=0.9))
    y = np.concatenate([frames["scale_true"], frames["scale_true_window"]])
    y = y[np.isfinite(y)]
    ax.set_ylim(0.8 * float(np.min(y)), 1.2 * float(np.max(y)))
    ax.legend(loc="lower right", fontsize=8)


def fig_trajectory(out_path, poses, suffix):
    """(g) The metric camera path in each map's gravity-aligned frame G
    (x forward at the start, y left, z up; metres at the scale served when
    the pose was logged): from above (x-y) and its height z over time. Each
    (run, epoch) is its own frame G: drawn apart, never joined."""
    fig, (top, side) = plt.subplots(1, 2, figsize=(12, 5), dpi=120,
                                    gridspec_kw={"width_ratios": [1, 1.4]})
    ok = np.isfinite(poses["x_m"]) & np.isfinite(poses["y_m"])
    pairs = list(zip(np.nan_to_num(poses["run"], nan=0).astype(int),
                     np.nan_to_num(poses["epoch"], nan=-1).astype(int)))
    groups = list(dict.fromkeys(p for p, m in zip(pairs, ok) if m))
    several_runs = len({r for r, _ in groups}) > 1
    cmap = plt.get_cmap("tab10")
    for i, (r, e) in enumerate(groups):
        sel = ok & np.array([p == (r, e) for p in pairs], dtype=bool)
        label = f"run {r} epoch {e}" if several_runs else f"epoch {e}"
        c = cmap(i % 10)
        x, y = poses["x_m"][sel], poses["y_m"][sel]
        top.plot(x, y, "-", color=c, lw=1.2, label=label)
        top.plot(x[:1], y[:1], "o", color=c, ms=5)
        top.plot(x[-1:], y[-1:], "s", color=c, ms=5)
        side.plot(poses["t_s"][sel], poses["z_m"][sel], "-", color=c, lw=1.2,
                  label=label, marker="o" if sel.sum() == 1 else None, ms=4)
    top.set_xlabel("x (m, forward at the start)")
    top.set_ylabel("y (m, left)")
    top.set_aspect("equal", adjustable="datalim")
    side.set_xlabel("time (s, source clock)")
    side.set_ylabel("height z (m, up)")
    if not groups:
        note(top, "no metric pose")
        note(side, "no metric pose")
    else:
        top.legend(loc="best", fontsize=8, title="o start, \u25a0 end",
                   title_fontsize=8)
        side.legend(loc="best", fontsize=8)
    for ax in (top, side):
        ax.grid(True, which="major", alpha=0.3)
    top.set_title("(g) Metric trajectory, from above" + suffix, fontsize=10)
    side.set_title("(g) Height over time", fontsize=10)
    fig.tight_layout()
    fig.savefig(out_path, dpi=120)
    plt.close(fig)
    print(out_path)


def run(out_dir, extra_title, curves=True):
    warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows etc.
    if not os.path.isdir(out_dir):
        raise InputError(EX_NOINPUT, f"{out_dir}: OUT_DIR is not a directory")
    path = lambda name: os.path.join(out_dir, name)  # noqa: E731
    frames = read_table(path("frames.csv"), FRAMES_COLS)
    upd = read_table(path("updates.csv"), UPDATES_COLS)
    obs = read_table(path("observations.csv"), OBS_COLS)
    if curves:
        post = read_grid(path("posterior.csv"), ["update", "frame"])
        lik = read_grid(path("likelihoods.csv"), ["observation", "update"])
    summary = read_summary(path("summary.json"))

    dataset = summary.get("dataset") or os.path.basename(
        os.path.normpath(out_dir))
    truth = number(summary.get("scale_true_final"))
    known = upd["scale_true"][np.isfinite(upd["scale_true"])]
    if truth is None and len(known):
        truth = float(known[-1])
    conv_frame = number(summary.get("converged_at_frame"))
    suffix = f" — {dataset}" + (f" — {extra_title}" if extra_title else "")
    n_upd = len(upd["update"])
    figs = [("fig_a_likelihoods.png", "(a) Observation likelihoods",
             lambda ax, fig: fig_likelihoods(ax, fig, lik, post, truth,
                                             n_upd)),
            ("fig_b_posterior.png", "(b) Posterior evolution",
             lambda ax, fig: fig_posterior(ax, fig, post, upd)),
            ("fig_c_estimates.png", "(c) Scale estimates",
             lambda ax, fig: fig_estimates(ax, upd, obs, conv_frame)),
            ("fig_d_rel_error.png", "(d) Relative error",
             lambda ax, fig: fig_errors(ax, frames, n_upd, conv_frame))]
    if not curves:
        figs = figs[2:]
    figs.append(("fig_f_map_scale.png", "(f) The map's scale",
                 lambda ax, fig: fig_map_scale(ax, frames, summary)))
    if os.path.isfile(path("objects.csv")):
        objs = read_table(path("objects.csv"), OBJ_COLS)
        figs.append(("fig_e_objects.png", "(e) Per-object estimates",
                     lambda ax, fig: fig_objects(ax, objs, upd)))
    for name, title, draw in figs:
        fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
        draw(ax, fig)
        ax.grid(True, which="major", alpha=0.3)
        ax.set_title(title + suffix)
        fig.tight_layout()
        fig.savefig(path(name), dpi=120)
        plt.close(fig)
        print(path(name))
    if os.path.isfile(path("poses.csv")):
        fig_trajectory(path("fig_g_trajectory.png"),
                       read_table(path("poses.csv"), POSES_COLS), suffix)
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(
        description="Plot scale-eval output (four PNGs into OUT_DIR).")
    ap.add_argument("out_dir", metavar="OUT_DIR",
                    help="directory written by scale-eval --out")
    ap.add_argument("--title", default="", help="text appended to titles")
    ap.add_argument("--no-curves", action="store_true",
                    help="no posterior.csv/likelihoods.csv (field-log): "
                    "draw figures (c) and (d) only")
    args = ap.parse_args(argv)
    if IMPORT_ERROR is not None:
        print(f"scale_eval_plot: cannot import numpy/matplotlib "
              f"({IMPORT_ERROR}); install python3-matplotlib python3-numpy",
              file=sys.stderr)
        return EX_UNAVAILABLE
    try:
        return run(args.out_dir, args.title, not args.no_curves)
    except InputError as e:
        print(f"scale_eval_plot: {e}", file=sys.stderr)
        return e.code


if __name__ == "__main__":
    sys.exit(main())
