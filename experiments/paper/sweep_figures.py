"""The figures of `trunkslam sweep` (`experiments.paper.sweep`): a metric against a swept field.

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from experiments.render import plots
from experiments.render.plots import METHOD_COLORS, Output


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
    fig, axes = plots.subplots(
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
    return plots.save(fig, path)
