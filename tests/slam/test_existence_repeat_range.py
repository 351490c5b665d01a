"""Persistent clutter's repeat rate by range (`map_policy.existence_repeat_prob_by_range`,
`slam.existence`, "Repeat rate by range"): a landmark's bin, a detection weighed against its
bin's rate (not the single rate scaled by Pd's fall-off), the run's map loop wiring it, and
off by default with its checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import SlamConfig
from slam.errors import SlamError
from slam.existence import ExistenceConfig, repeat_rate, update_existence_persistent


def test_a_landmark_takes_its_range_bins_rate_and_the_last_bin_beyond_the_table():
    cfg = ExistenceConfig(repeat_by_range=(0.2, 0.4, 0.7), repeat_bin_m=10.0)
    got = repeat_rate(np.array([0.0, 9.99, 10.0, 25.0, 35.0, 79.0]), cfg)
    assert got.tolist() == [0.2, 0.2, 0.4, 0.7, 0.7, 0.7]
    with pytest.raises(ValueError, match="repeat_by_range is empty"):
        repeat_rate(np.array([5.0]), ExistenceConfig())


def test_a_far_detection_is_weaker_evidence_when_the_far_bin_repeats_more():
    """Two detected landmarks, r 0.5, Pd 0.5, g = g_o = 1: r' = Pd / (Pd + repeat), with the
    near bin's 0.1 (r' 0.833) and the far bin's 0.6 (r' 0.455); the single rate 0.3 scaled by
    f = (1, 0.5) gives both 0.625."""
    cfg = ExistenceConfig(repeat_by_range=(0.1, 0.1, 0.1, 0.6))
    r, pd, det, g = np.full(2, 0.5), np.full(2, 0.5), np.ones(2, bool), np.ones(2)
    rep = repeat_rate(np.array([5.0, 35.0]), cfg)
    got = update_existence_persistent(r, pd, det, g, g, np.zeros(2), rep, cfg)
    assert got.tolist() == pytest.approx([0.5 / 0.6, 0.5 / 1.1], rel=1e-12)
    f = np.array([1.0, 0.5])
    one = update_existence_persistent(r, pd * f, det, g, g, np.zeros(2), 0.3, cfg, falloff=f)
    assert one.tolist() == pytest.approx([0.5 / 0.8, 0.25 / 0.4], rel=1e-12)


def test_a_miss_is_weighed_against_the_bins_rate():
    """Missed, no see-through beam, r 0.5, Pd 0.4: r' = 0.6 / (0.6 + (1 - repeat))."""
    cfg = ExistenceConfig(repeat_by_range=(0.2, 0.5))
    rep = repeat_rate(np.array([5.0, 15.0]), cfg)
    z = np.zeros(2)
    got = update_existence_persistent(np.full(2, 0.5), np.full(2, 0.4), z > 1, z, z, z, rep, cfg)
    assert got.tolist() == pytest.approx([0.6 / 1.4, 0.6 / 1.1], rel=1e-12)


def test_a_bad_rate_among_the_landmarks_is_refused():
    cfg = ExistenceConfig()
    z = np.zeros(2)
    with pytest.raises(ValueError, match="repeat_prob must be in"):
        update_existence_persistent(z + 0.5, z + 0.5, z > 1, z, z, z, np.array([0.2, 1.0]), cfg)


def test_off_by_default_and_checked():
    policy = SlamConfig().map_policy
    assert policy.existence_repeat_prob_by_range == ()
    assert policy.existence_repeat_prob_bin_m == 10.0
    cfg = SlamConfig().with_(**{"map_policy.existence_repeat_prob_by_range": [0.1, 0.5]})
    assert cfg.map_policy.existence_repeat_prob_by_range == (0.1, 0.5)
    for bad in ([0.0], [1.0], [1.5], [math.nan], [True], "0.1", [0.1] * 101):
        with pytest.raises(SlamError, match="existence_repeat_prob_by_range"):
            SlamConfig().with_(**{"map_policy.existence_repeat_prob_by_range": bad})
    for bad in (0.0, -1.0, math.inf, math.nan, True):
        with pytest.raises(SlamError, match="existence_repeat_prob_bin_m"):
            SlamConfig().with_(**{"map_policy.existence_repeat_prob_bin_m": bad})
    for bad in ((0.0,), (1.0,), (True,), "x"):
        with pytest.raises(ValueError, match="repeat_by_range"):
            ExistenceConfig(repeat_by_range=bad)
    with pytest.raises(ValueError, match="repeat_bin_m"):
        ExistenceConfig(repeat_bin_m=0.0)
    assert ExistenceConfig(repeat_by_range=[0.2]).repeat_by_range == (0.2,)  # hashable


