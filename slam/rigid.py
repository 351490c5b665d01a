"""Rigid motions and merges of a filter's landmarks: the algebra of loop closure
(`slam.closure`), beside the filter (`slam.ekf.Filter`, which keeps predict, update, augment
and marginalise).

Each function reads or changes a `Filter` in place, as its own steps do:
- `same_landmarks_nis`, `pair_difference`: whether "landmark keep_j is landmark drop_j" for
  all pairs is jointly compatible with the filter's covariance;
- `merge_landmarks`: apply it (one constrained update, then marginalise the duplicates);
- `rigid_fit`: the pairs up to one rigid motion (Kabsch) and the NIS of what it leaves;
- `free_rigid_motion`: let the vehicle and some landmarks move together by an unknown rigid
  motion (their covariance grows);
- `move_rigidly`: move the whole estimate by one rigid motion (a change of world frame).
`move_rigidly` moves the filter's hidden copies (the pass offsets' anchors, `slam.pass_state`)
with the landmarks. The two that change what the filter knows (merge, free) first restore them
(`Filter.restore_copies`), so they act on the landmarks alone: the passes open then end there.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from slam.ekf import Filter
from slam.errors import SlamError
from slam.se2 import procrustes_2d, wrap_angle

__all__ = [
    "free_rigid_motion",
    "merge_landmarks",
    "move_rigidly",
    "pair_difference",
    "rigid_fit",
    "same_landmarks_nis",
]


def same_landmarks_nis(state: Filter, keep_ids, drop_ids) -> float:
    """The joint compatibility of "landmark keep_ids[j] is landmark drop_ids[j]" for all j:
    d^T S^-1 d with d the stacked differences of their positions and S their covariance
    (chi-square with 2 x pairs degrees of freedom when the pairs are the same trees)."""
    d, S = pair_difference(state, keep_ids, drop_ids)
    L = np.linalg.cholesky(S)
    v = np.linalg.solve(L, d)
    return float(v @ v)


def pair_difference(
    state: Filter, keep_ids, drop_ids, tree_sd_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(d (q,), S (q, q)): the stacked differences x_keep - x_drop of the pairs of
    `same_landmarks_nis` and their covariance, tree_sd_m added to each landmark."""
    d, _, S, _, _ = _pair_constraint(state, keep_ids, drop_ids, math.sqrt(2.0) * tree_sd_m)
    return d, S


def merge_landmarks(state: Filter, keep_ids, drop_ids, sigma_m: float = 1e-3) -> float:
    """Landmark drop_ids[j] is landmark keep_ids[j]: one batch update with the measurement
    "their positions differ by 0" (noise sigma_m each axis, a hard constraint that keeps S
    invertible), then each drop_ids[j] is marginalised out (`remove_landmarks`). Returns
    the constraint's NIS (`same_landmarks_nis`, with the noise)."""
    state.restore_copies()  # the pass offsets' anchors first (`slam.pass_state`)
    d, HP, S, _, _ = _pair_constraint(state, keep_ids, drop_ids, sigma_m)
    L = np.linalg.cholesky(S)
    W = np.linalg.solve(L, HP).T  # (dim, q): P H^T L^-T
    v = np.linalg.solve(L, -d)  # L^-1 (0 - d)
    state.x += W @ v
    state.x[2] = float(wrap_angle(state.x[2]))
    P = state.P
    P -= W @ W.T
    P[:] = 0.5 * (P + P.T)
    state.remove_landmarks(drop_ids)
    return float(v @ v)


