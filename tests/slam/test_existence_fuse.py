"""A tentative's position fused over its sightings (`map_policy.existence_fuse_tentatives`,
`slam.tentatives.fuse`) and the see-through tolerance (`map_policy.existence_see_through_k`,
`slam.existence`, "See-through tolerance"): exact fused positions, beams inside / outside the
k-sigma region counted or not, and both off by default (the latest sighting, every beam past
the radius and gap counted, as before)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from slam import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.existence import ExistenceConfig, beam_evidence
from slam.log import NEW_TENTATIVE
from slam.sources import Measurements
from slam.tentatives import fuse, sighting
from tests.slam.test_map_managers import LASER, _existence_manager, _existence_scan

PERSISTENT = {
    "existence_clutter": "persistent",
    "existence_repeat_prob": 0.3,
    "existence_pd_max": 0.6,
}
K95 = 2.448  # sqrt(chi2_2(0.95)) to 4 figures: the setting's stated value


def test_fuse_is_the_inverse_covariance_weighted_mean_of_two_sightings():
    """(0, 0) with cov diag(1, 4) and (3, 3) with diag(2, 1): x = (0 * 1 + 3 * 1/2) / (1 +
    1/2) = 1, y = (0 * 1/4 + 3 * 1) / (1/4 + 1) = 2.4; cov diag(1 / 1.5, 1 / 1.25)."""
    xy, cov = fuse(np.zeros(2), np.diag([1.0, 4.0]), np.array([3.0, 3.0]), np.diag([2.0, 1.0]))
    assert xy == pytest.approx([1.0, 2.4], abs=1e-15)
    assert cov == pytest.approx(np.diag([2.0 / 3.0, 0.8]), abs=1e-15)


def test_fuse_over_three_sightings_is_their_batch_mean_in_any_order():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(3, 2)) * 0.3 + [20.0, 5.0]
    covs = []
    for _ in range(3):
        A = rng.normal(size=(2, 2)) * 0.2
        covs.append(A @ A.T + 0.01 * np.eye(2))
    info = sum(np.linalg.inv(C) for C in covs)
    want_cov = np.linalg.inv(info)
    want = want_cov @ sum(np.linalg.inv(C) @ p for C, p in zip(covs, pts))
    for order in ((0, 1, 2), (2, 0, 1)):
        xy, cov = pts[order[0]], covs[order[0]]
        for i in order[1:]:
            xy, cov = fuse(xy, cov, pts[i], covs[i])
        assert xy == pytest.approx(want, abs=1e-12)
        assert cov == pytest.approx(want_cov, abs=1e-12)
        assert np.array_equal(cov, cov.T)


def _sighted(z: tuple[float, float], k: int) -> Measurements:
    z_ = np.array([z])
    R = np.diag([1e-2, 1e-4])[None]
    return Measurements(k, None, None, z_, R, np.full(1, NEW_TENTATIVE, np.int64))


@pytest.mark.parametrize("fused", [False, True])
def test_a_tentative_is_placed_by_its_fused_sightings_only_when_asked(fused):
    """Two sightings of one trunk: the tentative's position is the second sighting alone
    (default) or both sightings fused (the batch inverse-covariance-weighted mean)."""
    manager, book = _existence_manager(
        "ihgr",
        existence_keep_tentatives=True,
        existence_fuse_tentatives=fused,
        **PERSISTENT,  # two sightings keep it a tentative
    )
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    zs = ((10.0, 0.0), (10.2, 0.01))
    for k, z in enumerate(zs):
        _existence_scan(manager, book, state, _sighted(z, k))
    assert len(manager.tent) == 1 and int(manager.tent.hits[0]) == 2
    seen = [
        sighting(state.pose, state.pose_cov, np.array(z), np.diag([1e-2, 1e-4]), LASER) for z in zs
    ]
    if fused:
        info = sum(np.linalg.inv(C) for _, C in seen)
        want = np.linalg.solve(info, sum(np.linalg.inv(C) @ m for m, C in seen))
        assert manager.tent.xy[0] == pytest.approx(want, abs=1e-12)
        assert manager.tent.cov[0] == pytest.approx(np.linalg.inv(info), rel=1e-9)
    else:
        assert np.array_equal(manager.tent.xy[0], seen[1][0])
        assert np.array_equal(manager.tent.cov[0], seen[1][1])


STEP = math.radians(0.5)
BEARINGS = STEP * np.arange(-3, 4)  # 7 beams, 0.5 deg apart; the middle 3 reach the trunk


def _evidence(ranges, sigma, k: float):
    cfg = ExistenceConfig(gap_m=0.3, see_through_k=k)
    return beam_evidence(
        np.asarray(ranges, float),
        BEARINGS,
        np.array([10.0]),
        np.array([0.0]),
        np.array([0.15]),
        cfg,
        place_sigma=None if sigma is None else np.array([sigma]),
    )


def test_a_beam_returning_inside_the_k_sigma_region_is_not_see_through():
    """A trunk at 10 m, radius 0.15, gap 0.3: without the tolerance a beam counts as passing
    beyond it past 10.45 m; with sd_range 0.2 and k 2, past 10.85 m, and no beam counts when a
    beam returned within 0.85 m of 10 m."""
    nan = math.nan
    inside = [nan, nan, 10.7, 20.0, nan, nan, nan]  # one reaching beam hit 0.7 m behind
    assert _evidence(inside, None, 0.0).reach.tolist() == [3]
    assert _evidence(inside, None, 0.0).through.tolist() == [3]
    assert _evidence(inside, (0.2, 0.0), 0.0).through.tolist() == [3]  # k 0: no tolerance
    assert _evidence(inside, (0.2, 0.0), 2.0).through.tolist() == [0]
    assert _evidence(inside, (0.1, 0.0), 2.0).through.tolist() == [3]  # edge 10.65: all beyond
    outside = [nan, nan, 10.9, 20.0, nan, nan, nan]
    assert _evidence(outside, (0.2, 0.0), 2.0).through.tolist() == [3]
    ev = _evidence(outside, (0.2, 0.0), 2.0)
    assert ev.reach.tolist() == [3] and ev.occluded.tolist() == [0]


def test_a_return_inside_the_region_at_a_bearing_the_trunk_may_be_at_stops_the_count():
    """The trunk's half-width asin(0.15 / 10) = 0.86 deg reaches the beams at -0.5, 0, 0.5 deg;
    with sd_bearing 0.002 rad and k 2 the region spans 0.86 + 0.23 = 1.09 deg: a return at
    10.1 m on the beam at 1 deg (not reaching) stops the count, on the beam at 1.5 deg it does
    not."""
    nan = math.nan
    side = [nan, nan, nan, nan, nan, 10.1, nan]  # 1 deg
    assert _evidence(side, (0.05, 0.0), 2.0).through.tolist() == [3]
    assert _evidence(side, (0.05, 0.002), 2.0).through.tolist() == [0]
    far_side = [nan, nan, nan, nan, nan, nan, 10.1]  # 1.5 deg
    assert _evidence(far_side, (0.05, 0.002), 2.0).through.tolist() == [3]


def _beams_scan(k: int, ranges) -> Measurements:
    scan = SimpleNamespace(
        ranges_m=np.asarray(ranges, float), angle_min_rad=-3 * STEP, angle_increment_rad=STEP
    )
    return Measurements(k, scan, None, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, np.int64))


@pytest.mark.parametrize("k", [0.0, K95])
def test_a_miss_charges_the_beams_past_the_tentative_only_outside_its_region(k):
    """A kept tentative placed at 10 m, then a scan without its circle whose 3 reaching beams
    return at 10.6 m (the trunk a little farther than placed): without the tolerance they are
    3 see-through beams (r' = r (1 - pd) q^3 / (r (1 - pd) q^3 + 1 - r)); with k 2.448 and the
    tentative's range sd 0.1 m they lie inside its region and the miss costs (1 - pd) only; the
    see-through beams drop it, the miss alone does not."""
    manager, book = _existence_manager(
        "ihgr",
        existence_keep_tentatives=True,
        existence_min_beams=2,
        existence_pd_max=0.6,
        existence_see_through_k=k,
    )
    state = Filter(initial_state(np.zeros(3), np.zeros((3, 3))))
    _existence_scan(manager, book, state, _sighted((10.0, 0.0), 0))
    lid = int(manager.tent.ids[0])
    sd_range = math.sqrt(manager.tent.cov[0][0, 0])
    assert sd_range == pytest.approx(0.1, rel=1e-12)  # R's range sd, the pose exact
    nan = math.nan
    _existence_scan(manager, book, state, _beams_scan(1, [nan, nan, 10.6, 10.6, 10.6, nan, nan]))
    r, pd, q = book.birth, 0.6, book.cfg.see_through_q
    n = 3 if k == 0 else 0
    want = r * (1 - pd) * q**n / (r * (1 - pd) * q**n + 1 - r)
    assert book.r[lid] == pytest.approx(want, rel=1e-12)
    # 3 see-through beams take it below remove_prob: dropped; inside its region: kept
    assert (lid in manager.tent.ids.tolist()) == (k > 0)


def test_the_defaults_are_off_and_the_settings_are_checked():
    policy = SlamConfig().map_policy
    assert policy.existence_fuse_tentatives is False and policy.existence_see_through_k == 0.0
    assert ExistenceConfig().see_through_k == 0.0
    for bad in (-1.0, math.inf, math.nan, True):
        with pytest.raises(SlamError, match="existence_see_through_k"):
            SlamConfig().with_(**{"map_policy.existence_see_through_k": bad})
    for bad in (1, "yes"):
        with pytest.raises(SlamError, match="existence_fuse_tentatives"):
            SlamConfig().with_(**{"map_policy.existence_fuse_tentatives": bad})
    with pytest.raises(ValueError, match="see_through_k"):
        ExistenceConfig(see_through_k=-0.5)
