"""What the static figures (PNG) share: making and saving a figure, the colours, gaps in a
series, and the feature figure two experiments draw (`plot_features`).

Each experiment's own figures are in a figure module beside it (`experiments/paper/*_figures.py`,
`experiments/paper/victoria_park/figures.py`); matplotlib is imported by these and this module
only. Every `plot_*` function draws one figure and writes it to `path`: a file (written atomically)
or a binary file object (`io.BytesIO`: a figure drawn in a worker, its bytes written by the
main process). Figures are `matplotlib.figure.Figure` objects, not pyplot's: pyplot keeps a
global list of open figures, and figures may be drawn in several threads of one process at
once (a Dask worker's threads).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Circle as CirclePatch  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from experiments.io.writers import write_atomic  # noqa: E402

__all__ = [
    "EDGE_COLOR",
    "METHOD_COLORS",
    "SCAN_POINT_COLOR",
    "SEGMENT_COLORS",
    "Output",
    "break_at_gaps",
    "gaps_of",
    "plot_features",
    "save",
    "segments_of",
    "subplots",
    "zoom_box",
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


def subplots(nrows: int = 1, ncols: int = 1, *, figsize, layout=None, **kwargs):
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
    fig, axes = subplots(1, ncols, figsize=(6.2 * ncols, 6.8), layout="constrained")
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
