"""The association's one-pass kernels against the vectorised code they replaced (the oracles
below): the same gated pairs and the same numbers to the bit, on random scenes."""

from __future__ import annotations

import numpy as np
import pytest

from association import CostModel
from association.inputs import _gated_pairs, chol2_solve, prepare, wrap_angle
from association.single import _csc_problem


def _gated_pairs_numpy(z, R, z_hat, S_feat, gate):
    """The vectorised form `_gated_pairs` replaced, in the same (row-major) order."""
    nu = z[:, None, :] - z_hat[None, :, :]
    nu[..., 1] = wrap_angle(nu[..., 1])
    S = S_feat[None, :, :, :] + R[:, None, :, :]
    d2, logdet, ok = chol2_solve(S, nu)
    assert ok.all()
    ii, jj = np.nonzero(d2 <= gate)
    return ii, jj, nu[ii, jj], S[ii, jj], d2[ii, jj], logdet[ii, jj]


def _csc_problem_numpy(prep, model):
    """The vectorised `_csc_problem` that `_csc_index` replaced."""
    m = prep.m
    feats = np.unique(prep.pair_j)
    feats = feats[np.argsort(prep.rank_feat[feats])]
    row_of_feat = np.full(prep.n, -1, np.int64)
    row_of_feat[feats] = m + np.arange(feats.size)
    k = prep.pair_i.size
    meas_order = np.argsort(prep.rank_meas)
    col_meas = np.concatenate([prep.pair_i, meas_order])
    col_feat = np.concatenate([prep.pair_j, np.full(m, -1, np.int64)])
    costs = np.concatenate(
        [model.pair_cost(prep.d2, prep.logdet_S), np.full(m, model.unexplained_cost())]
    )
    pair_rows = np.stack([prep.pair_i, row_of_feat[prep.pair_j]], axis=1).reshape(-1)
    indices = np.concatenate([pair_rows, meas_order]).astype(np.int64)
    indptr = np.concatenate([np.arange(0, 2 * k + 1, 2), 2 * k + np.arange(1, m + 1)])
    exact = np.zeros(m + feats.size, bool)
    exact[:m] = True
    return costs, m + feats.size, indptr.astype(np.int64), indices, exact, col_meas, col_feat


def _scene(rng, m, n, spread=1.0):
    z = np.column_stack([rng.uniform(1, 20, m), rng.uniform(-3.5, 3.5, m)])
    # features near the measurements (many gated pairs) and elsewhere
    near = z[rng.integers(0, max(m, 1), n)] if m else np.zeros((n, 2))
    z_hat = near + rng.normal(0, 0.3 * spread, (n, 2))
    z_hat[:, 0] = np.abs(z_hat[:, 0])
    A = rng.normal(size=(m, 2, 2))
    R = A @ A.transpose(0, 2, 1) * 0.01 + np.diag([1e-3, 1e-4])
    d = 3 + 2 * n
    B = rng.normal(size=(d, d)) * 0.05
    P = B @ B.T
    H = np.zeros((n, 2, d))
    H[:, :, :3] = rng.normal(size=(n, 2, 3))
    for j in range(n):
        H[j, :, 3 + 2 * j : 5 + 2 * j] = rng.normal(size=(2, 2))
    return z, R, z_hat, H, P


@pytest.mark.parametrize("seed", range(40))
def test_gated_pairs_equal_the_vectorised_form_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(0, 9)), int(rng.integers(0, 12))
    z, R, z_hat, _, _ = _scene(rng, m, n)
    A = rng.normal(size=(n, 2, 2))
    S_feat = A @ A.transpose(0, 2, 1) * 0.05
    got = _gated_pairs(z, R, z_hat, S_feat, 9.21)
    want = _gated_pairs_numpy(z, R, z_hat, S_feat, 9.21)
    assert got[7].tolist() == [-1, -1]
    for a, b in zip(got[:5], want[:5]):
        assert np.array_equal(a, b)
    assert np.array_equal(2.0 * (np.log(got[5]) + np.log(got[6])), want[5])


def test_gated_pairs_name_the_first_pair_not_positive_definite():
    z = np.zeros((2, 2))
    R = np.stack([np.eye(2), -np.eye(2)])
    S_feat = np.zeros((3, 2, 2))
    assert _gated_pairs(z, R, np.zeros((3, 2)), S_feat, 9.21)[7].tolist() == [1, 0]


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("validate", [True, False])
def test_csc_problem_equals_the_vectorised_form(seed, validate):
    rng = np.random.default_rng(100 + seed)
    m, n = int(rng.integers(0, 9)), int(rng.integers(0, 12))
    prep = prepare(*_scene(rng, m, n), 0.99, validate=validate)
    got = _csc_problem(prep, CostModel())
    want = _csc_problem_numpy(prep, CostModel())
    assert got[1] == want[1]
    for a, b in zip(got[:1] + got[2:], want[:1] + want[2:]):
        assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(40))
def test_trusted_prepare_equals_the_checked_one_to_the_bit(seed):
    """The trusted path's one-call kernel (`inputs._trusted_prepared`, up to _KERNEL_RANKS
    measurements and features) gives every field of the checked path's `Prepared`, the
    pairs in the same canonical order, to the bit; also with one R for all measurements."""
    rng = np.random.default_rng(400 + seed)
    m, n = int(rng.integers(0, 12)), int(rng.integers(0, 16))
    z, R, z_hat, H, P = _scene(rng, m, n)
    for R_arg in (R, np.diag([2e-3, 3e-4])):
        a = prepare(z, R_arg, z_hat, H, P, 0.99, validate=True)
        b = prepare(z, R_arg, z_hat, H, P, 0.99, validate=False)
        for name in vars(a):
            x, y = getattr(a, name), getattr(b, name)
            assert np.asarray(x).tobytes() == np.asarray(y).tobytes(), name
