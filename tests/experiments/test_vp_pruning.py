"""The map policy's pruning settings from the Victoria Park detection rates (experiments/paper/
vp_pruning.py): the rule on hand-made counts, and the experiment on the data."""

from __future__ import annotations

import json

import numpy as np
import pytest

from experiments.paper.vp_pruning import BIN_EDGES_M, derive


def rates(established: list[float]) -> dict:
    n = BIN_EDGES_M.size - 1
    e = np.full(n, 1000)
    d = np.zeros(n, np.int64)
    d[: len(established)] = np.round(np.array(established) * 1000).astype(np.int64)
    return {"established_expected": e, "established_detected": d}


def test_derive_follows_its_rule_on_a_hand_computed_case():
    # rates 0.7, 0.6, 0.75 then 0.45: the range ends at 15 m, the lowest rate inside is 0.6,
    # the ratio 0.3; a tree seen at 0.6 falls below 0.3 of n scans with probability
    # P(X <= 2 | 10) = 0.0123, P(X <= 3 | 11) = 0.0293, P(X <= 3 | 12) = 0.0153,
    # P(X <= 3 | 13) = 0.0078: the first n at or under 1% is 13
    got = derive(rates([0.7, 0.6, 0.75, 0.45, 0.8]))
    assert got["prune_range_m"] == 15.0
    assert got["prune_hit_ratio"] == 0.3
    assert got["prune_after_expected"] == 13
    assert got["lowest_established_rate"] == pytest.approx(0.6)


def test_derive_starts_at_the_first_bin_seen_half_the_time_and_refuses_none():
    from experiments.errors import DataError

    # a nearest bin under half (trunks passing the laser's side) is not the run's start
    got = derive(rates([0.4, 0.7, 0.65, 0.3]))
    assert got["prune_range_m"] == 15.0
    assert got["lowest_established_rate"] == pytest.approx(0.65)
    with pytest.raises(DataError, match="under half the scans in which they are in view in every"):
        derive(rates([0.4, 0.3, 0.45]))


@pytest.mark.slow
@pytest.mark.data
def test_pruning_experiment_on_the_first_scans(vp_dir, tmp_path):
    from typer.testing import CliRunner

    from experiments.cli import app

    out = tmp_path / "r"
    res = CliRunner().invoke(
        app, ["reproduce", "victoria-park-pruning", "--quick", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    cfg = json.loads((out / "manifest.json").read_text())["config"]["victoria-park-pruning"]
    assert cfg["scans"] == 1000
    assert 0 < cfg["prune_range_m"] <= 80 and 0 < cfg["prune_hit_ratio"] <= 0.5
    rows = (out / "victoria_park_pruning.csv").read_text().splitlines()
    assert rows[0] == "landmarks,range_from_m,range_to_m,expected,detected,rate"
    assert any(r.startswith("established,") for r in rows[1:])
