"""The shipped Victoria Park preset's laser latency is what the calibration's rule
(`derive_latency`) makes of the latency profile the calibration wrote into the docs snapshot
(`docs/results/victoria_park_latency.csv`): the preset and the page's table cannot drift apart."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from experiments.io.config_file import load_slam_config
from experiments.paper.victoria_park.calibration import derive_latency

PROFILE = Path(__file__).resolve().parents[2] / "docs" / "results" / "victoria_park_latency.csv"


def test_the_presets_latency_is_the_vertex_of_the_snapshots_profile():
    with PROFILE.open() as f:
        rows = [(float(r["latency_ms"]) / 1e3, float(r["j"])) for r in csv.DictReader(f)]
    assert len(rows) >= 3
    latency = load_slam_config("victoria_park_ute").vehicle.laser_latency_s
    assert latency > 0.0  # the profile's vertex lies inside its grid, above 0
    assert latency == pytest.approx(derive_latency(rows), rel=1e-9, abs=0.0)
