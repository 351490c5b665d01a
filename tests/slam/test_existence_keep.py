"""Tentatives kept through their misses (`map_policy.existence_keep_tentatives`, `slam.existence`,
"Intermittent detection"): a trunk the extractor reports in 60% of the scans that reach it
joins the map after the scans its probabilities say; a one-off false circle leaves after the
misses they say; off (the default), a tentative is dropped at its first miss as before."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from tests.slam.test_map_managers import _existence_manager, _existence_scan, _trunk_scan

REPEAT = 0.3  # persistent clutter's repeat_prob: a sighting multiplies the odds by pd / 0.3
PATTERN = (True, True, False, True, False)  # seen in 3 of every 5 scans that reach it: 60%


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def _scans_to_join(book, pattern, max_scans: int) -> int:
    """The scans (birth included) until the log-odds of a trunk seen as `pattern` (repeated)
    first reach join_prob, from the model's probabilities alone: birth, then + log(pd / repeat)
    a sighting and + log((1 - pd) / (1 - repeat)) a miss (no beams: no see-through factor)."""
    pd = book.cfg.pd_max
    lo = _logit(book.birth)
    for k in range(1, max_scans):
        seen = pattern[k % len(pattern)]
        lo += math.log(pd / REPEAT) if seen else math.log((1.0 - pd) / (1.0 - REPEAT))
        if seen and lo >= _logit(book.cfg.join_prob):  # joins in a scan it was seen in
            return k + 1
    raise AssertionError("the probabilities never reach join_prob")


def _run(manager, book, pattern, n: int) -> list:
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    joined = []
    for k in range(n):
        d = _existence_scan(manager, book, state, _trunk_scan(k, seen=pattern[k % len(pattern)]))
        joined += [k + 1] * len(d.joined)
    return joined


def _policy(keep: bool) -> dict:
    return {
        "existence_clutter": "persistent",
        "existence_repeat_prob": REPEAT,
        "existence_pd_max": 0.6,
        "existence_keep_tentatives": keep,
    }


def test_a_trunk_seen_in_60_percent_of_scans_joins_when_its_evidence_says_so():
    """Kept through its misses, the trunk joins the map once, in the scan the model's
    probabilities give (birth, then log(pd / repeat) a sighting and log((1 - pd) / (1 -
    repeat)) a miss); dropped at each miss (the default), it never strings together the
    sightings it needs and never joins."""
    manager, book = _existence_manager("ihgr", **_policy(keep=True))
    want = _scans_to_join(book, PATTERN, 200)
    assert want > len(PATTERN)  # more than one unbroken run of sightings
    assert _run(manager, book, PATTERN, want + 20) == [want]
    manager, book = _existence_manager("ihgr", **_policy(keep=False))
    assert _run(manager, book, PATTERN, 200) == []
    assert len(book.r) > 1  # each run of sightings a new tentative


def test_a_one_off_circle_kept_leaves_after_the_misses_its_probabilities_give():
    """A circle seen once and never again, in view: its existence falls by (1 - pd) / (1 -
    repeat) a scan and it is dropped in the first scan it is below remove_prob, never joined;
    behind the laser (Pd 0) it keeps its existence and stays a tentative."""
    manager, book = _existence_manager("ihgr", **_policy(keep=True))
    lo = _logit(book.birth)
    misses = 0
    while lo >= _logit(book.cfg.remove_prob):
        lo += math.log((1 - book.cfg.pd_max) / (1 - REPEAT))
        misses += 1
    assert misses > 1
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    lid = int(manager.tent.ids[0])
    for k in range(1, misses + 3):
        d = _existence_scan(manager, book, state, _trunk_scan(k, seen=False))
        assert not d.joined
        assert (lid in manager.tent.ids.tolist()) == (k < misses)
    assert book.r[lid] < book.cfg.remove_prob and state.n_landmarks == 0

    manager, book = _existence_manager("ihgr", **_policy(keep=True))
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    state.x[2] = math.pi  # turned round: the tentative is behind the laser
    for k in range(1, 20):
        _existence_scan(manager, book, state, _trunk_scan(k, seen=False))
    assert manager.tent.ids.tolist() == [lid] and book.r[lid] == book.birth


def test_the_default_drops_a_tentative_at_its_first_miss_as_before():
    cfg = SlamConfig()
    assert cfg.map_policy.existence_keep_tentatives is False
    manager, book = _existence_manager("ihgr", existence_pd_max=0.6)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    assert len(manager.tent) == 1
    _existence_scan(manager, book, state, _trunk_scan(1, seen=False))
    assert len(manager.tent) == 0 and book.r[0] > book.cfg.remove_prob


@pytest.mark.parametrize("value", [1, "yes", None])
def test_keep_tentatives_must_be_a_boolean(value):
    with pytest.raises(SlamError, match="existence_keep_tentatives"):
        SlamConfig().with_(**{"map_policy.existence_keep_tentatives": value})


UNREACHED = 5  # existence_unreached_scans of the tests below


def _behind(manager, book, state, scans: range) -> list[bool]:
    """Scans with the car turned away from the tentative (no beam reaches it, Pd 0): whether
    the first tentative is still kept after each."""
    state.x[2] = math.pi
    lid = min(book.r)
    kept = []
    for k in scans:
        _existence_scan(manager, book, state, _trunk_scan(k, seen=False))
        kept.append(lid in manager.tent.ids.tolist())
    return kept


def test_a_kept_tentative_out_of_reach_is_dropped_after_unreached_scans():
    """Seen once, then behind the laser: its existence cannot change, and it is dropped in
    exactly the existence_unreached_scans-th scan out of reach; a scan in reach (a miss in
    view) restarts the count; 0 (the default) keeps it to the end, as before."""
    policy = _policy(keep=True) | {"existence_unreached_scans": UNREACHED}
    manager, book = _existence_manager("ihgr", **policy)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    kept = _behind(manager, book, state, range(1, 2 * UNREACHED))
    assert kept == [k < UNREACHED for k in range(1, 2 * UNREACHED)]
    assert book.r[0] == book.birth  # dropped out of reach, not by its existence

    manager, book = _existence_manager("ihgr", **policy)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    assert all(_behind(manager, book, state, range(1, UNREACHED)))
    state.x[2] = 0.0  # facing it again: missed in view, its existence falls
    _existence_scan(manager, book, state, _trunk_scan(UNREACHED, seen=False))
    assert book.r[0] < book.birth
    kept = _behind(manager, book, state, range(UNREACHED + 1, 3 * UNREACHED))
    assert kept == [k < 2 * UNREACHED for k in range(UNREACHED + 1, 3 * UNREACHED)]

    manager, book = _existence_manager("ihgr", **_policy(keep=True))
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    assert all(_behind(manager, book, state, range(1, 4 * UNREACHED)))


def test_unreached_scans_needs_kept_tentatives():
    """Tentatives dropped at their first miss (the default) are never counted out of reach."""
    manager, book = _existence_manager(
        "ihgr", existence_pd_max=0.6, existence_unreached_scans=UNREACHED
    )
    assert book.unreached_limit == 0
    assert not book.unreached(np.array([0, 1])).any()


@pytest.mark.parametrize("value", [-1, 2.5, True, "5"])
def test_unreached_scans_must_be_a_whole_number_at_least_0(value):
    with pytest.raises(SlamError, match="existence_unreached_scans"):
        SlamConfig().with_(**{"map_policy.existence_unreached_scans": value})
