"""Simulated loops with known truth, for loop closure: a drive that maps a stand of trees,
leaves it through open ground long enough for the odometry to drift, and comes back.

`loop_scene(kind, seed)`: the stand around the start and a closed route (a rectangle of about
`2 excursion_m + 200` m). kind "park": 45 trunks of radius 0.15-0.35 m placed at random at least
3 m apart and 2.5 m from the route, over 60 m x 28 m; kind "orchard": 60 identical trunks
(radius 0.2 m) in four rows 6 m apart, one every 4 m: every tree has look-alikes one spacing
away, the case where a false closure is easy. Outside the stand the ground is open, so the
return is dead reckoned.
`loop_drive(seed, kind, noise_scale)`: one simulated Cycab run around it, with the Cycab's
odometry noise scaled by `noise_scale` (`experiments.paper.loop_closure` runs the filter on it).
"""

from __future__ import annotations

import math

import numpy as np

from experiments.sim.scene import Scene, scene_from_dict
from experiments.sim.trajectory import CycabParams, simulate_cycab_run
from slam import Sequence

__all__ = ["LOOP_KINDS", "loop_drive", "loop_params", "loop_scene"]

LOOP_KINDS = ("park", "orchard")
SPEED_MPS = 1.2  # the Cycab's cruising speed (`CycabParams`)


def _route(excursion_m: float) -> list[tuple[float, float, float]]:
    """The route's waypoints [x, y, heading]: east through the stand, north, west along the
    far side `excursion_m` away, south, and back east into the stand."""
    h = excursion_m
    return [
        (0.0, 0.0, 0.0),
        (45.0, 0.0, 0.0),
        (60.0, 10.0, math.pi / 2),
        (60.0, h, math.pi / 2),
        (30.0, h + 10.0, math.pi),
        (-20.0, h, -math.pi / 2),
        (-25.0, 10.0, -math.pi / 2),
        (-15.0, 0.0, 0.0),
    ]


def _distance_to_route(p: np.ndarray, way: list) -> float:
    pts = np.array([w[:2] for w in way] + [way[0][:2]], dtype=np.float64)
    best = math.inf
    for a, b in zip(pts[:-1], pts[1:]):
        ab = b - a
        t = float(np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0))
        best = min(best, float(np.hypot(*(a + t * ab - p))))
    return best


def loop_scene(kind: str, seed: int, excursion_m: float = 40.0) -> Scene:
    """The stand of `kind` ("park" or "orchard") and the route (module doc)."""
    if kind not in LOOP_KINDS:
        raise ValueError(f"kind: expected one of {LOOP_KINDS}, got {kind!r}")
    rng = np.random.default_rng(seed)
    way = _route(excursion_m)
    trees, radii = [], []
    if kind == "park":
        while len(trees) < 45:
            p = np.array([rng.uniform(-10.0, 50.0), rng.uniform(-14.0, 14.0)])
            if _distance_to_route(p, way) < 2.5 or any(np.hypot(*(p - q)) < 3.0 for q in trees):
                continue
            trees.append(p)
            radii.append(float(rng.uniform(0.15, 0.35)))
    else:
        for y in (-12.0, -6.0, 6.0, 12.0):
            for x in np.arange(-8.0, 50.0, 4.0):
                trees.append(np.array([x, y]))
                radii.append(0.2)
    circles = [
        {"name": f"T{i}", "kind": "trunk", "center_xy": [float(p[0]), float(p[1])], "radius_m": r}
        for i, (p, r) in enumerate(zip(trees, radii))
    ]
    return scene_from_dict(
        {
            "name": f"loop_{kind}_{seed}",
            "circles": circles,
            "scan_positions": [[float(v) for v in w] for w in way],
        }
    )


def loop_drive(
    seed: int, kind: str, noise_scale: float = 0.5, excursion_m: float = 40.0
) -> Sequence:
    """One run once around `loop_scene(kind, seed + 10_000)` and 60 m into the stand again,
    with the Cycab's odometry noise (0.1 m/s, 2 deg per sample) times `noise_scale`."""
    scene = loop_scene(kind, seed + 10_000, excursion_m)
    p = loop_params(noise_scale, excursion_m)
    return simulate_cycab_run(np.random.default_rng(seed), scene, p)


def loop_params(noise_scale: float, excursion_m: float = 40.0) -> CycabParams:
    """The car of `loop_drive`: the Cycab with its odometry noise times `noise_scale`, for one
    lap and 60 m more."""
    return CycabParams(
        n_scans=int((2 * excursion_m + 260.0) / SPEED_MPS * 5),
        speed_sigma_mps=0.1 * noise_scale,
        steer_sigma_rad=math.radians(2.0) * noise_scale,
    )
