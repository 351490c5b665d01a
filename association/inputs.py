"""Input checking, innovations and individual gating shared by every association method.

Conventions (all methods):
- A measurement is (range_m, bearing_rad); bearing differences are wrapped to (-pi, pi].
- Feature j's predicted measurement is z_hat[j] with Jacobian H[j] (2, d) with respect to the
  d-dimensional state whose covariance is P (d, d). Pairing measurement i with feature j has
  innovation nu_ij = z_i - z_hat_j and innovation covariance S_ij = H_j P H_j^T + R_i.
- Individual gate: d2_ij = nu_ij^T S_ij^-1 nu_ij <= chi2_2(gate_prob) = -2 ln(1 - gate_prob)
  (the chi-square quantile with 2 degrees of freedom has this closed form).

`H` is usually very sparse (a range-bearing Jacobian touches the 3 pose and 2 landmark columns),
so `H_j P H_j^T` and the cross-covariances `H_a P H_b^T` are computed by numba kernels that visit
only the non-zero columns of each H_j (`_project_cov_kernel`, `_cross_cov_kernel`); their
plain-numpy twins (`project_cov_numpy`, `cross_cov_numpy`) are the test oracles.

P is checked where it is used: every principal block P[nz_j, nz_j] on the non-zero columns of a
feature's Jacobian must be symmetric and positive semi-definite (blocks of up to
`_MAX_PSD_BLOCK` columns get an exact check; larger, dense Jacobians only get the projected
check H_j P H_j^T >= 0). A full eigen-decomposition of a 400 x 400 P would cost more than the
whole association.

`prepare(..., validate=False)` skips every check, for callers whose inputs are valid by
construction (the SLAM loop, thousands of small problems a run, where the checks cost more than
the association); it computes the same numbers as the checked path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from association.errors import AssociationError
from association.gating import pair_d2

__all__ = [
    "wrap_angle",
    "gate_threshold",
    "Prepared",
    "prepare",
    "project_cov_numpy",
    "cross_cov_numpy",
    "cross_cov",
    "chol2_solve",
    "as_float_array",
    "block_psd_ok",
    "check_finite",
]

_SYM_RTOL = 1e-8  # relative asymmetry tolerated in P and R
_PSD_RTOL = 1e-9  # eigenvalues down to -_PSD_RTOL * (largest diagonal) count as zero
_MAX_PSD_BLOCK = 16


def wrap_angle(a):
    """Angles (rad) wrapped to (-pi, pi]; works on scalars and arrays."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)


def gate_threshold(gate_prob: float, dof: int = 2) -> float:
    """chi-square quantile; closed form for 2 degrees of freedom (the individual gate)."""
    if dof == 2:
        return -2.0 * math.log1p(-gate_prob)
    from scipy.stats import chi2

    return float(chi2.ppf(gate_prob, dof))


def as_float_array(name: str, x, ndim_hint: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AssociationError(
            f"{name}: cannot be read as a float array {ndim_hint} ({exc})"
        ) from None
    return a


def check_finite(name: str, a: np.ndarray) -> None:
    # Fast path: a sum is finite only if every term is (a finite overflow to inf would only send
    # us to the exact check below).
    if a.size == 0 or math.isfinite(float(np.add.reduce(a, axis=None))):
        return
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0]
        where = tuple(int(b) for b in bad)
        raise AssociationError(f"{name}: contains NaN or inf (first at index {where})")


