"""Individual compatibility gating: which measurement may be which feature, by the chi-square
test on each pair's innovation. The one home of the gate's arithmetic: `association.prepare`
(every associator) and the SLAM loop's candidate selection both use `pair_d2`.

For measurement i and feature j: nu_ij = z_i - z_hat_j (bearing wrapped into (-pi, pi]),
S_ij = S_j + R_i with S_j = H_j P H_j^T the feature's own projected covariance, and
d2_ij = nu_ij^T S_ij^-1 nu_ij by the 2 x 2 Cholesky factor of S_ij (`inputs.chol2_solve`'s
arithmetic, operation for operation, so every path gets the same numbers to the bit).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["gate_matrix", "pair_d2"]


@njit(cache=True, inline="always")
def pair_d2(z, R, z_hat, S_feat, i, j):
    """(d2, nu0, nu1, s00, s01, s10, s11, l11, l22, ok) of measurement i and feature j; ok is
    False where S_ij is not positive definite (d2 is then NaN)."""
    nu0 = z[i, 0] - z_hat[j, 0]
    nu1 = np.pi - np.mod(np.pi - (z[i, 1] - z_hat[j, 1]), 2.0 * np.pi)  # `wrap_angle`
    s00 = S_feat[j, 0, 0] + R[i, 0, 0]
    s01 = S_feat[j, 0, 1] + R[i, 0, 1]
    s10 = S_feat[j, 1, 0] + R[i, 1, 0]
    s11 = S_feat[j, 1, 1] + R[i, 1, 1]
    s21 = 0.5 * (s10 + s01)
    l11 = math.sqrt(s00) if s00 >= 0.0 else math.nan
    l21 = s21 / l11
    q = s11 - l21 * l21
    l22 = math.sqrt(q) if q >= 0.0 else math.nan
    ok = s00 > 0.0 and q > 0.0
    if not ok:
        return math.nan, nu0, nu1, s00, s01, s10, s11, l11, l22, False
    y1 = nu0 / l11
    y2 = (nu1 - l21 * y1) / l22
    return y1 * y1 + y2 * y2, nu0, nu1, s00, s01, s10, s11, l11, l22, True


@njit(cache=True)
def _gate_matrix(z, R, z_hat, S_feat, gate):
    m, n = z.shape[0], z_hat.shape[0]
    out = np.zeros((m, n), np.bool_)
    for i in range(m):
        for j in range(n):
            r = pair_d2(z, R, z_hat, S_feat, i, j)
            out[i, j] = r[9] and r[0] <= gate
    return out


def gate_matrix(z, R, z_hat, S_feat, gate: float) -> np.ndarray:
    """(m, n) bool: measurement i (z (m, 2) [range, bearing], noise R (m, 2, 2)) passes the
    individual gate d2 <= `gate` of feature j (prediction z_hat (n, 2), projected covariance
    S_feat (n, 2, 2)). A pair whose S is not positive definite does not pass. Inputs are taken
    as valid (finite, the shapes above): the trusted path of the SLAM loop."""
    f = np.ascontiguousarray
    return _gate_matrix(
        f(z, np.float64), f(R, np.float64), f(z_hat, np.float64), f(S_feat, np.float64), gate
    )
