"""The figure of experiment `loop-closure` (`experiments.paper.loop_closure`).

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

import numpy as np

from experiments.render import plots
from experiments.render.plots import Output


def plot_loop_closure(
    trees_xy: np.ndarray, truth_xy: np.ndarray, runs: dict[str, dict], title: str, path: Output
) -> Output:
    """One panel per run (`runs`: label -> {"path": (N, 2), "landmarks": (L, 2), "closures":
    (C, 2) vehicle positions where a closure was accepted}): the true trees (open circles), the
    true path (grey), the estimated path (blue), the final map (black +) and the closures
    (red stars), world frame."""
    fig, axes = plots.subplots(1, len(runs), figsize=(6.5 * len(runs), 6.5), layout="constrained")
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
    return plots.save(fig, path)
