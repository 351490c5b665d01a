"""The see-through rate by range (`map_policy.existence_see_through_q_by_range`,
`slam.existence`, "See-through rate by range") and its derivation per range bin
(`experiments.eval.existence_rates.see_through_rates`): exact q per bin from given counts, a
landmark's miss charged with its bin's q, and off by default."""

from __future__ import annotations

import math

import numpy as np
import pytest

from experiments.eval.existence_rates import see_through_rates
from slam import SlamConfig
from slam.errors import SlamError
from slam.existence import ExistenceConfig, see_through_q, update_existence


def test_the_rate_per_bin_is_through_over_free_beams_and_the_pooled_where_none():
    """Bins 0-10, 10-20, 20-30, 30-40 m: 2 of 40 free beams passed, 0 of 25 (half a beam over
    25), 9 of 12, and no free beam (the pooled 0.3)."""
    q = see_through_rates(np.array([2, 0, 9, 0]), np.array([40, 25, 12, 0]), pooled=0.3)
    assert q.tolist() == [2 / 40, 0.5 / 25, 9 / 12, 0.3]
    assert see_through_rates(np.array([5]), np.array([4]), pooled=0.3).tolist() == [1.0]


def test_a_landmark_takes_its_range_bin_q_and_the_last_bin_beyond_the_table():
    cfg = ExistenceConfig(see_through_q=0.4, q_by_range=(0.05, 0.2, 0.6), q_bin_m=10.0)
    q = see_through_q(np.array([0.0, 9.99, 10.0, 25.0, 35.0, 79.0]), cfg)
    assert q.tolist() == [0.05, 0.05, 0.2, 0.6, 0.6, 0.6]
    assert see_through_q(np.array([5.0, 35.0]), ExistenceConfig(see_through_q=0.4)).tolist() == [
        0.4,
        0.4,
    ]


def test_a_miss_is_charged_with_the_bins_q():
    """Two missed landmarks with 2 see-through beams each, at 5 m and 35 m, r 0.5, Pd 0.6:
    r' = r (1 - pd) q^2 / (r (1 - pd) q^2 + 1 - r), q 0.05 near and 0.6 far."""
    cfg = ExistenceConfig(see_through_q=0.4, q_by_range=(0.05, 0.2, 0.6, 0.6))
    r, pd = np.full(2, 0.5), np.full(2, 0.6)
    q = see_through_q(np.array([5.0, 35.0]), cfg)
    got = update_existence(r, pd, np.zeros(2, bool), np.zeros(2), np.full(2, 2), 1.0, cfg, q=q)
    want = [0.5 * 0.4 * x**2 / (0.5 * 0.4 * x**2 + 0.5) for x in (0.05, 0.6)]
    assert got.tolist() == pytest.approx(want, rel=1e-12)
    with pytest.raises(ValueError, match="q_by_range is set"):  # no silent single q
        update_existence(r, pd, np.zeros(2, bool), np.zeros(2), np.full(2, 2), 1.0, cfg)


def test_off_by_default_and_checked():
    policy = SlamConfig().map_policy
    assert policy.existence_see_through_q_by_range == ()
    assert policy.existence_see_through_q_bin_m == 10.0
    cfg = SlamConfig().with_(**{"map_policy.existence_see_through_q_by_range": [0.1, 0.5]})
    assert cfg.map_policy.existence_see_through_q_by_range == (0.1, 0.5)
    for bad in ([0.0], [1.5], [math.nan], [True], "0.1", [0.1] * 101):
        with pytest.raises(SlamError, match="existence_see_through_q_by_range"):
            SlamConfig().with_(**{"map_policy.existence_see_through_q_by_range": bad})
    for bad in (0.0, -1.0, math.inf, True):
        with pytest.raises(SlamError, match="existence_see_through_q_bin_m"):
            SlamConfig().with_(**{"map_policy.existence_see_through_q_bin_m": bad})
    with pytest.raises(ValueError, match="q_by_range"):
        ExistenceConfig(q_by_range=(0.0,))
