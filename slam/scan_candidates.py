"""The single-scan association's inputs in one numba call (`slam.map_managers.TentativeMap`):
which landmarks and tentatives can be in view, which measurements gate with something at the
new-feature gate, and the sub-problem on the candidates that do; and, for loop closure's
revisit detection, the old landmarks in view and the spread of their predictions
(`revisit_spread`).

The same operations as the numpy code it replaced (`se2.observe`, `View.contains`, the
candidates' [pose, point] covariances read from P's lower triangle, `project_blocks`, the
gate's `association.pair_d2`, `sub_problem`), in the same order, so the run is the same to
the bit; one call a scan in place of some forty array operations, whose per-call cost was most
of the association step's. Every loop runs over the rows of its arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from association.gating import pair_d2
from slam.se2 import observe_kernel, observe_within

__all__ = ["project_blocks", "revisit_spread", "scan_candidates", "sub_problem", "view_bounds"]


def view_bounds(view) -> tuple[float, float, bool, float]:
    """(bearing low, bearing high, every bearing in view, range high) of a `View` with its
    margins, as `View.contains` compares them (rad, rad, bool, m)."""
    fov0, fov1 = view.fov
    m_rad, m_m = view.margin_rad, view.margin_m
    every = fov1 - fov0 + 2 * m_rad >= 2 * math.pi
    return (fov0 - m_rad, fov1 + m_rad, bool(every), view.max_range + m_m)


@njit(cache=True)
def _in_view(z_hat, lo, hi, every, r_max):
    """`View.contains(z_hat)` (margins on): (n,) bool."""
    n = z_hat.shape[0]
    out = np.empty(n, np.bool_)
    for i in range(n):
        b = z_hat[i, 1]
        out[i] = (every or (b >= lo and b <= hi)) and z_hat[i, 0] <= r_max
    return out


@njit(cache=True)
def _put_row(out, k, src, i):
    """out[k] = src[i] for 2-d arrays, element by element. These kernels assign no array to an
    array's slice: numba compiles that assignment's shape-mismatch error message (f-strings,
    str.join, int to str) once per process and per rank, about 5 s of CPU in every process that
    compiles a kernel holding one (lab notebook, 2026-11-29). Rows of another length raise (a
    constant message: cheap to compile), as the slice's assignment did."""
    if src.shape[1] != out.shape[1]:
        raise ValueError("_put_row: the rows differ in length")
    for q in range(src.shape[1]):
        out[k, q] = src[i, q]


@njit(cache=True)
def _put_block(out, k, src, i):
    """out[k] = src[i] for 3-d arrays, element by element (see `_put_row`)."""
    if src.shape[1] != out.shape[1] or src.shape[2] != out.shape[2]:
        raise ValueError("_put_block: the blocks differ in shape")
    for r in range(src.shape[1]):
        for q in range(src.shape[2]):
            out[k, r, q] = src[i, r, q]


@njit(cache=True)
def _sym(P, r, c):
    """P[r, c] of a symmetric P kept in its lower triangle."""
    return P[r, c] if r >= c else P[c, r]


