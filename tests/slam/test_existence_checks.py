"""Review mends of the see-through footprint and q by range (`slam.existence`): the footprint
checked against the trunk's own half-width, one range-bin rule, and the config's checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam.existence import (
    ExistenceConfig,
    beam_evidence,
    range_bin,
    see_through_q,
    update_existence,
    update_existence_persistent,
)

STEP = math.radians(0.5)
# beams at -0.3 and 0.2 deg (and farther): a trunk of radius 0.3 m at 35 m spans 0.491 deg
BEARINGS = math.radians(0.2) + STEP * np.arange(-3, 4)


def _through(sigma_b: float, f: float = 0.5, bearings=BEARINGS) -> tuple[int, int]:
    cfg = ExistenceConfig(footprint_steps=f)
    ev = beam_evidence(
        np.full(bearings.size, math.nan),
        bearings,
        np.array([35.0]),
        np.array([0.0]),
        np.array([0.3]),
        cfg,
        bearing_sigma_rad=sigma_b,
    )
    return int(ev.reach[0]), int(ev.through[0])


def test_the_footprint_lies_inside_the_trunks_own_half_width_not_the_widened_one():
    """asin(0.3 / 35) = 0.491 deg; half a step 0.25 deg: the beam at 0.2 deg fits (0.45), the
    one at -0.3 deg does not (0.55), also when a 0.1 deg bearing sd widens the reach to
    0.591 deg (both beams reach)."""
    assert _through(0.0) == (2, 1)
    assert _through(math.radians(0.1)) == (2, 1)


def test_the_footprint_with_fewer_than_two_bearings_is_an_error():
    with pytest.raises(ValueError, match="at least 2 bearings; got 1"):
        _through(0.0, bearings=np.array([0.0]))
    assert _through(0.0, f=0.0, bearings=np.array([0.0])) == (1, 1)  # no footprint: no step


def test_the_range_bin_is_floor_division_at_an_edge():
    """0.5 / 0.1 is 5.0 in floating point but 0.5 // 0.1 is 4.0 (0.1 is a little above a
    tenth): both the filter and the derivation take the // rule."""
    assert math.floor(0.5 / 0.1) == 5 and 0.5 // 0.1 == 4.0  # the edge where the rules part
    assert range_bin(np.array([0.5]), 0.1, 1000).tolist() == [4]
    assert range_bin(np.array([9.99, 10.0, 95.0, math.nan]), 10.0, 4).tolist() == [0, 1, 3, 0]
    cfg = ExistenceConfig(q_by_range=tuple([0.1] * 5 + [0.9] * 5), q_bin_m=0.1)
    assert see_through_q(np.array([0.5]), cfg).tolist() == [0.1]  # bin 4, not 5


def test_q_by_range_is_a_tuple_and_bools_are_rejected():
    cfg = ExistenceConfig(q_by_range=[0.1, 0.2])
    assert cfg.q_by_range == (0.1, 0.2)
    assert hash(cfg) == hash(ExistenceConfig(q_by_range=(0.1, 0.2)))
    for bad in ([True], [0.1, False]):
        with pytest.raises(ValueError, match="q_by_range"):
            ExistenceConfig(q_by_range=bad)
    with pytest.raises(ValueError, match="footprint_steps"):
        ExistenceConfig(footprint_steps=True)
    with pytest.raises(ValueError, match="q_by_range") as err:
        ExistenceConfig(q_by_range=[0.5] * 5000 + [2.0])
    assert len(str(err.value)) < 200


def test_a_table_without_q_given_is_an_error_not_the_single_q():
    cfg = ExistenceConfig(q_by_range=(0.05, 0.6))
    args = (np.full(1, 0.5), np.full(1, 0.6), np.zeros(1, bool), np.zeros(1), np.full(1, 2))
    with pytest.raises(ValueError, match="update_existence: cfg.q_by_range is set"):
        update_existence(*args, 1.0, cfg)
    with pytest.raises(ValueError, match="update_existence_persistent: cfg.q_by_range is set"):
        update_existence_persistent(*args[:4], np.zeros(1), args[4], 0.3, cfg)
    got = update_existence(*args, 1.0, cfg, q=np.array([0.6]))
    assert got[0] == pytest.approx(0.5 * 0.4 * 0.36 / (0.5 * 0.4 * 0.36 + 0.5), rel=1e-12)


def test_a_long_bad_q_table_in_the_config_gives_a_short_error():
    from slam import SlamConfig
    from slam.errors import SlamError

    with pytest.raises(SlamError, match="existence_see_through_q_by_range") as err:
        SlamConfig().with_(**{"map_policy.existence_see_through_q_by_range": [0.5] * 5000 + [2]})
    assert len(str(err.value)) < 300
