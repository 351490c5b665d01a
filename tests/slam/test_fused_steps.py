"""The per-scan work fused into one numba call each (issue 40, speed) against the code they
replaced, kept here as their oracles: `slam.scan_candidates.scan_candidates` (the single-scan
association's inputs), `slam.ekf._batch_inputs` (`Filter.update`'s), and loop closure's
`slam.scan_candidates.revisit_spread` and `slam.closure._nearest_far`. Both do the same
operations in the same order, so they must agree to the bit, not to a tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from association import gate_matrix
from slam import se2
from slam.closure import SAME_TREE_M, _k_nearest, _nearest_far
from slam.ekf import EkfState, Filter, _batch_blocks, _batch_inputs, landmark_columns
from slam.map_managers import View
from slam.scan_candidates import (
    project_blocks,
    revisit_spread,
    scan_candidates,
    sub_problem,
    view_bounds,
)

LASER = np.array([3.78, 0.5, -0.0187])
POSE_COLS = np.array([0, 1, 2], np.int64)


def _filter(rng, n: int, lower_only: bool) -> Filter:
    """A filter with n landmarks around the vehicle and a random SPD covariance; lower_only:
    its upper triangle garbage, as after an update (only the lower one is current)."""
    d = 3 + 2 * n
    A = rng.normal(size=(d, d + 2)) * 0.1
    P = A @ A.T + 1e-3 * np.eye(d)
    x = np.concatenate([[1.0, -2.0, 0.3], rng.uniform(-40, 40, 2 * n)])
    f = Filter(EkfState(x, P, np.arange(n, dtype=np.int64) * 3 + 1), first_estimates=True)
    f.first_xy = f.landmarks_xy + rng.normal(scale=0.2, size=(n, 2))
    if lower_only:
        iu = np.triu_indices(d, 1)
        f._P[iu] = rng.normal(size=iu[0].size)
        f._mirrored = False
    return f


def _candidates_numpy(state, hidden, tent_xy, tent_cov, view, z, R, usable, gate):
    """`TentativeMap.associate`'s steps before its associator, as they were written."""
    z_lm, H_lm = se2.observe(state.pose, state.landmarks_xy, LASER)
    z_t, H_t = se2.observe(state.pose, tent_xy, LASER)
    lm_idx = np.flatnonzero(view.contains(z_lm) & ~hidden)
    t_idx = np.flatnonzero(view.contains(z_t))
    n_l, n = lm_idx.size, lm_idx.size + t_idx.size
    ambiguous = np.zeros(z.shape[0], bool)
    use = np.flatnonzero(usable)
    if not (use.size and n):
        return lm_idx, t_idx, use, ambiguous, np.zeros(0, np.int64), None, None, None
    zh = np.concatenate([z_lm[lm_idx], z_t[t_idx]])
    H5 = np.concatenate([H_lm[lm_idx], H_t[t_idx]])
    C5 = np.zeros((n, 5, 5))
    C5[:n_l] = state.cov(landmark_columns(lm_idx))
    C5[n_l:, :3, :3] = state.pose_cov
    C5[n_l:, 3:, 3:] = tent_cov[t_idx]
    gated = gate_matrix(z[use], R[use], zh, project_blocks(H5, C5), gate)
    ambiguous[use] = gated.any(axis=1)
    cand = np.flatnonzero(gated.any(axis=0))
    c_lm = cand[cand < n_l]
    sub = np.concatenate([POSE_COLS, landmark_columns(lm_idx[c_lm])[:, 3:].ravel()])
    c_t = t_idx[cand[cand >= n_l] - n_l]
    H, P_sub = sub_problem(H5, cand, state.cov(sub), tent_cov[c_t])
    return lm_idx, t_idx, use, ambiguous, cand, zh[cand], H, P_sub


