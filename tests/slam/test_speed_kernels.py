"""The kernels of issue 40's speed work against the code they replaced: `Filter.positions_of`
(a pass per id for a few ids, the sort for more), `rigid.move_rigidly`'s one-pass rotation of P,
and `se2.observe_within` (the landmarks out of range skipped)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import rigid
from slam.ekf import EkfState, Filter
from slam.se2 import observe_kernel, observe_within


def _sorted_positions(landmark_ids: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The sort-and-search form `positions_of` used for every call before."""
    order = np.argsort(landmark_ids, kind="stable")
    at = np.minimum(np.searchsorted(landmark_ids[order], ids), order.size - 1)
    pos = order[at]
    return np.where(landmark_ids[pos] == ids, pos, -1)


@pytest.mark.parametrize("k", [1, 5, 32, 33, 200])
def test_positions_of_equals_the_sort(k):
    rng = np.random.default_rng(k)
    lm_ids = rng.permutation(5000)[:600].astype(np.int64)
    f = Filter(EkfState(np.zeros(3 + 2 * lm_ids.size), np.eye(3 + 2 * lm_ids.size), lm_ids))
    ids = np.concatenate([rng.choice(lm_ids, k - 1, replace=False), [99_999]])
    got = f.positions_of(ids)
    assert got[-1] == -1  # an id not in the state
    np.testing.assert_array_equal(got, _sorted_positions(lm_ids, ids))
    assert np.all(lm_ids[got[:-1]] == ids[:-1])


def test_positions_of_an_empty_state_and_no_ids():
    empty = Filter(EkfState(np.zeros(3), np.eye(3), np.zeros(0, np.int64)))
    np.testing.assert_array_equal(empty.positions_of([4, 7]), [-1, -1])
    assert empty.positions_of([]).shape == (0,)


def _two_pass(P: np.ndarray, theta: float) -> np.ndarray:
    """J P J^T by the numpy form `move_rigidly` used before: each position's rows, then its
    columns."""
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    out = P.copy()
    xy = np.concatenate([[0], 3 + 2 * np.arange((P.shape[0] - 3) // 2)])
    for a in xy:
        out[a : a + 2, :] = R @ out[a : a + 2, :]
    for a in xy:
        out[:, a : a + 2] = out[:, a : a + 2] @ R.T
    return out


@pytest.mark.parametrize("n", [0, 1, 7, 120])
def test_move_rigidly_rotates_p_as_the_two_passes(n):
    """The one-pass kernel gives the two passes' product (to the bit where the BLAS sums each
    entry's two products with a fused multiply-add, as OpenBLAS's kernels on this project's
    machines do; the bound here is a few ulp of the entries, which any BLAS meets)."""
    rng = np.random.default_rng(n)
    d = 3 + 2 * n
    A = rng.normal(size=(d, d))
    f = Filter(EkfState(rng.normal(size=d), A @ A.T, np.arange(n)))
    want = _two_pass(f.P, 0.3)
    rigid.move_rigidly(f, 0.3, np.array([1.0, -2.0]))
    got = f.P
    assert np.max(np.abs(got - want)) <= 8 * np.finfo(float).eps * np.max(np.abs(want))
    # the heading's row and column stay where they were, rotated only by the positions'
    assert np.max(np.abs(got[2, 2] - want[2, 2])) == 0.0


def test_observe_within_is_observe_kernel_within_range():
    rng = np.random.default_rng(3)
    m = rng.uniform(-80.0, 80.0, (500, 2))
    m[7] = np.nan
    args = (0.4, -1.2, 0.1, 0.2, 0.7, 0.05)
    z, H = observe_kernel(m, *args)
    z_in, H_in = observe_within(m, *args, 30.0)
    near = z[:, 0] <= 30.0
    assert 10 < near.sum() < 400
    np.testing.assert_array_equal(z_in[near], z[near])  # the same bits
    np.testing.assert_array_equal(H_in[near], H[near])
    np.testing.assert_array_equal(z_in[:, 0], z[:, 0])  # every range, NaN included
    assert np.all(H_in[~near] == 0.0) and np.all(z_in[~near, 1] == 0.0)


def test_add_landmark_writes_every_entry_of_the_grown_covariance(monkeypatch):
    """`Filter.add_landmark` grows P into an uninitialised array (no zeroing of d^2): with that
    array filled with NaN, every entry must still be written, hidden copies included."""
    rng = np.random.default_rng(5)
    n = 6
    A = rng.normal(size=(3 + 2 * n, 3 + 2 * n))
    f = Filter(EkfState(rng.normal(size=3 + 2 * n), A @ A.T, np.arange(n)))
    f.append_copies([1, 4], np.tile(0.1 * np.eye(2), (2, 1, 1)))
    real_empty = np.empty

    def nan_empty(shape, *args, **kwargs):
        out = real_empty(shape, *args, **kwargs)
        out.fill(np.nan)
        return out

    monkeypatch.setattr(np, "empty", nan_empty)
    f.add_landmark(np.array([5.0, 0.3]), 0.01 * np.eye(2), np.zeros(3), landmark_id=99)
    monkeypatch.undo()
    assert f.dim == 3 + 2 * (n + 1) + 4
    assert np.all(np.isfinite(f.P))
    assert f.landmark_ids[-1] == 99 and np.array_equal(f.copy_of, [1, 4])
