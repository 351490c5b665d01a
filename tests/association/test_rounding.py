"""The IHGR rounding core on set-partitioning problems, against scipy.optimize.milp."""

from __future__ import annotations

import numpy as np
import pytest

from association import ihgr_round, solve_set_partition


def odd_cycle():
    # columns: ab, bc, ac, a, b, c
    A = np.array([[1, 0, 1, 1, 0, 0], [1, 1, 0, 0, 1, 0], [0, 1, 1, 0, 0, 1]])
    c = np.array([-1.0, -1.0, -1.0, 0.0, 0.0, 0.0])
    return c, A, np.ones(3, bool)


def assert_feasible(A, exact, selected):
    cover = np.asarray(A)[:, selected].sum(axis=1)
    assert np.all(cover[exact] == 1)
    assert np.all(cover[~exact] <= 1)


def test_odd_cycle_lp_is_half_and_ihgr_needs_two_solves():
    c, A, e = odd_cycle()
    r = ihgr_round(c, A, e)
    assert r.lp_bound == pytest.approx(-1.5)  # x = 1/2 everywhere
    assert r.fractional
    assert r.cost == pytest.approx(-1.0)
    assert r.lp_solves == 2
    assert_feasible(A, e, r.selected)
    assert sorted(r.selected.tolist()) == [0, 5]  # ties: lowest cost, then lowest index -> ab
    exact = solve_set_partition(c, A, e, method="milp")
    assert exact.cost == pytest.approx(-1.0)


def test_odd_cycle_one_variable_per_pass_gives_the_same():
    c, A, e = odd_cycle()
    r = ihgr_round(c, A, e, fix_ones=False)
    assert (r.cost, r.lp_solves) == (pytest.approx(-1.0), 2)


def test_presolve_settles_single_choice_components_without_lp():
    # two independent measurements, each with a feature and a singleton; the features are
    # at-most-once rows used by one column only
    A = np.array([[1, 1, 0, 0], [0, 0, 1, 1], [1, 0, 0, 0], [0, 0, 1, 0]])
    c = np.array([-2.0, 0.5, 1.0, 0.5])
    e = np.array([True, True, False, False])
    r = ihgr_round(c, A, e)
    assert r.lp_solves == 0
    assert sorted(r.selected.tolist()) == [0, 3]
    assert r.cost == pytest.approx(-1.5) and r.lp_bound == pytest.approx(-1.5)
    r2 = ihgr_round(c, A, e, presolve=False)
    assert r2.lp_solves == 1 and sorted(r2.selected.tolist()) == [0, 3]


def random_assignment(rng, m, n, density):
    """A single-scan-like problem: bipartite pairs + a singleton per measurement (TU)."""
    pairs = [(i, j) for i in range(m) for j in range(n) if rng.random() < density]
    k = len(pairs)
    A = np.zeros((m + n, k + m))
    for col, (i, j) in enumerate(pairs):
        A[i, col] = A[m + j, col] = 1
    A[np.arange(m), k + np.arange(m)] = 1
    c = np.concatenate([rng.normal(-1.0, 1.5, k), rng.normal(0.0, 0.5, m)])
    e = np.zeros(m + n, bool)
    e[:m] = True
    return c, A, e


@pytest.mark.slow
def test_single_scan_like_problems_are_solved_exactly_in_one_lp():
    rng = np.random.default_rng(3)
    for _ in range(120):
        c, A, e = random_assignment(
            rng, int(rng.integers(1, 9)), int(rng.integers(1, 9)), rng.uniform(0.1, 0.7)
        )
        r = ihgr_round(c, A, e, presolve=False)
        opt = solve_set_partition(c, A, e, method="milp")
        assert r.cost == pytest.approx(opt.cost, abs=1e-9)
        assert not r.fractional and r.lp_solves <= 1
        assert r.lp_bound == pytest.approx(opt.cost, abs=1e-7)
        assert_feasible(A, e, r.selected)
        rp = ihgr_round(c, A, e)  # with presolve
        assert rp.cost == pytest.approx(opt.cost, abs=1e-9)


def random_multiscan(rng, K=3):
    m = rng.integers(2, 6, K)
    offs = np.concatenate([[0], np.cumsum(m)])
    cols = {
        tuple(
            int(offs[k] + rng.integers(m[k]))
            for k in rng.choice(K, rng.integers(2, K + 1), replace=False)
        )
        for _ in range(int(3 * offs[-1]))
    }
    cols = [tuple(sorted(t)) for t in cols] + [(r,) for r in range(int(offs[-1]))]
    A = np.zeros((int(offs[-1]), len(cols)))
    for k, t in enumerate(cols):
        A[list(t), k] = 1
    c = np.array([-rng.gamma(2.0) * len(t) if len(t) > 1 else 0.0 for t in cols])
    return c, A, np.ones(A.shape[0], bool)


@pytest.mark.slow
def test_multiscan_ihgr_is_feasible_and_bounded_by_lp_and_milp():
    rng = np.random.default_rng(5)
    fractional = 0
    for _ in range(60):
        c, A, e = random_multiscan(rng)
        opt = solve_set_partition(c, A, e, method="milp")
        for fix_ones in (True, False):
            r = ihgr_round(c, A, e, fix_ones=fix_ones, presolve=False)
            assert_feasible(A, e, r.selected)
            assert r.lp_bound <= opt.cost + 1e-7 <= r.cost + 2e-7
            assert 1 <= r.lp_solves <= A.shape[0]
            assert r.cost == pytest.approx(c[r.selected].sum())
        fractional += r.fractional
    assert fractional > 0  # the random 3-scan problems exercise the rounding


