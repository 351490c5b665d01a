"""Static figures (PNG) like the paper's; the only module that imports matplotlib.

Every `plot_*` function draws one figure and writes it to `path`: a file (written atomically)
or a binary file object (`io.BytesIO`: a figure drawn in a worker, its bytes written by the
main process). Figures are `matplotlib.figure.Figure` objects, not pyplot's: pyplot keeps a
global list of open figures, and figures may be drawn in several threads of one process at
once (a Dask worker's threads).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO, NamedTuple

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle as CirclePatch  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from experiments.io.writers import write_atomic  # noqa: E402
from experiments.render.shapes import ellipse_polyline  # noqa: E402

__all__ = [
    "METHOD_COLORS",
    "SEGMENT_COLORS",
    "break_at_gaps",
    "gaps_of",
    "plot_features",
    "plot_raw_scan",
    "save",
]

Output = Path | BinaryIO  # where a figure goes: a file, or a binary file object

# One colour per kind of thing, in every feature figure (Figs. 3, 4, the Victoria Park scan),
# with the same hues in the rerun views (`experiments.render.viz`): the segments (runs of beams)
# by class, and the fitted circles by method; no colour is used for two kinds.
SEGMENT_COLORS = {  # segment class (`Features.segment_kind`) -> (legend name, colour)
    0: ("clutter", "tab:orange"),
    1: ("line", "tab:blue"),
    2: ("circle", "tab:brown"),
}
METHOD_COLORS = {  # circle-fitting method -> colour of its circles (and curves)
    "paper": "tab:green",
    "geometric": "m",
    "bailey": "goldenrod",
    "taubin": "c",
    "kasa": "tab:purple",
}
EDGE_COLOR = "red"
SCAN_POINT_COLOR = "0.55"


def _subplots(nrows: int = 1, ncols: int = 1, *, figsize, layout=None, **kwargs):
    """(figure, axes) as `pyplot.subplots` makes them, without pyplot's global figure list."""
    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path: Output) -> Output:
    """Write the figure as PNG: to the file `path` atomically (see `write_atomic`), or into the
    binary file object `path` (an `io.BytesIO`); the same bytes either way."""

    def draw(fh) -> None:
        fig.savefig(fh, format="png", dpi=130, bbox_inches="tight")

    if hasattr(path, "write"):
        draw(path)
        return path
    return write_atomic(path, draw)


def break_at_gaps(x, *ys, max_step: float):
    """(x, *ys) with a NaN row inserted wherever consecutive x are more than `max_step` apart,
    so that a line drawn through them stops at the gap (an unobserved landmark, a GPS dropout)
    instead of joining the samples on either side as if there were data between them.

    x (n,) increasing; each y (n,) or (n, k). Returns float arrays of n + (number of gaps) rows.
    """
    x = np.asarray(x, float)
    cut = np.flatnonzero(np.diff(x) > max_step) + 1
    out = [np.insert(x, cut, np.nan)]
    for y in ys:
        out.append(np.insert(np.asarray(y, float), cut, np.nan, axis=0))
    return tuple(out)


def gaps_of(t, max_step: float) -> list[tuple[float, float]]:
    """The gaps of the increasing times t: [(t_before, t_after)] of every pair of consecutive
    samples more than `max_step` apart."""
    t = np.asarray(t, float)
    i = np.flatnonzero(np.diff(t) > max_step)
    return [(float(t[k]), float(t[k + 1])) for k in i]