class _View:
    fov, max_range = (-1.5, 1.5), 80.0


def test_a_new_tentative_starts_at_its_range_bins_birth():
    """Birth table (0.5, 0.2, 0.05) by 10 m: circles at 5, 15 and 99 m (the last bin beyond),
    and one of unknown range (the single birth 0.3); a window track of 1 sighting starts the
    same, and without a table every range starts at the single birth."""
    from slam.config import MapPolicy
    from slam.existence_map import LandmarkExistence

    pol = MapPolicy(existence_birth_prob=0.3, existence_birth_prob_by_range=(0.5, 0.2, 0.05))
    book = LandmarkExistence(pol, _View(), np.zeros(3))
    for lid, d in ((1, 5.0), (2, 15.0), (3, 99.0), (4, math.nan)):
        book.born(lid, 0.15, d)
    assert book.of([1, 2, 3, 4]).tolist() == [0.5, 0.2, 0.05, 0.3]
    R = np.diag([0.01, 1e-4])
    assert book.track_existence(1, R, 15.0) == pytest.approx(0.2, rel=1e-12)
    plain = LandmarkExistence(MapPolicy(existence_birth_prob=0.3), _View(), np.zeros(3))
    plain.born(1, 0.15, 15.0)
    assert plain.of([1]).tolist() == [0.3]


def test_the_birth_table_is_off_by_default_and_checked():
    policy = SlamConfig().map_policy
    assert policy.existence_birth_prob_by_range == ()
    assert policy.existence_birth_prob_bin_m == 10.0
    for bad in ([0.0], [1.5], [math.nan], [True], "0.1", [0.1] * 101):
        with pytest.raises(SlamError, match="existence_birth_prob_by_range"):
            SlamConfig().with_(**{"map_policy.existence_birth_prob_by_range": bad})
    for bad in ([0.5, 1.0], [1]):  # a birth of 1: no evidence would ever lower it
        with pytest.raises(SlamError, match=r"existence_birth_prob_by_range: .* in \(0, 1\) "):
            SlamConfig().with_(**{"map_policy.existence_birth_prob_by_range": bad})
    for bad in (0.0, -1.0, math.inf, math.nan, True):
        with pytest.raises(SlamError, match="existence_birth_prob_bin_m"):
            SlamConfig().with_(**{"map_policy.existence_birth_prob_bin_m": bad})
    cfg = SlamConfig().with_(**{"map_policy.existence_birth_prob_by_range": [0.999, 0.5]})
    assert cfg.map_policy.existence_birth_prob_by_range == (0.999, 0.5)


def test_a_window_track_is_born_in_its_first_sightings_bin_not_its_latest():
    """Birth table (0.5, 1e-4) by 10 m: a trunk seen at 9.95 m (bin 0), then at 10.05 m (bin
    1) joins with the existence its first circle's birth gives (0.5, as
    `existence_rates.derive_birth_by_range` bins a track), not its latest's (1e-4)."""
    from slam.ekf import Filter, initial_state
    from slam.log import NEW_TENTATIVE
    from slam.sources import Measurements
    from tests.slam.test_map_managers import _existence_manager, _existence_scan

    manager, book = _existence_manager(
        "ihgr-window",
        existence_birth_prob_by_range=(0.5, 1e-4),
        existence_birth_prob_bin_m=10.0,
        existence_join_prob=0.99,
    )
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    R = np.tile(np.diag([1e-2, 1e-4]), (1, 1, 1))
    for k, d in enumerate((9.95, 10.05)):
        z = np.array([[d, 0.1]])
        meas = Measurements(k, None, None, z, R, np.full(1, NEW_TENTATIVE, np.int64))
        _existence_scan(manager, book, state, meas)
    assert manager.first_range.tolist() == [9.95]
    first = book.track_existence(2, R[0], 10.05, 9.95)
    latest = book.track_existence(2, R[0], 10.05)
    assert first > 0.99 > latest  # only the first bin's birth lets it join after 2 sightings
    assert state.landmark_ids.tolist() == [int(state.landmark_ids[0])]
    assert book.of(state.landmark_ids).tolist() == [first]
