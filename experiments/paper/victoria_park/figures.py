"""The Victoria Park figures (`experiments.paper.victoria_park.real_run`, and the smoother's
`experiments.paper.smoother`): the map over the GPS track, the time series, the GPS errors and
the loop closures.

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from experiments.render import plots
from experiments.render.plots import Output, break_at_gaps, gaps_of


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
    fig, ax = plots.subplots(figsize=(9, 9))
    _gps_paths_map(ax, gps_xy, paths, map_xy, map_ms=5)
    if reference_xy is not None and len(reference_xy):
        ref = reference_xy
        label = "reference trees (SLAM school 2002)"
        ax.plot(ref[:, 0], ref[:, 1], "o", ms=6, mfc="none", color="tab:orange", label=label)
    _world_frame(ax, title)
    return plots.save(fig, path)


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
    fig, axes = plots.subplots(3, 1, figsize=(11, 9), sharex=True, layout="constrained")
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
    return plots.save(fig, path)


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
    fig, ax = plots.subplots(figsize=(10, 4.5), layout="constrained")
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
    return plots.save(fig, path)


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
    fig, ax = plots.subplots(figsize=(9, 9))
    _gps_paths_map(ax, gps_xy, {"estimate": path_xy}, map_xy, map_ms=4)
    for outcome, (marker, colour) in CLOSURE_MARKS.items():
        xy = np.array([m[0] for m in matches if m[1] == outcome], float).reshape(-1, 2)
        if xy.size:
            ax.plot(xy[:, 0], xy[:, 1], marker, ms=12 if marker == "*" else 7, color=colour,
                    mfc="none" if marker == "o" else colour, zorder=4,
                    label=f"match: {outcome} ({xy.shape[0]})")  # fmt: skip
    _world_frame(ax, title)
    return plots.save(fig, path)
