"""Experiment 1: CE/RE formulas, the Cramer-Rao bound against Monte Carlo, golden quick numbers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from regenerate_golden import FILES
from scipy.optimize import least_squares

from experiments.eval.circles import beam_range_jacobian, center_error, circle_crlb, radius_error
from experiments.paper.circles import (
    METHODS,
    TABLE_PILLARS,
    efficiency,
    pillar_monte_carlo,
    summarise,
)
from experiments.paper.runner import RunContext


def test_ce_re_on_hand_made_numbers():
    # true centre (3, 4): distance 5; estimate off by (0.3, -0.4): error 0.5 -> CE 0.1
    assert center_error([3.0, 4.0], [3.3, 3.6]) == pytest.approx(0.1, abs=1e-12)
    assert radius_error(0.25, 0.2) == pytest.approx(0.2, abs=1e-12)
    assert radius_error(0.25, 0.3) == pytest.approx(0.2, abs=1e-12)
    np.testing.assert_allclose(center_error([[3, 4], [0, 2]], [[3, 4], [0, 1]]), [0.0, 0.5])
    with pytest.raises(ValueError, match="radius"):
        radius_error(0.0, 1.0)
    with pytest.raises(ValueError, match="sensor"):
        center_error([0.0, 0.0], [1.0, 1.0])


def test_range_jacobian_matches_numerical_derivative():
    c, r = np.array([6.0, 1.5]), 0.4
    ang = math.atan2(1.5, 6.0) + np.radians([-3.0, -1.5, 0.0, 1.0, 2.5])

    def ranges(p):
        u = np.stack([np.cos(ang), np.sin(ang)], 1)
        t = u[:, 0] * p[1] - u[:, 1] * p[0]
        return u @ p[:2] - np.sqrt(p[2] ** 2 - t * t)

    p0 = np.array([*c, r])
    h = 1e-7
    num = np.column_stack([(ranges(p0 + h * e) - ranges(p0 - h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(beam_range_jacobian(c, r, ang), num, rtol=1e-6, atol=1e-8)


@pytest.mark.slow
def test_crlb_against_monte_carlo_of_an_efficient_estimator():
    """A simple geometry (no grazing beams, small noise): maximum likelihood in range space is
    efficient, so its covariance over many draws matches the bound."""
    rng = np.random.default_rng(11)
    c, r, sigma = np.array([5.0, 0.0]), 0.5, 0.005
    ang = np.radians(np.arange(-4.0, 4.01, 0.5))  # 17 beams, all well inside the circle
    u = np.stack([np.cos(ang), np.sin(ang)], 1)

    def model(p):
        t = u[:, 0] * p[1] - u[:, 1] * p[0]
        return u @ p[:2] - np.sqrt(p[2] ** 2 - t * t)

    truth = np.array([*c, r])
    z0 = model(truth)
    est = []
    for _ in range(3000):
        z = z0 + rng.normal(0, sigma, z0.size)
        est.append(least_squares(lambda p, z=z: model(p) - z, truth, xtol=1e-12).x)
    emp = np.cov(np.array(est).T)
    bound = circle_crlb(c, r, ang, sigma)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(bound)), rtol=0.06)


def test_crlb_rejects_missing_beams():
    with pytest.raises(ValueError, match="misses"):
        circle_crlb([5.0, 0.0], 0.2, [0.0, 0.5], 0.01)
    with pytest.raises(ValueError, match=">= 3 beams"):
        circle_crlb([5.0, 0.0], 0.2, [0.0, 0.01], 0.01)


@pytest.fixture(scope="module")
def quick_mc():
    ctx = RunContext(out_dir=None, quick=True, seed=0)
    return pillar_monte_carlo(20, ctx.rng("table1"))


def test_quick_run_matches_golden_numbers(quick_mc):
    """Golden numbers from `python tests/regenerate_golden.py circles` (seed 0, 20 draws).
    The run is deterministic; the tolerance (relative 1e-6) only absorbs floating-point
    differences between platforms."""
    gold = json.loads(FILES["circles"].read_text())
    s = summarise(quick_mc)
    for m in METHODS:
        for p in TABLE_PILLARS:
            for k in ("ce_mean", "re_mean", "miss"):
                assert s[m][p].get(k) == pytest.approx(gold[m][p][k], rel=1e-6, abs=1e-12), (
                    m,
                    p,
                    k,
                )


def test_geometric_fit_is_near_the_bound(quick_mc):
    """Issue target: within 1.5x of the bound (RMS centre error) on pillars with >= 5 beams.
    Measured at 20 draws: median ratio ~1.2, max ~1.5 (the default 200-draw run is in
    results/crlb_efficiency.md)."""
    ratios = np.array([row[5] for row in efficiency(quick_mc)])
    assert len(ratios) >= 20
    assert np.median(ratios) <= 1.3
    assert np.mean(ratios <= 1.5) >= 0.9


def test_paper_fit_shows_the_kasa_bias(quick_mc):
    """On average over the pillars the paper's fit gives smaller circles than the geometric one."""
    s = summarise(quick_mc)
    paper = np.nanmean([s["paper"][p].get("r_bias_m", np.nan) for p in quick_mc.names])
    geo = np.nanmean([s["geometric"][p].get("r_bias_m", np.nan) for p in quick_mc.names])
    assert paper < geo
    assert abs(geo) < 0.01
