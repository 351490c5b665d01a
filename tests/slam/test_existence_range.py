"""Pd's range fall-off (`slam.existence`, "Range fall-off"; `map_policy.existence_pd_range_m`):
Pd = pd_max / (1 + exp((d - pd_range_m) / scale)), persistent clutter's repeat_prob scaled
alike; inf (the default) leaves every figure as before. `derive_pd_range` recovers the
fall-off from detection counts."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from experiments.eval import existence_rates
from slam import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.existence import (
    BeamEvidence,
    ExistenceConfig,
    detection_probability,
    update_existence_persistent,
)
from tests.slam.test_map_managers import _existence_manager, _existence_scan, _trunk_scan

REPEAT = 0.3


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def test_pd_falls_with_range_as_the_logistic_says_and_inf_is_the_constant():
    d = np.array([5.0, 30.0, 35.0, 50.0])
    ev = BeamEvidence(np.full(4, 3), np.zeros(4, np.int64), np.zeros(4, np.int64))
    fov = np.ones(4, bool)
    flat = detection_probability(ev, d, fov, ExistenceConfig(pd_max=0.8, min_beams=2))
    assert flat.tolist() == [0.8] * 4
    cfg = ExistenceConfig(pd_max=0.8, min_beams=2, pd_range_m=35.0, pd_range_scale_m=4.0)
    pd = detection_probability(ev, d, fov, cfg)
    assert pd == pytest.approx(0.8 / (1.0 + np.exp((d - 35.0) / 4.0)), rel=1e-15)
    assert pd[2] == pytest.approx(0.4) and pd[0] > 0.79 and pd[3] < 0.02


def test_persistent_repeat_prob_falls_alike_so_a_far_miss_weighs_little():
    """r' = r (1 - pd f) / (r (1 - pd f) + (1 - r) (1 - repeat f)) at a miss, r (pd f) g /
    (r pd f g + (1 - r) repeat f g_o) at a sighting (the same odds ratio pd / repeat at any
    range)."""
    cfg = ExistenceConfig(pd_max=0.8, min_beams=2)
    r, f = np.array([0.4, 0.4]), np.array([1.0, 0.05])
    pd = 0.8 * f
    miss = update_existence_persistent(
        r, pd, np.zeros(2, bool), np.zeros(2), np.zeros(2), np.zeros(2), REPEAT, cfg, falloff=f
    )
    want = 0.4 * (1 - pd) / (0.4 * (1 - pd) + 0.6 * (1 - REPEAT * f))
    assert miss == pytest.approx(want, rel=1e-14)
    assert miss[1] - 0.4 > -0.01 > miss[0] - 0.4  # the far miss costs little
    seen = update_existence_persistent(
        r, pd, np.ones(2, bool), np.ones(2), np.ones(2), np.zeros(2), REPEAT, cfg, falloff=f
    )
    assert seen[0] == pytest.approx(seen[1], rel=1e-14)
    assert seen[0] == pytest.approx(0.4 * 0.8 / (0.4 * 0.8 + 0.6 * REPEAT), rel=1e-14)


def test_a_one_off_circle_at_the_half_range_leaves_after_the_misses_its_halved_pd_gives():
    """The test trunk is at 10 m: with pd_range_m 10 its Pd and repeat_prob are halved, and a
    circle seen once leaves after exactly the misses log((1 - pd / 2) / (1 - repeat / 2))
    give, more than without the fall-off."""
    policy = {
        "existence_clutter": "persistent",
        "existence_repeat_prob": REPEAT,
        "existence_pd_max": 0.6,
        "existence_keep_tentatives": True,
        "existence_pd_range_m": 10.0,
        "existence_pd_range_scale_m": 2.0,
    }
    manager, book = _existence_manager("ihgr", **policy)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _existence_scan(manager, book, state, _trunk_scan(0))
    lid = int(manager.tent.ids[0])
    f = 0.5  # the trunk's range (10 m, `_trunk_scan`) is pd_range_m
    lo, misses = _logit(book.birth), 0
    while lo >= _logit(book.cfg.remove_prob):
        lo += math.log((1 - 0.6 * f) / (1 - REPEAT * f))
        misses += 1
    flat = math.ceil((_logit(book.birth) - _logit(0.01)) / -math.log(0.4 / 0.7))
    assert misses > flat
    for k in range(1, misses + 2):
        _existence_scan(manager, book, state, _trunk_scan(k, seen=False))
        assert (lid in manager.tent.ids.tolist()) == (k < misses)


def test_derive_pd_range_recovers_the_fall_off_from_counts(monkeypatch):
    """Counts drawn to the expectation of pd_max 0.75, pd_range_m 36, scale 4 (10^6 views a
    metre, 2 free beams) give back those values to the grid's step; too few beams: no
    views, a DataError naming the cause."""
    mid = np.arange(80) + 0.5
    p = 0.75 / (1.0 + np.exp((mid - 36.0) / 4.0))

    def rates(lg, seq, scans, edges, established):
        e = np.zeros((edges.size - 1, existence_rates.MAX_BEAMS + 1), np.int64)
        d = np.zeros_like(e)
        e[:80, 2], d[:80, 2] = 1_000_000, np.round(1_000_000 * p).astype(np.int64)
        return e, d

    monkeypatch.setattr(existence_rates, "range_detection_rates", rates)
    seq = SimpleNamespace(scan_max_range=80.0)
    lg = SimpleNamespace(config={"measurement": {"max_range_m": 80.0}})
    out = existence_rates.derive_pd_range(lg, seq, (0, 1), min_beams=2)["settings"]
    assert out["map_policy.existence_pd_max"] == pytest.approx(0.75, abs=0.005)
    assert out["map_policy.existence_pd_range_m"] == pytest.approx(36.0, abs=0.25)
    assert out["map_policy.existence_pd_range_scale_m"] == pytest.approx(4.0, abs=0.125)
    with pytest.raises(existence_rates.DataError, match="no established landmark"):
        existence_rates.derive_pd_range(lg, seq, (0, 1), min_beams=3)


def test_derive_pd_range_names_a_bad_beam_count_or_an_unbounded_range(monkeypatch):
    """min_beams beyond the beams counted apart, or no finite range to bin by (a scan's max
    range and measurement.max_range_m both inf): a DataError naming it, never numpy's
    allocation error."""
    monkeypatch.setattr(existence_rates, "range_detection_rates", None)  # never reached
    seq = SimpleNamespace(scan_max_range=math.inf)
    lg = SimpleNamespace(config={"measurement": {"max_range_m": math.inf}})
    with pytest.raises(existence_rates.DataError, match="finite range limit"):
        existence_rates.derive_pd_range(lg, seq, (0, 1), min_beams=2)
    too_many = existence_rates.MAX_BEAMS + 1
    with pytest.raises(existence_rates.DataError, match="min_beams must be"):
        existence_rates.derive_pd_range(lg, seq, (0, 1), min_beams=too_many)


def test_a_detection_at_the_half_range_has_half_pd_max(monkeypatch):
    """The trace of a tentative seen at 10 m with pd_range_m 10: its Pd in the scans it is
    detected is pd_max / 2 (a detection's Pd is pd_max f(d), `LandmarkExistence.update`), and
    pd_max without the fall-off."""
    pds = []
    for pd_range in (10.0, math.inf):
        manager, book = _existence_manager(
            "ihgr",
            existence_pd_max=0.6,
            existence_pd_range_m=pd_range,
            existence_pd_range_scale_m=2.0,
            existence_keep_tentatives=True,
        )
        book.trace = []
        state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
        for k in range(2):
            _existence_scan(manager, book, state, _trunk_scan(k))
        seen = [row for row in book.trace if row["detected"].any()]
        assert [row["scan"] for row in seen] == [1]  # the birth scan has nothing to update
        pds.append(float(seen[0]["pd"][seen[0]["detected"]][0]))
    assert pds == [pytest.approx(0.3, rel=1e-12), pytest.approx(0.6, rel=1e-12)]


def test_a_window_track_gains_pd_max_f_a_sighting_against_uniform_clutter():
    """track_existence at the half range: each sighting after the first adds log(1/2) to the
    log-odds it has without the fall-off (pd_max f g / kappa a sighting)."""
    R = np.diag([1e-2, 1e-4])
    lo = []
    for pd_range in (10.0, math.inf):
        _, book = _existence_manager(
            "ihgr-window", existence_pd_range_m=pd_range, existence_pd_range_scale_m=2.0
        )
        lo.append([_logit(book.track_existence(n, R, 10.0)) for n in (1, 2, 3)])
    assert lo[0][0] == pytest.approx(lo[1][0], rel=1e-12)  # the birth: no sighting yet
    for n in (1, 2):
        assert lo[0][n] - lo[1][n] == pytest.approx(n * math.log(0.5), rel=1e-9)


def test_the_default_is_no_fall_off():
    policy = SlamConfig().map_policy
    assert math.isinf(policy.existence_pd_range_m)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("existence_pd_range_m", 0.0),
        ("existence_pd_range_m", -3.0),
        ("existence_pd_range_m", math.nan),
        ("existence_pd_range_scale_m", 0.0),
        ("existence_pd_range_scale_m", math.inf),
        ("existence_pd_range_scale_m", True),
    ],
)
def test_fall_off_settings_are_checked(name, value):
    with pytest.raises(SlamError, match=name):
        SlamConfig().with_(**{f"map_policy.{name}": value})
