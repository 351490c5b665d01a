"""The joint compatibility check of one scan's pairings (Neira and Tardos, IEEE T-RA 17(6),
2001): the pairings share the vehicle's pose, so they can be jointly incompatible although
each passes its individual gate.

Given the stacked innovation nu (k, 2) of k pairings and its joint covariance S (2k, 2k)
(block (a, b) H_a P H_b^T, plus R_a on the diagonal blocks), the joint Mahalanobis distance
D2 = nu^T S^-1 nu is tested against chi2_{2k}(gate_prob), the probability of the individual
gates (no new number). While it fails, the pairing whose removal lowers D2 the most is dropped.
Without pairing a, D2 falls by a^T (S^-1)_aa^-1 a with a = (S^-1 nu)_a, the block of S^-1 nu
(the Schur complement of the partitioned inverse), so each step costs one Cholesky factor of S.
This is a greedy pruning of the one hypothesis the associator chose, not JCBB's search over
hypotheses (`association.jcbb`).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from association.errors import AssociationError

__all__ = ["JointCheck", "joint_check"]


class JointCheck(NamedTuple):
    """keep (k,) bool: the pairings kept; d2_before, d2_after: the joint Mahalanobis distance
    of all k pairings and of those kept (0 when none is); dropped: the pairings dropped, in the
    order they were dropped."""

    keep: np.ndarray
    d2_before: float
    d2_after: float
    dropped: tuple[int, ...]


@lru_cache(maxsize=64)
def _gate(gate_prob: float, dof: int) -> float:
    """chi2_dof(gate_prob): the joint gate of dof / 2 pairings (JCBB's, `association.jcbb`)."""
    from scipy.stats import chi2

    return float(chi2.ppf(gate_prob, dof))


def _d2_and_drop_gain(nu: np.ndarray, S: np.ndarray) -> tuple[float, np.ndarray]:
    """(D2, (k,) the fall of D2 without each pairing) of innovations nu (2k,), S (2k, 2k)."""
    c = cho_factor(S, lower=True)
    a = cho_solve(c, nu)  # S^-1 nu
    # The fall of D2 without pairing j needs the 2x2 diagonal block j of S^-1 itself (module
    # doc), for every j: every column of S^-1 is used, so it is formed, from the same factor.
    Si = cho_solve(c, np.eye(S.shape[0]))
    k = nu.size // 2
    gain = np.empty(k)
    for j in range(k):
        b = slice(2 * j, 2 * j + 2)
        gain[j] = float(a[b] @ np.linalg.solve(Si[b, b], a[b]))
    return float(nu @ a), gain


def joint_check(nu, S, gate_prob: float) -> JointCheck:
    """The pairings of one scan kept by the joint test (module doc): nu (k, 2) innovations
    (z - z_hat, bearing wrapped), S (2k, 2k) their joint covariance, symmetric positive
    definite; gate_prob in (0, 1). Raises `AssociationError` for shapes that do not agree, values
    that are not finite or an S that is not positive definite."""
    nu = np.asarray(nu, dtype=np.float64).reshape(-1)
    S = np.asarray(S, dtype=np.float64)
    k = nu.size // 2
    if nu.size % 2 or S.shape != (2 * k, 2 * k):
        raise AssociationError(
            f"joint_check: nu must be (k, 2) and S (2k, 2k), got {nu.size} values and {S.shape}"
        )
    if not (np.isfinite(nu).all() and np.isfinite(S).all()):
        raise AssociationError("joint_check: nu and S must be finite")
    if not 0.0 < gate_prob < 1.0:
        raise AssociationError(f"joint_check: gate_prob must be in (0, 1), got {gate_prob!r}")
    keep = np.ones(k, bool)
    if k == 0:
        return JointCheck(keep, 0.0, 0.0, ())
    dropped, d2_before = [], None
    try:
        while keep.any():
            rows = np.repeat(keep, 2)
            d2, gain = _d2_and_drop_gain(nu[rows], S[np.ix_(rows, rows)])
            d2_before = d2 if d2_before is None else d2_before
            if d2 <= _gate(float(gate_prob), 2 * int(keep.sum())):
                break
            j = int(np.flatnonzero(keep)[int(np.argmax(gain))])
            keep[j] = False
            dropped.append(j)
    except np.linalg.LinAlgError:
        raise AssociationError("joint_check: S is not positive definite") from None
    return JointCheck(keep, d2_before, d2 if keep.any() else 0.0, tuple(dropped))
