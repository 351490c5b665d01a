"""`slam.checks.check_noise`, the one check the loop makes on every scan: every usable
measurement's R finite and positive definite, else an error naming the scan and the feature."""

from __future__ import annotations

import numpy as np
import pytest

from slam.checks import check_noise
from slam.errors import SlamError


def _first_bad_numpy(R, usable) -> int:
    """The vectorised test the kernel replaced: the first usable bad R, or -1."""
    a, b, c = R[:, 0, 0], 0.5 * (R[:, 0, 1] + R[:, 1, 0]), R[:, 1, 1]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(R).all(axis=(1, 2)) & (a > 0) & (c > 0) & (a * c - b * b > 0)
    bad = np.flatnonzero(usable & ~ok)
    return int(bad[0]) if bad.size else -1


@pytest.mark.parametrize("seed", range(30))
def test_the_first_bad_usable_noise_is_named_as_the_vectorised_test_finds_it(seed):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(0, 12))
    L = rng.normal(size=(m, 2, 2)) * 0.1
    R = L @ L.transpose(0, 2, 1) + 1e-6 * np.eye(2)
    for _ in range(int(rng.integers(0, 3))):  # a few broken ones: NaN, inf, not definite
        if m:
            i, j, l_ = rng.integers(0, m), rng.integers(0, 2), rng.integers(0, 2)
            R[i, j, l_] = rng.choice([np.nan, np.inf, -np.inf, -1e-3, 0.0, 10.0])
    usable = rng.random(m) < 0.7
    want = _first_bad_numpy(R, usable)
    if want < 0:
        check_noise(4, R, usable, "fit")
        return
    with pytest.raises(SlamError, match=rf"scan 4, feature {want} has a covariance R"):
        check_noise(4, R, usable, "fit")


def test_an_unusable_measurement_may_have_any_noise():
    R = np.array([np.eye(2), np.full((2, 2), np.nan), [[1.0, 2.0], [2.0, 1.0]]])
    check_noise(0, R, np.array([True, False, False]), "fit")
    with pytest.raises(SlamError, match="scan 0, feature 2 .*'constant'"):
        check_noise(0, R, np.array([True, False, True]), "constant")