def test_at_most_once_rows_without_exact_rows():
    # pure packing: pick the cheapest disjoint negative columns
    A = np.array([[1, 1, 0], [0, 1, 1]])
    c = np.array([-1.0, -1.5, -1.0])
    r = ihgr_round(c, A, np.zeros(2, bool))
    assert r.cost == pytest.approx(-2.0)
    assert sorted(r.selected.tolist()) == [0, 2]


@pytest.mark.parametrize(
    "costs, A, exact, match",
    [
        ([1.0, np.nan], np.eye(2), np.ones(2, bool), "costs"),
        ([1.0], np.eye(2), np.ones(2, bool), "A: has 2 columns"),
        ([1.0, 1.0], [[2, 0], [0, 1]], np.ones(2, bool), "A: entries"),
        ([1.0, 1.0], [[1, 0], [0, 0]], np.ones(2, bool), "A: column 1"),
        ([1.0, 1.0], np.eye(2), [1, 1], "exact"),
        ([1.0, 1.0], np.eye(2), np.ones(3, bool), "exact"),
    ],
)
def test_malformed_problems_raise(costs, A, exact, match):
    with pytest.raises(ValueError, match=match):
        ihgr_round(costs, A, exact)


def test_infeasible_and_unknown_method():
    A = np.array([[1.0], [0.0]])
    with pytest.raises(RuntimeError, match="exact row 1"):
        ihgr_round([0.0], A, np.array([True, True]))
    with pytest.raises(ValueError, match="method"):
        solve_set_partition([0.0], [[1.0]], np.array([True]), method="simplex")
    with pytest.raises(ValueError, match="eps"):
        ihgr_round([0.0], [[1.0]], np.array([True]), eps=0.7)


def test_small_problem_components_partition_as_scipy_does():
    """The union-find of small problems (numba) and scipy's labelling of large ones find the
    same components."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from association.rounding import _components

    rng = np.random.default_rng(4)
    for _ in range(200):
        n_rows, n_cols = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        rows = [
            rng.choice(n_rows, size=int(rng.integers(1, min(n_rows, 3) + 1)), replace=False)
            for _ in range(n_cols)
        ]
        indptr = np.concatenate([[0], np.cumsum([r.size for r in rows])]).astype(np.int64)
        indices = np.concatenate(rows).astype(np.int64)
        k, row_lab, col_lab = _components(n_rows, indptr, indices)
        col = np.repeat(np.arange(n_cols), np.diff(indptr)) + n_rows
        g = sp.coo_array((np.ones(indices.size), (indices, col)), shape=(n_rows + n_cols,) * 2)
        k_ref, ref = connected_components(g, directed=False)
        assert k == k_ref
        # the same partition: the labels map one to one
        pairs = set(zip(np.r_[row_lab, col_lab].tolist(), ref.tolist()))
        assert len(pairs) == k
        np.testing.assert_array_equal(col_lab, row_lab[indices[indptr[:-1]]])


def _csc(A):
    A = np.asarray(A)
    rows = [np.flatnonzero(A[:, h]) for h in range(A.shape[1])]
    indptr = np.concatenate([[0], np.cumsum([r.size for r in rows])]).astype(np.int64)
    return indptr, np.concatenate(rows).astype(np.int64)


def test_both_paths_of_the_csc_rounding_give_the_same_result(monkeypatch):
    """`ihgr_round_csc` settles small problems in one kernel (`_settle`, at most
    `_UNION_FIND_MAX` entries) and large ones by scipy's labelling; forced down the large path,
    every problem gives the same selection, cost, bound and solves, presolve on and off; an
    infeasible problem is refused on both."""
    from association import rounding

    rng = np.random.default_rng(11)
    problems = [random_assignment(rng, int(rng.integers(1, 9)), int(rng.integers(1, 9)), 0.4)]
    problems += [random_multiscan(rng) for _ in range(20)] + [
        random_assignment(rng, int(rng.integers(1, 9)), int(rng.integers(1, 9)), 0.5)
        for _ in range(40)
    ]
    for presolve in (True, False):
        for c, A, e in problems:
            indptr, indices = _csc(A)
            args = (np.asarray(c, float), A.shape[0], indptr, indices, e)
            small = rounding.ihgr_round_csc(*args, presolve=presolve)
            with monkeypatch.context() as m:
                m.setattr(rounding, "_UNION_FIND_MAX", -1)
                large = rounding.ihgr_round_csc(*args, presolve=presolve)
            assert small.selected.tolist() == large.selected.tolist()
            assert (small.cost, small.lp_bound, small.lp_solves) == (
                large.cost,
                large.lp_bound,
                large.lp_solves,
            )
    A = np.array([[1, 0], [0, 0]])  # row 1 exact, no column covers it
    indptr, indices = _csc(A)
    for limit in (rounding._UNION_FIND_MAX, -1):
        monkeypatch.setattr(rounding, "_UNION_FIND_MAX", limit)
        with pytest.raises(RuntimeError, match="exact row 1 has no column"):
            rounding.ihgr_round_csc(np.zeros(2), 2, indptr, indices, np.ones(2, bool))


@pytest.mark.parametrize("rows, exact_len", [([0, 5], 2), ([0, -1], 2), ([0, 1], 1)])
def test_csc_rows_outside_the_problem_are_refused_before_the_kernels(rows, exact_len):
    """The kernels index rows unchecked: a row index outside [0, n_rows) or an `exact` of
    another length is a ValueError, not a read out of bounds (a crash, or a silent answer)."""
    from association.rounding import ihgr_round_csc

    indptr, indices = np.array([0, 1, 2], np.int64), np.array(rows, np.int64)
    with pytest.raises(ValueError, match="ihgr_round_csc: needs exact of shape"):
        ihgr_round_csc(np.zeros(2), 2, indptr, indices, np.ones(exact_len, bool))
