"""The figures of the circle experiments (`experiments.paper.circles`): the pillar court's scene and
raw scan (Fig. 2), and the circle sweep.

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.patches import Circle as CirclePatch

from experiments.render import plots
from experiments.render.plots import METHOD_COLORS, Output


def plot_raw_scan(points_xy: np.ndarray, title: str, path: Output) -> Output:
    """Fig. 2(b): the points of one whole scan around the sensor at the origin."""
    fig, ax = plots.subplots(figsize=(6.5, 6.5))
    p = points_xy[np.all(np.isfinite(points_xy), axis=1)]
    ax.plot(p[:, 0], p[:, 1], ".", ms=2.5, color="k", label="scan points")
    ax.plot([0], [0], "r+", ms=12, mew=2, label="laser (two PLS200 back to back)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return plots.save(fig, path)


def plot_scene(scene, path: Output) -> Output:
    """Fig. 2(a): the scene from above, pillars labelled, scan positions as numbered crosses."""
    fig, ax = plots.subplots(figsize=(8, 6.5))
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
    return plots.save(fig, path)


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
    fig, axes = plots.subplots(2, len(variables), figsize=(5 * len(variables), 7.8), squeeze=False)
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
    return plots.save(fig, path)


_SWEEP_NAMES = {"crlb": "Cramer-Rao bound (RMS)"}


# ---- EKF-SLAM (experiment 2: the paper's Figs. 7, 10, 11; consistency) -------------------------
