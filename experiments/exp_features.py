"""Experiment `features`: how the extractor classifies, and what it finds in real scans.

Writes
  classification.md/.csv/.png   how trunks, walls and bushes are classified (lrt vs paper eq. 5)
  fig_vp_scan.png               a real Victoria Park scan: paper and Bailey circles, edges, zoom
  features.rrd                  the Victoria Park scans in rerun (timeline `scan`)
The paper's Figs. 2-4 on the simulated pillar court come from experiment `table1`
(experiments/exp_circles.py).
"""

from __future__ import annotations

import logging

import numpy as np

from experiments import plots
from experiments.classification import RADII_M, RANGES_M, classification_study
from experiments.errors import DataError
from experiments.export import write_table
from experiments.viz import open_recording
from features import extract_features

log = logging.getLogger(__name__)


def _zoom_box(circles_xyr: np.ndarray, n: int = 1, margin: float = 1.5):
    """A box around the n circles nearest the sensor."""
    if len(circles_xyr) == 0:
        return None
    near = circles_xyr[np.argsort(np.hypot(circles_xyr[:, 0], circles_xyr[:, 1]))[:n]]
    lo = near[:, :2].min(axis=0) - margin
    hi = near[:, :2].max(axis=0) + margin
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _segments(f):
    return [((int(a), int(b)), int(k)) for (a, b), k in zip(f.segment_beams, f.segment_kind)]


def classification(ctx) -> None:
    n = 8 if ctx.quick else 60
    sigma = 0.01
    ctx.config["features"]["classification"] = {
        "n_trials": n,
        "sigma_m": sigma,
        "radii_m": RADII_M,
        "ranges_m": RANGES_M,
    }
    res = classification_study(ctx.rng("classification"), n, sigma, progress=ctx.progress)
    header = [
        "radius (m)",
        "range (m)",
        "beams on trunk",
        "circle rate (lrt)",
        "circle rate (paper eq. 5)",
    ]
    rows = [
        [
            r,
            d,
            round(res.beams[(r, d)], 1),
            res.circle_rate["lrt"][(r, d)],
            res.circle_rate["paper"][(r, d)],
        ]
        for r in RADII_M
        for d in RANGES_M
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
    ctx.outputs += write_table(
        ctx.out_dir / "classification",
        header,
        rows,
        title="Classification of simulated trunks, walls and bushes",
        notes=notes,
    )
    ctx.outputs.append(plots.plot_circle_rates(res, ctx.out_dir / "classification.png"))


def victoria_park_figure(ctx, rec) -> None:
    from experiments.victoria_park import load_victoria_park

    try:
        seq = load_victoria_park()
    except DataError as exc:
        log.warning("Victoria Park figure skipped: %s", exc)
        ctx.config["features"]["victoria_park"] = f"skipped: {exc}"
        return
    n = 300 if ctx.quick else seq.n_scans
    best_k, best_n = 0, -1
    for k in range(n):
        scan = seq.scan(k)
        f = extract_features(scan, "paper")
        b = extract_features(scan, "bailey")
        rec.set_scan(k)
        rec.log_scan(scan, path="victoria_park/scan")
        rec.log_features(scan, f, path="victoria_park/features/paper")
        rec.log_circles("victoria_park/features/bailey/circles", b.circle_params, method="bailey")
        if f.n_circles > best_n:
            best_k, best_n = k, f.n_circles
        if k % 100 == 0:
            ctx.progress("victoria park scans", k + 1, n)
    ctx.progress("victoria park scans", n, n)
    scan = seq.scan(best_k)
    f = extract_features(scan, "paper")
    b = extract_features(scan, "bailey")
    ctx.config["features"]["victoria_park"] = {"scan_index": best_k, "scans_logged": n}
    ctx.outputs.append(
        plots.plot_features(
            scan.points_xy,
            _segments(f),
            [
                ("paper", f.circle_params, plots.METHOD_COLORS["paper"]),
                ("bailey", b.circle_params, plots.METHOD_COLORS["bailey"]),
            ],
            f.edge_xy,
            f"Victoria Park scan {best_k + 1} (t = {scan.stamp_s:.2f} s; laser frame)",
            ctx.out_dir / "fig_vp_scan.png",
            zoom=_zoom_box(f.circle_params),
        )
    )


def run(ctx) -> None:
    from dataclasses import asdict

    from features.bailey import BaileyParams
    from features.extract import ExtractorParams

    ctx.config.setdefault("features", {})
    ctx.config["features"]["extractor_defaults"] = ExtractorParams().to_dict()
    ctx.config["features"]["bailey"] = asdict(BaileyParams())
    classification(ctx)
    rec = open_recording(ctx.path("features.rrd"))
    try:
        victoria_park_figure(ctx, rec)
    finally:
        rec.close()
