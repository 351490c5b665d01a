"""The figure of experiment `association` (`experiments.paper.association`).

matplotlib is imported by figure modules only; the helpers they share are in
`experiments.render.plots`.
"""

from __future__ import annotations

from experiments.render import plots
from experiments.render.plots import Output


def plot_association(
    rows: list[dict], path: Output, method_labels: dict[str, str], sweep_xlabels: dict[str, str]
) -> Output:
    """Correct-association and false-pairing rates against each sweep, one column per sweep.

    rows: dicts with keys sweep, value, method, correct_rate, false_pair_rate (as `rate_study`
    returns); method_labels: method -> legend label (also the plotting order); sweep_xlabels:
    sweep -> x-axis label.
    """
    sweeps = list(dict.fromkeys(r["sweep"] for r in rows))
    fig, axes = plots.subplots(2, len(sweeps), figsize=(4.6 * len(sweeps), 7.2), squeeze=False)
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
    return plots.save(fig, path)
