"""experiments.eval.pass_drift: the within-pass semivariogram recovers a known Gauss-Markov
offset (s, L) on synthetic passes, and tells a constant offset and white noise apart from it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.pass_drift import Sightings, fit_drift, semivariogram

R_WHITE = (0.03**2, 0.02**2)  # m^2 along, across


def synthetic(rng, s, L: float, n_pass: int = 1500, passes_per_tree: int = 3) -> Sightings:
    """Passes of 8-40 sightings whose view turns 0.2-1.2 rad (one way, uneven steps), each an
    exact Gauss-Markov offset of sd s per axis and correlation length L in the turn (L = inf:
    constant per pass, L = 0: white), plus white noise R_WHITE and the tree's own error."""
    pid, lm, tau, e, r = [], [], [], [], []
    tree_err = 0.02 * rng.standard_normal((n_pass // passes_per_tree + 1, 2))  # cancels in pairs
    for q in range(n_pass):
        n = int(rng.integers(8, 41))
        steps = rng.uniform(0.2, 1.8, n - 1)
        t = np.r_[0.0, np.cumsum(steps / steps.sum() * rng.uniform(0.2, 1.2))]
        b = np.empty((n, 2))
        b[0] = rng.standard_normal(2) * s
        for j in range(1, n):
            phi = math.exp(-(t[j] - t[j - 1]) / L) if L > 0 else 0.0
            b[j] = phi * b[j - 1] + math.sqrt(1 - phi**2) * rng.standard_normal(2) * s
        pid.append(np.full(n, q))
        lm.append(np.full(n, q // passes_per_tree))
        tau.append(t)
        e.append(
            b + tree_err[q // passes_per_tree] + rng.standard_normal((n, 2)) * np.sqrt(R_WHITE)
        )
        r.append(np.tile(R_WHITE, (n, 1)))
    cat = np.concatenate
    return Sightings(cat(pid), cat(lm), cat(tau), cat(e), cat(r))


@pytest.mark.parametrize("L", [0.15, 0.4])
def test_fit_recovers_a_known_gauss_markov_offset(L):
    """s = (0.06, 0.04) m within 10% and L within 30%, r_eff the white variance within 15%, the
    between-pass sill's s within 10% (about 36,000 sightings in 1,500 passes; over seeds 0-5
    the fit gave L 0.136-0.176 for 0.15 and 0.36-0.50 for 0.4, s within 9%, the sill's s
    within 3%); each axis fitted alone, L within 35% (0.32-0.51 for 0.4)."""
    rng = np.random.default_rng(7)
    s = np.array([0.06, 0.04])
    fit = fit_drift(semivariogram(synthetic(rng, s, L)))
    assert fit.corr_rad == pytest.approx(L, rel=0.3)
    np.testing.assert_allclose(fit.sd_m, s, rtol=0.1)
    np.testing.assert_allclose(fit.r_eff_m2, R_WHITE, rtol=0.15)
    np.testing.assert_allclose(fit.sd_between_m, s, rtol=0.1)
    for La in fit.corr_axis_rad:
        assert La == pytest.approx(L, rel=0.35)


def test_a_constant_offset_reads_as_a_long_correlation_and_white_noise_as_none():
    """L = inf (a constant per pass): the within-pass variogram is flat at r, the fit puts no
    drift inside the passes (s^2 (1 - exp(-1.2 / L)) below a tenth of r); the between-pass sill
    still sees s. White noise of the same total variance: flat at r + s^2, the sill equal."""
    rng = np.random.default_rng(3)
    s = np.array([0.06, 0.04])
    fit = fit_drift(semivariogram(synthetic(rng, s, math.inf)))
    for a in (0, 1):
        assert fit.sd_m[a] ** 2 * (1 - math.exp(-1.2 / fit.corr_rad)) < 0.1 * R_WHITE[a]
    np.testing.assert_allclose(fit.sd_between_m, s, rtol=0.15)
    white = fit_drift(semivariogram(synthetic(rng, s, 0.0)))
    total = np.asarray(R_WHITE) + s**2
    np.testing.assert_allclose(np.add(white.r_eff_m2, np.square(white.sd_m)), total, rtol=0.1)
    gamma = semivariogram(synthetic(rng, s, 0.0)).gamma
    np.testing.assert_allclose(gamma[:10], np.tile(total, (10, 1)), rtol=0.1)


def test_the_variogram_counts_each_pair_of_a_pass_once_and_splits_the_between_pairs():
    """Two passes of one tree (3 and 2 sightings): 3 + 1 within pairs at their turns, 6
    between pairs, and the sums by hand."""
    e = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 1.0], [0.0, 2.0], [2.0, 2.0]])
    s = Sightings(
        pass_id=np.array([0, 0, 0, 1, 1]),
        landmark=np.zeros(5, np.int64),
        tau_rad=np.array([0.0, 0.1, 0.3, 0.0, 0.25]),
        e=e,
        r=np.ones((5, 2)),
    )
    v = semivariogram(s, edges_rad=[0.0, 0.15, 0.28, 0.5])
    np.testing.assert_array_equal(v.pairs, [1, 2, 1])
    np.testing.assert_allclose(v.gamma[0], [0.5, 0.0])  # (0,1)
    np.testing.assert_allclose(v.gamma[1], 0.25 * np.array([4.0 + 4.0, 1.0 + 0.0]))  # (1,2),(3,4)
    np.testing.assert_allclose(v.gamma[2], [4.5, 0.5])  # (0,2)
    between = [(0, 3), (0, 4), (1, 3), (1, 4), (2, 3), (2, 4)]
    want = 0.5 * np.mean([(e[j] - e[k]) ** 2 for j, k in between], axis=0)
    np.testing.assert_allclose(v.between, want)
    assert v.between_pairs == 6


def test_too_few_pairs_is_refused_naming_the_reason():
    s = Sightings(np.zeros(3, np.int64), np.zeros(3, np.int64), np.array([0.0, 0.1, 0.2]),
                  np.zeros((3, 2)) + 0.01, np.ones((3, 2)))  # fmt: skip
    with pytest.raises(DataError, match="bins with at least 30 pairs"):
        fit_drift(semivariogram(s))
    with pytest.raises(DataError, match="Sightings.e: expected shape"):
        Sightings(np.zeros(3, np.int64), np.zeros(3, np.int64), np.zeros(3), np.zeros((2, 2)),
                  np.ones((3, 2)))  # fmt: skip


def test_an_axis_without_drift_gets_none():
    """Drift along only (s = (0.06, 0)): the fit puts under 1 cm of drift across (seeds 11-13:
    0-2.3 mm; that axis's own L is then arbitrary, inf when its s is exactly 0), s along within
    10%, and the shared L is the along axis's (within 30%)."""
    rng = np.random.default_rng(11)
    fit = fit_drift(semivariogram(synthetic(rng, np.array([0.06, 0.0]), 0.15, n_pass=800)))
    assert fit.sd_m[1] < 0.01
    assert fit.sd_m[0] == pytest.approx(0.06, rel=0.1)
    assert fit.corr_rad == pytest.approx(0.15, rel=0.3)