def chol2_solve(S: np.ndarray, nu: np.ndarray):
    """Batched 2x2 Cholesky solve: returns (d2 = nu^T S^-1 nu, ln|S|, ok) for S (..., 2, 2).

    This is np.linalg.solve specialised to 2x2 symmetric positive-definite blocks (vectorised,
    without LAPACK call overhead); `ok` is False where S is not positive definite.
    """
    s11 = S[..., 0, 0]
    s21 = 0.5 * (S[..., 1, 0] + S[..., 0, 1])
    s22 = S[..., 1, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        l11 = np.sqrt(s11)
        l21 = s21 / l11
        q = s22 - l21 * l21
        l22 = np.sqrt(q)
        ok = (s11 > 0.0) & (q > 0.0)
        y1 = nu[..., 0] / l11
        y2 = (nu[..., 1] - l21 * y1) / l22
        d2 = y1 * y1 + y2 * y2
        logdet = 2.0 * (np.log(l11) + np.log(l22))
    return d2, logdet, ok


@njit(cache=True)
def _nonzero_cols(H, j):
    d = H.shape[2]
    idx = np.empty(d, np.int64)
    q = 0
    for c in range(d):
        if H[j, 0, c] != 0.0 or H[j, 1, c] != 0.0:
            idx[q] = c
            q += 1
    return idx[:q]


@njit(cache=True)
def block_psd_ok(P, idx, tol_rel):
    """True if the principal block B = P[idx, idx] is positive semi-definite within tolerance.

    Cholesky of B + tol I with tol = tol_rel * max(diag B): succeeds for every PSD B and fails
    when B has an eigenvalue below -tol.
    """
    q = idx.shape[0]
    scale = 0.0
    for a in range(q):
        scale = max(scale, P[idx[a], idx[a]])
    tol = tol_rel * scale + 1e-300
    L = np.zeros((q, q))
    for a in range(q):
        for b in range(a + 1):
            s = 0.5 * (P[idx[a], idx[b]] + P[idx[b], idx[a]])
            for k in range(b):
                s -= L[a, k] * L[b, k]
            if a == b:
                s += tol
                if s <= 0.0:
                    return False
                L[a, a] = math.sqrt(s)
            else:
                L[a, b] = s / L[b, b]
    return True


@njit(cache=True)
def _project_one(H, P, j, idx, S):
    """S[j] = H_j P H_j^T over the columns idx of H_j (the arithmetic of both kernels below)."""
    q = idx.shape[0]
    for r in range(2):
        for s in range(r, 2):
            acc = 0.0
            for a in range(q):
                ha = H[j, r, idx[a]]
                inner = 0.0
                for b in range(q):
                    inner += P[idx[a], idx[b]] * H[j, s, idx[b]]
                acc += ha * inner
            S[j, r, s] = acc
    S[j, 1, 0] = S[j, 0, 1]


@njit(cache=True)
def _project_cov_kernel(H, P, sym_rtol, psd_rtol, max_block):
    """S[j] = H_j P H_j^T over the non-zero columns of H_j, with checks of the block of P used.

    Returns S (n, 2, 2), asym (n,) the largest relative asymmetry |P_ab - P_ba| / max|P_block|
    on each block, and psd_ok (n,) the exact PSD check of blocks of <= max_block columns.
    """
    n = H.shape[0]
    S = np.zeros((n, 2, 2))
    asym = np.zeros(n)
    psd_ok = np.ones(n, np.bool_)
    for j in range(n):
        idx = _nonzero_cols(H, j)
        q = idx.shape[0]
        big = 0.0
        worst = 0.0
        for a in range(q):
            for b in range(q):
                pab = P[idx[a], idx[b]]
                if abs(pab) > big:
                    big = abs(pab)
                if b > a:
                    dlt = abs(pab - P[idx[b], idx[a]])
                    if dlt > worst:
                        worst = dlt
        asym[j] = worst / big if big > 0.0 else 0.0
        _project_one(H, P, j, idx, S)
        if q <= max_block:
            psd_ok[j] = block_psd_ok(P, idx, psd_rtol)
    return S, asym, psd_ok


@njit(cache=True)
def _project_cov_trusted(H, P):
    """`_project_cov_kernel`'s S (n, 2, 2) without its checks (trusted inputs)."""
    n = H.shape[0]
    S = np.zeros((n, 2, 2))
    for j in range(n):
        _project_one(H, P, j, _nonzero_cols(H, j), S)
    return S


@njit(cache=True)
def _cross_cov_kernel(H, P, feats):
    """C[a, b] = H_fa P H_fb^T (c, c, 2, 2) for the features `feats`, over non-zero columns."""
    c = feats.shape[0]
    C = np.zeros((c, c, 2, 2))
    cols = []
    for a in range(c):
        cols.append(_nonzero_cols(H, feats[a]))
    for a in range(c):
        ia = cols[a]
        fa = feats[a]
        for b in range(c):
            ib = cols[b]
            fb = feats[b]
            for r in range(2):
                for s in range(2):
                    acc = 0.0
                    for u in range(ia.shape[0]):
                        hu = H[fa, r, ia[u]]
                        if hu == 0.0:
                            continue
                        inner = 0.0
                        for v in range(ib.shape[0]):
                            inner += P[ia[u], ib[v]] * H[fb, s, ib[v]]
                        acc += hu * inner
                    C[a, b, r, s] = acc
    return C


def project_cov_numpy(H: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Dense twin of the kernel: H_j P H_j^T for all j, (n, 2, 2)."""
    HP = np.einsum("nad,de->nae", H, P)
    S = np.einsum("nae,nbe->nab", HP, H)
    return 0.5 * (S + np.swapaxes(S, 1, 2))


def cross_cov_numpy(H: np.ndarray, P: np.ndarray, feats: np.ndarray) -> np.ndarray:
    """Dense twin: C[a, b] = H_fa P H_fb^T, (c, c, 2, 2)."""
    Hf = H[feats]
    return np.einsum("ard,de,bse->abrs", Hf, P, Hf)


def cross_cov(H: np.ndarray, P: np.ndarray, feats: np.ndarray) -> np.ndarray:
    """Cross-covariances of the predicted measurements of `feats`; checks the symmetry used."""
    feats = np.ascontiguousarray(feats, dtype=np.int64)
    if feats.size == 0:
        return np.zeros((0, 0, 2, 2))
    C = _cross_cov_kernel(H, P, feats)
    # C[a, b] must equal C[b, a]^T when P is symmetric on the blocks used.
    D = C - np.transpose(C, (1, 0, 3, 2))
    scale = max(float(np.abs(C).max()), 1e-300)
    if float(np.abs(D).max()) > _SYM_RTOL * scale * 10:
        raise AssociationError(
            "P: not symmetric on the cross-covariance blocks used by the features"
        )
    return C


@dataclass(frozen=True, eq=False)
class Prepared:
    """Checked inputs and the individually gated pairings of one scan (internal).

    z: (m, 2) measurements [range_m, bearing_rad]; R: (m, 2, 2) their noise covariances.
    z_hat: (n, 2) predicted measurements; S_feat: (n, 2, 2) H_j P H_j^T; H (n, 2, d), P (d, d).
    gate: the chi-square threshold used; rank_meas (m,), rank_feat (n,): canonical ranks that
        make every method independent of the order of measurements and features.
    pair_i, pair_j (k,): gated pairings sorted by (rank_meas[i], rank_feat[j]);
    nu (k, 2) innovations (bearing wrapped), S (k, 2, 2), d2 (k,), logdet_S (k,) = ln|S|.
    """

    z: np.ndarray
    R: np.ndarray
    z_hat: np.ndarray
    S_feat: np.ndarray
    H: np.ndarray
    P: np.ndarray
    gate: float
    rank_meas: np.ndarray
    rank_feat: np.ndarray
    pair_i: np.ndarray
    pair_j: np.ndarray
    nu: np.ndarray
    S: np.ndarray
    d2: np.ndarray
    logdet_S: np.ndarray

    @property
    def m(self) -> int:
        return self.z.shape[0]

    @property
    def n(self) -> int:
        return self.z_hat.shape[0]


def check_R(R, m: int, name: str = "R") -> np.ndarray:
    """R as (m, 2, 2), checked symmetric positive definite."""
    R = as_float_array(name, R, "(2, 2) or (m, 2, 2)")
    if R.shape == (2, 2):
        R = np.broadcast_to(R, (m, 2, 2))
    elif R.shape != (m, 2, 2):
        raise AssociationError(
            f"{name}: expected shape (2, 2) or (m, 2, 2) with m = {m}, got {R.shape}"
        )
    check_finite(name, R)
    if m:
        scale = np.maximum(np.abs(R).reshape(m, 4).max(axis=1), 1e-300)
        asym = np.abs(R[:, 0, 1] - R[:, 1, 0]) / scale
        if (asym > _SYM_RTOL).any():
            k = int(np.argmax(asym))
            raise AssociationError(f"{name}[{k}]: not symmetric ({R[k].tolist()})")
        _, _, ok = chol2_solve(R, np.zeros((m, 2)))
        if not ok.all():
            k = int(np.flatnonzero(~ok)[0])
            raise AssociationError(
                f"{name}[{k}]: not positive definite ({R[k].tolist()}); measurement noise "
                "must have positive variance in range and bearing"
            )
    return R


def check_measurements(name: str, z, shape_hint: str) -> np.ndarray:
    z = as_float_array(name, z, shape_hint)
    if z.ndim != 2 or z.shape[1] != 2:
        raise AssociationError(
            f"{name}: expected shape {shape_hint} [range_m, bearing_rad], got {z.shape}"
        )
    check_finite(name, z)
    if (z[:, 0] < 0).any():
        k = int(np.flatnonzero(z[:, 0] < 0)[0])
        raise AssociationError(f"{name}[{k}]: negative range {z[k, 0]!r}")
    return z


def check_gate_prob(gate_prob) -> float:
    try:
        g = float(gate_prob)
    except (TypeError, ValueError):
        raise AssociationError(
            f"gate_prob: must be a number in (0, 1), got {gate_prob!r}"
        ) from None
    if not 0.0 < g < 1.0:
        raise AssociationError(f"gate_prob: must be in (0, 1), got {gate_prob!r}")
    return g


def prepare(z, R, z_hat, H, P, gate_prob: float, *, validate: bool = True) -> Prepared:
    """Check the inputs of `associate`, compute S_j and the individually gated pairings.

    validate=False is the trusted path for callers whose inputs are valid by construction (the
    SLAM loop): z (m, 2), R (m, 2, 2) or (2, 2), z_hat (n, 2), H (n, 2, d), P (d, d) as float64
    arrays, gate_prob in (0, 1), P symmetric positive semi-definite. Nothing is checked (no
    error is raised for bad input, the answer is then undefined); for valid input the result is
    the checked path's, to the bit (the same kernels and arithmetic).
    """
    if validate:
        gate_prob = check_gate_prob(gate_prob)
        z, R, z_hat, H, P, S_feat = _checked(z, R, z_hat, H, P)
    else:
        z, z_hat = np.asarray(z, np.float64), np.asarray(z_hat, np.float64)
        m = z.shape[0]
        R = np.asarray(R, np.float64)
        if R.shape == (2, 2):
            R = np.broadcast_to(R, (m, 2, 2))
        H = np.ascontiguousarray(H, np.float64)
        P = np.ascontiguousarray(P, np.float64)
        if R.ndim == 3 and max(m, z_hat.shape[0]) <= _KERNEL_RANKS:  # a scan's few: one call
            return _trusted_prepared(z, R, z_hat, H, P, gate=gate_threshold(gate_prob))
        S_feat = _project_cov_trusted(H, P) if z_hat.shape[0] else np.zeros((0, 2, 2))
    m, n = z.shape[0], z_hat.shape[0]
    gate = gate_threshold(gate_prob)
    # Canonical ranks: lexicographic on the data, so results do not depend on input order.
    rank_meas = _ranks_of(z, R.reshape(m, 4))
    rank_feat = _ranks_of(z_hat, S_feat.reshape(n, 4))

    if m and n:
        f = _kernel_array
        ii, jj, nu, S, d2, l11, l22, bad = _gated_pairs(f(z), f(R), f(z_hat), S_feat, gate)
        if bad[0] >= 0:  # cannot happen with R > 0 and H P H^T >= 0, kept as a guard
            raise AssociationError(
                f"P, R: innovation covariance S[{bad[0]}, {bad[1]}] is not positive definite"
            )
        if validate:
            _check_joint_psd(H, P, np.unique(jj))
        order = np.lexsort((rank_feat[jj], rank_meas[ii]))
        logdet = 2.0 * (np.log(l11[order]) + np.log(l22[order]))  # as `chol2_solve`
        pairs = {
            "pair_i": ii[order],
            "pair_j": jj[order],
            "nu": nu[order],
            "S": S[order],
            "d2": d2[order],
            "logdet_S": logdet,
        }
    else:
        e = np.zeros(0, np.int64)
        pairs = {
            "pair_i": e,
            "pair_j": e,
            "nu": np.zeros((0, 2)),
            "S": np.zeros((0, 2, 2)),
            "d2": np.zeros(0),
            "logdet_S": np.zeros(0),
        }
    return Prepared(
        z=z,
        R=R,
        z_hat=z_hat,
        S_feat=S_feat,
        H=H,
        P=P,
        gate=gate,
        rank_meas=rank_meas,
        rank_feat=rank_feat,
        **pairs,
    )


def _trusted_prepared(z, R, z_hat, H, P, *, gate: float) -> Prepared:
    """`prepare`'s trusted path for at most `_KERNEL_RANKS` measurements and features: the
    same kernels (`_project_cov_trusted`, `_rank_kernel`, `_gated_pairs`) in one call,
    the pairs sorted by their (unique) rank pairs as np.lexsort sorts them."""
    f = _kernel_array
    z, R, z_hat = f(z), f(R), f(z_hat)
    S_feat, rank_meas, rank_feat, ii, jj, nu, S, d2, l11, l22, bad = _trusted_kernel(
        z, R, z_hat, H, P, gate
    )
    if bad[0] >= 0:  # cannot happen with R > 0 and H P H^T >= 0, kept as a guard
        raise AssociationError(
            f"P, R: innovation covariance S[{bad[0]}, {bad[1]}] is not positive definite"
        )
    logdet = 2.0 * (np.log(l11) + np.log(l22))  # as `chol2_solve`
    return Prepared(
        z=z,
        R=R,
        z_hat=z_hat,
        S_feat=S_feat,
        H=H,
        P=P,
        gate=gate,
        rank_meas=rank_meas,
        rank_feat=rank_feat,
        pair_i=ii,
        pair_j=jj,
        nu=nu,
        S=S,
        d2=d2,
        logdet_S=logdet,
    )


@njit(cache=True)
def _trusted_kernel(z, R, z_hat, H, P, gate):
    """`_trusted_prepared`'s arrays: (S_feat, rank_meas, rank_feat, then the gated pairs'
    ii, jj, nu, S, d2, l11, l22 in canonical order, bad). Ranks are permutations, so the
    key rank_meas[i] n + rank_feat[j] is unique per pair and any sort orders the pairs as
    the stable lexsort did."""
    m, n = z.shape[0], z_hat.shape[0]
    S_feat = _project_cov_trusted(H, P) if n else np.zeros((0, 2, 2))
    rank_meas = _rank_kernel(z, R.reshape(m, 4))
    rank_feat = _rank_kernel(z_hat, S_feat.reshape(n, 4))
    if m and n:
        ii, jj, nu, S, d2, l11, l22, bad = _gated_pairs(z, R, z_hat, S_feat, gate)
    else:
        ii, jj = np.zeros(0, np.int64), np.zeros(0, np.int64)
        nu, S, d2 = np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0)
        l11, l22, bad = np.zeros(0), np.zeros(0), np.full(2, -1, np.int64)
    key = np.empty(ii.size, np.int64)
    for t in range(ii.size):
        key[t] = rank_meas[ii[t]] * n + rank_feat[jj[t]]
    order = np.argsort(key)
    return (
        S_feat,
        rank_meas,
        rank_feat,
        ii[order],
        jj[order],
        nu[order],
        S[order],
        d2[order],
        l11[order],
        l22[order],
        bad,
    )


@njit(cache=True)
def _gated_pairs(z, R, z_hat, S_feat, gate):
    """The individually gated pairings of m measurements and n features, in one pass over the
    m x n pairs (the vectorised form built (m, n, 2, 2) arrays of every pair, and its dozen
    array operations cost more than the arithmetic).

    For each pair `association.gating.pair_d2` (the one home of the gate's arithmetic): nu_ij =
    z_i - z_hat_j (bearing wrapped as `wrap_angle`), S_ij = S_feat_j + R_i, and d2_ij with the
    arithmetic of `chol2_solve`, so the same numbers to the bit.
    Returns the pairs with d2 <= gate in row-major order: ii, jj (k,), nu (k, 2),
    S (k, 2, 2), d2 (k,), and the Cholesky diagonals l11, l22 (k,) (ln|S| = 2 ln(l11 l22));
    bad (2,): the first pair whose S is not positive definite, or (-1, -1)."""
    m, n = z.shape[0], z_hat.shape[0]
    cap = m * n
    ii = np.empty(cap, np.int64)
    jj = np.empty(cap, np.int64)
    nu = np.empty((cap, 2))
    S = np.empty((cap, 2, 2))
    d2 = np.empty(cap)
    l11s = np.empty(cap)
    l22s = np.empty(cap)
    bad = np.full(2, -1, np.int64)
    k = 0
    for i in range(m):
        for j in range(n):
            dd, nu0, nu1, s00, s01, s10, s11, l11, l22, ok = pair_d2(z, R, z_hat, S_feat, i, j)
            if not ok:
                if bad[0] < 0:
                    bad[0] = i
                    bad[1] = j
                continue
            if dd <= gate:  # eq. individual compatibility gate
                ii[k] = i
                jj[k] = j
                nu[k, 0] = nu0
                nu[k, 1] = nu1
                S[k, 0, 0] = s00
                S[k, 0, 1] = s01
                S[k, 1, 0] = s10
                S[k, 1, 1] = s11
                d2[k] = dd
                l11s[k] = l11
                l22s[k] = l22
                k += 1
    return ii[:k], jj[:k], nu[:k], S[:k], d2[:k], l11s[:k], l22s[:k], bad


def _checked(z, R, z_hat, H, P):
    """The checks of `prepare` on its arrays (after gate_prob's): (z, R, z_hat, H, P) as checked
    float arrays, and S_feat."""
    z = check_measurements("z", z, "(m, 2)")
    m = z.shape[0]
    R = check_R(R, m)
    z_hat = check_measurements("z_hat", z_hat, "(n, 2)")
    n = z_hat.shape[0]
    P = as_float_array("P", P, "(d, d)")
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise AssociationError(f"P: expected a square (d, d) matrix, got shape {P.shape}")
    d = P.shape[0]
    H = as_float_array("H", H, "(n, 2, d)")
    if H.shape != (n, 2, d):
        raise AssociationError(
            f"H: expected shape (n, 2, d) = ({n}, 2, {d}) from z_hat and P, got {H.shape}"
        )
    check_finite("P", P)
    check_finite("H", H)
    if (np.diag(P) < 0).any():
        k = int(np.flatnonzero(np.diag(P) < 0)[0])
        raise AssociationError(
            f"P: negative variance P[{k}, {k}] = {P[k, k]!r}; not positive semi-definite"
        )
    H = np.ascontiguousarray(H)
    P = np.ascontiguousarray(P)
    if n:
        S_feat, asym, psd_ok = _project_cov_kernel(H, P, _SYM_RTOL, _PSD_RTOL, _MAX_PSD_BLOCK)
    else:
        S_feat, asym, psd_ok = np.zeros((0, 2, 2)), np.zeros(0), np.ones(0, bool)
    if (asym > _SYM_RTOL).any():
        k = int(np.argmax(asym))
        raise AssociationError(
            f"P: not symmetric on the state block used by feature {k} "
            f"(relative asymmetry {asym[k]:.2e})"
        )
    if not psd_ok.all():
        k = int(np.flatnonzero(~psd_ok)[0])
        raise AssociationError(
            f"P: not positive semi-definite on the state block used by feature {k}"
        )
    if n:
        # Projected check (covers dense Jacobians whose blocks are too big for the exact check).
        tr = np.maximum(S_feat[:, 0, 0] + S_feat[:, 1, 1], 1e-300)
        det = S_feat[:, 0, 0] * S_feat[:, 1, 1] - S_feat[:, 0, 1] ** 2
        bad = (
            (S_feat[:, 0, 0] < -_PSD_RTOL * tr)
            | (S_feat[:, 1, 1] < -_PSD_RTOL * tr)
            | (det < -_PSD_RTOL * tr * tr)
        )
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise AssociationError(
                f"P: H[{k}] P H[{k}]^T is not positive semi-definite ({S_feat[k].tolist()})"
            )
    return z, R, z_hat, H, P, S_feat


def _check_joint_psd(H: np.ndarray, P: np.ndarray, feats: np.ndarray) -> None:
    """P on the state columns of the gated features, taken together, is positive semi-definite.

    The per-feature checks above see each feature's block alone; a defect in the cross terms
    between features shows only in their joint block, which JCBB and the window use (the joint
    innovation covariance). Only the gated features count: the block stays small (the state of
    the candidates of one scan), so an eigenvalue check is cheap."""
    if feats.size < 2:
        return
    cols = np.flatnonzero(np.any(H[feats] != 0.0, axis=(0, 1)))
    if cols.size < 2:
        return
    block = P[np.ix_(cols, cols)]
    scale = max(float(np.max(np.diag(block))), 1e-300)
    low = float(np.linalg.eigvalsh(0.5 * (block + block.T))[0])
    if low < -_PSD_RTOL * scale * cols.size:
        raise AssociationError(
            f"P: not positive semi-definite on the joint block of the gated features "
            f"{feats.tolist()} (smallest eigenvalue {low:.3g}; the cross-covariances between "
            "them are inconsistent)"
        )


# Rows ranked by `_rank_kernel` (an insertion sort) up to this many, by np.lexsort beyond
_KERNEL_RANKS = 64


def _ranks_of(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """`_ranks` of the rows [a | b] (a (k, 2), b (k, 4)): for the few rows of one scan a
    kernel, the same ranks without building the keys and the lexsort's arrays."""
    if a.shape[0] > _KERNEL_RANKS:
        return _ranks(np.column_stack([a, b]))
    return _rank_kernel(_kernel_array(a), _kernel_array(b))


def _kernel_array(a: np.ndarray) -> np.ndarray:
    """`a` as the kernels take it: float64, C-contiguous and writable, copied only when it is
    not. numba compiles a kernel again for a read-only array (a `Features` array, or a 2 x 2
    R broadcast to one measurement, which numpy calls contiguous): one more signature of
    `_trusted_kernel`, `_gated_pairs` and `_rank_kernel`, about 6 s of CPU in each process
    that met one (lab notebook, 2026-11-29). The same values, so the same results."""
    return np.require(a, np.float64, ["C", "W"])


@njit(cache=True)
def _row_before(a, b, i, j) -> bool:
    """Row i of [a | b] before row j in np.lexsort's order of the columns (first column
    most significant; NaN after every number, NaNs equal; equal rows by index: stable)."""
    for c in range(a.shape[1] + b.shape[1]):
        x = a[i, c] if c < a.shape[1] else b[i, c - a.shape[1]]
        y = a[j, c] if c < a.shape[1] else b[j, c - a.shape[1]]
        if x < y:
            return True
        if x > y:
            return False
        if (x != x) != (y != y):  # one NaN: the number first
            return y != y
    return i < j


@njit(cache=True)
def _rank_kernel(a, b):
    """`_ranks_of` by a stable insertion sort (k rows, k - 1 insertions of at most k - 1
    steps each)."""
    k = a.shape[0]
    order = np.arange(k)
    for t in range(1, k):
        row = order[t]
        p = t
        for _ in range(t):
            if not _row_before(a, b, row, order[p - 1]):
                break
            order[p] = order[p - 1]
            p -= 1
        order[p] = row
    r = np.empty(k, np.int64)
    for t in range(k):
        r[order[t]] = t
    return r


def _ranks(keys: np.ndarray) -> np.ndarray:
    """Rank of each row in lexicographic order of its columns (first column most significant)."""
    if keys.shape[0] == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort(keys.T[::-1])
    r = np.empty(keys.shape[0], np.int64)
    r[order] = np.arange(keys.shape[0])
    return r
