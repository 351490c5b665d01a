"""Experiment `features`: how the extractor classifies, and what it finds in real scans.

Writes
  classification.md/.csv/.png   how trunks, walls and bushes are classified (lrt vs paper eq. 5)
  fig_vp_scan.png               a real Victoria Park scan: paper and Bailey circles, edges, zoom
  features.rrd                  the Victoria Park scans in rerun (timeline `scan`)
The Victoria Park scans (the recording and the figure) are one trial on the executor
(`victoria_park_trial`), running beside the classification trials; their files are written
after the other experiments have started (`RunContext.later`). The paper's Figs. 2-4 on the
simulated pillar court come from experiment `table1` (experiments/paper/circles.py).
"""

from __future__ import annotations

import logging

from experiments.errors import MissingDataError
from experiments.io.writers import write_tidy_table
from experiments.paper import features_figures, products
from experiments.paper.classification import RADII_M, RANGES_M, classification_study
from experiments.paper.registry import experiment
from experiments.render import plots
from features import extract_features

__all__ = ["classification", "run", "victoria_park_scans", "victoria_park_trial"]

log = logging.getLogger(__name__)

SERIES = [("circles_per_scan", "circles per scan (paper, Bailey)")]


def classification(ctx) -> None:
    n = 8 if ctx.quick else 60
    sigma = 0.01
    ctx.config["features"]["classification"] = {
        "n_trials": n,
        "sigma_m": sigma,
        "radii_m": RADII_M,
        "ranges_m": RANGES_M,
    }
    res = classification_study(
        ctx.rng("classification"), n, sigma, progress=ctx.progress, executor=ctx.executor
    )
    records = [
        {
            "radius_m": r,
            "range_m": d,
            "beams_on_trunk": res.beams[(r, d)],
            "line_test": test,
            "circle_rate": res.circle_rate[test][(r, d)],
        }
        for r in RADII_M
        for d in RANGES_M
        for test in ("lrt", "paper")
    ]
    notes = (
        f"{n} trials per cell, PLS200 with {sigma} m range noise and 1 cm quantisation.\n\n"
        "| object | lrt | paper eq. 5 |\n|---|---|---|\n"
        f"| wall beams inside line segments | {res.wall_line_fraction['lrt']:.3f} | "
        f"{res.wall_line_fraction['paper']:.3f} |\n"
        f"| false circles per wall | {res.wall_false_circles['lrt']:.3f} | "
        f"{res.wall_false_circles['paper']:.3f} |\n"
        f"| bushes extracted as a circle | {res.bush_circle_rate['lrt']:.3f} | "
        f"{res.bush_circle_rate['paper']:.3f} |\n"
    )
    ctx.outputs += write_tidy_table(
        ctx.out_dir / "classification",
        records,
        index=["radius_m", "range_m", "beams_on_trunk"],
        columns=["line_test"],
        values="circle_rate",
        labels={
            "radius_m": "radius (m)",
            "range_m": "range (m)",
            "beams_on_trunk": "beams on trunk",
            "lrt": "circle rate (lrt)",
            "paper": "circle rate (paper eq. 5)",
        },
        title="Classification of simulated trunks, walls and bushes",
        notes=notes,
    )
    setup = (
        f"Simulated trunks ahead of a PLS200 (0.5 deg beams), {100 * sigma:g} cm range noise, "
        f"1 cm quantisation, {n} trials per point"
    )
    spec = ("classification.png", features_figures.plot_circle_rates, (res,), {"setup": setup})
    products.figures(ctx, [spec], desc="classification figure")


def victoria_park_trial(quick: bool, seed=None) -> dict:
    """The Victoria Park scans (`victoria_park_scans`) as a trial (deterministic: the seed is
    unused): {"files": {file name: bytes} (features.rrd, and fig_vp_scan.png unless the data
    are absent), "victoria_park": what the manifest says of it}."""
    from experiments.render.viz import MemoryRecorder

    with MemoryRecorder("features", series=SERIES) as rec:
        note, figure = victoria_park_scans(quick, rec)
    files = {"features.rrd": rec.data}
    if figure is not None:
        files["fig_vp_scan.png"] = figure
    return {"files": files, "victoria_park": note}


def victoria_park_scans(quick: bool, rec) -> tuple[dict | str, bytes | None]:
    """Every raw Victoria Park scan (--quick: the first 300) through the paper's and Bailey's
    extractors, logged to `rec`, and the figure of the scan with the most paper circles: returns
    (scan index and scans logged, or "skipped: why" when the data are absent; the figure's PNG
    bytes, or None). Corrupt data raise."""
    from experiments.io.victoria_park import load_victoria_park

    try:
        seq = load_victoria_park()
    except MissingDataError as exc:
        log.warning("Victoria Park figure skipped: %s", exc)
        return f"skipped: {exc}", None
    n = 300 if quick else seq.n_scans
    best_k, best_n = 0, -1
    for k in range(n):
        scan = seq.scan(k)
        f = extract_features(scan, "paper")
        b = extract_features(scan, "bailey")
        rec.set_scan(k, scan.stamp_s)
        rec.log_scalars("circles_per_scan", {"paper": f.n_circles, "bailey": b.n_circles})
        rec.log_scan(scan, path="laser/scan")
        rec.log_features(scan, f, path="laser/features/paper")
        rec.log_circles("laser/features/bailey/circles", b.circle_params, method="bailey")
        if f.n_circles > best_n:
            best_k, best_n = k, f.n_circles
    scan = seq.scan(best_k)
    f = extract_features(scan, "paper")
    b = extract_features(scan, "bailey")
    figure = products.png(
        plots.plot_features,
        scan.points_xy,
        segments=plots.segments_of(f),
        circles=[
            ("paper", f.circle_params, plots.METHOD_COLORS["paper"]),
            ("bailey", b.circle_params, plots.METHOD_COLORS["bailey"]),
        ],
        edges_xy=f.edge_xy,
        title=f"Victoria Park scan index {best_k} (0-based, as in the manifest and the "
        f"recording; t = {scan.stamp_s:.2f} s; laser frame)",
        zoom=plots.zoom_box(f.circle_params),
    )
    return {"scan_index": best_k, "scans_logged": n}, figure


@experiment(
    "features",
    order=10,
    page="features.md",
    help="classification of simulated trunks, the Victoria Park scan figure, features.rrd",
)
def run(ctx) -> None:
    from dataclasses import asdict

    from features.bailey import BaileyParams
    from features.extract import ExtractorParams

    ctx.config.setdefault("features", {})
    ctx.config["features"]["extractor_defaults"] = ExtractorParams().to_dict()
    ctx.config["features"]["bailey"] = asdict(BaileyParams())
    # the Victoria Park scans first, on a worker, beside the classification trials
    vp = ctx.submit(victoria_park_trial, [ctx.quick], desc="victoria park scans")

    def finish(got: list) -> None:
        products.write(ctx, got[0]["files"])
        ctx.config["features"]["victoria_park"] = got[0]["victoria_park"]

    ctx.later(vp, finish)
    classification(ctx)