def rigid_fit(
    state: Filter, keep_ids, drop_ids, tree_sd_m: float = 0.0
) -> tuple[float, np.ndarray, np.ndarray]:
    """The pairs of `same_landmarks_nis` up to one rigid motion: the least-squares motion
    (Kabsch: the drop landmarks' centroid onto the keep landmarks', rotated by theta) and
    the NIS of what it leaves. The residuals r_j = (x_keep_j - c_keep) - R(theta)
    (x_drop_j - c_drop) have covariance M P M^T (M: the centring and rotation, linear in
    the landmarks); in a basis without the common translation (2 x pairs - 2 coordinates)
    the rotation's direction is projected out by generalised least squares, and what is
    left, chi-square with 2 x pairs - 3 dof when the pairs are the same trees once the drop
    side is moved, is the NIS. tree_sd_m: an independent error (m, per axis) of each
    landmark's position added to P's landmark blocks for the test (the trunk's centre as
    seen from one side, which the filter's white measurement noise averages away).
    Returns (nis, motion (tx, ty, theta) that moves the drop centroid and rotates about
    it, c_drop (2,))."""
    _, _, _, ck, cd = _pair_constraint(state, keep_ids, drop_ids, 0.0)
    n = ck.size // 2
    if n < 2:
        raise SlamError("rigid_fit: needs at least two pairs")
    xk, xd = state.x[ck].reshape(n, 2), state.x[cd].reshape(n, 2)
    ak, ad = xk - xk.mean(axis=0), xd - xd.mean(axis=0)
    theta, _ = procrustes_2d(xd, xk)
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    moved = ad @ rot.T
    r = (ak - moved).reshape(-1)
    centre = np.eye(n) - 1.0 / n  # the centring, per axis
    M = np.hstack([np.kron(centre, np.eye(2)), -np.kron(centre, rot)])
    cols = np.concatenate([ck, cd])
    Sigma = M @ state.P[np.ix_(cols, cols)] @ M.T + tree_sd_m**2 * (M @ M.T)
    # an orthonormal basis of the residuals without the common translation
    Q = np.linalg.svd(np.kron(centre, np.eye(2)))[0][:, : 2 * n - 2]
    g = Q.T @ np.stack([-moved[:, 1], moved[:, 0]], axis=1).reshape(-1)
    L = np.linalg.cholesky(Q.T @ Sigma @ Q)
    v, w = np.linalg.solve(L, Q.T @ r), np.linalg.solve(L, g)
    nis = float(v @ v - (w @ v) ** 2 / (w @ w))
    c = xd.mean(axis=0)
    return nis, np.array([*(xk.mean(axis=0) - c), theta]), c


def free_rigid_motion(state: Filter, landmark_ids, center, cov: np.ndarray, shares=None) -> None:
    """Let the vehicle and these landmarks move together by an unknown rigid motion
    (tx, ty, theta about `center`) of covariance cov (3, 3): P += B cov B^T, with B the
    motion's Jacobian on their rows (the other landmarks' rows are 0).

    shares: (L,) in [0, 1], or None (all 1): the motion grew as a random walk, and the
    landmark with share f moved by the part accumulated when it was mapped, f of it (the
    vehicle: all of it). Two rows with shares f, g then share min(f, g) cov:
    P += sum_k (f_k - f_(k-1)) B_k cov B_k^T over the distinct shares f_1 < ... < f_K,
    with B_k on the rows whose share is at least f_k."""
    state.restore_copies()  # the pass offsets' anchors first (`slam.pass_state`)
    ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
    pos = np.array([state.index_of(int(i)) for i in ids], dtype=np.int64)
    f = np.ones(ids.size) if shares is None else np.asarray(shares, dtype=np.float64)
    if f.shape != ids.shape or not np.all((f >= 0.0) & (f <= 1.0)):
        raise SlamError("free_rigid_motion.shares: one in [0, 1] per landmark")
    xy_rows = np.concatenate([[0], 3 + 2 * pos])
    f = np.concatenate([[1.0], f])
    B = np.zeros((state.dim, 3))
    B[xy_rows, 0] = B[xy_rows + 1, 1] = 1.0
    B[xy_rows, 2] = -(state.x[xy_rows + 1] - center[1])
    B[xy_rows + 1, 2] = state.x[xy_rows] - center[0]
    B[2, 2] = 1.0
    lam, V = np.linalg.eigh(np.asarray(cov, dtype=np.float64))
    L = V * np.sqrt(np.maximum(lam, 0.0))  # L L^T = cov (cov may be singular)
    row_share = np.zeros(state.dim)
    row_share[xy_rows] = row_share[xy_rows + 1] = f
    row_share[2] = 1.0
    levels = np.unique(f[f > 0.0])
    steps = np.diff(np.concatenate([[0.0], levels]))
    G = np.hstack(
        [np.sqrt(w) * ((row_share >= lv)[:, None] * B) @ L for lv, w in zip(levels, steps)]
    )
    P = state.P
    P += G @ G.T
    P[:] = 0.5 * (P + P.T)