@pytest.mark.parametrize("seed", range(40))
def test_scan_candidates_equal_the_numpy_steps_to_the_bit(seed):
    """Landmarks and tentatives in and out of view, some hidden, some measurements out of
    range, a view with margins (and one that sees all round): every output identical."""
    rng = np.random.default_rng(seed)
    state = _filter(rng, int(rng.integers(0, 60)), lower_only=seed % 2 == 0)
    n, t, m = state.n_landmarks, int(rng.integers(0, 12)), int(rng.integers(0, 12))
    hidden = rng.random(n) < 0.2
    tent_xy = rng.uniform(-40, 40, (t, 2))
    A = rng.normal(size=(t, 2, 2)) * 0.3
    tent_cov = A @ A.transpose(0, 2, 1) + 1e-3 * np.eye(2)
    fov = (-np.pi / 2, np.pi / 2) if seed % 5 else (-np.pi, np.pi)
    view = View(fov, 30.0, margin_m=float(rng.uniform(0, 2)), margin_rad=float(rng.uniform(0, 0.1)))
    # measurements near predicted landmarks (so that some gate), and a few anywhere
    z_lm, _ = se2.observe(state.pose, state.landmarks_xy, LASER)
    near = z_lm[rng.integers(0, max(n, 1), m)] if n else np.zeros((m, 2))
    z = near + rng.normal(scale=[0.3, 0.02], size=(m, 2))
    z[::4] = np.column_stack(
        [rng.uniform(1, 35, z[::4].shape[0]), rng.uniform(-1.5, 1.5, z[::4].shape[0])]
    )
    z[:, 0] = np.abs(z[:, 0])
    R = np.tile(np.diag([0.03**2, 0.003**2]), (m, 1, 1))
    usable = z[:, 0] <= 30.0
    gate = -2.0 * np.log1p(-0.9999)
    got = scan_candidates(
        state.P_lower,
        state.pose,
        state.landmarks_xy,
        hidden,
        tent_xy,
        tent_cov,
        se2.sensor_numbers(state.pose, LASER),
        float(LASER[2]),
        z,
        R,
        usable,
        view_bounds(view),
        gate,
    )
    want = _candidates_numpy(state, hidden, tent_xy, tent_cov, view, z, R, usable, gate)
    for name, a, b in zip(("lm_idx", "t_idx", "use", "ambiguous", "cand"), got, want):
        assert np.array_equal(a, b), name
    if got[4].size:
        for name, a, b in zip(("zh_cand", "H", "P_sub"), got[5:], want[5:]):
            assert a.tobytes() == b.tobytes(), name


def _batch_numpy(state, idx, z, R):
    """`Filter.update`'s inputs as they were written (FEJ Jacobians)."""
    z_hat, H5 = se2.observe(state.pose, state.landmarks_xy[idx], LASER)
    if state.first_estimates:
        H5 = se2.observe(state.pose, state.first_xy[idx], LASER)[1]
    nu = z - z_hat
    nu[:, 1] = se2.wrap_angle(nu[:, 1])
    return (nu, *_batch_blocks(idx, H5, R))


@pytest.mark.parametrize("seed", range(30))
@pytest.mark.parametrize("fej", [True, False])
def test_batch_inputs_equal_the_numpy_steps_to_the_bit(seed, fej):
    rng = np.random.default_rng(100 + seed)
    state = _filter(rng, int(rng.integers(1, 40)), lower_only=False)
    state.first_estimates = fej
    k = int(rng.integers(1, state.n_landmarks + 1))
    idx = rng.choice(state.n_landmarks, k, replace=False).astype(np.int64)
    z_hat, _ = se2.observe(state.pose, state.landmarks_xy[idx], LASER)
    z = z_hat + rng.normal(scale=[0.1, 0.5], size=(k, 2))  # bearings past +-pi to wrap
    A = rng.normal(size=(k, 2, 2)) * 0.05
    R = A @ A.transpose(0, 2, 1) + 1e-4 * np.eye(2)
    got = _batch_inputs(
        state.landmarks_xy,
        state.first_xy,
        idx,
        z,
        R,
        se2.sensor_numbers(state.pose, LASER),
        (float(state.x[2]), float(LASER[2])),
        fej,
    )
    for name, a, b in zip(("nu", "cols", "Hc", "R_blk"), got[:4], _batch_numpy(state, idx, z, R)):
        assert a.tobytes() == b.tobytes(), name
    assert not got[4]  # no landmark twice


def test_batch_inputs_find_a_landmark_twice():
    """A batch that names one landmark twice is refused by the update (its error)."""
    rng = np.random.default_rng(7)
    state = _filter(rng, 5, lower_only=False)
    idx = np.array([3, 1, 3], np.int64)
    z, _ = se2.observe(state.pose, state.landmarks_xy[idx], LASER)
    R = np.tile(np.diag([0.03**2, 0.003**2]), (3, 1, 1))
    with pytest.raises(ValueError, match="appears twice"):
        state.update(idx, z, R, LASER)


