"""Static figures (PNG) like the paper's; the only module that imports matplotlib."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle as CirclePatch  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

__all__ = ["plot_raw_scan", "plot_features", "save"]


def save(fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(tmp, dpi=130, bbox_inches="tight")
    plt.close(fig)
    tmp.replace(path)
    return path


def plot_raw_scan(points_xy: np.ndarray, title: str, path: Path) -> Path:
    """Fig. 2(b): the points of one whole scan around the sensor at the origin."""
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    p = points_xy[np.all(np.isfinite(points_xy), axis=1)]
    ax.plot(p[:, 0], p[:, 1], ".", ms=2.5, color="k")
    ax.plot([0], [0], "r+", ms=12, mew=2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return save(fig, path)


def _draw(ax, points_xy, segments, circles, edges, truth, lw=1.0):
    p = points_xy
    ax.plot(p[:, 0], p[:, 1], ".", ms=2, color="0.55", zorder=1)
    colors = {0: "tab:orange", 1: "tab:blue", 2: "tab:green"}
    for (a, b), k in segments:
        q = p[a : b + 1]
        ax.plot(q[:, 0], q[:, 1], "-", color=colors[int(k)], lw=lw, zorder=2)
    for name, circ, color in circles:
        for i, (cx, cy, r) in enumerate(circ):
            ax.add_patch(CirclePatch((cx, cy), r, fill=False, color=color, lw=1.3, zorder=3,
                                     label=name if i == 0 else None))  # fmt: skip
    if truth is not None and len(truth):
        for i, (cx, cy, r) in enumerate(truth):
            ax.add_patch(CirclePatch((cx, cy), r, fill=False, ls="--", color="k", lw=0.8,
                                     zorder=2, label="truth" if i == 0 else None))  # fmt: skip
    if len(edges):
        ax.plot(edges[:, 0], edges[:, 1], "x", color="red", ms=7, mew=1.5, zorder=4,
                label="edges")  # fmt: skip
    ax.plot([0], [0], "k^", ms=7)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)


def plot_features(
    points_xy: np.ndarray,
    segments: Sequence,
    circles: Sequence[tuple[str, np.ndarray, str]],
    edges_xy: np.ndarray,
    title: str,
    path: Path,
    zoom: tuple[float, float, float, float] | None = None,
    truth_xyr: np.ndarray | None = None,
) -> Path:
    """Figs. 3 and 4: circles and edges on the scan (left), and a zoom on a box (right).

    points_xy: (B, 2) scan points (NaN rows for no return). segments: [((first, last), kind)].
    circles: [(label, (C, 3) [x, y, r], colour)]. zoom: (xmin, xmax, ymin, ymax).
    """
    ncols = 2 if zoom else 1
    fig, axes = plt.subplots(1, ncols, figsize=(6.5 * ncols, 6.2))
    axes = np.atleast_1d(axes)
    for ax in axes:
        _draw(ax, points_xy, segments, circles, edges_xy, truth_xyr, lw=1.0)
    axes[0].set_title(title)
    axes[0].set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    if zoom:
        x0, x1, y0, y1 = zoom
        axes[0].add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", color="m"))
        axes[1].set_xlim(x0, x1)
        axes[1].set_ylim(y0, y1)
        axes[1].set_title("zoom on the dashed box")
        axes[1].legend(loc="best", fontsize=8)
    else:
        axes[0].legend(loc="best", fontsize=8)
    return save(fig, path)


def plot_rates(table: dict[str, dict[str, float]], title: str, ylabel: str, path: Path) -> Path:
    """Grouped bars: table[group][series] = value."""
    groups = list(table)
    series = sorted({s for g in table.values() for s in g})
    fig, ax = plt.subplots(figsize=(7, 4))
    w = 0.8 / max(len(series), 1)
    for i, s in enumerate(series):
        ax.bar(np.arange(len(groups)) + i * w, [table[g].get(s, np.nan) for g in groups], w,
               label=s)  # fmt: skip
    ax.set_xticks(np.arange(len(groups)) + 0.4 - w / 2, groups)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return save(fig, path)


def plot_circle_rates(res, path: Path) -> Path:
    """Circle-extraction rate of simulated trunks against range, per radius and line test."""
    tests = list(res.circle_rate)
    fig, axes = plt.subplots(1, len(tests), figsize=(5.5 * len(tests), 4), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, t in zip(axes, tests):
        cells = res.circle_rate[t]
        for r in sorted({r for r, _ in cells}):
            ds = sorted(d for rr, d in cells if rr == r)
            ax.plot(ds, [cells[(r, d)] for d in ds], "o-", label=f"r = {r} m")
        ax.set_title({"lrt": "likelihood-ratio test (default)",
                      "paper": "paper's eq. (5) test"}.get(t, t))  # fmt: skip
        ax.set_xlabel("range (m)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("fraction of trunks extracted as circles")
    axes[0].legend(fontsize=8)
    return save(fig, path)


def plot_scene(scene, path: Path) -> Path:
    """Fig. 2(a): the scene from above, pillars labelled, scan positions as numbered crosses."""
    fig, ax = plt.subplots(figsize=(8, 6.5))
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
    ax.set_title(f"Fig. 2(a): {scene.name} (walls solid, low balusters dotted, shrubs green)")
    ax.grid(alpha=0.3)
    return save(fig, path)


def plot_sweep(results: dict, path: Path) -> Path:
    """CE and RE (rows) against each swept variable (columns), one line per method."""
    variables = list(results)
    fig, axes = plt.subplots(2, len(variables), figsize=(5 * len(variables), 7.5))
    styles = {"paper": "o-", "geometric": "s-", "bailey": "^-", "taubin": "d-", "crlb": "k--"}
    for j, var in enumerate(variables):
        xs = sorted(results[var])
        methods = list(results[var][xs[0]])
        for i, label in enumerate(("RMS CE", "RMS RE")):
            ax = axes[i, j]
            for m in methods:
                ys = [results[var][x][m][i] for x in xs]
                ax.plot(xs, ys, styles.get(m, "o-"), label="Cramer-Rao (RMS)" if m == "crlb" else m,
                        ms=4)  # fmt: skip
            ax.set_yscale("log")
            ax.set_xlabel(var.replace("_m", " (m)"))
            ax.set_ylabel(label)
            ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Circle accuracy: one pillar ahead of a PLS200 (others at 10 m, 0.3 m, 1 cm)")
    return save(fig, path)