@njit(cache=True)
def scan_candidates(
    P, pose, lm_xy, hidden, tent_xy, tent_cov, sensor, sensor_yaw, z, R, usable, bounds, gate
):
    """The association step's work before its associator (`TentativeMap.associate`).

    P (d, d): the filter's covariance (its lower triangle read); pose (3,); lm_xy (n, 2) the
    landmarks; hidden (n,) bool those it must not pair; tent_xy (t, 2), tent_cov (t, 2, 2) the
    tentatives; sensor: `se2.sensor_numbers`'s four numbers, sensor_yaw the laser's yaw;
    z (m, 2), R (m, 2, 2), usable (m,) bool the measurements; bounds: `view_bounds`; gate: the
    new-feature gate's chi-square threshold.

    Returns (lm_idx, t_idx, use, ambiguous, cand, zh_cand, H, P_sub): the landmarks and
    tentatives in view (state positions, tentative indices), the usable measurements'
    indices, each measurement gated with something (m,), the candidates that gate with a
    measurement (indices into [landmarks in view, tentatives in view]), their predictions,
    and the sub-problem H (nc, 2, 3 + 2 nc), P_sub on [pose, candidate landmarks, candidate
    tentatives] (`sub_problem`)."""
    lo, hi, every, r_max = bounds
    px, py, dpx, dpy = sensor
    th = pose[2]
    z_lm, H_lm = observe_within(lm_xy, px, py, dpx, dpy, th, sensor_yaw, r_max)
    z_t, H_t = observe_kernel(tent_xy, px, py, dpx, dpy, th, sensor_yaw)
    lm_idx = np.flatnonzero(_in_view(z_lm, lo, hi, every, r_max) & ~hidden)
    t_idx = np.flatnonzero(_in_view(z_t, lo, hi, every, r_max))
    n_l = lm_idx.size
    n = n_l + t_idx.size
    m = z.shape[0]
    use = np.flatnonzero(usable)
    ambiguous = np.zeros(m, np.bool_)
    zh = np.empty((n, 2))
    H5 = np.empty((n, 2, 5))
    C5 = np.zeros((n, 5, 5))
    for a in range(n):
        src_z, src_H, i = (z_lm, H_lm, lm_idx[a]) if a < n_l else (z_t, H_t, t_idx[a - n_l])
        zh[a, 0], zh[a, 1] = src_z[i, 0], src_z[i, 1]
        _put_block(H5, a, src_H, i)
        for u in range(3):
            for v in range(3):
                C5[a, u, v] = _sym(P, u, v)
        if a < n_l:  # the landmark's [pose, point] block of P
            for u in range(5):
                cu = u if u < 3 else 3 + 2 * i + (u - 3)
                for v in range(5):
                    cv = v if v < 3 else 3 + 2 * i + (v - 3)
                    C5[a, u, v] = _sym(P, cu, cv)
        else:  # a tentative: its own covariance, no correlation with the pose
            for u in range(2):
                for v in range(2):
                    C5[a, 3 + u, 3 + v] = tent_cov[i, u, v]
    z_use = np.empty((use.size, 2))
    R_use = np.empty((use.size, 2, 2))
    for r in range(use.size):
        _put_row(z_use, r, z, use[r])
        _put_block(R_use, r, R, use[r])
    S = project_blocks(H5, C5)
    any_feat = np.zeros(n, np.bool_)
    if use.size and n:
        for r in range(use.size):
            for j in range(n):
                g = pair_d2(z_use, R_use, zh, S, r, j)
                if g[9] and g[0] <= gate:
                    ambiguous[use[r]] = True
                    any_feat[j] = True
    cand = np.flatnonzero(any_feat)
    zh_cand = np.empty((cand.size, 2))
    for a in range(cand.size):
        _put_row(zh_cand, a, zh, cand[a])
    # the sub-state [pose, candidate landmarks, candidate tentatives]
    c_lm = cand[cand < n_l]
    c_t = t_idx[cand[cand >= n_l] - n_l]
    sub = np.empty(3 + 2 * c_lm.size, np.int64)
    sub[0], sub[1], sub[2] = 0, 1, 2
    for a in range(c_lm.size):
        sub[3 + 2 * a] = 3 + 2 * lm_idx[c_lm[a]]
        sub[4 + 2 * a] = 4 + 2 * lm_idx[c_lm[a]]
    P_lm = np.empty((sub.size, sub.size))
    for a in range(sub.size):
        for b in range(sub.size):
            P_lm[a, b] = _sym(P, sub[a], sub[b])
    H, P_sub = sub_problem(H5, cand, P_lm, tent_cov[c_t])
    return lm_idx, t_idx, use, ambiguous, cand, zh_cand, H, P_sub