def plot_raw_scan(points_xy: np.ndarray, title: str, path: Output) -> Output:
    """Fig. 2(b): the points of one whole scan around the sensor at the origin."""
    fig, ax = _subplots(figsize=(6.5, 6.5))
    p = points_xy[np.all(np.isfinite(points_xy), axis=1)]
    ax.plot(p[:, 0], p[:, 1], ".", ms=2.5, color="k", label="scan points")
    ax.plot([0], [0], "r+", ms=12, mew=2, label="laser (two PLS200 back to back)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return save(fig, path)


def zoom_box(circles_xyr: np.ndarray, n: int = 1, margin: float = 1.5):
    """A box around the n circles nearest the sensor."""
    if len(circles_xyr) == 0:
        return None
    near = circles_xyr[np.argsort(np.hypot(circles_xyr[:, 0], circles_xyr[:, 1]))[:n]]
    lo = near[:, :2].min(axis=0) - margin
    hi = near[:, :2].max(axis=0) + margin
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def segments_of(f):
    """[((first, last), kind)] of a `Features`' segments, as `plot_features` takes them."""
    return [((int(a), int(b)), int(k)) for (a, b), k in zip(f.segment_beams, f.segment_kind)]


def _draw(ax, points_xy, segments, circles, edges, truth, lw=1.0):
    p = points_xy
    ax.plot(p[:, 0], p[:, 1], ".", ms=2.5, color=SCAN_POINT_COLOR, zorder=1)
    for (a, b), k in segments:
        q = p[np.arange(a, b + 1) % len(p)]  # runs may cross a 360 deg scan's seam
        ax.plot(q[:, 0], q[:, 1], "-", color=SEGMENT_COLORS[int(k)][1], lw=lw, zorder=2)
    for name, circ, color in circles:
        label = f"circle fit: {name}"
        for i, (cx, cy, r) in enumerate(circ):
            ax.add_patch(
                CirclePatch(
                    (cx, cy),
                    r,
                    fill=False,
                    color=color,
                    lw=1.6,
                    zorder=3,
                    label=label if i == 0 else None,
                )
            )
            ax.patches[-1]._key = label
    if truth is not None and len(truth):
        for i, (cx, cy, r) in enumerate(truth):
            ax.add_patch(
                CirclePatch(
                    (cx, cy),
                    r,
                    fill=False,
                    ls="--",
                    color="k",
                    lw=0.9,
                    zorder=2,
                    label="true pillar" if i == 0 else None,
                )
            )
            ax.patches[-1]._key = "true pillar"
    if len(edges):
        ax.plot(
            edges[:, 0], edges[:, 1], "x", color=EDGE_COLOR, ms=7, mew=1.5, zorder=4, label="edges"
        )
    ax.plot([0], [0], "k^", ms=7, label="laser")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)


def _key(ax) -> list:
    """Legend entries: what the point and segment colours mean, then the circles (by method),
    the true pillars, edges and the laser, as drawn on `ax`."""
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], ls="", marker=".", color=SCAN_POINT_COLOR, label="scan points (no segment)")
    ]
    handles += [
        Line2D([], [], color=color, lw=2, label=f"segment classified {name}")
        for name, color in (SEGMENT_COLORS[k] for k in (2, 1, 0))
    ]
    for h in ax.patches + ax.lines:
        label = h.get_label() or ""
        if label and not label.startswith("_"):
            handles.append(h)
    return handles


def plot_features(
    points_xy: np.ndarray,
    segments: Sequence,
    circles: Sequence[tuple[str, np.ndarray, str]],
    edges_xy: np.ndarray,
    title: str,
    path: Output,
    zoom: tuple[float, float, float, float] | None = None,
    truth_xyr: np.ndarray | None = None,
) -> Output:
    """Figs. 3 and 4: circles and edges on the scan (left), and a zoom on a box (right).

    points_xy: (B, 2) scan points (NaN rows for no return). segments: [((first, last), kind)].
    circles: [(label, (C, 3) [x, y, r], colour)]. zoom: (xmin, xmax, ymin, ymax). Colours:
    `SEGMENT_COLORS` for the segments, the given ones (`METHOD_COLORS`) for the circles.
    """
    ncols = 2 if zoom else 1
    fig, axes = _subplots(1, ncols, figsize=(6.2 * ncols, 6.8), layout="constrained")
    axes = np.atleast_1d(axes)
    for ax in axes:
        _draw(ax, points_xy, segments, circles, edges=edges_xy, truth=truth_xyr, lw=1.2)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    if zoom:
        fig.suptitle(title, fontsize=11)
        axes[0].set_title("whole scan", fontsize=10)
        x0, x1, y0, y1 = zoom
        axes[0].add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", color="k"))
        axes[1].set_xlim(x0, x1)
        axes[1].set_ylim(y0, y1)
        axes[1].set_title("zoom on the dashed box", fontsize=10)
    else:
        axes[0].set_title(title, fontsize=10)
    # one legend for both panels, under them: a legend inside a panel hides scan points
    handles = _key(axes[0])
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 4), fontsize=9)
    return save(fig, path)


def plot_rates(table: dict[str, dict[str, float]], title: str, ylabel: str, path: Output) -> Output:
    """Grouped bars: table[group][series] = value."""
    groups = list(table)
    series = sorted({s for g in table.values() for s in g})
    fig, ax = _subplots(figsize=(7, 4))
    w = 0.8 / max(len(series), 1)
    for i, s in enumerate(series):
        ax.bar(
            np.arange(len(groups)) + i * w, [table[g].get(s, np.nan) for g in groups], w, label=s
        )
    ax.set_xticks(np.arange(len(groups)) + 0.4 - w / 2, groups)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return save(fig, path)