def move_rigidly(state: Filter, theta: float, t: np.ndarray) -> None:
    """Move the whole estimate by one rigid motion (p -> R(theta) p + t for the vehicle's
    and every landmark's position, theta added to the heading): a change of the world
    frame, which nothing observes. P -> J P J^T (J: R(theta) on each position's rows), and
    the first estimates move with it, so the filter is the same filter in the new frame. The
    hidden copies (the pass offsets' anchors, `slam.pass_state`) are positions too and move
    with the landmarks: a pass goes on through a change of frame."""
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    t = np.asarray(t, dtype=np.float64).reshape(2)
    xy = np.concatenate([[0], 3 + 2 * np.arange((state.dim - 3) // 2)])
    pts = np.stack([state.x[xy], state.x[xy + 1]], axis=1) @ R.T + t
    state.x[xy], state.x[xy + 1] = pts[:, 0], pts[:, 1]
    state.x[2] = float(wrap_angle(state.x[2] + theta))
    _rotate_positions(state.P, c, s)  # J P J^T, J block diagonal (P mirrored, both written)
    state.first_xy = state.first_xy @ R.T + t
    state.prior_pose = np.array(
        [*(R @ state.prior_pose[:2] + t), wrap_angle(state.prior_pose[2] + theta)]
    )


@intrinsic
def _fma(typingctx, a, b, c):
    """a b + c rounded once (LLVM's fma), for kernels that must give the bits of a BLAS
    kernel built on fused multiply-adds."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


@njit(cache=True)
def _rotate_positions(P: np.ndarray, c: float, s: float) -> None:
    """P <- J P J^T in place, J = R(theta) (c = cos theta, s = sin theta) on the rows of every
    position (the pose's x, y and each 2-D slot after it), identity on the heading: in one
    pass over P's rows, each row pair rotated, then its column pairs. The same rounding as
    the numpy form it replaced (the rows of each pair by R @ P[a:a + 2, :], then the columns
    by P[:, a:a + 2] @ R.T, with OpenBLAS, whose kernels sum each entry's two products as
    fma(second, ., first) in the order of k): the same bits, where that pass read and wrote
    the whole matrix twice, the second time by columns. Loops bounded by P's size."""
    d = P.shape[0]
    row0 = np.empty(d)
    row1 = np.empty(d)
    for a in range(d):
        if a == 2 or (a > 2 and (a - 3) % 2) or a == 1:
            continue  # a pair's second row (or the heading, done below)
        for j in range(d):  # rows a, a + 1: R @ P[a:a + 2, :]
            p0, p1 = P[a, j], P[a + 1, j]
            row0[j] = _fma(-s, p1, c * p0)
            row1[j] = _fma(c, p1, s * p0)
        _rotate_columns(row0, c, s)
        _rotate_columns(row1, c, s)
        for j in range(d):
            P[a, j], P[a + 1, j] = row0[j], row1[j]
    for j in range(d):  # the heading's row: its columns only
        row0[j] = P[2, j]
    _rotate_columns(row0, c, s)
    for j in range(d):
        P[2, j] = row0[j]


@njit(cache=True)
def _rotate_columns(row: np.ndarray, c: float, s: float) -> None:
    """One row of Q @ R.T on every position's column pair (columns 0, 1, then 3, 4, ...)."""
    d = row.size
    for b in range(d):
        if b == 2 or (b > 2 and (b - 3) % 2) or b == 1:
            continue
        q0, q1 = row[b], row[b + 1]
        row[b] = _fma(q1, -s, q0 * c)
        row[b + 1] = _fma(q1, c, q0 * s)


def _pair_constraint(state: Filter, keep_ids, drop_ids, sigma_m: float):
    """(d (q,), H P (q, dim), S (q, q), keep columns, drop columns) of the constraint
    x_keep - x_drop = 0 over the pairs (q = 2 x pairs)."""
    keep = np.asarray(keep_ids, dtype=np.int64).reshape(-1)
    drop = np.asarray(drop_ids, dtype=np.int64).reshape(-1)
    if keep.size != drop.size or not keep.size:
        raise SlamError("merge_landmarks: keep_ids and drop_ids must pair up, at least one")
    ids = np.concatenate([keep, drop])
    if np.unique(ids).size != ids.size:
        raise SlamError("merge_landmarks: a landmark appears twice among the pairs")
    pk = np.array([state.index_of(int(i)) for i in keep], np.int64)
    pd = np.array([state.index_of(int(i)) for i in drop], np.int64)
    ck = ((3 + 2 * pk)[:, None] + np.arange(2)).reshape(-1)
    cd = ((3 + 2 * pd)[:, None] + np.arange(2)).reshape(-1)
    HP = state.rows(ck) - state.rows(cd)  # P[ck] - P[cd], P not mirrored for it
    S = HP[:, ck] - HP[:, cd] + sigma_m**2 * np.eye(ck.size)
    return state.x[ck] - state.x[cd], HP, 0.5 * (S + S.T), ck, cd
