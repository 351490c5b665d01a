"""`trunkslam reproduce features --quick`: every promised output, and a manifest to re-create it."""

from __future__ import annotations

import csv
import json

import pytest
from support import assert_outputs, assert_tidy_tables, quick_reproduce


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    return quick_reproduce(tmp_path_factory, "features", seed=7)


@pytest.mark.slow
def test_outputs_exist(quick_run):
    names = ["classification.md", "classification.csv", "classification.png", "features.rrd"]
    assert_outputs(quick_run, names + ["manifest.json"], 501)


@pytest.mark.slow
def test_victoria_park_figure_with_data(quick_run, vp_dir):
    assert (quick_run / "fig_vp_scan.png").stat().st_size > 500


def test_victoria_park_figure_skipped_and_said_without_data(tmp_path, monkeypatch):
    """Without the data, the Victoria Park trial says so (for the manifest) and returns the
    recording (its layout, no scans) but no figure."""
    from support import read_recording

    from experiments.paper.features import victoria_park_trial

    monkeypatch.setenv("TRUNKSLAM_DATA", str(tmp_path / "nowhere"))
    got = victoria_park_trial(True)
    assert got["victoria_park"].startswith("skipped")
    assert set(got["files"]) == {"features.rrd"}
    (tmp_path / "features.rrd").write_bytes(got["files"]["features.rrd"])
    rec = read_recording(tmp_path / "features.rrd")
    assert rec["blueprints"] == 1 and not any(e.startswith("laser/scan") for e in rec["entities"])


@pytest.mark.slow
def test_manifest_records_how_to_recreate(quick_run):
    m = json.loads((quick_run / "manifest.json").read_text())
    assert m["seed"] == 7 and m["quick"] is True and m["experiments"] == ["features"]
    assert m["config"]["features"]["extractor_defaults"]["gate"] == 6.63
    assert m["config"]["features"]["extractor_defaults"]["q_m2"] == 1e-4
    assert m["versions"]["numpy"] and "features" in m["seconds"]
    assert "classification.csv" in m["outputs"]


@pytest.mark.slow
def test_classification_table_is_consistent(quick_run):
    rows = list(csv.DictReader((quick_run / "classification.csv").open()))
    assert list(rows[0]) == ["radius_m", "range_m", "beams_on_trunk", "line_test", "circle_rate"]
    assert len(rows) == 25 * 2  # 5 radii x 5 ranges x 2 line tests
    big = [r for r in rows if float(r["beams_on_trunk"]) >= 8 and r["line_test"] == "lrt"]
    assert big and all(float(r["circle_rate"]) >= 0.75 for r in big)


@pytest.mark.slow
def test_classification_table_is_tidy(quick_run):
    assert assert_tidy_tables(quick_run) == {"classification.csv"}


@pytest.mark.slow
def test_features_recording_carries_its_layout(quick_run, vp_dir):
    from support import read_recording

    rec = read_recording(quick_run / "features.rrd")
    assert {
        "laser/scan",
        "laser/features/paper/circles",
        "laser/features/bailey/circles",
        "series/circles_per_scan",
    } <= rec["entities"]
    assert {"scan", "time"} <= rec["timelines"]
    assert {v[0] for v in rec["views"]} == {"2D", "TimeSeries"}
