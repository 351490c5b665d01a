"""The figure of experiment `features` (`experiments.paper.features`): circle rates by line test.

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

import numpy as np

from experiments.render import plots
from experiments.render.plots import Output


def plot_circle_rates(res, path: Output, setup: str = "") -> Output:
    """Circle-extraction rate of simulated trunks against range, per radius and line test;
    setup: a line saying how they were simulated (the figure's title)."""
    tests = list(res.circle_rate)
    fig, axes = plots.subplots(1, len(tests), figsize=(5.5 * len(tests), 4), sharey=True)
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
    return plots.save(fig, path)
