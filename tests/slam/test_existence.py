"""Landmark existence (`slam.existence`): the probability logic against hand-derived cases."""

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from slam.existence import (
    BeamEvidence,
    ExistenceConfig,
    beam_evidence,
    clutter_density,
    decide,
    detection_probability,
    gaussian_likelihood,
    initial_existence,
    predict_existence,
    update_existence,
)

INC = math.radians(0.5)


def _scan(ranges_by_bearing: dict[int, float], n: int = 361):
    """(ranges (n,), bearings (n,)): beams at -90..90 deg every 0.5 deg, no return but where
    `ranges_by_bearing` {beam offset from the centre beam: range} says."""
    bearings = -math.pi / 2 + INC * np.arange(n)
    ranges = np.full(n, np.nan)
    for k, r in ranges_by_bearing.items():
        ranges[n // 2 + k] = r
    return ranges, bearings


def test_the_beams_that_reach_a_trunk_are_counted_with_occlusion_and_see_through():
    # a trunk of radius 0.1 m at 10 m dead ahead spans asin(0.01) = 0.573 deg either side:
    # the beams at -0.5, 0 and +0.5 deg reach it; one hits something at 5 m (occluded), one
    # the trunk, one returns nothing (passes through)
    ranges, bearings = _scan({-1: 5.0, 0: 9.9, 1: math.nan, 2: 3.0})
    ev = beam_evidence(ranges, bearings, np.array([10.0]), np.array([0.0]), np.array([0.1]),
                       ExistenceConfig())  # fmt: skip
    assert (ev.reach[0], ev.occluded[0], ev.through[0]) == (3, 1, 1)
    # a trunk of radius 0.1 m at 30 m spans 0.19 deg either side: only the centre beam
    ev = beam_evidence(ranges, bearings, np.array([30.0]), np.array([0.0]), np.array([0.1]),
                       ExistenceConfig())  # fmt: skip
    assert ev.reach[0] == 1 and ev.occluded[0] == 1  # 9.9 m < 30 - 0.1 - 0.3


def test_detection_needs_enough_unoccluded_beams_in_view_and_in_range():
    ev = BeamEvidence(np.array([3, 3, 1, 3, 3]), np.array([1, 2, 0, 0, 0]), np.zeros(5, int))
    d = np.array([10.0, 10.0, 30.0, 10.0, 90.0])
    fov = np.array([True, True, True, False, True])
    pd = detection_probability(ev, d, fov, ExistenceConfig(pd_max=0.9, min_beams=2))
    np.testing.assert_array_equal(pd, [0.9, 0.0, 0.0, 0.0, 0.0])


def test_a_miss_is_bayes_rule_with_one_minus_pd_and_see_through_beams():
    cfg = ExistenceConfig(see_through_q=0.1)
    r = update_existence(
        np.array([0.5, 0.5, 0.5]),
        np.array([0.9, 0.9, 0.0]),
        np.zeros(3, bool),
        np.zeros(3),
        np.array([0, 1, 0]),
        kappa=0.2,
        cfg=cfg,
    )
    # 0.5 * 0.1 / (0.05 + 0.5) = 1/11; with one beam through: 0.005 / 0.505 = 1/101;
    # Pd = 0 and nothing through: nothing learnt
    np.testing.assert_allclose(r, [1 / 11, 1 / 101, 0.5], rtol=1e-12)


def test_a_detection_weighs_the_measurement_likelihood_against_the_clutter_density():
    cfg = ExistenceConfig()
    r = update_existence(
        np.array([0.5, 0.2]), np.array([0.9, 0.9]), np.array([True, True]), np.array([2.0, 2.0]),
        np.zeros(2, int), kappa=0.2, cfg=cfg,
    )  # fmt: skip
    # 0.5 * 0.9 * 2 / (0.9 + 0.5 * 0.2) = 0.9; 0.2 * 1.8 / (0.36 + 0.8 * 0.2) = 0.36 / 0.52
    np.testing.assert_allclose(r, [0.9, 0.36 / 0.52], rtol=1e-12)


def test_sequential_misses_multiply_the_odds_by_one_minus_pd_each():
    cfg = ExistenceConfig()
    r = np.array([0.8])
    for _ in range(5):
        r = update_existence(r, np.array([0.6]), np.array([False]), np.zeros(1), np.zeros(1),
                             kappa=0.1, cfg=cfg)  # fmt: skip
    odds = 0.8 / 0.2 * 0.4**5
    assert r[0] == pytest.approx(odds / (1 + odds), rel=1e-12)


def test_clutter_density_spreads_the_false_detections_over_the_measurement_space():
    assert clutter_density(0.5, 80.0, math.pi) == pytest.approx(0.5 / (80.0 * math.pi))
    with pytest.raises(ValueError, match="max_range_m"):
        clutter_density(0.5, 0.0, math.pi)


def test_gaussian_likelihood_is_the_bivariate_normal_density():
    nu = np.array([[0.1, -0.02], [0.0, 0.0]])
    S = np.array([[[0.04, 0.001], [0.001, 0.0009]], [[0.01, 0.0], [0.0, 0.0004]]])
    want = [multivariate_normal(np.zeros(2), S[i]).pdf(nu[i]) for i in range(2)]
    np.testing.assert_allclose(gaussian_likelihood(nu, S), want, rtol=1e-10)


def test_a_new_tentative_starts_at_the_share_of_births_among_births_and_clutter():
    assert initial_existence(1.0, 3.0) == 0.25
    assert initial_existence(0.0, 3.0) == 0.0


def test_decisions_are_the_stated_probability_thresholds():
    cfg = ExistenceConfig(join_prob=0.99, remove_prob=0.01, survival=0.5)
    join, remove = decide(np.array([0.995, 0.99, 0.5, 0.01, 0.005]), cfg)
    np.testing.assert_array_equal(join, [True, True, False, False, False])
    np.testing.assert_array_equal(remove, [False, False, False, False, True])
    np.testing.assert_allclose(predict_existence(np.array([0.8]), cfg), [0.4])


@pytest.mark.parametrize(
    "field,value",
    [("pd_max", 1.5), ("see_through_q", 0.0), ("min_beams", 0), ("remove_prob", 0.995)],
)
def test_bad_settings_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        ExistenceConfig(**{field: value})


def test_persistent_clutter_weighs_a_resighting_against_an_object_seen_again():
    """Against persistent clutter a detection multiplies the odds by Pd g / (repeat g_o), a
    miss where the beams reach by (1 - Pd) q^n / (1 - repeat); where Pd is 0 and no beam passes,
    nothing is learnt (hand-derived from the module doc)."""
    from slam.existence import update_existence_persistent

    cfg = ExistenceConfig(pd_max=0.9, see_through_q=0.1)
    r0 = np.full(4, 0.25)
    pd = np.array([0.9, 0.9, 0.9, 0.0])
    det = np.array([True, False, False, False])
    g, g_o = np.array([40.0, 0, 0, 0]), np.array([10.0, 0, 0, 0])
    through = np.array([0, 0, 2, 0])
    r = update_existence_persistent(r0, pd, det, g, g_o, through, 0.3, cfg)
    odds = r / (1 - r)
    np.testing.assert_allclose(
        odds / (1 / 3), [0.9 * 40 / (0.3 * 10), 0.1 / 0.7, 0.1 * 0.01 / 0.7, 1.0], rtol=1e-12
    )
    # a rigid circle (g_o = g) seen every scan gains only Pd / repeat a scan: far less than
    # against the clutter density, where one sighting is worth Pd g / kappa
    r = update_existence_persistent(r0[:1], pd[:1], det[:1], g[:1], g[:1], through[:1], 0.3, cfg)
    assert r[0] / (1 - r[0]) == pytest.approx((1 / 3) * 3.0, rel=1e-12)
    with pytest.raises(ValueError, match="repeat_prob"):
        update_existence_persistent(r0, pd, det, g, g_o, through, 1.0, cfg)
