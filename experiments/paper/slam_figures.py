"""The figures of the EKF-SLAM experiment (`experiments.paper.slam`): Figs. 7, 10, 11 and the NEES.

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from experiments.render import plots
from experiments.render.plots import Output, break_at_gaps
from experiments.render.shapes import ellipse_polyline


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
    fig, ax = plots.subplots(figsize=(8, 6))
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
    return plots.save(fig, path)


def plot_innovations(series: Sequence[dict], title: str, path: Output) -> Output:
    """Fig. 10: range and bearing innovations with their 3-sigma bounds.

    series: dicts with label, scan (k,), innov (k, 2) [m, rad], sigma (k, 2) and style (a
    matplotlib line style such as "-." or "-"). The scans at which the landmark was not
    observed are gaps: the lines stop there (`break_at_gaps`), and every observation has a dot
    so that one between two gaps shows.
    """
    fig, axes = plots.subplots(2, 1, figsize=(8, 6.5), sharex=True, layout="constrained")
    _plot_with_bounds(axes, series, "innov", "innovation", markers=True)
    axes[0].set_ylabel("range innovation (m)")
    axes[1].set_ylabel("bearing innovation (rad)")
    axes[1].set_xlabel("scan (lines stop at scans where the tree was not observed)")
    fig.suptitle(title, fontsize=11)
    for ax in axes:
        ax.grid(alpha=0.3)
    _outside_legend(fig, axes[0])
    return plots.save(fig, path)


def plot_pose_errors(series: Sequence[dict], title: str, path: Output) -> Output:
    """Fig. 11: x, y and heading errors of the vehicle with their 3-sigma bounds.

    series: dicts with label, scan (N,), err (N, 3) [m, m, rad], sigma (N, 3), style; a scan
    missing from `scan` is a gap (the lines stop there).
    """
    fig, axes = plots.subplots(3, 1, figsize=(8, 8), sharex=True, layout="constrained")
    names = ["x error (m)", "y error (m)", "heading error (rad)"]
    _plot_with_bounds(axes, series, "err", "error")
    for ax, n in zip(axes, names):
        ax.set_ylabel(n)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("scan")
    fig.suptitle(title, fontsize=11)
    _outside_legend(fig, axes[0])
    return plots.save(fig, path)


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
    fig, ax = plots.subplots(figsize=(8, 4.2), layout="constrained")
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
    return plots.save(fig, path)


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
