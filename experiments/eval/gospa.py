"""GOSPA and OSPA between an estimated landmark map and a reference map (2D points, m).

GOSPA (Rahmathullah, Garcia-Fernandez and Svensson, "Generalized optimal sub-pattern assignment
metric", FUSION 2017, eq. (1)): for X (m points) and Y (n points), m <= n,

    d_p^(c,alpha)(X, Y) = ( min_pi sum_i d^(c)(x_i, y_pi(i))^p + c^p / alpha * (n - m) )^(1/p)

with d^(c)(x, y) = min(|x - y|, c) and pi over the injections of X into Y. With alpha = 2 it
is the optimal assignment's cost split into three parts (the paper's Proposition 1), each
reported apart here as the p-th power sums whose total is d^p:

    localisation  sum of |x - y|^p over the assigned pairs (those closer than c),
    missed        c^p / 2 for each reference point assigned to no estimate,
    false         c^p / 2 for each estimate assigned to no reference point.

Stone Soup's `GOSPAMetric` (alpha = 2 only) reports the same three sums; the tests check both
against each other and against a brute force over the assignments. The RFS-SLAM papers (PHD-SLAM
3.0, GM-PHD-PMAU-SLAM) score maps with p = 2, c = 20 m, alpha = 2; a cut-off of 1 m matches the
1 m of the precision and recall figures (`experiments.eval.map_quality`).

OSPA (Schuhmacher, Vo and Vo, IEEE TSP 2008, eq. (3)): ((min_pi sum_i d^(c)(x_i, y_pi(i))^p +
c^p (n - m)) / n)^(1/p), 0 for two empty maps; it is GOSPA with alpha = 1, normalised by n.
Stone Soup's `OSPAMetric` assigns on the distances rather than their p-th powers, which is the
optimal assignment only for p = 1; the tests compare with it at p = 1.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = [
    "GOSPA_COLUMNS",
    "GOSPA_LABELS",
    "GOSPA_SETTINGS",
    "Gospa",
    "gospa",
    "gospa_columns",
    "ospa",
]

# (c m, p, alpha) of the published RFS-SLAM figure and of the 1 m of precision and recall
GOSPA_SETTINGS = ((1.0, 2.0, 2.0), (20.0, 2.0, 2.0))
# the keys of `gospa_columns` with the default settings, and their labels for result tables
GOSPA_LABELS = {
    f"gospa_{c:g}m{part}": f"GOSPA c = {c:g} m{label}"
    for c, _, _ in GOSPA_SETTINGS
    for part, label in (
        ("", ", m"),
        ("_localisation", ": localisation, m^2"),
        ("_missed", ": missed, m^2"),
        ("_false", ": false, m^2"),
    )
}
GOSPA_COLUMNS = tuple(GOSPA_LABELS)


@dataclass(frozen=True)
class Gospa:
    """A GOSPA figure. distance: d (m). localisation, missed, false: the p-th power sums (m^p)
    that add up to distance^p when alpha = 2 (NaN otherwise: the split is alpha = 2's).
    assigned: pairs closer than c; n_missed, n_false: reference points and estimates left out
    (alpha = 2; the unassigned of the larger set otherwise). p, c, alpha: the settings."""

    distance: float
    localisation: float
    missed: float
    false: float
    assigned: int
    n_missed: int
    n_false: int
    p: float
    c: float
    alpha: float

    def to_dict(self) -> dict:
        return asdict(self)


def _points(name: str, a) -> np.ndarray:
    try:
        x = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"gospa: {name}: expected (K, 2) numbers") from e
    if x.size == 0:
        return np.zeros((0, 2))
    if x.ndim != 2 or x.shape[1] < 2:
        raise ValueError(f"gospa: {name}: expected shape (K, 2), got {x.shape}")
    if not np.isfinite(x[:, :2]).all():
        raise ValueError(f"gospa: {name}: contains NaN or infinite coordinates")
    return x[:, :2]


def _settings(p: float, c: float, alpha: float) -> None:
    if not (isinstance(p, (int, float)) and 1.0 <= p < math.inf):
        raise ValueError(f"gospa: p: expected 1 <= p < inf, got {p!r}")
    if not (isinstance(c, (int, float)) and 0.0 < c < math.inf):
        raise ValueError(f"gospa: c: expected 0 < c < inf, got {c!r}")
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha <= 2.0):
        raise ValueError(f"gospa: alpha: expected 0 < alpha <= 2, got {alpha!r}")


def _assignment(est: np.ndarray, ref: np.ndarray, p: float, c: float):
    """(rows, cols, d) of the optimal assignment of min(d, c)^p (rows: est, cols: ref)."""
    d = np.hypot(est[:, None, 0] - ref[None, :, 0], est[:, None, 1] - ref[None, :, 1])
    cost = np.minimum(d, c) ** p
    rows, cols = linear_sum_assignment(cost)
    return rows, cols, d[rows, cols]


def gospa(estimate, reference, p: float = 2.0, c: float = 20.0, alpha: float = 2.0) -> Gospa:
    """GOSPA between `estimate` (K, 2) and `reference` (T, 2) points (m); see the module doc.
    Defaults: the RFS-SLAM papers' p = 2, c = 20 m, alpha = 2."""
    _settings(p, c, alpha)
    est, ref = _points("estimate", estimate), _points("reference", reference)
    m, n = est.shape[0], ref.shape[0]
    rows, cols, d = _assignment(est, ref, p, c) if m and n else ((), (), np.zeros(0))
    close = d < c
    loc = float(np.sum(d[close] ** p))
    pad = c**p / alpha
    if alpha == 2.0:  # a pair at c or beyond costs c^p: one missed and one false
        n_missed, n_false = n - int(close.sum()), m - int(close.sum())
        missed, false = pad * n_missed, pad * n_false
        total = loc + missed + false
    else:
        n_missed, n_false = max(n - m, 0), max(m - n, 0)
        total = loc + float(np.sum(~close)) * c**p + pad * abs(n - m)
        missed = false = math.nan
    return Gospa(
        distance=float(total ** (1.0 / p)),
        localisation=loc,
        missed=float(missed),
        false=float(false),
        assigned=int(close.sum()),
        n_missed=n_missed,
        n_false=n_false,
        p=float(p),
        c=float(c),
        alpha=float(alpha),
    )


def ospa(estimate, reference, p: float = 2.0, c: float = 20.0) -> float:
    """OSPA distance (m) between `estimate` (K, 2) and `reference` (T, 2); 0 for two empty
    maps."""
    _settings(p, c, 1.0)
    est, ref = _points("estimate", estimate), _points("reference", reference)
    n = max(est.shape[0], ref.shape[0])
    if n == 0:
        return 0.0
    g = gospa(est, ref, p=p, c=c, alpha=1.0)
    return float((g.distance**p / n) ** (1.0 / p))


def gospa_columns(estimate, reference, settings=GOSPA_SETTINGS) -> dict:
    """The flat figures a results table or summary carries for each (c, p, alpha) of
    `settings`: gospa_{c}m and its localisation, missed and false parts (m^p), e.g.
    gospa_20m, gospa_20m_localisation, gospa_20m_missed, gospa_20m_false."""
    out: dict = {}
    for c, p, alpha in settings:
        g = gospa(estimate, reference, p=p, c=c, alpha=alpha)
        key = f"gospa_{c:g}m"
        out[key] = g.distance
        for part in ("localisation", "missed", "false"):
            out[f"{key}_{part}"] = getattr(g, part)
    return out
