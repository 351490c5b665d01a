"""LP relaxation with iterative heuristic greedy rounding (IHGR) for set-partitioning problems.

The problem (docs/method.md section 1; Storms & Spieksma 2003):

    minimise   c^T x
    subject to A[r] x  = 1   for every row r with exact[r]       (e.g. a measurement)
               A[r] x <= 1   for every other row                   (e.g. a map feature)
               x in {0, 1}^N

Columns are hypotheses (a pairing, a multi-scan tuple, a clutter singleton), rows are the things
they use; A is a 0/1 (rows x columns) matrix.

IHGR:
1. Solve the LP relaxation (0 <= x <= 1) with HiGHS (`scipy.optimize.linprog`, dual simplex, so
   the answer is a vertex and a totally unimodular problem gives an integral x).
2. If every x is within `eps` of 0 or 1, take the x = 1 columns and stop.
3. Otherwise fix the largest fractional x_h to 1 (ties: lower cost, then lower column index); with
   `fix_ones` (off by default) also fix every x >= 1 - eps in the same pass (they cannot conflict
   with h or with each other): fewer passes, but on random 3-scan problems it lands on the optimum
   less often (see results/association_optimality.md).
   Remove every column that shares a row with a fixed one, and the rows they cover.
4. Re-solve the reduced LP and go to 2.

Two exact speed-ups that do not change the method (up to ties between equally good LP vertices):
- The problem splits into connected components (columns linked by shared rows); the rounding
  runs on each independently. All fractional components are handled by the same LP solve (their
  LPs are independent blocks), so the solve count is the longest per-component count.
- `presolve`: a component whose columns all cover its only exact row is a choice of one column,
  whose LP optimum is the cheapest column; it is taken directly without an LP. Single-scan
  association after gating is mostly such components.

Each pass fixes at least one column, so IHGR ends after at most (number of rows) solves. If a
reduced LP becomes infeasible (possible only when some exact row has no singleton column), a
RuntimeError is raised; association problems always give each measurement a singleton.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.optimize import Bounds, LinearConstraint, linprog, milp
from scipy.sparse.csgraph import connected_components

from association.errors import AssociationError

__all__ = [
    "ROUNDING_OPTIONS",
    "RoundingResult",
    "check_problem",
    "check_rounding_options",
    "ihgr_round",
    "solve_set_partition",
]

ROUNDING_OPTIONS = ("eps", "fix_ones", "presolve")  # the keyword options of `ihgr_round`


def check_rounding_options(options: dict) -> dict:
    """The options of `ihgr_round` in `options`, checked: no other names, eps a number in
    (0, 0.5), fix_ones and presolve True or False (a string such as "no" is refused, not read
    as true). `AssociationError` naming the option otherwise."""
    unknown = sorted(set(options) - set(ROUNDING_OPTIONS))
    if unknown:
        raise AssociationError(f"{unknown}: not options of ihgr_round ({list(ROUNDING_OPTIONS)})")
    eps = options.get("eps", 1e-6)
    if (
        isinstance(eps, bool)
        or not isinstance(eps, (int, float, np.floating))
        or not (0.0 < eps < 0.5)
    ):
        raise AssociationError(f"eps: must be a number in (0, 0.5), got {eps!r}")
    for flag in ("fix_ones", "presolve"):
        if flag in options and not isinstance(options[flag], (bool, np.bool_)):
            raise AssociationError(f"{flag}: must be True or False, got {options[flag]!r}")
    return dict(options)


_UNION_FIND_MAX = 2000  # entries: at most, `_settle` (`_union_find`); more, scipy's labelling
_DENSE_MAX_ENTRIES = 40_000  # below this, a dense A is faster through linprog than a sparse one


@dataclass(frozen=True, eq=False)
class RoundingResult:
    """The answer of a set-partitioning solve.

    selected: (k,) int, indices of the chosen columns, ascending.
    cost: c^T x of the chosen columns.
    lp_bound: optimum of the first LP relaxation (a lower bound on the integer optimum); for
        method "milp" the integer optimum itself.
    lp_solves: number of LP solves (linprog calls); 0 when presolve settled everything.
    fractional: True if the first LP relaxation was fractional in some component.
    method: "ihgr" or "milp".
    """

    selected: np.ndarray
    cost: float
    lp_bound: float
    lp_solves: int
    fractional: bool
    method: str


class _Csc(NamedTuple):
    """A set-partitioning problem in CSC index form: column h covers rows
    indices[indptr[h]:indptr[h + 1]]."""

    c: np.ndarray  # (N,) float64 column costs
    n_rows: int
    indptr: np.ndarray  # (N + 1,) int64
    indices: np.ndarray  # (nnz,) int64 row of each entry
    exact: np.ndarray  # (n_rows,) bool: covered exactly once, else at most once


class _Components(NamedTuple):
    """The connected components of the row-column graph (`_components`)."""

    n_comp: int
    row_lab: np.ndarray  # (n_rows,) int, the component of each row
    col_lab: np.ndarray  # (N,) int, the component of each column


def check_problem(costs, A, exact) -> tuple[np.ndarray, sp.csc_array, np.ndarray]:
    """Validate and normalise (costs (N,), A (rows, N) 0/1, exact (rows,) bool)."""
    c, n_rows, indptr, indices, e = _check(costs, A, exact)
    Acsc = sp.csc_array((np.ones(indices.size), indices, indptr), shape=(n_rows, c.size))
    return c, Acsc, e


def _check(costs, A, exact):
    """Validated (costs, n_rows, indptr, indices, exact): the columns of A in CSC index form."""
    try:
        c = np.asarray(costs, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AssociationError(f"costs: cannot be read as a float array ({exc})") from None
    if c.ndim != 1:
        raise AssociationError(f"costs: expected shape (N,), got {c.shape}")
    if not np.isfinite(c).all():
        raise AssociationError("costs: contains NaN or inf")
    if sp.issparse(A):
        if A.ndim != 2:
            raise AssociationError(f"A: expected a 2-D (rows, N) matrix, got shape {A.shape}")
        Acsc = sp.csc_array(A, dtype=np.float64)
        Acsc.sum_duplicates()
        Acsc.eliminate_zeros()
        n_rows, n_cols = Acsc.shape
        if Acsc.nnz and not np.all(Acsc.data == 1.0):
            raise AssociationError("A: entries must be 0 or 1")
        indptr = Acsc.indptr.astype(np.int64)
        indices = Acsc.indices.astype(np.int64)
    else:
        try:
            Ad = np.asarray(A, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise AssociationError(f"A: cannot be read as a float matrix ({exc})") from None
        if Ad.ndim != 2:
            raise AssociationError(f"A: expected a 2-D (rows, N) matrix, got shape {Ad.shape}")
        n_rows, n_cols = Ad.shape
        if not np.isin(Ad, (0.0, 1.0)).all():
            raise AssociationError("A: entries must be 0 or 1")
        col, indices = np.nonzero(Ad.T)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(col, minlength=n_cols))])
        indices = indices.astype(np.int64)
    if n_cols != c.shape[0]:
        raise AssociationError(f"A: has {n_cols} columns but costs has {c.shape[0]} entries")
    counts = np.diff(indptr)
    if (counts == 0).any():
        raise AssociationError(f"A: column {int(np.flatnonzero(counts == 0)[0])} covers no row")
    e = np.asarray(exact)
    if e.shape != (n_rows,) or e.dtype != bool:
        raise AssociationError(
            f"exact: expected a bool array of shape ({n_rows},), got {e.dtype} {e.shape}"
        )
    return c, n_rows, indptr, indices, e


def _components(n_rows: int, indptr: np.ndarray, indices: np.ndarray) -> _Components:
    """Connected components of the row-column graph: (count, row labels, column labels).

    Labels number the components in the order of their smallest union-find root (rows joined by
    a column hang under the column's first row); large problems go to scipy's labelling."""
    n_cols = indptr.size - 1
    if indices.size > _UNION_FIND_MAX:
        col = np.repeat(np.arange(n_cols), np.diff(indptr)) + n_rows
        g = sp.coo_array((np.ones(indices.size), (indices, col)), shape=(n_rows + n_cols,) * 2)
        k, labels = connected_components(g, directed=False)
        return _Components(k, labels[:n_rows], labels[n_rows:])
    return _Components._make(_union_find(n_rows, indptr, indices))


@njit(cache=True)
def _find(parent: np.ndarray, a: int) -> int:
    """The root of a's tree, halving the path. A union only hangs one root under another, so
    the trees have no cycle and the path is shorter than parent.size: the loop's bound."""
    for _ in range(parent.size):
        if parent[a] == a:
            break
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True)
def _union_find(n_rows, indptr, indices):
    """`_components` of a small problem: union-find with path halving over the columns."""
    n_cols = indptr.size - 1
    parent = np.arange(n_rows)
    for h in range(n_cols):
        r0 = _find(parent, indices[indptr[h]])
        for t in range(indptr[h] + 1, indptr[h + 1]):
            r = _find(parent, indices[t])
            if r != r0:
                parent[r] = r0
    label_of_root = np.full(n_rows, -1, np.int64)
    is_root = np.zeros(n_rows, np.bool_)
    roots = np.empty(n_rows, np.int64)
    for r in range(n_rows):
        roots[r] = _find(parent, r)
        is_root[roots[r]] = True
    n_comp = 0
    for r in range(n_rows):  # roots in ascending order: the labels of np.unique(roots)
        if is_root[r]:
            label_of_root[r] = n_comp
            n_comp += 1
    row_lab = np.empty(n_rows, np.int64)
    for r in range(n_rows):
        row_lab[r] = label_of_root[roots[r]]
    col_lab = np.empty(n_cols, np.int64)
    for h in range(n_cols):
        col_lab[h] = row_lab[indices[indptr[h]]]
    return n_comp, row_lab, col_lab


