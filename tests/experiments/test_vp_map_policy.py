"""The map policy's settings from Victoria Park scans 1-2000
(experiments/paper/victoria_park/map_policy.py): the rules on hand-made figures, the
experiment on the data, and the preset's confirm_scans derived again."""

from __future__ import annotations

import json

import numpy as np
import pytest

from experiments.paper.victoria_park.map_policy import BIN_EDGES_M, derive, derive_confirm


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


def sweep(f1: dict) -> list[dict]:
    return [{"confirm_scans": k, "f1": v} for k, v in f1.items()]


def test_derive_confirm_takes_the_best_f1_and_the_fewer_scans_on_a_tie():
    assert derive_confirm(sweep({2: 0.75, 3: 0.87, 4: 0.92, 5: 0.91, 6: 0.88})) == 4
    assert derive_confirm(sweep({5: 0.91, 2: 0.75, 4: 0.92, 3: 0.87, 6: 0.88})) == 4  # any order
    assert derive_confirm(sweep({2: 0.7, 3: 0.9, 4: 0.9, 5: 0.8})) == 3
    # a candidate without a score (no landmark judged) is never chosen
    assert derive_confirm(sweep({2: 0.7, 3: float("nan"), 4: 0.8, 5: 0.6})) == 4


def test_derive_confirm_refuses_a_maximum_at_an_end_of_the_candidates():
    from experiments.errors import DataError

    with pytest.raises(DataError, match=r"highest at confirm_scans = 6, an end of the candidates"):
        derive_confirm(sweep({2: 0.7, 3: 0.8, 4: 0.85, 5: 0.86, 6: 0.9}))
    with pytest.raises(DataError, match="confirm_scans = 2"):
        derive_confirm(sweep({2: 0.9, 3: 0.8, 4: 0.7}))
    with pytest.raises(DataError, match="no candidate confirm_scans has an F1"):
        derive_confirm(sweep({2: float("nan"), 3: float("nan")}))


@pytest.mark.slow
@pytest.mark.data
def test_the_presets_confirm_scans_is_derived_again_from_scans_1_2000(vp_dir):
    """The procedure rerun on scans 1-2000 with the preset gives the preset's confirm_scans,
    and the maximum is one: the F1 falls on both sides of it."""
    from experiments.io.config_file import load_slam_config, preset_path
    from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
    from experiments.paper.victoria_park.map_policy import FIT_SCANS, confirm_sweep

    # the calibration derives confirm_scans before the pass offset: white errors
    cfg = load_slam_config(preset_path("victoria_park_ute")).with_(
        **{"measurement.pass_offset_sd_m": [0.0, 0.0]}
    )
    rows = confirm_sweep(
        load_victoria_park(n_scans=FIT_SCANS), cfg, load_ss2002_reference(), candidates=(3, 4, 5)
    )
    assert derive_confirm(rows) == cfg.map_policy.confirm_scans == 4
    f1 = [r["f1"] for r in rows]
    assert f1[0] < f1[1] > f1[2]
    # fewer landmarks and a higher precision with each more scan asked for
    assert rows[0]["landmarks"] > rows[1]["landmarks"] > rows[2]["landmarks"]
    assert rows[0]["precision"] < rows[1]["precision"] < rows[2]["precision"]


@pytest.mark.slow
@pytest.mark.data
def test_map_policy_experiment_on_the_first_scans(vp_dir, tmp_path):
    from typer.testing import CliRunner

    from experiments.cli import app

    out = tmp_path / "r"
    res = CliRunner().invoke(
        app,  # one worker: no pool of processes to start
        ["reproduce", "victoria-park-map-policy", "--quick", "--workers", "1", "--out", str(out)],
    )
    assert res.exit_code == 0, res.output
    cfg = json.loads((out / "manifest.json").read_text())["config"]["victoria-park-map-policy"]
    assert cfg["scans"] == 1000
    assert cfg["confirm_scans"] in (3, 4, 5)
    rows = (out / "victoria_park_confirm.csv").read_text().splitlines()
    assert rows[0].split(",") == [
        "confirm_scans",
        "landmarks",
        "recall",
        "precision",
        "f1",
        "f1_1_1000",
        "f1_1001_2000",
        "one_tree_pairs",
    ]
    assert [int(r.split(",")[0]) for r in rows[1:]] == [2, 3, 4, 5, 6]
    assert 0 < cfg["prune_range_m"] <= 80 and 0 < cfg["prune_hit_ratio"] <= 0.5
    rows = (out / "victoria_park_pruning.csv").read_text().splitlines()
    assert rows[0] == "landmarks,range_from_m,range_to_m,expected,detected,rate"
    assert any(r.startswith("established,") for r in rows[1:])
