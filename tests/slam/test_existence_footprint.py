"""The beam footprint of the see-through count (`map_policy.existence_see_through_footprint`,
`slam.existence`, "Beam footprint"): a beam counts as passing beyond a trunk only when its
footprint, f beam steps either side of its ray (+ k sd_bearing with the tolerance), lies
inside the trunk's angular half-width asin(radius / range). Exact counts for a grazing beam at
35 m, a tentative's miss charged or not, and the setting off by default."""

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
from tests.slam.test_map_managers import _existence_manager, _existence_scan

STEP = math.radians(0.5)  # Victoria Park's beam spacing
# 7 beams 0.5 deg apart, offset 0.2 deg: at -1.3, -0.8, -0.3, 0.2, 0.7, 1.2, 1.7 deg
OFFSET_BEARINGS = math.radians(0.2) + STEP * np.arange(-3, 4)
NAN = math.nan


def _through(radius: float, f: float, sigma=None, k: float = 0.0, bearings=OFFSET_BEARINGS):
    cfg = ExistenceConfig(gap_m=0.3, footprint_steps=f, see_through_k=k)
    ev = beam_evidence(
        np.full(bearings.size, NAN),  # no return: every reaching beam passed beyond
        bearings,
        np.array([35.0]),
        np.array([0.0]),
        np.array([radius]),
        cfg,
        place_sigma=None if sigma is None else np.array([sigma]),
    )
    return int(ev.reach[0]), int(ev.through[0])


def test_a_beam_grazing_a_trunk_at_35_m_is_not_see_through_with_the_footprint():
    """A trunk of radius 0.15 m at 35 m spans asin(0.15 / 35) = 0.2456 deg either side: the
    beam at 0.2 deg reaches it and, with no return, counts as passing beyond it; with half a
    0.5 deg step as its footprint (0.2 + 0.25 = 0.45 > 0.2456) it does not, and neither does
    a beam dead centre (0 + 0.25 > 0.2456): at that range the grid cannot say a beam passed."""
    assert math.degrees(math.asin(0.15 / 35.0)) == pytest.approx(0.2456, abs=1e-4)
    assert _through(0.15, 0.0) == (1, 1)
    assert _through(0.15, 0.5) == (1, 0)
    centred = STEP * np.arange(-3, 4)
    assert _through(0.15, 0.0, bearings=centred) == (1, 1)
    assert _through(0.15, 0.5, bearings=centred) == (1, 0)


def test_a_wide_trunk_keeps_the_beam_whose_footprint_lies_inside_it():
    """Radius 0.3 m at 35 m: half-width 0.4911 deg, reached by the beams at -0.3 and 0.2 deg;
    with the footprint only the one at 0.2 deg counts (0.45 <= 0.4911; 0.55 > 0.4911); with the
    tolerance's k 2.448 and sd_bearing 0.0005 rad (0.070 deg) neither does (0.52 > 0.4911)."""
    assert _through(0.3, 0.0) == (2, 2)
    assert _through(0.3, 0.5) == (2, 1)
    assert _through(0.3, 0.5, sigma=(0.01, 0.0), k=2.448) == (2, 1)
    assert _through(0.3, 0.5, sigma=(0.01, 0.0005), k=2.448) == (2, 0)
    assert _through(0.3, 0.0, sigma=(0.01, 0.0005), k=2.448) == (2, 2)  # tolerance alone


def _scan(k: int, ranges, z=None) -> Measurements:
    scan = SimpleNamespace(
        ranges_m=np.asarray(ranges, float), angle_min_rad=-3 * STEP, angle_increment_rad=STEP
    )
    if z is None:
        return Measurements(k, scan, None, np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, int))
    R = np.diag([1e-2, 1e-4])[None]
    return Measurements(k, scan, None, np.array([z]), R, np.full(1, NEW_TENTATIVE, np.int64))


@pytest.mark.parametrize("f", [0.0, 0.5])
def test_a_miss_at_35_m_charges_the_centre_beam_only_without_the_footprint(f):
    """A kept tentative at 35 m, bearing 0 (radius 0.15 m, the default), then a scan without
    its circle whose one reaching beam (dead centre) has no return: Pd is 0 (fewer than
    min_beams 2 reach it); without the footprint that beam is see-through and r' = r q / (r q +
    1 - r); with half a step it is not and nothing is learnt (r' = r)."""
    manager, book = _existence_manager(
        "ihgr",
        existence_keep_tentatives=True,
        existence_min_beams=2,
        existence_see_through_footprint=f,
    )
    state = Filter(initial_state(np.zeros(3), np.zeros((3, 3))))
    _existence_scan(manager, book, state, _scan(0, [NAN] * 7, z=(35.0, 0.0)))
    lid = int(manager.tent.ids[0])
    r0, q = book.r[lid], book.cfg.see_through_q
    _existence_scan(manager, book, state, _scan(1, [NAN] * 7))
    want = r0 * q / (r0 * q + 1 - r0) if f == 0 else r0
    assert book.r[lid] == pytest.approx(want, rel=1e-12)
    assert book.r[lid] < r0 if f == 0 else book.r[lid] == r0


def test_the_footprint_is_off_by_default_and_checked():
    assert SlamConfig().map_policy.existence_see_through_footprint == 0.0
    assert ExistenceConfig().footprint_steps == 0.0
    for bad in (-0.5, math.inf, math.nan, True, "half"):
        with pytest.raises(SlamError, match="existence_see_through_footprint"):
            SlamConfig().with_(**{"map_policy.existence_see_through_footprint": bad})
    with pytest.raises(ValueError, match="footprint_steps"):
        ExistenceConfig(footprint_steps=-1.0)
