"""Single-scan IHGR: the assignment integer program of METHOD_NOTES section 1 and its costs.

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
            if not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise AssociationError(f"CostModel.{name}: must be a finite number, got {v!r}")
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
    m = prep.m
    feats = np.unique(prep.pair_j)
    feats = feats[np.argsort(prep.rank_feat[feats])]
    row_of_feat = np.full(prep.n, -1, np.int64)
    row_of_feat[feats] = m + np.arange(feats.size)
    k = prep.pair_i.size
    meas_order = np.argsort(prep.rank_meas)
    col_meas = np.concatenate([prep.pair_i, meas_order])
    col_feat = np.concatenate([prep.pair_j, np.full(m, -1, np.int64)])
    costs = np.concatenate(
        [model.pair_cost(prep.d2, prep.logdet_S), np.full(m, model.unexplained_cost())]
    )
    # a pair column covers its measurement's row and (below it) its feature's row
    pair_rows = np.stack([prep.pair_i, row_of_feat[prep.pair_j]], axis=1).reshape(-1)
    indices = np.concatenate([pair_rows, meas_order]).astype(np.int64)
    indptr = np.concatenate([np.arange(0, 2 * k + 1, 2), 2 * k + np.arange(1, m + 1)])
    exact = np.zeros(m + feats.size, bool)
    exact[:m] = True
    return costs, m + feats.size, indptr.astype(np.int64), indices, exact, col_meas, col_feat


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