@njit(cache=True)
def _presolve(problem, components, chosen, active):
    """The presolve of `ihgr_round_csc`, in place on `chosen` and `active` ((N,) bool); returns
    the cost of the columns it chose (summed in component order). problem: a `_Csc`,
    components: its `_Components`, both as plain tuples (numba's dispatcher types a plain tuple
    in C but a NamedTuple in Python, about 1.5 us a call).

    A component whose columns all cover its only exact row (or, with no exact row, all share
    one row) is a choice of at most one column: the cheapest (ties: the lowest index) is taken
    when a row must be covered or its cost is negative, and the component is closed."""
    c, n_rows, indptr, indices, exact = problem
    n_comp, row_lab, col_lab = components
    n_cols = c.size
    n_exact = np.zeros(n_comp, np.int64)
    n_rows_k = np.zeros(n_comp, np.int64)
    for r in range(n_rows):
        n_rows_k[row_lab[r]] += 1
        if exact[r]:
            n_exact[row_lab[r]] += 1
    # the columns of each component in ascending order (a stable counting sort by label)
    starts = np.zeros(n_comp + 1, np.int64)
    for h in range(n_cols):
        starts[col_lab[h] + 1] += 1
    for k in range(n_comp):
        starts[k + 1] += starts[k]
    fill = starts[:-1].copy()
    col_order = np.empty(n_cols, np.int64)
    for h in range(n_cols):
        col_order[fill[col_lab[h]]] = h
        fill[col_lab[h]] += 1
    count = np.zeros(n_rows, np.int64)
    bound = 0.0
    for k in range(n_comp):
        k0, k1 = starts[k], starts[k + 1]
        n_k = k1 - k0
        if n_exact[k] > 1 or n_k == 0:
            continue
        if n_k > 1 or n_rows_k[k] > 1:
            for t in range(k0, k1):
                h = col_order[t]
                for e in range(indptr[h], indptr[h + 1]):
                    count[indices[e]] += 1
            n_common = 0
            common_exact = False
            for t in range(k0, k1):  # the rows of component k are among its columns' rows
                h = col_order[t]
                for e in range(indptr[h], indptr[h + 1]):
                    r = indices[e]
                    if count[r] == n_k:
                        n_common += 1
                        common_exact |= exact[r]
            for t in range(k0, k1):
                h = col_order[t]
                for e in range(indptr[h], indptr[h + 1]):
                    count[indices[e]] = 0
            if n_common == 0:
                continue
            if n_exact[k] == 1 and not common_exact:
                continue
        best = col_order[k0]
        for t in range(k0 + 1, k1):  # cheapest; ties: lower index (col_order ascends)
            if c[col_order[t]] < c[best]:
                best = col_order[t]
        if n_exact[k] == 1 or c[best] < 0.0:
            chosen[best] = True
            bound += c[best]
        for t in range(k0, k1):
            active[col_order[t]] = False
    return bound


