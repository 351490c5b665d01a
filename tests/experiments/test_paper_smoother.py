"""`trunkslam reproduce smoother --quick` and `bench smoother`: GTSAM's graph and the EKF's run
re-solved, with the data; skipped and said without."""

from __future__ import annotations

import csv
import json

import pytest
from support import assert_outputs, assert_tidy_tables, quick_reproduce

from experiments.bench.smoother import format_table


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory, vp_dir):
    return quick_reproduce(tmp_path_factory, "smoother", seed=0)


@pytest.mark.slow
def test_outputs_and_figures(quick_run):
    names = ["smoother.md", "vp_smoother_map.png", "vp_smoother_errors.png", "manifest.json"]
    assert_outputs(quick_run, names, 501)
    assert_outputs(quick_run, ["smoother.csv"], 200)


@pytest.mark.slow
def test_table_rows(quick_run):
    rows = list(csv.DictReader((quick_run / "smoother.csv").open()))
    graph, *runs = rows
    assert graph["poses"] == "6969" and graph["landmarks"] == "151"
    assert float(graph["chi2_per_dof"]) <= 1.0 and graph["rmse_m"] == ""
    assert [r["problem"] for r in runs] == [
        *["Victoria Park, 1500 scans"] * 2,
        *["Victoria Park, 1500 scans, loop closure"] * 2,
    ]
    for ekf, smoothed in (runs[:2], runs[2:]):
        assert ekf["solver"] == "EKF" and smoothed["solver"] == "smoother (batch)"
        assert ekf["landmarks"] == smoothed["landmarks"] and ekf["poses"] == "1500"
        assert 0.1 < float(smoothed["chi2_per_dof"]) < 5
        # both within a few metres of the GPS on the first 1500 scans, on every protocol
        for key in ("rmse_m", "rmse_vouched_m", "rmse_rfs_m"):
            assert float(ekf[key]) < 5 and float(smoothed[key]) < 5


@pytest.mark.slow
def test_manifest_says_what_each_part_ran(quick_run):
    """The parts finished after the other experiments (the runs) still reach the manifest."""
    cfg = json.loads((quick_run / "manifest.json").read_text())["config"]["smoother"]
    assert cfg["gtsam_graph"]["method"].startswith("isam2")
    assert cfg["victoria_park"] == {"preset": "victoria_park_ute", "scans": 1500, "closure": False}
    assert cfg["victoria_park_closure"]["closure"] is True


@pytest.mark.slow
def test_table_is_tidy(quick_run):
    assert assert_tidy_tables(quick_run) == {"smoother.csv"}


def test_skipped_and_said_without_data(tmp_path, monkeypatch):
    from experiments.paper.runner import RunContext
    from experiments.paper.smoother import run

    monkeypatch.setenv("TRUNKSLAM_DATA", str(tmp_path / "nowhere"))
    ctx = RunContext(out_dir=tmp_path)
    run(ctx)
    assert ctx.config["smoother"]["gtsam_graph"].startswith("skipped")
    assert ctx.config["smoother"]["victoria_park"].startswith("skipped")
    assert ctx.config["smoother"]["victoria_park_closure"].startswith("skipped")
    assert not ctx.outputs


def test_bench_table_says_the_machine():
    text = format_table([{"problem": "p", "solver": "batch", "seconds": 1.0}])
    assert "GTSAM smoother seconds" in text and "| p | batch | 1 |" in text and "cores" in text