def plot_circle_rates(res, path: Output, setup: str = "") -> Output:
    """Circle-extraction rate of simulated trunks against range, per radius and line test;
    setup: a line saying how they were simulated (the figure's title)."""
    tests = list(res.circle_rate)
    fig, axes = _subplots(1, len(tests), figsize=(5.5 * len(tests), 4), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, t in zip(axes, tests):
        cells = res.circle_rate[t]
        for r in sorted({r for r, _ in cells}):
            ds = sorted(d for rr, d in cells if rr == r)
            ax.plot(ds, [cells[(r, d)] for d in ds], "o-", label=f"r = {r} m")
        ax.set_title(
            {"lrt": "likelihood-ratio test (default)", "paper": "paper's eq. (5) test"}.get(t, t)
        )
        ax.set_xlabel("range (m)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("fraction of trunks extracted as circles")
    axes[0].legend(fontsize=8, title="trunk radius (both panels)", title_fontsize=8)
    if setup:
        fig.suptitle(setup, fontsize=10)
    return save(fig, path)


def plot_scene(scene, path: Output) -> Output:
    """Fig. 2(a): the scene from above, pillars labelled, scan positions as numbered crosses."""
    fig, ax = _subplots(figsize=(8, 6.5))
    for w in scene.walls:
        p = np.vstack([w.points_xy, w.points_xy[:1]]) if w.closed else w.points_xy
        style = dict(color="0.2", lw=2.0) if w.kind == "wall" else dict(color="0.5", lw=1.2, ls=":")
        ax.plot(p[:, 0], p[:, 1], **style)
    for b in scene.bushes:
        p = np.vstack([b.points_xy, b.points_xy[:1]])
        ax.fill(p[:, 0], p[:, 1], color="tab:olive", alpha=0.5, lw=0)
    for c in scene.circles:
        ax.add_patch(CirclePatch(c.center_xy, c.radius_m, color="tab:brown"))
        ax.annotate(c.name, c.center_xy, xytext=(6, 6), textcoords="offset points")
    for i, p in enumerate(scene.scan_positions):
        ax.plot(p[0], p[1], "r+", ms=11, mew=2)
        ax.annotate(str(i + 1), p[:2], xytext=(5, -12), textcoords="offset points", color="r")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        f"Fig. 2(a): {scene.name}, world frame: walls solid, low balusters dotted,\n"
        "shrubs olive, pillars a-j brown (true size), scan positions 1-6 red +",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    return save(fig, path)


SWEEP_AXES = {
    "range_m": "pillar range (m)",
    "radius_m": "pillar radius (m)",
    "noise_m": "range noise sigma (m)",
}


def plot_sweep(results: dict, path: Output, held: dict | None = None) -> Output:
    """CE and RE (rows) against each swept variable (columns), one line per method.

    results[var][value][method] = (RMS CE, RMS RE, extracted fraction); held: the values of the
    variables not swept (for the title). Where a method extracted no circle the figure says
    so, so a curve that stops has its reason on it.
    """
    variables = list(results)
    fig, axes = _subplots(2, len(variables), figsize=(5 * len(variables), 7.8), squeeze=False)
    styles = {"paper": "o-", "geometric": "s-", "bailey": "^-", "taubin": "d-", "crlb": "--"}
    panels = (  # (title, y label with the unit) of each row
        ("RMS centre error CE (eq. 10)", "CE = centre error / range (log)"),
        ("RMS radius error RE (eq. 11)", "RE = radius error / radius (log)"),
    )
    for j, var in enumerate(variables):
        xs = sorted(results[var])
        methods = list(results[var][xs[0]])
        missing: dict[tuple, list[str]] = {}  # values a method never extracted -> methods
        for m in methods:
            gone = tuple(x for x in xs if m != "crlb" and results[var][x][m][2] == 0)
            if gone:
                missing.setdefault(gone, []).append(m)
        note = "; ".join(
            f"{', '.join(ms)}: no circle at {', '.join(f'{x:g}' for x in gone)}"
            for gone, ms in missing.items()
        )
        for i, (head, ylabel) in enumerate(panels):
            ax = axes[i, j]
            for m in methods:
                ys = [results[var][x][m][i] for x in xs]
                ax.plot(
                    xs,
                    ys,
                    styles.get(m, "o-"),
                    color=METHOD_COLORS.get(m, "k"),  # crlb: black
                    label=_SWEEP_NAMES.get(m, m),
                    ms=4,
                )
            if note and i == 0:
                ax.text(
                    0.02,
                    0.02,
                    f"{note}\n(fewer than 4 beams on the pillar)",
                    transform=ax.transAxes,
                    fontsize=7,
                    va="bottom",
                    bbox=dict(facecolor="white", alpha=0.8, lw=0),
                )
            ax.set_yscale("log")
            ax.set_xlabel(SWEEP_AXES.get(var, var))
            ax.set_title(f"{head} against {SWEEP_AXES.get(var, var).split(' (')[0]}", fontsize=10)
            ax.set_ylabel(ylabel, fontsize=9)
            ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9)
    held_txt = ", ".join(
        f"{SWEEP_AXES.get(k, k).split(' (')[0]} {v:g} m" for k, v in (held or {}).items()
    )
    fig.suptitle(
        "Circle accuracy, one pillar straight ahead of a PLS200 (0.5 deg beams); one variable "
        f"swept, the others held at: {held_txt}",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return save(fig, path)


_SWEEP_NAMES = {"crlb": "Cramer-Rao bound (RMS)"}


# ---- EKF-SLAM (experiment 2: the paper's Figs. 7, 10, 11; consistency) -------------------------


def plot_slam_path(
    truth_xy: np.ndarray,
    est_xy: np.ndarray,
    trees_xyr: np.ndarray,
    map_xy: np.ndarray,
    map_cov: np.ndarray,
    title: str,
    path: Output,
    walls: Sequence[np.ndarray] = (),
    bushes: Sequence[np.ndarray] = (),
) -> Output:
    """Fig. 7: estimated path (wide, translucent) under the true path (dashed, the simulated
    pose itself), trees (stars), the map's landmarks with 95% ellipses (magnified x10 to be
    visible), walls and bushes of the scene (grey), the start (dot)."""
    fig, ax = _subplots(figsize=(8, 6))
    for w in walls:
        ax.plot(w[:, 0], w[:, 1], "-", color="0.4", lw=2)
    for b in bushes:
        q = np.vstack([b, b[:1]])
        ax.fill(q[:, 0], q[:, 1], color="0.85", zorder=0)
    ax.plot(
        est_xy[:, 0],
        est_xy[:, 1],
        "-",
        color="tab:blue",
        lw=3.0,
        alpha=0.45,
        zorder=2,
        label="estimated path",
    )
    ax.plot(
        truth_xy[:, 0],
        truth_xy[:, 1],
        "--",
        color="k",
        lw=1.0,
        dashes=(4, 3),
        zorder=3,
        label="true path (exact simulated pose)",
    )
    ax.plot(trees_xyr[:, 0], trees_xyr[:, 1], "*", color="tab:green", ms=13, label="trees (truth)")
    if len(map_xy):
        ax.plot(
            map_xy[:, 0], map_xy[:, 1], "+", color="tab:red", ms=10, mew=1.5, label="map landmarks"
        )
        for i, (c, P) in enumerate(zip(map_xy, map_cov)):
            e = ellipse_polyline(c, 100.0 * np.asarray(P))
            ax.plot(
                e[:, 0],
                e[:, 1],
                "-",
                color="tab:red",
                lw=0.7,
                label="95% ellipse x10" if i == 0 else None,
            )
    ax.plot(truth_xy[0, 0], truth_xy[0, 1], "ko", ms=6, zorder=4, label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return save(fig, path)


def plot_innovations(series: Sequence[dict], title: str, path: Output) -> Output:
    """Fig. 10: range and bearing innovations with their 3-sigma bounds.

    series: dicts with label, scan (k,), innov (k, 2) [m, rad], sigma (k, 2) and style (a
    matplotlib line style such as "-." or "-"). The scans at which the landmark was not
    observed are gaps: the lines stop there (`break_at_gaps`), and every observation has a dot
    so that one between two gaps shows.
    """
    fig, axes = _subplots(2, 1, figsize=(8, 6.5), sharex=True, layout="constrained")
    _plot_with_bounds(axes, series, "innov", "innovation", markers=True)
    axes[0].set_ylabel("range innovation (m)")
    axes[1].set_ylabel("bearing innovation (rad)")
    axes[1].set_xlabel("scan (lines stop at scans where the tree was not observed)")
    fig.suptitle(title, fontsize=11)
    for ax in axes:
        ax.grid(alpha=0.3)
    _outside_legend(fig, axes[0])
    return save(fig, path)


def plot_pose_errors(series: Sequence[dict], title: str, path: Output) -> Output:
    """Fig. 11: x, y and heading errors of the vehicle with their 3-sigma bounds.

    series: dicts with label, scan (N,), err (N, 3) [m, m, rad], sigma (N, 3), style; a scan
    missing from `scan` is a gap (the lines stop there).
    """
    fig, axes = _subplots(3, 1, figsize=(8, 8), sharex=True, layout="constrained")
    names = ["x error (m)", "y error (m)", "heading error (rad)"]
    _plot_with_bounds(axes, series, "err", "error")
    for ax, n in zip(axes, names):
        ax.set_ylabel(n)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("scan")
    fig.suptitle(title, fontsize=11)
    _outside_legend(fig, axes[0])
    return save(fig, path)


def _outside_legend(fig, ax, ncol: int = 4) -> None:
    """The legend of `ax`'s lines under the panels, off the data."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=9)


def plot_consistency(
    series: dict[str, np.ndarray],
    bounds: tuple[float, float],
    title: str,
    ylabel: str,
    path: Output,
    expected: float | None = None,
    first_scan: int = 0,
) -> Output:
    """Average NEES (or NIS) per scan over Monte Carlo runs, with its 95% chi-square bounds
    (shaded) and its expected value. series: label -> (N,) values of scans first_scan,
    first_scan + 1, ...; NaN (no value at that scan) is a gap, the line stops there."""
    fig, ax = _subplots(figsize=(8, 4.2), layout="constrained")
    band = f"95% bounds ({bounds[0]:.3g}-{bounds[1]:.3g})"
    ax.axhspan(bounds[0], bounds[1], color="0.88", lw=0, zorder=0, label=band)
    for b in bounds:
        ax.axhline(b, color="0.4", ls="--", lw=0.8, zorder=1)
    if expected is not None:
        ax.axhline(expected, color="k", ls=":", lw=1.0, label=f"expected value ({expected:g})")
    for label, v in series.items():
        v = np.asarray(v, float)
        ax.plot(first_scan + np.arange(len(v)), v, "-", lw=1.0, label=label)
    ax.set_xlabel("scan")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.legend(loc="outside right upper", fontsize=8)
    return save(fig, path)


def plot_association(
    rows: list[dict], path: Output, method_labels: dict[str, str], sweep_xlabels: dict[str, str]
) -> Output:
    """Correct-association and false-pairing rates against each sweep, one column per sweep.

    rows: dicts with keys sweep, value, method, correct_rate, false_pair_rate (as `rate_study`
    returns); method_labels: method -> legend label (also the plotting order); sweep_xlabels:
    sweep -> x-axis label.
    """
    sweeps = list(dict.fromkeys(r["sweep"] for r in rows))
    fig, axes = _subplots(2, len(sweeps), figsize=(4.6 * len(sweeps), 7.2), squeeze=False)
    styles = ["o-", "s--", "^-", "v:", "d-."]
    colors = ["tab:blue", "tab:cyan", "tab:red", "tab:gray", "tab:green"]
    n_methods = len(method_labels)
    for c, sw in enumerate(sweeps):
        for k, (m, label) in enumerate(method_labels.items()):
            rs = [r for r in rows if r["sweep"] == sw and r["method"] == m]
            if not rs:
                continue
            x = [r["value"] for r in rs]
            st, color = styles[k % len(styles)], colors[k % len(colors)]
            # earlier methods drawn larger and hollow beneath the later ones: equal rates (IHGR
            # single scan and its K = 3 window often agree) stay visible as ringed markers
            kw = dict(color=color, mfc="none", ms=4 + 2.5 * (n_methods - k), zorder=2 + k)
            axes[0, c].plot(x, [r["correct_rate"] for r in rs], st, label=label, **kw)
            axes[1, c].plot(x, [r["false_pair_rate"] for r in rs], st, **kw)
        axes[1, c].set_xlabel(sweep_xlabels.get(sw, sw))
        axes[0, c].set_title(f"sweep: {sw}")
        for ax in axes[:, c]:
            ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("correct association rate")
    axes[1, 0].set_ylabel("false pairing rate")
    axes[0, 0].legend(fontsize=8, loc="lower left")
    fig.suptitle(
        "Data association on simulated maps: correct-association and false-pairing rates "
        "(hollow markers: methods drawn beneath, visible where the rates are equal)",
        fontsize=10,
    )
    fig.tight_layout()
    return save(fig, path)


def _plot_with_bounds(axes, series, key: str, what: str, markers: bool = False) -> None:
    """Each series' column i of s[key] on axes[i], with its +-3 sigma bounds dotted; the lines
    stop where scans are missing (a gap of more than one scan, `break_at_gaps`)."""
    colors = ["tab:blue", "tab:orange", "tab:green", "tab:red"]
    for s, c in zip(series, colors):
        scan, val, sig = break_at_gaps(s["scan"], s[key], s["sigma"], max_step=1)
        for i, ax in enumerate(axes):
            ax.plot(
                scan,
                val[:, i],
                s.get("style", "-"),
                color=c,
                lw=1.0,
                marker="." if markers else None,
                ms=3.5,
                label=f"{s['label']} {what}",
            )
            ax.plot(scan, 3 * sig[:, i], ":", color=c, lw=1.0, label=f"{s['label']} 3 sigma")
            ax.plot(scan, -3 * sig[:, i], ":", color=c, lw=1.0)


# ---- Victoria Park ------------------------------------------------------------------------------


def plot_vp_map(
    gps_xy: np.ndarray,
    paths: dict[str, np.ndarray],
    map_xy: np.ndarray,
    title: str,
    path: Output,
    reference_xy: np.ndarray | None = None,
) -> Output:
    """The GPS fixes (grey dots), estimated antenna paths (one line each), the map's landmarks
    (black +) and, when given, reference landmarks (open circles), world frame."""
    fig, ax = _subplots(figsize=(9, 9))
    _gps_paths_map(ax, gps_xy, paths, map_xy, map_ms=5)
    if reference_xy is not None and len(reference_xy):
        ref = reference_xy
        label = "reference trees (SLAM school 2002)"
        ax.plot(ref[:, 0], ref[:, 1], "o", ms=6, mfc="none", color="tab:orange", label=label)
    _world_frame(ax, title)
    return save(fig, path)


def _gps_paths_map(ax, gps_xy, paths: dict, map_xy, map_ms: float) -> None:
    """The GPS fixes (grey dots), the paths (one line each, blue first) and the map (black +)."""
    ax.plot(gps_xy[:, 0], gps_xy[:, 1], ".", ms=2, color="0.6", label="GPS fixes", zorder=1)
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple"]
    for (label, xy), c in zip(paths.items(), colors):
        ax.plot(xy[:, 0], xy[:, 1], "-", lw=0.9, color=c, label=label, zorder=2)
    if len(map_xy):
        ax.plot(map_xy[:, 0], map_xy[:, 1], "+", ms=map_ms, color="k", label="map landmarks",
                zorder=3)  # fmt: skip


def _world_frame(ax, title: str) -> None:
    """Equal axes in metres east and north, the title, a grid and the legend."""
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")


def plot_vp_timeseries(
    gps_t: np.ndarray,
    errors: dict[str, np.ndarray],
    jumps: np.ndarray,
    gaps: Sequence[tuple[float, float]],
    scan_t: np.ndarray,
    nis_in: np.ndarray,
    map_size: dict[str, np.ndarray],
    title: str,
    path: Output,
    gap_s: float = 2.0,
) -> Output:
    """Three panels against time: distance to each GPS fix (jumps marked x, the GPS `gaps`
    shaded), the fraction of recent scans whose NIS is inside its 95% bounds (100-scan window),
    and the map size; the per-scan lines stop where consecutive scans are more than `gap_s`
    seconds apart (no scan there)."""
    fig, axes = _subplots(3, 1, figsize=(11, 9), sharex=True, layout="constrained")
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple"]
    for a, b in gaps:
        for ax in axes:
            ax.axvspan(a, b, color="0.85", lw=0)
    for (label, e), c in zip(errors.items(), colors):
        axes[0].plot(gps_t[~jumps], e[~jumps], ".", ms=2.5, color=c, label=label)
        axes[0].plot(gps_t[jumps], e[jumps], "x", ms=5, color=c)
    axes[0].set_ylabel("distance to GPS fix (m)")
    axes[0].set_yscale("log")
    axes[0].legend(
        fontsize=8,
        markerscale=4,
        loc="upper left",
        title=f"x: fixes flagged as jumps; grey: no GPS fix for over {gap_s:g} s",
        title_fontsize=8,
    )
    t, w = break_at_gaps(scan_t, nis_in, max_step=gap_s)
    axes[1].plot(t, w, "-", color="tab:blue", lw=1)
    axes[1].axhline(0.95, color="k", ls="--", lw=0.8, label="0.95: a consistent filter")
    axes[1].legend(fontsize=8, loc="lower right")
    axes[1].set_ylabel("NIS inside 95% bounds\n(100-scan window)")
    axes[1].set_ylim(0, 1.05)
    for (label, n), c in zip(map_size.items(), colors):
        t, m = break_at_gaps(scan_t[: n.size], n, max_step=gap_s)
        axes[2].plot(t, m, "-", color=c, lw=1, label=label)
    axes[2].set_ylabel("landmarks in the map")
    axes[2].set_xlabel("time (s)")
    axes[0].set_title(title)
    for ax in axes:
        ax.grid(alpha=0.3)
    return save(fig, path)


def plot_gps_errors(
    series: dict[str, tuple[np.ndarray, np.ndarray]],
    jumps: np.ndarray,
    title: str,
    path: Output,
    gap_s: float = 2.0,
) -> Output:
    """Distance of each estimated antenna path to the GPS fixes against time: series label ->
    (fix times (s), distances (m)), all on the same fixes; fixes flagged as jumps marked x.
    Where consecutive fixes are more than `gap_s` apart (a GPS dropout) the time is shaded
    and the lines stop."""
    fig, ax = _subplots(figsize=(10, 4.5), layout="constrained")
    colors = ["tab:blue", "tab:red", "tab:green", "tab:purple"]
    if series:
        t0 = next(iter(series.values()))[0]
        for i, (a, b) in enumerate(gaps_of(t0, gap_s)):
            label = f"no GPS fix for over {gap_s:g} s" if i == 0 else None
            ax.axvspan(a, b, color="0.85", lw=0, zorder=0, label=label)
    for (label, (t, e)), c in zip(series.items(), colors):
        rmse = float(np.sqrt(np.mean(e**2))) if e.size else float("nan")
        tb, eb = break_at_gaps(t, e, max_step=gap_s)
        ax.plot(tb, eb, "-", lw=0.8, color=c, label=f"{label} (RMSE {rmse:.2f} m)")
        if np.any(jumps):
            ax.plot(t[jumps], e[jumps], "x", ms=4, color=c)
    ax.set_yscale("log")  # metre-level errors beside GPS jumps of 100 m and more
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance to GPS fix (m, log scale)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    fig.legend(loc="outside lower center", ncol=3, fontsize=8)
    return save(fig, path)


class _SweepLayout(NamedTuple):
    """How `plot_sweep_field` reads and places the sweep's rows: the swept fields, the one on
    the x axis (k), each x value's position, the x shift between lines drawn side by side, and
    per method a colour, per combination of the other swept fields a (line style, marker)."""

    swept: list
    k: int
    pos: dict
    dodge: float
    color_of: dict
    style_of: dict

    def combo(self, row) -> tuple:
        """The row's values of the swept fields other than k."""
        return tuple(row[1 + i] for i in range(len(self.swept)) if i != self.k)

    def label(self, row) -> str:
        """The row's line: its method, and the other swept fields' values."""
        n = len(self.swept)
        others = ", ".join(f"{self.swept[i]}={row[1 + i]}" for i in range(n) if i != self.k)
        return row[n + 1] + (f" ({others})" if others else "")


def _sweep_layout(rows: list, swept: list, k: int, numeric: bool) -> _SweepLayout:
    off = len(swept)
    xs = list(dict.fromkeys(r[1 + k] for r in rows))
    pos = {x: (x if numeric else i) for i, x in enumerate(xs)}
    steps = np.diff(sorted(pos.values()))
    dodge = 0.03 * float(steps.min()) if steps.size else 0.0  # x shift between lines
    # a colour per method, a line style and marker per combination of the other swept fields
    methods = list(dict.fromkeys(r[off + 1] for r in rows))
    color_of = {m: METHOD_COLORS.get(m, f"C{i % 10}") for i, m in enumerate(methods)}
    combos = list(dict.fromkeys(tuple(r[1 + i] for i in range(off) if i != k) for r in rows))
    styles = [("-", "o"), ("--", "s"), (":", "^"), ("-.", "D")]
    style_of = {c: styles[i % len(styles)] for i, c in enumerate(combos)}
    return _SweepLayout(
        swept=swept, k=k, pos=pos, dodge=dodge, color_of=color_of, style_of=style_of
    )


def _sweep_panel(ax, rows: list, metric: str, layout: _SweepLayout, references: dict) -> None:
    """One metric's panel: its reference bands and lines, then a line per method and
    combination of the other swept fields, with +-1 standard error."""
    off = len(layout.swept)
    for kind, value, label in references.get(metric, ()):
        if kind == "band":
            ax.axhspan(*value, color="0.85", lw=0, zorder=0, label=label)
        else:
            ax.axhline(value, color="k", ls="--", lw=1.0, zorder=1, label=label)
    lines: dict = {}
    for r in rows:
        if r[off + 2] != metric:
            continue
        pts = lines.setdefault((layout.label(r), r[off + 1], layout.combo(r)), [])
        pts.append((layout.pos[r[1 + layout.k]], r[off + 3], r[off + 4], r[off + 5]))
    for j, ((label, method, combo), pts) in enumerate(lines.items()):
        x, mean, std, n = (np.array(v, float) for v in zip(*sorted(pts)))
        se = np.where(n > 1, std / np.sqrt(np.maximum(n, 1)), np.nan)
        ls, marker = layout.style_of[combo]
        shift = (j - (len(lines) - 1) / 2) * layout.dodge  # bars of equal means side by side
        ax.errorbar(
            x + shift,
            mean,
            yerr=se,
            ls=ls,
            marker=marker,
            ms=4,
            capsize=3,
            lw=1.2,
            color=layout.color_of[method],
            label=label,
        )


def _sweep_legend(fig, axes, rows: list, off: int) -> None:
    """One legend under the panels (each label once), saying what the bars are."""
    seen: dict[str, object] = {}
    for ax in axes.flat:
        for h, label in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(label, h)
    counts = sorted({int(r[off + 5]) for r in rows})
    n_text = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    fig.legend(
        list(seen.values()),
        list(seen),
        loc="outside lower center",
        ncol=min(len(seen), 3),
        fontsize=8,
        title=f"bars: \u00b11 standard error of the mean over the n = {n_text} trials of each "
        "point (lines drawn side by side, shifted a little along x)",
        title_fontsize=8,
    )


def plot_sweep_field(
    rows: list,
    swept: list,
    k: int,
    title: str,
    path: Output,
    metrics: dict[str, tuple[str, str]] | None = None,
    references: dict[str, list[tuple]] | None = None,
) -> Output:
    """One panel per metric of a sweep (`experiments.paper.sweep.sweep_rows`: [point, *swept
    values, method, metric, mean, std, n]): the mean against swept field k with +-1 standard
    error (std / sqrt(n), as the figure says), one line per method and combination of the other
    swept fields.

    metrics: metric -> (panel title, y label with its unit); a metric missing from it is titled
    by its name with spaces. references: metric -> [("band", (low, high), label) for a shaded
    band such as the NEES 95% bounds, or ("line", y, label) for a dashed line such as an
    expected value].
    """
    metrics = metrics or {}
    references = references or {}
    off = len(swept)
    names = list(dict.fromkeys(r[off + 2] for r in rows))
    xs = list(dict.fromkeys(r[1 + k] for r in rows))
    numeric = all(isinstance(x, int | float) and not isinstance(x, bool) for x in xs)
    layout = _sweep_layout(rows, swept, k, numeric)
    ncols = min(len(names), 3) or 1
    nrows = max(1, math.ceil(len(names) / ncols))
    fig, axes = _subplots(
        nrows, ncols, figsize=(4.6 * ncols, 3.6 * nrows + 1.2), squeeze=False, layout="constrained"
    )
    for ax, metric in zip(axes.flat, names):
        _sweep_panel(ax, rows, metric, layout, references)
        head, ylabel = metrics.get(metric, (metric.replace("_", " "), ""))
        ax.set_title(head, fontsize=10)
        ax.set_ylabel(ylabel)
        ax.set_xlabel(swept[k])
        if not numeric:
            ax.set_xticks(range(len(xs)), [str(x) for x in xs])
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names) :]:
        ax.set_visible(False)
    _sweep_legend(fig, axes, rows, off)
    fig.suptitle(title, fontsize=11)
    return save(fig, path)


def plot_loop_closure(
    trees_xy: np.ndarray, truth_xy: np.ndarray, runs: dict[str, dict], title: str, path: Output
) -> Output:
    """One panel per run (`runs`: label -> {"path": (N, 2), "landmarks": (L, 2), "closures":
    (C, 2) vehicle positions where a closure was accepted}): the true trees (open circles), the
    true path (grey), the estimated path (blue), the final map (black +) and the closures
    (red stars), world frame."""
    fig, axes = _subplots(1, len(runs), figsize=(6.5 * len(runs), 6.5), layout="constrained")
    axes = np.atleast_1d(axes)
    for ax, (label, r) in zip(axes, runs.items()):
        ax.plot(truth_xy[:, 0], truth_xy[:, 1], "-", lw=1.0, color="0.6", label="true path")
        ax.plot(r["path"][:, 0], r["path"][:, 1], "-", lw=0.9, color="tab:blue", label="estimate")
        ax.plot(trees_xy[:, 0], trees_xy[:, 1], "o", ms=6, mfc="none", color="tab:green",
                label="true trees")  # fmt: skip
        lm = r["landmarks"]
        ax.plot(lm[:, 0], lm[:, 1], "+", ms=5, color="k", label=f"map ({lm.shape[0]} landmarks)")
        c = np.asarray(r["closures"], float).reshape(-1, 2)
        if c.size:
            ax.plot(c[:, 0], c[:, 1], "*", ms=14, color="red", label="closure accepted")
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(title)
    return save(fig, path)


CLOSURE_MARKS = {  # outcome -> (marker, colour); "too few" is not drawn
    "accepted": ("*", "red"),
    "not jointly compatible": ("x", "tab:orange"),
    "beyond dead reckoning": ("^", "tab:purple"),
    "no margin": ("o", "tab:cyan"),
}


def plot_closure_map(
    gps_xy: np.ndarray,
    path_xy: np.ndarray,
    map_xy: np.ndarray,
    matches: Sequence[tuple[np.ndarray, str]],
    title: str,
    path: Output,
) -> Output:
    """A run with loop closure: the GPS fixes (grey dots), the estimated path (blue), the map
    (black +) and the vehicle's position at each constellation match (`matches`: (xy, outcome)
    pairs), by outcome (`CLOSURE_MARKS`; "too few" not drawn), world frame."""
    fig, ax = _subplots(figsize=(9, 9))
    _gps_paths_map(ax, gps_xy, {"estimate": path_xy}, map_xy, map_ms=4)
    for outcome, (marker, colour) in CLOSURE_MARKS.items():
        xy = np.array([m[0] for m in matches if m[1] == outcome], float).reshape(-1, 2)
        if xy.size:
            ax.plot(xy[:, 0], xy[:, 1], marker, ms=12 if marker == "*" else 7, color=colour,
                    mfc="none" if marker == "o" else colour, zorder=4,
                    label=f"match: {outcome} ({xy.shape[0]})")  # fmt: skip
    _world_frame(ax, title)
    return save(fig, path)
