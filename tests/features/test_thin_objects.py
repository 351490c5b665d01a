"""Thin objects (issue 26): simulated poles of radius 0.03-0.15 m seen by 1-3 beams, with a
wall, a parked-car box (4.5 x 1.8 m) and a bush in the same scan, at least 3 m beyond the
pole's clearance. The geometric extractor with short trunks (the preset's settings otherwise
at their defaults) must find the poles, with a covariance whose NEES is inside its 95% bound as
often as that bound says, and must not make circles of the wall's ends, the box's corners or
the bush. Rates over 300 seeded scenes; the measured figures are in the comments."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from features import extract_features

N_SCENES = 300
CLEARANCE_M = 2.0  # ExtractorParams.short_trunk_clearance_m's default


def _scene(rng):
    from experiments.sim import make_bush, scene_from_dict

    r_pole = rng.uniform(0.03, 0.15)
    d, th = rng.uniform(6.0, 25.0), rng.uniform(-1.0, 1.0)
    pole = np.array([d * np.cos(th), d * np.sin(th)])

    def away() -> np.ndarray:  # a place in view, clear of the pole's clearance by 3 m
        while True:
            p = np.array([rng.uniform(4.0, 25.0), rng.uniform(-15.0, 15.0)])
            if np.hypot(*(p - pole)) > CLEARANCE_M + 3.0 + 3.0:  # (+ the object's own size)
                return p

    w0, a = away(), rng.uniform(0.0, np.pi)
    wall = [w0.tolist(), (w0 + 5.0 * np.array([np.cos(a), np.sin(a)])).tolist()]
    b0, a = away(), rng.uniform(0.0, np.pi)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    corners = ([-2.25, -0.9], [2.25, -0.9], [2.25, 0.9], [-2.25, 0.9])
    box = [(b0 + rot @ np.array(c)).tolist() for c in corners]
    bush = make_bush(away(), rng.uniform(0.5, 1.5), rng, 12, 0.35)
    doc = {
        "circles": [{"name": "pole", "center_xy": pole.tolist(), "radius_m": r_pole}],
        "walls": [
            {"name": "wall", "points_xy": wall},
            {"name": "car", "points_xy": box, "closed": True},
        ],
        "bushes": [{"name": "bush", "points_xy": np.asarray(bush).tolist()}],
    }
    return scene_from_dict(doc), pole


@pytest.fixture(scope="module")
def rates():
    from experiments.sim import sensor_preset, simulate_scan

    rng = np.random.default_rng(2026)
    sensor = sensor_preset("lms200", range_sigma_m=0.01)
    found = {1: [], 2: [], 3: []}
    nees_inside, circles_on = [], {1: [], 2: [], 3: []}  # labels: 1 wall, 2 car, 3 bush
    for _ in range(N_SCENES):
        scene, pole = _scene(rng)
        ranges, labels = simulate_scan(scene, (0.0, 0.0, 0.0), sensor, rng)
        f = extract_features(sensor.scan(ranges), "geometric", short_trunks=True)
        hit = [set(labels[a : b + 1].tolist()) for a, b in f.circle_beams]
        for obj in circles_on:
            circles_on[obj].append(any(obj in h for h in hit))
        beams = int(np.sum(labels == 0))
        if beams in found:
            on_pole = [i for i, h in enumerate(hit) if h == {0}]
            found[beams].append(len(on_pole) == 1)
            if on_pole:
                e = f.circle_params[on_pole[0], :2] - pole
                nees = e @ np.linalg.solve(f.circle_cov[on_pole[0], :2, :2], e)
                nees_inside.append(nees <= chi2.ppf(0.95, 2))
    return found, nees_inside, circles_on


def test_thin_poles_of_one_to_three_beams_are_found(rates):
    found, _, _ = rates
    for beams, hits in found.items():
        assert len(hits) >= 20, (beams, len(hits))  # each case is really tried
        assert np.mean(hits) >= 0.9, (beams, np.mean(hits))  # measured 0.99, 0.99, 0.94


def test_a_poles_covariance_covers_its_error(rates):
    """The NEES of the pole's centre is inside its 95% bound in 95% of the scans, up to the
    sampling spread (about 1.4% on 237 scans: at least 92%), although the radius prior
    (0.2 +- 0.1 m) is a tree's, not these poles'. Measured: 0.97."""
    _, inside, _ = rates
    assert len(inside) >= 200
    assert np.mean(inside) >= 0.92, np.mean(inside)


def test_wall_ends_box_corners_and_bushes_are_not_circles(rates):
    _, _, circles_on = rates
    names = {1: "wall", 2: "parked-car box", 3: "bush"}
    for obj, made in circles_on.items():  # measured 0.02, 0.00, 0.04
        assert np.mean(made) <= 0.05, (names[obj], np.mean(made))


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    cyclic=st.booleans(),
    clearance=st.floats(0.1, 30.0),
    centre_r=st.floats(0.0, 60.0),
    centre_bearing=st.floats(-4.0, 4.0),
)
def test_the_clear_space_test_reads_only_the_beams_that_can_be_near(
    seed, cyclic, clearance, centre_r, centre_bearing
):
    """`_crowded` reads only the beams whose bearing is within asin(clearance / range) of the
    centre's: it must answer as the scan over every beam does, for a scan that wraps around
    (360 deg) or not, a centre nearer than the clearance, and a centre outside the view."""
    from features.extract import _crowded

    rng = np.random.default_rng(seed)
    n = 720 if cyclic else 361
    gamma = 2 * np.pi / n if cyclic else np.radians(0.5)
    angle_min = rng.uniform(-np.pi, np.pi) if cyclic else -np.pi / 2
    ranges = np.full(n, np.nan)  # a sparse scan: a few returns, one planted at the clearance
    ranges[rng.integers(0, n, 3)] = rng.uniform(0.5, 60.0, 3)
    a = int(rng.integers(0, n - 3))
    b = a + int(rng.integers(0, 3))
    ranges[a : b + 1] = centre_r
    cx, cy = centre_r * np.cos(centre_bearing), centre_r * np.sin(centre_bearing)
    phi = rng.uniform(-np.pi, np.pi)
    p = np.array([cx, cy]) + clearance * rng.uniform(0.97, 1.03) * np.array(
        [np.cos(phi), np.sin(phi)]
    )
    k = int(np.round((np.arctan2(p[1], p[0]) - angle_min) / gamma))
    k = k % n if cyclic else k
    if 0 <= k < n and not a <= k <= b:
        ranges[k] = np.hypot(*p)
    bearings = angle_min + gamma * np.arange(n)
    xy = ranges[:, None] * np.c_[np.cos(bearings), np.sin(bearings)]
    near = np.hypot(xy[:, 0] - cx, xy[:, 1] - cy) < clearance
    near[a : b + 1] = False
    want = bool(np.any(near[~np.isnan(ranges)]))
    got = _crowded(ranges, angle_min, gamma, a, b, cx, cy, clearance, float(cyclic))
    assert got == want
