"""Joint compatibility branch and bound (Neira and Tardos, IEEE T-RA 17(6), 2001).

Searches the interpretation tree for the hypothesis with the most pairings whose joint
innovation passes the joint chi-square gate; ties are broken by the smaller joint Mahalanobis
distance (Neira and Tardos keep the first one found; breaking ties makes the answer independent
of the search order).

- Joint covariance of the pairings {(i_1, j_1), ..., (i_k, j_k)}: block (a, b) is
  H_ja P H_jb^T, plus R_ia on the diagonal blocks; computed for the individually compatible
  features only, by the sparse kernel in `association.inputs`.
- Joint Mahalanobis distance D2 = nu^T S^-1 nu is kept incrementally: the Cholesky factor L of
  S and the whitened innovation y = L^-1 nu are extended by one 2x2 block per pairing
  (Schur complement), so each node costs O(k^2) instead of a fresh O(k^3) solve.
- Joint gate: D2 <= chi2_{2k}(gate_prob).
- Search order: measurements in canonical order (lexicographic on the data), each measurement's
  candidate features in increasing individual d2, the "unpaired" branch last. Bound: a branch is
  cut when its pairings plus the measurements still to visit cannot beat the best (or can only
  tie it with a larger D2; D2 never decreases along a branch).
- Node budget: at most `max_nodes` nodes (visits of the interpretation tree) are expanded.
  Fallback when the budget runs out: the best hypothesis found so far. Because the search is
  depth-first with the nearest candidate first, the first leaf is reached after at most m + 1
  nodes and is the sequential nearest-neighbour hypothesis restricted to jointly compatible
  pairings, so the fallback is never empty-handed. `budget_exhausted` reports it.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit

from association.errors import AssociationError
from association.inputs import Prepared, cross_cov

__all__ = ["jcbb_assign", "JCBBStats", "DEFAULT_MAX_NODES"]

DEFAULT_MAX_NODES = 20_000


@lru_cache(maxsize=64)
def _joint_gates(gate_prob: float, kmax: int) -> tuple[float, ...]:
    from scipy.stats import chi2

    return (0.0,) + tuple(float(v) for v in chi2.ppf(gate_prob, 2 * np.arange(1, kmax + 1)))


class JCBBStats:
    """Search statistics of one call: nodes expanded, whether the budget ran out, best D2."""

    __slots__ = ("nodes", "budget_exhausted", "joint_d2")

    def __init__(self) -> None:
        self.nodes = 0
        self.budget_exhausted = False
        self.joint_d2 = 0.0


class _Branch(NamedTuple):
    """The branch of the interpretation tree being searched, its arrays extended in place."""

    L: np.ndarray  # (2M, 2M) lower Cholesky factor of the joint innovation covariance
    y: np.ndarray  # (2M,) whitened joint innovation L^-1 nu
    C: np.ndarray  # (c, c, 2, 2) cross-covariances H_a P H_b^T of the gated features
    fl_stack: np.ndarray  # (M,) int64 the branch's features (local indices), in pairing order


@njit(cache=True)
def _extend_kernel(branch, k, fl, nu, S_new):
    """Add pairing number k (feature fl, innovation nu, covariance S_new) to the branch, a
    `_Branch` whose rows 0..2k-1 of L and y and entries 0..k-1 of fl_stack are valid
    (as a plain tuple: numba's dispatcher types a plain tuple in C but a NamedTuple in Python,
    about 1.5 us a call). Writes rows 2k, 2k+1 and returns the increment of the joint
    Mahalanobis distance, or -1.0 if the extended covariance is not positive definite.
    """
    L, y, C, fl_stack = branch
    n = 2 * k
    # B = L^-1 Cx by forward substitution, Cx[2a + r, s] = C[fl_stack[a], fl, r, s]
    B = np.empty((n, 2))
    for row in range(n):
        a, r = row // 2, row % 2
        for s in range(2):
            acc = C[fl_stack[a], fl, r, s]
            for t in range(row):
                acc -= L[row, t] * B[t, s]
            B[row, s] = acc / L[row, row]
    # Schur complement S_new - B^T B and the new whitened innovation nu - B^T y
    s00, s01, s11 = S_new[0, 0], 0.5 * (S_new[0, 1] + S_new[1, 0]), S_new[1, 1]
    v0, v1 = nu[0], nu[1]
    for t in range(n):
        s00 -= B[t, 0] * B[t, 0]
        s01 -= B[t, 0] * B[t, 1]
        s11 -= B[t, 1] * B[t, 1]
        v0 -= B[t, 0] * y[t]
        v1 -= B[t, 1] * y[t]
    if not s00 > 0.0:
        return -1.0
    l00 = math.sqrt(s00)
    l10 = s01 / l00
    q = s11 - l10 * l10
    if not q > 0.0:
        return -1.0
    l11 = math.sqrt(q)
    for t in range(n):
        L[n, t] = B[t, 0]
        L[n + 1, t] = B[t, 1]
    L[n, n], L[n, n + 1], L[n + 1, n], L[n + 1, n + 1] = l00, 0.0, l10, l11
    y0 = v0 / l00
    y1 = (v1 - l10 * y0) / l11
    y[n], y[n + 1] = y0, y1
    return y0 * y0 + y1 * y1


def _candidates(prep: Prepared, local: np.ndarray, C: np.ndarray):
    """The search's levels: the measurements with a gated pairing, in canonical order (m',),
    and each one's candidate pairings (fl, nu, S): the feature's local index fl (into C, the
    (c, c, 2, 2) cross-covariances; local: (n,) maps features to it), the innovation nu (2,) and
    its covariance S = C[fl, fl] + R_i (2, 2), in increasing individual d2 (ties: canonical
    feature order)."""
    meas = np.unique(prep.pair_i)
    meas = meas[np.argsort(prep.rank_meas[meas])]
    cands: list[list[tuple[int, np.ndarray, np.ndarray]]] = []
    for i in meas:
        ks = np.flatnonzero(prep.pair_i == i)
        ks = ks[np.lexsort((prep.rank_feat[prep.pair_j[ks]], prep.d2[ks]))]
        fls = local[prep.pair_j[ks]]
        cands.append([(int(f), prep.nu[k], C[f, f] + prep.R[i]) for f, k in zip(fls, ks)])
    return meas, cands


def jcbb_assign(prep: Prepared, gate_prob: float, max_nodes: int = DEFAULT_MAX_NODES):
    """Assignment (m,) int (feature index or -1) and `JCBBStats`."""
    if not isinstance(max_nodes, (int, np.integer)) or max_nodes < 1:
        raise AssociationError(f"max_nodes: must be a positive integer, got {max_nodes!r}")
    stats = JCBBStats()
    out = np.full(prep.m, -1, np.int64)
    if prep.pair_i.size == 0:
        return out, stats
    feats = np.unique(prep.pair_j)
    local = np.full(prep.n, -1, np.int64)
    local[feats] = np.arange(feats.size)
    C = cross_cov(prep.H, prep.P, feats)  # (c, c, 2, 2)

    meas, cands = _candidates(prep, local, C)
    M = meas.size
    gates = _joint_gates(float(gate_prob), M)
    used = np.zeros(feats.size, bool)
    chosen = np.full(M, -1, np.int64)  # local feature per level, -1 = unpaired
    best = {"n": 0, "d2": 0.0, "pairs": chosen.copy(), "leaf": False}
    # The Cholesky factor and whitened innovation of the current branch: rows 0..2k-1 are valid
    # at depth k (pairings); a child overwrites rows 2k, 2k+1 only, so backtracking is free.
    L = np.zeros((2 * M, 2 * M))
    y = np.zeros(2 * M)
    fl_stack = np.zeros(M, np.int64)
    branch = tuple(_Branch(L, y, C, fl_stack))

    def extend(k: int, fl: int, nu: np.ndarray, S_new: np.ndarray) -> float | None:
        inc = _extend_kernel(branch, k, fl, nu, S_new)
        return None if inc < 0.0 else inc

    def better(n: int, d2: float) -> bool:
        return n > best["n"] or (n == best["n"] and d2 < best["d2"])

    def rec(level: int, npair: int, d2: float) -> None:
        stats.nodes += 1
        if stats.nodes > max_nodes and best["leaf"]:
            stats.budget_exhausted = True
            return
        if level == M:
            if better(npair, d2) or not best["leaf"]:
                best.update(n=npair, d2=d2, pairs=chosen.copy(), leaf=True)
            return
        remaining = M - level - 1
        for fl, nu, S_new in cands[level]:
            if used[fl]:
                continue
            if best["leaf"] and npair + 1 + remaining < best["n"]:
                break
            inc = extend(npair, fl, nu, S_new)
            if inc is None:
                continue
            d2n = d2 + inc
            if d2n > gates[npair + 1]:
                continue  # joint compatibility test
            if best["leaf"] and not better(npair + 1 + remaining, d2n):
                continue  # cannot beat the best even with every remaining pairing
            used[fl] = True
            chosen[level] = fl
            fl_stack[npair] = fl
            rec(level + 1, npair + 1, d2n)
            used[fl] = False
            chosen[level] = -1
            if stats.budget_exhausted:
                return
        if not best["leaf"] or better(npair + remaining, d2):
            rec(level + 1, npair, d2)

    rec(0, 0, 0.0)
    for lvl, fl in enumerate(best["pairs"]):
        if fl >= 0:
            out[meas[lvl]] = feats[fl]
    stats.joint_d2 = float(best["d2"])
    return out, stats
