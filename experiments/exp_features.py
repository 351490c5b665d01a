"""Experiment `features`: the extractor on simulated and real scans (paper Figs. 2(b), 3, 4).

Writes
  classification.md/.csv/.png   how trunks, walls and bushes are classified (lrt vs paper eq. 5)
  fig2b_raw_scan.png            one whole 360 deg scan of the simulated pillar court
  fig3_position2.png            circles and edges at position 2, with a zoom
  fig4_position4.png            the same at position 4
  fig_vp_scan.png               a real Victoria Park scan: paper and Bailey circles, edges, zoom
  features.rrd                  all of it in rerun (timeline `scan`)
"""

from __future__ import annotations

import logging
import math

import numpy as np

from experiments import plots
from experiments.classification import RADII_M, RANGES_M, _extractor_sigma, classification_study
from experiments.errors import DataError
from experiments.export import write_table
from experiments.viz import open_recording
from features import extract_features

log = logging.getLogger(__name__)

METHOD_COLORS = {"paper": "tab:green", "geometric": "m", "bailey": "goldenrod"}


def _to_laser(xyr: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """World circles (L, 3) into the frame of a sensor at `pose` [x, y, theta]."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = xyr[:, :2] - pose[:2]
    return np.column_stack([d @ np.array([c, -s]), d @ np.array([s, c]), xyr[:, 2]])


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
    ctx.config["features"]["classification"] = {"n_trials": n, "sigma_m": sigma,
                                                "radii_m": RADII_M, "ranges_m": RANGES_M}  # fmt: skip
    res = classification_study(ctx.rng("classification"), n, sigma, progress=ctx.progress)
    header = ["radius (m)", "range (m)", "beams on trunk", "circle rate (lrt)",
              "circle rate (paper eq. 5)"]  # fmt: skip
    rows = [
        [r, d, round(res.beams[(r, d)], 1), res.circle_rate["lrt"][(r, d)],
         res.circle_rate["paper"][(r, d)]]
        for r in RADII_M for d in RANGES_M
    ]  # fmt: skip
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
        ctx.out_dir / "classification", header, rows,
        title="Classification of simulated trunks, walls and bushes", notes=notes,
    )  # fmt: skip
    ctx.outputs.append(plots.plot_circle_rates(res, ctx.out_dir / "classification.png"))


def pillar_figures(ctx, rec) -> None:
    from experiments.sim import load_scene, sensor_preset, simulate_scan

    scene = load_scene("pillar_court")
    sensor = sensor_preset("pls200", back_to_back=True)
    rng = ctx.rng("pillar_figures")
    sigma = _extractor_sigma(sensor)
    truth = scene.truth_landmarks
    ctx.config["features"]["pillar_figures"] = {"scene": "pillar_court", "sensor": "pls200 x2",
                                                "sigma_r_m": sigma}  # fmt: skip
    for k, pose in enumerate(scene.scan_positions):
        ranges, _ = simulate_scan(scene, pose, sensor, rng)
        scan = sensor.scan(ranges, stamp_s=float(k))
        feats = {m: extract_features(scan, m, sigma_r_m=sigma) for m in ("paper", "geometric")}
        feats["bailey"] = extract_features(scan, "bailey")
        rec.set_scan(k)
        rec.log_scan(scan, pose=pose)
        for m, f in feats.items():
            rec.log_features(scan, f, pose=pose, path=f"world/features/{m}")
        rec.log_circles("world/truth/pillars", truth, method="truth",
                        labels=[c.name for c in scene.circles])  # fmt: skip
        truth_l = _to_laser(truth, pose)
        if k == 0:
            ctx.outputs.append(plots.plot_raw_scan(
                scan.points_xy, "Fig. 2(b): one whole scan (simulated pillar court, position 1)",
                ctx.out_dir / "fig2b_raw_scan.png"))  # fmt: skip
        if k in (1, 3):
            fig = {1: "fig3_position2.png", 3: "fig4_position4.png"}[k]
            f = feats["paper"]
            circles = [(m, feats[m].circle_params, METHOD_COLORS[m]) for m in feats]
            ctx.outputs.append(plots.plot_features(
                scan.points_xy, _segments(f), circles, f.edge_xy,
                f"Circles and edges at position {k + 1} (simulated; laser frame)",
                ctx.out_dir / fig, zoom=_zoom_box(truth_l), truth_xyr=truth_l,
            ))  # fmt: skip


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
        rec.set_scan(1000 + k)
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
    ctx.config["features"]["victoria_park"] = {"scan_index": best_k, "scans_logged": n,
                                               "rerun_scan_offset": 1000}  # fmt: skip
    ctx.outputs.append(plots.plot_features(
        scan.points_xy, _segments(f),
        [("paper", f.circle_params, METHOD_COLORS["paper"]),
         ("bailey", b.circle_params, METHOD_COLORS["bailey"])],
        f.edge_xy, f"Victoria Park scan {best_k + 1} (t = {scan.stamp_s:.2f} s; laser frame)",
        ctx.out_dir / "fig_vp_scan.png", zoom=_zoom_box(f.circle_params),
    ))  # fmt: skip


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
        pillar_figures(ctx, rec)
        victoria_park_figure(ctx, rec)
    finally:
        rec.close()
