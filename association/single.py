"""Single-scan IHGR: the assignment integer program of docs/method.md section 1 and its costs.

Variables x_ij (measurement i paired with map feature j, only for individually gated pairs) and
x_i0 (measurement i is a new feature or clutter). Constraints: every measurement exactly once,
every feature at most once. Costs are negative log-likelihoods (`CostModel`):

    c_ij = 1/2 d2_ij + 1/2 ln|2 pi S_ij| - ln P_D + ln(1 - P_D)
    c_i0 = -ln(lambda_b + lambda_c)

The joint likelihood of a hypothesis is  prod_paired P_D N(nu_ij; 0, S_ij)
* prod_unpaired features (1 - P_D) * prod_unpaired measurements (lambda_b + lambda_c);
dividing by the constant prod_all features (1 - P_D) gives the costs above. The ln(1 - P_D)
term therefore makes the single scan exactly the K = 1 case of the sliding window
(`association.window`), whose tuples pay -ln(1 - P_D) per miss.

The constraint matrix is that of a bipartite matching (totally unimodular), so the LP relaxation
is integral and IHGR stops after its first LP; the rounding loop still runs (it is the same code
as the multi-scan case, `association.rounding.ihgr_round`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from association.errors import AssociationError
from association.inputs import Prepared
from association.rounding import RoundingResult, ihgr_round_csc

__all__ = ["CostModel", "single_scan_problem", "ihgr_single"]

LN_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class CostModel:
    """Probabilities and densities behind the negative-log-likelihood costs.

    p_detect: P_D, probability that a feature in view is detected, in (0, 1).
    clutter_density: lambda_c, false returns per unit of measurement space, 1/(m rad). The
        default 1e-2 is a few false trunks per scan over a 40 m x pi rad field of view.
    birth_density: lambda_b, first sightings of unmapped landmarks per unit of measurement
        space, 1/(m rad). Default 1e-3 (a new tree every few scans).
    """

    p_detect: float = 0.9
    clutter_density: float = 1e-2
    birth_density: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("p_detect", "clutter_density", "birth_density"):
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            if not ok or abs(v) > 1e300 or not math.isfinite(v):  # abs first: 10**400 overflows
                shown = repr(v) if len(repr(v)) < 60 else repr(v)[:57] + "..."
                raise AssociationError(f"CostModel.{name}: must be a finite number, got {shown}")
            object.__setattr__(self, name, float(v))
        if not 0.0 < self.p_detect < 1.0:
            raise AssociationError(f"CostModel.p_detect: must be in (0, 1), got {self.p_detect!r}")
        if self.clutter_density < 0 or self.birth_density < 0:
            raise AssociationError("CostModel.clutter_density, birth_density: must be >= 0")
        if self.clutter_density + self.birth_density <= 0:
            raise AssociationError("CostModel.clutter_density + birth_density: must be > 0")

    @property
    def detect_cost(self) -> float:
        """-ln P_D."""
        return -math.log(self.p_detect)

    @property
    def miss_cost(self) -> float:
        """-ln(1 - P_D): a feature (or tracked new landmark) in view but not detected."""
        return -math.log1p(-self.p_detect)

    @property
    def birth_cost(self) -> float:
        """-ln lambda_b: the first sighting of a new landmark."""
        return -math.log(self.birth_density) if self.birth_density > 0 else math.inf

    def nll(self, d2, logdet_S):
        """-ln N(nu; 0, S) = 1/2 d2 + 1/2 ln|2 pi S| for a 2-D measurement."""
        return 0.5 * np.asarray(d2) + 0.5 * (2.0 * LN_2PI + np.asarray(logdet_S))

    def pair_cost(self, d2, logdet_S):
        """Measurement paired with a map feature, relative to that feature being missed."""
        return self.nll(d2, logdet_S) + self.detect_cost - self.miss_cost

    def unexplained_cost(self, later_scans: int = 0) -> float:
        """A measurement explained by nothing else: clutter, or a new landmark not seen again in
        `later_scans` further scans: -ln(lambda_b (1 - P_D)^later + lambda_c)."""
        return -math.log(
            self.birth_density * (1.0 - self.p_detect) ** later_scans + self.clutter_density
        )


def _csc_problem(prep: Prepared, model: CostModel):
    """(costs, n_rows, indptr, indices, exact, col_meas, col_feat) of the single-scan program:
    rows are the m measurements (exact) followed by the gated features (at most once); columns
    are the gated pairs in canonical order, then one new/clutter singleton per measurement."""
    costs = np.concatenate(
        [model.pair_cost(prep.d2, prep.logdet_S), np.full(prep.m, model.unexplained_cost())]
    )
    n_rows, indptr, indices, exact, col_meas, col_feat = _csc_index(
        prep.pair_i, prep.pair_j, prep.rank_meas, prep.rank_feat
    )
    return costs, n_rows, indptr, indices, exact, col_meas, col_feat


@njit(cache=True)
def _csc_index(pair_i, pair_j, rank_meas, rank_feat):
    """The index part of `_csc_problem` in one pass (its array operations cost more than the
    work): (n_rows, indptr, indices, exact, col_meas, col_feat). The gated features' rows
    follow the m measurement rows in canonical (rank) order; the singletons' columns take the
    measurements in canonical order. Ranks are permutations of 0..m-1 and 0..n-1."""
    m, n, k = rank_meas.size, rank_feat.size, pair_i.size
    meas_order = np.empty(m, np.int64)  # argsort of a permutation: its inverse
    for i in range(m):
        meas_order[rank_meas[i]] = i
    gated = np.zeros(n, np.bool_)
    for t in range(k):
        gated[pair_j[t]] = True
    by_rank = np.full(n, -1, np.int64)
    for j in range(n):
        if gated[j]:
            by_rank[rank_feat[j]] = j
    row_of_feat = np.full(n, -1, np.int64)
    n_rows = m
    for r in range(n):
        if by_rank[r] >= 0:
            row_of_feat[by_rank[r]] = n_rows
            n_rows += 1
    col_meas = np.empty(k + m, np.int64)
    col_feat = np.full(k + m, -1, np.int64)
    indptr = np.empty(k + m + 1, np.int64)
    indices = np.empty(2 * k + m, np.int64)
    for t in range(k):  # a pair column covers its measurement's row and (below it) its feature's
        col_meas[t] = pair_i[t]
        col_feat[t] = pair_j[t]
        indptr[t] = 2 * t
        indices[2 * t] = pair_i[t]
        indices[2 * t + 1] = row_of_feat[pair_j[t]]
    for i in range(m):
        col_meas[k + i] = meas_order[i]
        indptr[k + i] = 2 * k + i
        indices[2 * k + i] = meas_order[i]
    indptr[k + m] = 2 * k + m
    exact = np.zeros(n_rows, np.bool_)
    exact[:m] = True
    return n_rows, indptr, indices, exact, col_meas, col_feat


def single_scan_problem(prep: Prepared, model: CostModel):
    """The set-partitioning form of the single-scan program.

    Returns (costs, A, exact, col_meas, col_feat): rows are the m measurements (exact) followed by
    the gated features (at most once); columns are the gated pairs in canonical order, then one
    new/clutter singleton per measurement (col_feat = -1). A is a scipy.sparse CSC matrix.
    """
    costs, n_rows, indptr, indices, exact, col_meas, col_feat = _csc_problem(prep, model)
    A = sp.csc_array((np.ones(indices.size), indices, indptr), shape=(n_rows, costs.size))
    return costs, A, exact, col_meas, col_feat


def ihgr_single(prep: Prepared, model: CostModel, **rounding) -> tuple[np.ndarray, RoundingResult]:
    """Assignment (m,) of one scan by IHGR, and the rounding result."""
    costs, n_rows, indptr, indices, exact, col_meas, col_feat = _csc_problem(prep, model)
    res = ihgr_round_csc(costs, n_rows, indptr, indices, exact, **rounding)
    out = np.full(prep.m, -1, np.int64)
    sel = res.selected
    out[col_meas[sel]] = col_feat[sel]
    return out, res
