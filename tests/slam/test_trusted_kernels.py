"""The run loop's and the filter's numba kernels against the vectorised code they replaced."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from association import gate_matrix
from association.inputs import chol2_solve
from slam import se2
from slam.closure import _k_nearest, _pairs_within
from slam.ekf import _batch_blocks
from slam.scan_candidates import project_blocks as _project_kernel
from slam.scan_candidates import sub_problem as _sub_problem
from slam.vehicle import _pieces

_PAIR = np.array([0, 1])


def _sub_problem_numpy(H5, cand, P_lm, cov_t):
    """The vectorised build `_sub_problem` replaced (`slam.map_managers.TentativeMap.associate`)."""
    nc = cand.size
    H = np.zeros((nc, 2, 3 + 2 * nc))
    H[:, :, :3] = H5[cand, :, :3]
    j = np.arange(nc)[:, None, None]
    H[j, _PAIR[:, None], 3 + 2 * j + _PAIR] = H5[cand, :, 3:5]
    P_sub = np.zeros((3 + 2 * nc, 3 + 2 * nc))
    P_sub[: P_lm.shape[0], : P_lm.shape[0]] = P_lm
    a = P_lm.shape[0] + 2 * np.arange(cov_t.shape[0])[:, None, None]
    P_sub[a + _PAIR[:, None], a + _PAIR] = cov_t
    return H, P_sub


def _gate_matrix_numpy(z, R, z_hat, S_feat, gate):
    """The individual gates of every pair, vectorised: S_ij = S_feat_j + R_i, the bearing of
    nu_ij wrapped (`se2.wrap_angle`), d2_ij by `chol2_solve`. Also returns d2 (m, n)."""
    S = S_feat[None, :, :, :] + R[:, None, :, :]  # (m, n, 2, 2)
    nu = z[:, None, :] - z_hat[None, :, :]
    nu[..., 1] = se2.wrap_angle(nu[..., 1])
    d2, _, ok = chol2_solve(S, nu)
    return ok & (d2 <= gate), d2


def _batch_blocks_numpy(idx, H5, R):
    """The vectorised blocks of `Filter.update` that `_batch_blocks` replaced."""
    k = idx.size
    cols = np.concatenate([[0, 1, 2], np.stack([3 + 2 * idx, 4 + 2 * idx], 1).reshape(-1)])
    q = 2 * k
    j = np.arange(k)
    Hc = np.zeros((q, 3 + q))
    Hc[:, :3] = H5[:, :, :3].reshape(q, 3)
    H_lm = np.zeros((k, 2, k, 2))
    H_lm[j, :, j, :] = H5[:, :, 3:5]
    Hc[:, 3:] = H_lm.reshape(q, q)
    R_blk = np.zeros((k, 2, k, 2))
    R_blk[j, :, j, :] = R
    return cols, Hc, R_blk.reshape(q, q)


def _spd(rng, n, k, scale):
    A = rng.normal(size=(n, k, k))
    return A @ A.transpose(0, 2, 1) * scale + 1e-4 * np.eye(k)


@pytest.mark.parametrize("seed", range(30))
def test_gate_matrix_gives_the_gates_of_the_vectorised_twin(seed):
    """`gate_matrix` does `chol2_solve`'s arithmetic operation for operation, so its d2 is the
    vectorised one to the bit: the gates agree exactly, also with the gate set at one of the
    pairs' own d2 (the pair exactly on the boundary passes in both), and a pair whose S is not
    positive definite passes in neither."""
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(0, 9)), int(rng.integers(0, 40))
    z = np.column_stack([rng.uniform(1, 30, m), rng.uniform(-1.6, 1.6, m)])
    z_hat = np.column_stack([rng.uniform(1, 30, n), rng.uniform(-3.2, 3.2, n)])
    R = _spd(rng, m, 2, 0.01)
    H5 = rng.normal(size=(n, 2, 5))
    S_feat = np.einsum("nij,njk,nlk->nil", H5, _spd(rng, n, 5, 0.1), H5)
    if n > 2:  # one feature whose S is not positive definite with any measurement's R
        S_feat[1] = -np.eye(2)
    _, d2 = _gate_matrix_numpy(z, R, z_hat, S_feat, 0.0)
    finite = np.sort(d2[np.isfinite(d2)])
    on_the_boundary = finite[:: max(1, finite.size // 5)].tolist()
    for gate in (1.0, 9.21, 30.0, *on_the_boundary):
        want, _ = _gate_matrix_numpy(z, R, z_hat, S_feat, gate)
        assert np.array_equal(gate_matrix(z, R, z_hat, S_feat, gate), want), gate


@pytest.mark.parametrize("seed", range(20))
def test_project_kernel_equals_einsum_to_the_rounding_of_its_sums(seed):
    """Each entry of H5 C5 H5^T is a sum of 25 products of three factors, summed by the kernel
    and by np.einsum in their own orders: each is within gamma_27 = 27 u / (1 - 27 u) (u the
    unit roundoff) of sum |h c h| from the exact value (Higham, Accuracy and Stability of
    Numerical Algorithms, 2nd ed., sec. 3.1), so they differ by at most twice that."""
    rng = np.random.default_rng(120 + seed)
    n = int(rng.integers(0, 30))
    H5 = rng.normal(size=(n, 2, 5))
    C5 = _spd(rng, n, 5, 0.1)
    got = _project_kernel(H5, C5)
    want = np.einsum("nij,njk,nlk->nil", H5, C5, H5)
    u = np.finfo(np.float64).eps / 2
    bound = 2 * (27 * u / (1 - 27 * u)) * np.einsum("nij,njk,nlk->nil", *map(np.abs, (H5, C5, H5)))
    assert got.shape == want.shape == (n, 2, 2)
    assert np.all(np.abs(got - want) <= bound)


@pytest.mark.parametrize("seed", range(20))
def test_sub_problem_equals_the_vectorised_build(seed):
    rng = np.random.default_rng(50 + seed)
    n = int(rng.integers(1, 15))
    H5 = rng.normal(size=(n, 2, 5))
    cand = np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False)).astype(np.int64)
    n_lm = int(rng.integers(0, cand.size + 1))
    P_lm = _spd(rng, 1, 3 + 2 * n_lm, 0.1)[0]
    cov_t = _spd(rng, cand.size - n_lm, 2, 0.1)
    for a, b in zip(_sub_problem(H5, cand, P_lm, cov_t), _sub_problem_numpy(H5, cand, P_lm, cov_t)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(20))
def test_batch_blocks_equal_the_vectorised_build(seed):
    rng = np.random.default_rng(80 + seed)
    k = int(rng.integers(1, 10))
    idx = rng.choice(40, k, replace=False).astype(np.int64)
    H5 = rng.normal(size=(k, 2, 5))
    R = _spd(rng, k, 2, 0.01)
    for a, b in zip(_batch_blocks(idx, H5, R), _batch_blocks_numpy(idx, H5, R)):
        assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(20))
def test_k_nearest_is_the_k_d_trees_query_to_the_bit(seed):
    """Loop closure's nearest-other-tree search (`_k_nearest`) against the `cKDTree` query it
    replaced: the same distances to the bit and the same neighbours; with ties (odd seeds:
    points on a 25 m grid, duplicates) the same ones nearer than the k-th distance, and each
    neighbour at its distance (which of several tied points comes first is the tree's own)."""
    rng = np.random.default_rng(110 + seed)
    n = int(rng.integers(1, 400))
    xy = rng.uniform(-200.0, 200.0, (n, 2))
    if seed % 2:
        xy = np.round(2.0 * xy / 50.0) / 2.0  # many equal distances and coincident points
    pos = rng.choice(n, int(rng.integers(1, min(n, 40) + 1)), replace=False)
    k = min(16, n)
    want_d, want_j = cKDTree(xy).query(xy[pos], k=k)
    got_d, got_j = _k_nearest(xy, xy[pos], k)
    want_d, want_j = want_d.reshape(pos.size, k), want_j.reshape(pos.size, k)
    assert got_d.tobytes() == want_d.tobytes()
    if seed % 2 == 0:
        assert np.array_equal(got_j, want_j)
    diff = xy[pos][:, None, :] - xy[got_j]
    assert np.array_equal(np.sqrt(diff[..., 0] ** 2 + diff[..., 1] ** 2), got_d)
    for r in range(pos.size):
        inner = got_d[r] < got_d[r, -1]
        assert set(got_j[r, inner].tolist()) == set(want_j[r, inner].tolist())


def _pieces_numpy(t, speed, steer, t0_s, t1_s):
    """The vectorised `Odometry.pieces` that `_pieces` replaced."""
    a = int(np.searchsorted(t, t0_s, side="right"))
    b = max(int(np.searchsorted(t, t1_s, side="left")), a)
    edges = np.concatenate([[t0_s], t[a:b], [t1_s]])
    idx = np.maximum(np.arange(a - 1, b), 0)
    dt = np.diff(edges)
    keep = dt > 0
    return dt[keep], speed[idx[keep]], steer[idx[keep]]


@pytest.mark.parametrize("seed", range(20))
def test_pieces_equal_the_vectorised_build(seed):
    """The odometry's hold pieces over intervals before, across, between and after the
    samples, on a sample and of zero length."""
    rng = np.random.default_rng(140 + seed)
    m = int(rng.integers(1, 30))
    t = np.cumsum(rng.uniform(0.01, 0.1, m)) + 1.0
    speed, steer = rng.normal(size=m), rng.normal(size=m)
    ends = np.concatenate([t, rng.uniform(0.5, t[-1] + 0.5, 20), [0.0, t[-1] + 1.0]])
    for _ in range(40):
        t0, t1 = np.sort(rng.choice(ends, 2))
        if seed % 4 == 0:
            t1 = t0
        for a, b in zip(_pieces(t, speed, steer, t0, t1), _pieces_numpy(t, speed, steer, t0, t1)):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", range(20))
def test_pairs_within_are_the_distance_matrix_pairs(seed):
    """Loop closure's pairs of landmarks seen together within SAME_TREE_M (`_pairs_within`)
    against the n x n np.hypot matrix it replaced, points on a grid (distances exactly at the
    bound) included."""
    rng = np.random.default_rng(170 + seed)
    for _ in range(50):
        n = int(rng.integers(0, 25))
        xy = rng.uniform(0.0, 5.0, (n, 2))
        if seed % 2:
            xy = np.round(2.0 * xy) / 2.0
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        want = np.transpose(np.nonzero(np.triu(d <= 1.5, 1)))
        assert np.array_equal(_pairs_within(xy, 1.5), want)
