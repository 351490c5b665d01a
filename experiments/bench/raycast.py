"""`trunkslam bench raycast`: the simulator's speed, microseconds per 720-beam scan."""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from experiments.io.provenance import machine
from experiments.io.writers import markdown_table
from experiments.sim.raycast import raycast, raycast_dense
from experiments.sim.scene import BushObject, CircleObject, Scene, WallObject, load_scene, make_bush
from experiments.sim.simulate import sensor_preset, simulate_scan

__all__ = ["bench_raycast", "format_table", "random_scene"]


def random_scene(
    rng: np.random.Generator, n_circles: int = 30, n_walls: int = 10, n_bushes: int = 10
) -> Scene:
    """A cluttered 60 m x 60 m scene around the origin (kept 2 m clear) for benchmarks."""

    def spot() -> np.ndarray:
        while True:
            p = rng.uniform(-30, 30, 2)
            if np.hypot(*p) > 2.0:
                return p

    circles = tuple(CircleObject(f"c{i}", spot(), rng.uniform(0.1, 0.6)) for i in range(n_circles))
    walls = []
    for i in range(n_walls):
        p0 = spot()
        pts = [p0, p0 + rng.uniform(-8, 8, 2)]
        pts.append(pts[-1] + rng.uniform(-8, 8, 2))
        walls.append(WallObject(f"w{i}", pts))
    bushes = tuple(
        BushObject(f"b{i}", make_bush(spot(), rng.uniform(0.4, 1.2), rng)) for i in range(n_bushes)
    )
    return Scene(circles=circles, walls=tuple(walls), bushes=bushes, name="random")


def _time_us(f, repeats: int) -> float:
    f()  # warm-up (geometry cache)
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(repeats):
            f()
        best = min(best, (time.perf_counter() - t0) / repeats)
    return best * 1e6


def bench_raycast(repeats: int = 300, seed: int = 0, progress=None) -> list[dict]:
    """Best-of-5 mean time per call, us, of `raycast`, `raycast_dense` and `simulate_scan`
    (720 beams, back-to-back PLS200) on the bundled scenes and a random 50-object scene.
    progress: an optional callback(description, done, total) after each scene."""
    rng = np.random.default_rng(seed)
    sensor = sensor_preset("pls200", back_to_back=True)
    scenes = [load_scene("pillar_court"), load_scene("test_yard"), random_scene(rng)]
    rows = []
    for k, scene in enumerate(scenes):
        if progress is not None:
            progress("ray casting scenes", k, len(scenes))
        pose = scene.scan_positions[0] if scene.scan_positions.shape[0] else np.zeros(3)
        ang = pose[2] + sensor.angles_rad
        geo = scene.geometry(sensor.mount_height_m)
        srng = np.random.default_rng(seed)
        rows.append(
            {
                "scene": scene.name,
                "objects": scene.n_objects,
                "primitives": int(geo["circ_xyr"].shape[0] + geo["seg_p"].shape[0]),
                "beams": sensor.n_beams,
                "raycast_us": _time_us(partial(raycast, scene, pose[:2], ang), repeats),
                "raycast_dense_us": _time_us(
                    partial(raycast_dense, scene, pose[:2], ang), max(1, repeats // 10)
                ),
                "simulate_scan_us": _time_us(
                    partial(simulate_scan, scene, pose, sensor, srng), repeats
                ),
            }
        )
    if progress is not None:
        progress("ray casting scenes", len(scenes), len(scenes))
    return rows


def format_table(rows: list[dict]) -> str:
    """Markdown table of `bench_raycast` rows, with the machine."""
    body = markdown_table(
        [
            "scene",
            "objects",
            "circles + segments",
            "beams",
            "raycast us",
            "raycast_dense us",
            "simulate_scan us",
        ],
        [
            [
                r["scene"],
                r["objects"],
                r["primitives"],
                r["beams"],
                round(r["raycast_us"], 1),
                round(r["raycast_dense_us"], 1),
                round(r["simulate_scan_us"], 1),
            ]
            for r in rows
        ],
    )
    return f"Ray casting, best of 5 (one thread; {machine()})\n\n{body}"