@njit(cache=True)
def project_blocks(H5, C5):
    """(n, 2, 2) H5_j C5_j H5_j^T of each candidate's [pose, point] block (H5 (n, 2, 5),
    C5 (n, 5, 5))."""
    n = H5.shape[0]
    out = np.zeros((n, 2, 2))
    for t in range(n):
        for i in range(2):
            for u in range(2):
                acc = 0.0
                for j in range(5):
                    hij = H5[t, i, j]
                    for k in range(5):
                        acc += hij * C5[t, j, k] * H5[t, u, k]
                out[t, i, u] = acc
    return out


@njit(cache=True)
def sub_problem(H5, cand, P_lm, cov_t):
    """The association's sub-problem on the state [pose, candidate landmarks, candidate
    tentatives]: H (nc, 2, 3 + 2 nc), candidate j's point in columns 3 + 2 j, 4 + 2 j, and its
    covariance P_sub, which is P_lm (the pose and the candidate landmarks, from the filter)
    followed by the tentatives' own 2 x 2 blocks cov_t (no correlation with anything). The
    candidates `cand` index H5, landmarks first."""
    nc = cand.size
    d = 3 + 2 * nc
    H = np.zeros((nc, 2, d))
    for j in range(nc):
        c = cand[j]
        for r in range(2):
            for q in range(3):
                H[j, r, q] = H5[c, r, q]
            H[j, r, 3 + 2 * j] = H5[c, r, 3]
            H[j, r, 4 + 2 * j] = H5[c, r, 4]
    P_sub = np.zeros((d, d))
    n_sub = P_lm.shape[0]
    for r in range(n_sub):  # element by element: see `_put_row`
        for q in range(n_sub):
            P_sub[r, q] = P_lm[r, q]
    for t in range(cov_t.shape[0]):
        a = n_sub + 2 * t
        for r in range(2):
            for q in range(2):
                P_sub[a + r, a + q] = cov_t[t, r, q]
    return H, P_sub


@njit(cache=True)
def revisit_spread(P, lm_xy, seen_s, before_s, sensor, sensor_yaw, heading, bounds):
    """Loop closure's revisit detection before its gate (`slam.closure.LoopCloser.revisit`):
    the landmarks last seen before `before_s` (seen_s (n,) s, each landmark's last sighting)
    whose predictions are in view (`bounds`: `view_bounds`), as state positions (c,), and the
    largest metric sd of each one's predicted measurement (c,), sqrt(max(S_rr, r^2 S_bb))
    with S = H5 C5 H5^T on its [pose, point] block (`project_blocks`; with numpy 2.4 the same
    bits as the np.einsum it replaced, which numpy does not promise across versions).
    P (d, d): its lower triangle read; lm_xy (n, 2); sensor: `se2.sensor_numbers`."""
    lo, hi, every, r_max = bounds
    px, py, dpx, dpy = sensor
    old = np.flatnonzero(seen_s < before_s)
    m = np.empty((old.size, 2))
    for a in range(old.size):
        m[a, 0], m[a, 1] = lm_xy[old[a], 0], lm_xy[old[a], 1]
    z_hat, H5_all = observe_within(m, px, py, dpx, dpy, heading, sensor_yaw, r_max)
    keep = np.flatnonzero(_in_view(z_hat, lo, hi, every, r_max))
    cand = old[keep]
    H5 = np.empty((cand.size, 2, 5))
    C5 = np.empty((cand.size, 5, 5))
    for a in range(cand.size):
        _put_block(H5, a, H5_all, keep[a])
        i = cand[a]
        for u in range(5):
            cu = u if u < 3 else 3 + 2 * i + (u - 3)
            for v in range(5):
                cv = v if v < 3 else 3 + 2 * i + (v - 3)
                C5[a, u, v] = _sym(P, cu, cv)
    S = project_blocks(H5, C5)
    sd = np.empty(cand.size)
    for a in range(cand.size):
        r = z_hat[keep[a], 0]
        s_r, s_b = S[a, 0, 0], r * r * S[a, 1, 1]
        sd[a] = math.sqrt(s_r if (s_r >= s_b or s_r != s_r) else s_b)  # np.maximum's
    return cand, sd
