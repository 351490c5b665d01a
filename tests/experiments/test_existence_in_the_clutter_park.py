"""`slam.existence` on scans of the clutter park, where the truth is exact: what the beams say
about a trunk, a thin post far away, and a landmark where nothing stands."""

import math

import numpy as np
import pytest

from experiments.sim import sensor_preset, simulate_scan
from experiments.sim.clutter import clutter_park
from slam import se2
from slam.existence import ExistenceConfig, beam_evidence, detection_probability, update_existence


def _evidence(names_or_xy, radius_m):
    sc = clutter_park()
    sensor = sensor_preset("lms200")
    pose = np.array([14.0, -5.0, 0.0])  # the route's start, heading east
    ranges, _ = simulate_scan(sc, pose, sensor, np.random.default_rng(0))
    xy = np.array(
        [sc.circles[sc.label_of(n)].center_xy if isinstance(n, str) else n for n in names_or_xy]
    )
    z, _ = se2.observe(pose, xy, np.zeros(3))
    cfg = ExistenceConfig(min_beams=2, max_range_m=sensor.max_range_m)
    ev = beam_evidence(ranges, sensor.angles_rad, z[:, 0], z[:, 1], np.asarray(radius_m), cfg)
    fov = np.abs(z[:, 1]) <= sensor.fov_rad / 2
    return ev, detection_probability(ev, z[:, 0], fov, cfg), cfg


def test_a_near_trunk_is_detectable_and_a_thin_post_far_away_is_not():
    # T2: radius 0.3 m at about 4.1 m, many beams; P1: a 0.15 m lamp post 23.1 m away
    # spans asin(0.075 / 23.1) = 0.19 deg either side: one beam of 0.5 deg at most
    ev, pd, cfg = _evidence(["T2", "P1"], [0.3, 0.075])
    assert ev.reach[0] > 10 and ev.occluded[0] == 0 and ev.through[0] == 0
    assert ev.reach[1] <= 1
    np.testing.assert_array_equal(pd, [cfg.pd_max, 0.0])
    # so missing the post says nothing: its existence is kept
    r = update_existence(np.array([0.5, 0.5]), pd, np.zeros(2, bool), np.zeros(2), ev.through,
                         kappa=1e-3, cfg=cfg)  # fmt: skip
    assert r[1] == 0.5 and r[0] < 0.5


def test_a_landmark_where_nothing_stands_loses_existence_by_its_see_through_beams():
    # open ground 8 m ahead of the start: the beams there run on to the far side
    ev, pd, cfg = _evidence([(22.0, -5.0)], [0.3])
    assert ev.reach[0] >= 4 and ev.through[0] == ev.reach[0]
    r = update_existence(np.array([0.5]), pd, np.zeros(1, bool), np.zeros(1), ev.through,
                         kappa=1e-3, cfg=cfg)  # fmt: skip
    want = 0.5 * (1 - cfg.pd_max) * cfg.see_through_q ** ev.through[0]
    assert r[0] == pytest.approx(want / (want + 0.5), rel=1e-12) and r[0] < cfg.remove_prob
    assert math.isfinite(r[0])
