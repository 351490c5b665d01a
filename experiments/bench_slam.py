"""`trunkslam bench slam`: EKF-SLAM time per scan against the size of the map.

The map has to grow to hundreds of landmarks, which the tree park cannot give, so the bench
drives the filter down a long avenue: trees every `spacing_m` on both sides of a straight road,
the car at `speed_mps` with 5 Hz scans and 20 Hz odometry (the Cycab noise), and every tree
within `view_m` ahead measured as a circle centre with the `paper` noise model (the extractor
itself is timed by `trunkslam bench extract`). `slam.run` times its phases per scan; the rows
give their medians over the scans whose map size falls in each bin. One process; numpy's
BLAS may use more than one thread for the larger matrices.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from types import SimpleNamespace

import numpy as np

from experiments.bench import machine
from experiments.export import markdown_table
from features.types import Features, Scan
from slam import SlamConfig, run
from slam.run import TIMING_KEYS

__all__ = ["avenue", "bench", "format_table"]


def avenue(
    n_trees: int,
    rng: np.random.Generator,
    spacing_m: float = 4.0,
    half_width_m: float = 6.0,
    speed_mps: float = 10.0,
    view_m: float = 20.0,
):
    """(sequence-like object, list of Features): a straight drive past n_trees trees."""
    length = spacing_m * n_trees / 2 + view_m
    dt, every = 0.05, 4
    n_scans = int(length / (speed_mps * dt * every)) + 1
    t = np.arange((n_scans - 1) * every + 1) * dt
    x = speed_mps * t
    truth = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    side = np.where(np.arange(n_trees) % 2, 1.0, -1.0)
    trees = np.column_stack(
        [
            view_m * 0.5 + spacing_m * (np.arange(n_trees) // 2),
            side * half_width_m + rng.uniform(-1, 1, n_trees),
        ]
    )
    laser = np.array([1.55, 0.0, 0.0])
    feats = []
    for k in range(n_scans):
        px = x[k * every] + laser[0]
        d = trees - np.array([px, 0.0])
        r = np.hypot(d[:, 0], d[:, 1])
        b = np.arctan2(d[:, 1], d[:, 0])
        seen = (r < view_m) & (np.abs(b) < math.pi / 2)
        rr = r[seen] + (0.011 + 0.001 * r[seen]) * rng.standard_normal(seen.sum())
        bb = b[seen] + np.sqrt(0.00022**2 + (0.0067 / r[seen]) ** 2) * rng.standard_normal(
            seen.sum()
        )
        n = int(seen.sum())
        f = Features.empty(float(t[k * every]), "paper")
        feats.append(
            dataclasses.replace(
                f,
                circle_params=np.column_stack([rr * np.cos(bb), rr * np.sin(bb), np.full(n, 0.3)]),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    speed = speed_mps + 0.1 * rng.standard_normal(t.size)
    steer = math.radians(2.0) * rng.standard_normal(t.size)
    empty = np.full(361, np.nan)
    seq = SimpleNamespace(
        scan_t=t[::every],
        scan_ranges=np.full((n_scans, 361), np.nan),
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        scan_max_range=80.0,
        laser_pose=laser,
        odo_t=t,
        odo_speed=speed,
        odo_steer=steer,
        vehicle={"model": "ackermann", "wheelbase_m": 1.2, "encoder_offset_m": 0.0},
        truth_t=t,
        truth_pose=truth,
        gps_t=None,
        scan=lambda k: Scan(empty, -math.pi / 2, math.pi / 360, float(t[k * every]), 80.0),
    )
    return seq, feats


def bench(
    n_trees: int = 800,
    association: str = "ihgr",
    seed: int = 0,
    bins=(0, 25, 50, 100, 200, 300, 400, 600, 800, 1200),
) -> list[dict]:
    """Median ms per scan of each phase, by map size (landmarks in the filter)."""
    seq, feats = avenue(n_trees, np.random.default_rng(seed))
    t0 = time.perf_counter()
    log = run(seq, features=feats, association=association, config=SlamConfig())
    wall = time.perf_counter() - t0
    n_map = log.n_map
    rows = []
    for lo, hi in itertools.pairwise(bins):
        sel = (n_map >= lo) & (n_map < hi)
        if not sel.any():
            continue
        row = {
            "map size": f"{lo}-{hi - 1}",
            "scans": int(sel.sum()),
            "state dim": int(3 + 2 * np.median(n_map[sel])),
            "measurements": round(float(np.mean(log.n_features[sel])), 1),
        }
        for k in TIMING_KEYS:
            if k != "features":
                row[f"{k} ms"] = round(1e3 * float(np.median(log.timing_s[k][sel])), 3)
        rows.append(row)
    rows.append(
        {
            "map size": "whole run",
            "scans": log.n_scans,
            "state dim": int(3 + 2 * n_map[-1]),
            "measurements": round(float(np.mean(log.n_features)), 1),
            "total ms": round(1e3 * wall / log.n_scans, 3),
        }
    )
    return rows


def format_table(rows: list[dict]) -> str:
    header = list(dict.fromkeys(k for r in rows for k in r))
    body = [[r.get(k, "") for k in header] for r in rows]
    return (
        f"EKF-SLAM time per scan against map size (avenue of trees, IHGR; {machine()})\n\n"
        + markdown_table(header, body)
    )


if __name__ == "__main__":  # pragma: no cover
    print(format_table(bench()))
