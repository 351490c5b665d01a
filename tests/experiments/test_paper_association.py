"""The association experiment (`trunkslam reproduce association`) and benchmark, in quick form."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from support import assert_outputs, assert_tidy_tables, quick_reproduce

from association import wrap_angle
from experiments.sim.landmarks import LandmarkSimConfig, simulate_landmark_scans


def test_simulator_is_consistent_with_its_covariances():
    """True pairings have chi-square(2) innovations: mean NIS 2, about 1% outside the gate."""
    rng = np.random.default_rng(0)
    nis = []
    for _ in range(150):
        s = simulate_landmark_scans(LandmarkSimConfig(n_scans=1, clutter_per_scan=0.0), rng)[0]
        ok = s.truth >= 0
        for i, j in zip(np.flatnonzero(ok), s.truth[ok]):
            nu = s.z[i] - s.z_hat[j]
            nu[1] = wrap_angle(nu[1])
            S = s.H[j] @ s.P @ s.H[j].T + s.R
            nis.append(float(nu @ np.linalg.solve(S, nu)))
    nis = np.array(nis)
    assert nis.size > 1000
    assert nis.mean() == pytest.approx(2.0, abs=0.25)
    assert (nis > -2 * math.log(0.01)).mean() < 0.03


def test_simulator_truth_labels():
    cfg = LandmarkSimConfig(unmapped_fraction=0.3, clutter_per_scan=5.0)
    seq = simulate_landmark_scans(cfg, np.random.default_rng(1))
    assert len(seq) == cfg.n_scans
    for s in seq:
        n = s.z_hat.shape[0]
        assert s.H.shape == (n, 2, 3 + 2 * n) and s.P.shape == (3 + 2 * n,) * 2
        assert s.truth.shape == s.truth_landmark.shape == (s.z.shape[0],)
        mapped = s.truth >= 0
        # a mapped measurement's feature is its landmark
        np.testing.assert_array_equal(s.feature_ids[s.truth[mapped]], s.truth_landmark[mapped])
        assert np.all((s.z[:, 1] > -np.pi) & (s.z[:, 1] <= np.pi))


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    return quick_reproduce(tmp_path_factory, "association", seed=3)


@pytest.mark.slow
def test_quick_run_writes_tables_plot_and_optimality(quick_run):
    names = ["association.md", "association.csv", "association.png"]
    assert_outputs(
        quick_run, names + ["association_optimality.md", "association_optimality.csv"], 501
    )
    rows = list(csv.DictReader((quick_run / "association.csv").open()))
    methods = {r["method"] for r in rows}
    assert methods == {"IHGR (single scan)", "IHGR (K = 3 window)", "JCBB", "NN"}
    assert {r["sweep"] for r in rows} == {"clutter", "density", "pose"}
    for r in rows:
        assert 0.5 <= float(r["correct_rate"]) <= 1.0
        total = float(r["correct_rate"]) + float(r["false_pair_rate"])
        assert total <= 1.0 + 1e-9
        assert (r["jcbb_budget_hits"] != "") == (r["method"] == "JCBB")


@pytest.mark.slow
def test_quick_run_tables_are_tidy(quick_run):
    # association_optimality.csv (every instance) is summarised, not pivoted, in its Markdown
    assert assert_tidy_tables(quick_run) == {"association.csv", "association_loop.csv"}


@pytest.mark.slow
def test_quick_run_has_the_in_the_loop_section(quick_run):
    assert "## In the SLAM loop" in (quick_run / "association.md").read_text()
    rows = list(csv.DictReader((quick_run / "association_loop.csv").open()))
    tree = [r for r in rows if r["data"].startswith("tree park")]
    assert {r["data"] for r in tree} == {f"tree park, odometry noise x{s}" for s in (1, 2, 4)}
    assert {r["method"] for r in tree} == {
        "IHGR (single scan)",
        "IHGR window K = 2",
        "IHGR window K = 3",
        "IHGR window K = 4",
        "JCBB",
        "NN",
    }
    for r in tree:
        assert 0 <= int(r["false_pairings"]) <= int(r["updates"])
        assert 4 <= float(r["landmarks"]) <= 12 and int(r["missed_trees"]) <= 2
        assert 0 < float(r["pose_error_m"]) < 0.5
        window = r["method"].startswith("IHGR window")
        assert bool(r["window_lps_fractional"]) == bool(r["window_steps"]) == window
        if window:
            frac, steps = int(r["window_lps_fractional"]), int(r["window_steps"])
            assert steps == 2 * 120 and 0 <= frac <= steps
            assert 0 <= int(r["window_steps_rounded"]) <= steps


@pytest.mark.slow
def test_quick_run_single_scan_ihgr_is_always_optimal(quick_run):
    rows = list(csv.DictReader((quick_run / "association_optimality.csv").open()))
    single = [r for r in rows if r["family"].startswith("single")]
    assert single and all(abs(float(r["gap"])) < 1e-6 for r in single)
    assert all(r["fractional"] == "False" for r in single)
    for r in rows:  # IHGR never beats the optimum, and the LP bound is below both
        assert float(r["gap"]) >= -1e-6
        assert float(r["lp_bound"]) <= float(r["optimum"]) + 1e-6
    md = (quick_run / "association_optimality.md").read_text()
    assert "IHGR cost -1.000 after 2 LP solves" in md


def test_bench_rows():
    from experiments.bench.association import bench, format_table

    calls = []
    rows = bench(repeats=3, seed=1, progress=lambda *a: calls.append(a))
    n = calls[-1][2]  # the scans, warm-up ones included
    assert calls[0] == ("association scans", 0, n) and calls[-1] == ("association scans", n, n)
    assert [r["method"] for r in rows][1:] == [
        "IHGR single scan",
        "IHGR single scan, presolve off",
        "IHGR K = 3 window",
        "JCBB (node budget 20000)",
        "NN (gated, greedy)",
    ]
    assert all(0 < r["median_ms"] <= r["p90_ms"] for r in rows)
    assert "median ms/scan" in format_table(rows)
