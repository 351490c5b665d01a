"""How the extractor classifies simulated trunks, walls and bushes (known truth, per-beam labels).

Each trial is a small scene seen by one SICK PLS200 (180 deg, 0.5 deg, 50 m, 1 cm quantisation)
from the origin:
- trunk trials: one trunk of radius r at range d, at a random bearing within +-60 deg, with a
  background wall 2-10 m behind it in half of the trials (nothing behind in the others);
- wall trials: one 12 m wall at 2-20 m, seen at 0-60 deg incidence;
- bush trials: one irregular bush (`make_bush`, mean radius 0.3-1.0 m) at 3-20 m.
A circle "finds" an object when most of its beams carry the object's label.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from experiments.eval.detections import found
from experiments.exec import SerialExecutor, spawn_seeds
from experiments.sim import make_bush, scene_from_dict, sensor_preset, simulate_scan
from features import extract_features

__all__ = [
    "ClassificationResult",
    "classification_study",
    "classification_trial",
    "trunk_trial",
    "wall_trial",
    "bush_trial",
]

RADII_M = (0.1, 0.2, 0.3, 0.45, 0.6)
RANGES_M = (2.0, 5.0, 10.0, 15.0, 20.0)


def _sensor(sigma_m: float):
    return sensor_preset("pls200", range_sigma_m=sigma_m)


def _extract(scene, rng, sigma_m, method="geometric", line_test="lrt", **params):
    """Simulate the scene from the origin and extract; returns (features, per-beam labels)."""
    sensor = _sensor(sigma_m)
    ranges, labels = simulate_scan(scene, (0.0, 0.0, 0.0), sensor, rng)
    f = extract_features(
        sensor.scan(ranges),
        method,
        sigma_r_m=sensor.effective_sigma_m,
        line_test=line_test,
        **({"short_trunks": False} | params),  # paper-faithful unless asked
    )
    return f, labels


def trunk_trial(rng, r_m, d_m, sigma_m=0.01, method="geometric", line_test="lrt", **params):
    """One trunk; returns (found as circle, number of beams on the trunk)."""
    bearing = rng.uniform(-math.pi / 3, math.pi / 3)
    c = d_m * np.array([math.cos(bearing), math.sin(bearing)])
    data = {"circles": [{"name": "t", "kind": "trunk", "center_xy": c.tolist(), "radius_m": r_m}]}
    if rng.random() < 0.5:
        u = np.array([math.cos(bearing), math.sin(bearing)])
        w = (d_m + rng.uniform(2, 10)) * u
        t = np.array([-u[1], u[0]]) * 15.0
        data["walls"] = [{"name": "w", "points_xy": [(w - t).tolist(), (w + t).tolist()]}]
    f, labels = _extract(scene_from_dict(data), rng, sigma_m, method, line_test, **params)
    return found(f, labels, 0), int(np.sum(labels == 0))


def wall_trial(rng, sigma_m=0.01, line_test="lrt", **params):
    """One wall; returns (fraction of its beams in line segments, circles found on it)."""
    d = rng.uniform(2, 20)
    inc = rng.uniform(0, math.radians(60))
    n = np.array([math.cos(inc), math.sin(inc)])
    p = d * np.array([1.0, 0.0])  # the wall passes through (d, 0) with normal at `inc`
    t = np.array([-n[1], n[0]]) * 6.0
    scene = scene_from_dict(
        {"walls": [{"name": "w", "points_xy": [(p - t).tolist(), (p + t).tolist()]}]}
    )
    f, labels = _extract(scene, rng, sigma_m, line_test=line_test, **params)
    on_wall = labels == 0
    in_line = np.zeros_like(on_wall)
    for a, b in f.line_beams:
        in_line[f.beams(a, b)] = True
    n_circ = sum(np.mean(labels[f.beams(a, b)] == 0) > 0.5 for a, b in f.circle_beams)
    return float(np.mean(in_line[on_wall])) if on_wall.any() else math.nan, int(n_circ)


def bush_trial(rng, sigma_m=0.01, line_test="lrt", **params):
    """One bush; returns True when it is (falsely) extracted as a circle."""
    d = rng.uniform(3, 20)
    bearing = rng.uniform(-math.pi / 3, math.pi / 3)
    c = d * np.array([math.cos(bearing), math.sin(bearing)])
    pts = make_bush(c, rng.uniform(0.3, 1.0), rng)
    scene = scene_from_dict({"bushes": [{"name": "b", "points_xy": pts.tolist()}]})
    f, labels = _extract(scene, rng, sigma_m, line_test=line_test, **params)
    return found(f, labels, 0)


@dataclass
class ClassificationResult:
    """circle_rate[test][(r, d)], mean beams[(r, d)], wall line-beam fraction and false circles,
    bush false-circle rate, per line test."""

    circle_rate: dict
    beams: dict
    wall_line_fraction: dict
    wall_false_circles: dict
    bush_circle_rate: dict
    n_trials: int


def classification_trial(cell: tuple, seed) -> list:
    """One cell of the classification study, a trial with its own seed: `cell` is
    ("trunk", line_test, r, d, n, sigma), ("wall", line_test, n, sigma) or ("bush", line_test, n,
    sigma); returns the n trials' results in order."""
    rng = np.random.default_rng(seed)
    kind, t = cell[:2]
    if kind == "trunk":
        r, d, n, sigma = cell[2:]
        return [trunk_trial(rng, r, d, sigma, line_test=t) for _ in range(n)]
    n, sigma = cell[2:]
    one = wall_trial if kind == "wall" else bush_trial
    return [one(rng, sigma, line_test=t) for _ in range(n)]


def classification_study(
    rng: np.random.Generator,
    n_trials: int = 40,
    sigma_m: float = 0.01,
    line_tests=("lrt", "paper"),
    radii=RADII_M,
    ranges=RANGES_M,
    progress=lambda desc, done, total: None,
    executor=None,
) -> ClassificationResult:
    """Every cell (line test x trunk radius x range, walls, bushes) is a trial of n_trials
    scenes with its own seed (`spawn_seeds(rng, cells)`), run on `executor`."""
    cells = []
    for t in line_tests:
        cells += [("trunk", t, r, d, n_trials, sigma_m) for r in radii for d in ranges]
        cells += [("wall", t, n_trials, sigma_m), ("bush", t, n_trials, sigma_m)]
    got = (executor or SerialExecutor()).map(
        classification_trial,
        cells,
        spawn_seeds(rng, len(cells)),
        desc="classification",
        progress=progress,
    )
    rate: dict = {t: {} for t in line_tests}
    beams: dict = {}
    wall_frac: dict = {}
    wall_fc: dict = {}
    bush: dict = {}
    for cell, res in zip(cells, got):
        kind, t = cell[:2]
        if kind == "trunk":
            r, d = cell[2:4]
            rate[t][(r, d)] = float(np.mean([f for f, _ in res]))
            beams[(r, d)] = float(np.mean([n for _, n in res]))
        elif kind == "wall":
            wall_frac[t] = float(np.nanmean([f for f, _ in res]))
            wall_fc[t] = float(np.mean([c for _, c in res]))
        else:
            bush[t] = float(np.mean(res))
    return ClassificationResult(
        circle_rate=rate,
        beams=beams,
        wall_line_fraction=wall_frac,
        wall_false_circles=wall_fc,
        bush_circle_rate=bush,
        n_trials=n_trials,
    )
