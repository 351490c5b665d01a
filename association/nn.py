"""Gated nearest neighbour: one-to-one, greedy by individual Mahalanobis distance.

All individually gated pairs are visited in increasing d2_ij (ties by the canonical order of
measurement, then feature); a pair is taken when neither its measurement nor its feature is
taken yet. This is the classic "global nearest neighbour by greedy" baseline: it ignores the
correlation between pairings, which JCBB uses.
"""

from __future__ import annotations

import numpy as np

from association.inputs import Prepared

__all__ = ["nn_assign"]


def nn_assign(prep: Prepared) -> np.ndarray:
    """Assignment (m,) int: feature index or -1."""
    out = np.full(prep.m, -1, np.int64)
    if prep.pair_i.size == 0:
        return out
    order = np.lexsort((prep.rank_feat[prep.pair_j], prep.rank_meas[prep.pair_i], prep.d2))
    used = np.zeros(prep.n, bool)
    for k in order:
        i, j = prep.pair_i[k], prep.pair_j[k]
        if out[i] < 0 and not used[j]:
            out[i] = j
            used[j] = True
    return out
