"""The noise calibration's range-bias line (experiments/paper/calibration.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from experiments.paper.calibration import range_bias_line


def test_range_bias_line_is_the_maximum_likelihood_line_under_the_given_variances():
    """Weighted least squares with weights 1 / var is the Gaussian maximum-likelihood line; with
    equal variances it is the ordinary least-squares line."""
    rng = np.random.default_rng(3)
    r = rng.uniform(2.0, 30.0, 400)
    var = (0.002 + 0.001 * rng.uniform(0, 20, 400)) ** 2
    err = -0.002 + 0.0003 * r + np.sqrt(var) * rng.standard_normal(400)
    a, b = range_bias_line(r, err, var)

    def nll(q):
        return float(np.sum((err - q[0] - q[1] * r) ** 2 / var))

    ml = minimize(nll, [0.0, 0.0], method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14})
    assert (a, b) == pytest.approx(tuple(ml.x), abs=1e-7)
    ols = np.linalg.lstsq(np.column_stack([np.ones_like(r), r]), err, rcond=None)[0]
    assert range_bias_line(r, err, np.full(400, 0.01)) == pytest.approx(tuple(ols), abs=1e-12)


def test_range_bias_line_follows_the_precise_circles():
    """Precise circles 1 mm short and rough ones 5 mm long at the same ranges: the line the
    filter needs is the precise circles' (it trusts them 100 times more); an unweighted one
    sits near the middle."""
    r = np.tile(np.linspace(3.0, 20.0, 50), 2)
    err = np.r_[np.full(50, -0.001), np.full(50, 0.005)]
    var = np.r_[np.full(50, 0.002**2), np.full(50, 0.02**2)]
    a, b = range_bias_line(r, err, var)
    assert a == pytest.approx(-0.001 + 0.006 / 101, abs=1e-9) and b == pytest.approx(0.0, abs=1e-12)
    unweighted = np.linalg.lstsq(np.column_stack([np.ones_like(r), r]), err, rcond=None)[0]
    assert unweighted[0] == pytest.approx(0.002)