@njit(cache=True)
def _settle(c, n_rows, indptr, indices, exact, presolve):
    """`ihgr_round_csc`'s first steps on a small problem (at most `_UNION_FIND_MAX` entries) in
    one call: (the first exact row without a column or -1, the components (`_union_find`),
    chosen, active, the presolve's cost, whether a column is still active). Loops over the
    rows and entries."""
    n_cols = c.size
    row_has_col = np.zeros(n_rows, np.bool_)
    for e in range(indices.size):
        row_has_col[indices[e]] = True
    bad = -1
    for r in range(n_rows):
        if exact[r] and not row_has_col[r]:
            bad = r
            break
    chosen = np.zeros(n_cols, np.bool_)
    active = np.ones(n_cols, np.bool_)
    if bad >= 0 or n_cols == 0:
        none = np.zeros(0, np.int64)
        return bad, 0, none, none, chosen, active, 0.0, n_cols > 0
    n_comp, row_lab, col_lab = _union_find(n_rows, indptr, indices)
    bound = 0.0
    if presolve:
        bound += _presolve(
            (c, n_rows, indptr, indices, exact), (n_comp, row_lab, col_lab), chosen, active
        )
    open_cols = False
    for h in range(n_cols):
        open_cols = open_cols or active[h]
    return bad, n_comp, row_lab, col_lab, chosen, active, bound, open_cols