def _revisit_numpy(state, seen, before, view):
    """`LoopCloser.revisit`'s steps before its gate, as they were written."""
    cand = np.flatnonzero(seen < before)
    z_hat, H5 = se2.observe(state.pose, state.landmarks_xy[cand], LASER)
    inside = view.contains(z_hat)
    cand, z_hat, H5 = cand[inside], z_hat[inside], H5[inside]
    C5 = state.cov(landmark_columns(cand))
    S = np.einsum("nij,njk,nlk->nil", H5, C5, H5)
    return cand, np.sqrt(np.maximum(S[:, 0, 0], z_hat[:, 0] ** 2 * S[:, 1, 1]))


@pytest.mark.parametrize("seed", range(30))
def test_revisit_spread_equals_the_numpy_steps_to_the_bit(seed):
    """The sds came from np.einsum in the code it replaced: with numpy 2.4 `project_blocks`
    sums its 25 products in einsum's order, so they agree to the bit (what kept the full run
    identical). numpy does not promise einsum's order: if a numpy upgrade fails only this
    test, the kernel is within `test_trusted_kernels`' rounding bound of einsum, and the
    reference here should then use `project_blocks`."""
    rng = np.random.default_rng(200 + seed)
    state = _filter(rng, int(rng.integers(0, 80)), lower_only=seed % 2 == 1)
    seen = rng.uniform(0, 100, state.n_landmarks)
    seen[rng.random(state.n_landmarks) < 0.1] = np.nan  # never seen (seen_at's default)
    view = View((-np.pi / 2, np.pi / 2), 30.0, margin_m=1.0, margin_rad=0.05)
    got = revisit_spread(
        state.P_lower,
        state.landmarks_xy,
        seen,
        60.0,
        se2.sensor_numbers(state.pose, LASER),
        float(LASER[2]),
        float(state.pose[2]),
        view_bounds(view),
    )
    want = _revisit_numpy(state, seen, 60.0, view)
    assert np.array_equal(got[0], want[0])
    assert got[1].tobytes() == want[1].tobytes()


def _nearest_numpy(xy, pos, k, match_m):
    """`LoopCloser._nearest_other_tree`'s search as it was written (before its loop over
    the close ones)."""
    d, j = _k_nearest(np.ascontiguousarray(xy), xy[pos], k)
    other = d > match_m
    close = other & (d <= SAME_TREE_M)
    far = other & ~close
    first = np.argmax(far, axis=1)
    rows = np.arange(d.shape[0])
    return np.where(far[rows, first], d[rows, first], np.inf), close, d, j


@pytest.mark.parametrize("seed", range(30))
def test_nearest_far_equals_the_numpy_steps(seed):
    """Clustered points (trees mapped twice within SAME_TREE_M) and a match_m on either side
    of it, with landmarks whose k nearest hold no far one (inf)."""
    rng = np.random.default_rng(300 + seed)
    n = int(rng.integers(2, 60))
    centres = rng.uniform(-20, 20, (max(n // 2, 1), 2))
    xy = centres[rng.integers(0, centres.shape[0], n)] + rng.normal(scale=0.7, size=(n, 2))
    pos = rng.choice(n, int(rng.integers(1, n + 1)), replace=False).astype(np.int64)
    k = min(16, n)
    for match_m in (0.3, 1.0, 2.0):
        got = _nearest_far(xy, pos, k, match_m)
        want = _nearest_numpy(xy, pos, k, match_m)
        for a, b in zip(got, want):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("bad", [-1, 5, 40])
def test_an_update_of_a_landmark_position_outside_the_state_is_refused(bad):
    """The fused kernel reads idx unchecked: an index outside [0, n) is the update's clear
    error before it (numpy's indexing raised one before the kernel; a negative index wrapped)."""
    rng = np.random.default_rng(7)
    state = _filter(rng, 5, lower_only=False)
    idx = np.array([1, bad], np.int64)
    z = np.array([[5.0, 0.1], [6.0, -0.1]])
    R = np.tile(np.diag([0.03**2, 0.003**2]), (2, 1, 1))
    before = state.x.copy()
    with pytest.raises(ValueError, match=r"update.idx: landmark positions must be in \[0, 5\)"):
        state.update(idx, z, R, LASER)
    assert state.x.tobytes() == before.tobytes()