def _solve_lp(problem: _Csc, cols: np.ndarray, rows: np.ndarray):
    """LP relaxation of `problem` over columns `cols` and rows `rows`; <= rows get slack columns
    so that HiGHS sees only equalities. Returns (x over cols, optimum)."""
    c, n_rows, indptr, indices, exact = problem
    row_pos = np.full(n_rows, -1, np.int64)
    row_pos[rows] = np.arange(rows.size)
    counts = np.diff(indptr)[cols]
    starts = indptr[cols]
    entry = np.repeat(starts - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    entry += np.arange(counts.sum())
    r = row_pos[indices[entry]]
    col = np.repeat(np.arange(cols.size), counts)
    keep = r >= 0
    slack = np.flatnonzero(~exact[rows])
    n_var = cols.size + slack.size
    r = np.concatenate([r[keep], slack])
    col = np.concatenate([col[keep], cols.size + np.arange(slack.size)])
    c_full = np.concatenate([c[cols], np.zeros(slack.size)])
    if rows.size * n_var <= _DENSE_MAX_ENTRIES:
        A_eq = np.zeros((rows.size, n_var))
        A_eq[r, col] = 1.0
    else:
        A_eq = sp.csc_array((np.ones(r.size), (r, col)), shape=(rows.size, n_var))
    res = linprog(c_full, A_eq=A_eq, b_eq=np.ones(rows.size), bounds=(0.0, 1.0), method="highs-ds")
    if res.status != 0:
        raise RuntimeError(f"IHGR: LP relaxation failed ({res.message})")
    return np.asarray(res.x[: cols.size]), float(res.fun)


def ihgr_round(
    costs, A, exact, *, eps: float = 1e-6, fix_ones: bool = False, presolve: bool = True
) -> RoundingResult:
    """Solve a set-partitioning problem by LP relaxation + iterative heuristic greedy rounding.

    costs: (N,) column costs; A: (rows, N) 0/1 matrix, dense or scipy.sparse; exact: (rows,) bool,
    True for "covered exactly once", False for "at most once". See the module docstring.
    """
    check_rounding_options({"eps": eps, "fix_ones": fix_ones, "presolve": presolve})
    c, n_rows, indptr, indices, exact = _check(costs, A, exact)
    return ihgr_round_csc(
        c, n_rows, indptr, indices, exact, eps=eps, fix_ones=fix_ones, presolve=presolve
    )


def _round_by_lp(problem: _Csc, components: _Components, chosen, active, bound, *, eps, fix_ones):
    """IHGR's LP and rounding rounds on the columns still `active` after the presolve (in
    place on `chosen` and `active`); returns (bound plus the first LP's optimum, LP solves,
    whether the first LP was fractional)."""
    c, n_rows, indptr, indices, exact = problem
    counts = np.diff(indptr)
    solves = 0
    fractional = False
    covered = np.zeros(n_rows, bool)
    covered[indices[np.repeat(chosen, counts)]] = True
    while active.any():
        cols = np.flatnonzero(active)
        in_play = np.bincount(indices[np.repeat(active, counts)], minlength=n_rows) > 0
        missing = exact & ~covered & ~in_play
        if missing.any():
            raise RuntimeError(
                f"IHGR: infeasible after rounding, exact row "
                f"{int(np.flatnonzero(missing)[0])} has no column left"
            )
        rows = np.flatnonzero(in_play & ~covered)
        x, fun = _solve_lp(problem, cols, rows)
        solves += 1
        if solves == 1:
            bound += fun
        frac = (x > eps) & (x < 1.0 - eps)
        if solves == 1 and frac.any():
            fractional = True
        labs = components.col_lab[cols]
        to_fix, closed = _columns_to_fix(x, frac, cols, c, labs, eps=eps, fix_ones=fix_ones)
        for cols_k in closed:
            active[cols_k] = False
        for h in to_fix:
            chosen[h] = True
            covered[indices[indptr[h] : indptr[h + 1]]] = True
        # remove every column that shares a row with a fixed one (the fixed ones included)
        conflict = np.add.reduceat(covered[indices].astype(np.int64), indptr[:-1]) > 0
        active &= ~conflict
    return bound, solves, fractional


def _settle_small(problem: _Csc, presolve: bool):
    """`ihgr_round_csc`'s first steps by `_settle`, in one call: (the first exact row without a
    column or -1, the components, chosen, active, the presolve's cost, whether a column is
    still active)."""
    bad, n_comp, row_lab, col_lab, chosen, active, bound, open_cols = _settle(*problem, presolve)
    return bad, _Components(n_comp, row_lab, col_lab), chosen, active, bound, open_cols


def _settle_large(problem: _Csc, presolve: bool):
    """`_settle_small`'s answer by numpy and scipy's labelling (`_components`), for problems
    of more than `_UNION_FIND_MAX` entries."""
    c, n_rows, indptr, indices, exact = problem
    n_cols = c.size
    row_has_col = np.bincount(indices, minlength=n_rows) > 0
    missing = np.flatnonzero(exact & ~row_has_col)
    chosen = np.zeros(n_cols, bool)
    active = np.ones(n_cols, bool)  # columns still in play
    if missing.size or n_cols == 0:
        return (int(missing[0]) if missing.size else -1), None, chosen, active, 0.0, n_cols > 0
    components = _components(n_rows, indptr, indices)
    bound = 0.0
    if presolve:  # single-choice components settled without an LP (`_presolve`)
        bound += _presolve(tuple(problem), tuple(components), chosen, active)
    return -1, components, chosen, active, bound, bool(active.any())


def ihgr_round_csc(
    c: np.ndarray,
    n_rows: int,
    indptr: np.ndarray,
    indices: np.ndarray,
    exact: np.ndarray,
    *,
    eps: float = 1e-6,
    fix_ones: bool = False,
    presolve: bool = True,
) -> RoundingResult:
    """`ihgr_round` on a problem given in CSC index form (column h covers rows
    indices[indptr[h]:indptr[h + 1]]), without the input checks: for problems this package
    builds itself, valid by construction (the single-scan program), where the checks and the
    sparse-matrix round trip would cost more than the solve. Only what would read memory out
    of bounds is checked (row indices, exact's length): a ValueError."""
    n_cols = c.size
    # the kernels below index rows by `indices` unchecked: what would read out of bounds is
    # refused (the other input checks are left to the caller)
    if np.shape(exact) != (n_rows,) or (
        indices.size and (int(indices.min()) < 0 or int(indices.max()) >= n_rows)
    ):
        raise ValueError(
            f"ihgr_round_csc: needs exact of shape ({n_rows},) and row indices in [0, {n_rows}), "
            f"got exact {np.shape(exact)} and rows {indices.min() if indices.size else '-'}.."
            f"{indices.max() if indices.size else '-'}"
        )
    problem = _Csc(c, n_rows, indptr, indices, exact)
    settle = _settle_small if indices.size <= _UNION_FIND_MAX else _settle_large
    bad, components, chosen, active, bound, open_cols = settle(problem, presolve)
    if bad >= 0:
        raise RuntimeError(f"IHGR: infeasible, exact row {bad} has no column")
    if n_cols == 0:
        return _no_columns("ihgr")
    solves, fractional = 0, False
    if open_cols:  # else presolve settled every component (most scans): no LP
        bound, solves, fractional = _round_by_lp(
            problem, components, chosen, active, bound, eps=eps, fix_ones=fix_ones
        )
    sel = np.flatnonzero(chosen)
    return RoundingResult(
        selected=sel,
        cost=float(c[sel].sum()),
        lp_bound=float(bound),
        lp_solves=solves,
        fractional=fractional,
        method="ihgr",
    )


def _columns_to_fix(x, frac, cols, c, labs, *, eps: float, fix_ones: bool):
    """IHGR steps 2-3 on one LP solution x over the columns `cols` (frac: x is fractional;
    labs: each column's component; c: all column costs): in each fractional component the
    largest fractional column (ties: lower cost, then lower index), with `fix_ones` also its
    x = 1 columns; in each integral component its x = 1 columns, and the component is closed.
    Returns (columns to fix, [the columns of each closed component])."""
    to_fix: list[int] = []
    closed = []
    for k in np.unique(labs):
        in_k = labs == k
        fk = frac & in_k
        if fk.any():
            if fix_ones:
                to_fix += cols[in_k & (x >= 1.0 - eps)].tolist()
            cand = np.flatnonzero(fk)
            # largest fractional value; ties: lower cost, then lower index
            best = cand[np.lexsort((cols[cand], c[cols[cand]], -x[cand]))[0]]
            to_fix.append(int(cols[best]))
        else:
            # integral component: take it and close it
            to_fix += cols[in_k & (x >= 1.0 - eps)].tolist()
            closed.append(cols[in_k])
    return to_fix, closed


def _milp(costs, A, exact) -> RoundingResult:
    c, A, exact = check_problem(costs, A, exact)
    n_rows, n_cols = A.shape
    if n_cols == 0:
        return _no_columns("milp")
    lb = np.where(exact, 1.0, 0.0)
    res = milp(
        c,
        constraints=LinearConstraint(sp.csr_array(A), lb, np.ones(n_rows)),
        integrality=np.ones(n_cols),
        bounds=Bounds(0.0, 1.0),
    )
    if res.status != 0:
        raise RuntimeError(f"milp: no optimal solution ({res.message})")
    sel = np.flatnonzero(res.x > 0.5)
    cost = float(c[sel].sum())
    return RoundingResult(
        selected=sel, cost=cost, lp_bound=cost, lp_solves=0, fractional=False, method="milp"
    )


def _no_columns(method: str) -> RoundingResult:
    """The answer of a problem without columns (and so without exact rows)."""
    return RoundingResult(
        selected=np.zeros(0, np.int64),
        cost=0.0,
        lp_bound=0.0,
        lp_solves=0,
        fractional=False,
        method=method,
    )


def solve_set_partition(costs, A, exact, method: str = "ihgr", **params) -> RoundingResult:
    """Set partitioning by `method`: "ihgr" (LP + rounding, `ihgr_round`) or "milp" (exact
    branch and bound, `scipy.optimize.milp`, for reference)."""
    if method == "ihgr":
        return ihgr_round(costs, A, exact, **params)
    if method == "milp":
        if params:
            raise AssociationError(f"method 'milp' takes no parameters, got {sorted(params)}")
        return _milp(costs, A, exact)
    raise AssociationError(f"method: expected 'ihgr' or 'milp', got {method!r}")
