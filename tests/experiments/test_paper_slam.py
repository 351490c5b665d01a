"""Experiment 2 (Tables 3 and 4): the simulated Cycab runs, false detections, golden numbers,
the outputs of `run_table34` and of `trunkslam slam` (`slam_command`)."""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest
from regenerate_golden import FILES, slam_rng
from support import assert_tidy_tables

from experiments.eval.detections import false_detections
from experiments.eval.gospa import gospa
from experiments.io.results import MAP_COLUMNS, TRAJECTORY_COLUMNS
from experiments.io.sequence_file import save_sequence
from experiments.paper.reproduce import run_experiments
from experiments.paper.runner import RunContext
from experiments.paper.slam import PAPER_TABLE3, SCAN_SETS, Exp2Config, key_figures, monte_carlo
from experiments.paper.slam import run as run_experiment2
from experiments.pipeline.slam import run_slam_file
from experiments.render.viz import NullRecorder, Recorder
from experiments.sim import load_scene
from experiments.sim.trajectory import CycabParams, simulate_cycab_run
from features.types import Features
from slam import NullVisualiser, SlamConfig
from slam.vehicle import AckermannModel, Odometry, integrate


def test_cycab_run_truth_odometry_dgps_and_labels():
    p = CycabParams(n_scans=60, speed_sigma_mps=0.0, steer_sigma_rad=0.0)
    seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", p)
    assert seq.n_scans == 60 and seq.scan_labels.shape == seq.scan_ranges.shape == (60, 361)
    # exact odometry reproduces the truth at every scan (same zero-order hold, exact arcs)
    car = AckermannModel.from_vehicle(seq.vehicle)
    odo = Odometry(seq.odo_t, seq.odo_speed, seq.odo_steer)
    pose = seq.truth_pose[0]
    for k in range(1, 60):
        pose = integrate(car, pose, odo, seq.scan_t[k - 1], seq.scan_t[k])[0]
        i = int(np.flatnonzero(seq.truth_t == seq.scan_t[k])[0])
        d = pose - seq.truth_pose[i]
        d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
        assert np.abs(d).max() < 1e-9
    # DGPS at 10 Hz on its own clock, 2 cm noise about the laser position
    assert np.allclose(np.diff(seq.gps_t), 0.1) and seq.gps_t[0] == pytest.approx(0.03)
    np.testing.assert_array_equal(seq.gps_pose, p.laser_pose)


def test_tree_park_route_and_noise_statistics():
    seq = simulate_cycab_run(np.random.default_rng(1))
    scene = load_scene("tree_park")
    assert len(scene.circles) == 8 and len(scene.walls) >= 1 and len(scene.bushes) >= 1
    assert seq.n_scans >= 170  # Table 4 counts scans 10-160
    d = np.hypot(
        *(seq.truth_pose[:, None, :2] - seq.truth_landmarks[None, :, :2]).transpose(2, 0, 1)
    )
    assert d.min() > 2.0  # the car never brushes a trunk
    # odometry noise: readings minus the hold the truth was built with
    p = CycabParams()
    noiseless = simulate_cycab_run(
        np.random.default_rng(1),
        "tree_park",
        dataclasses.replace(p, speed_sigma_mps=0.0, steer_sigma_rad=0.0),
    )
    dv = seq.odo_speed - noiseless.odo_speed
    assert np.std(dv) == pytest.approx(p.speed_sigma_mps, rel=0.05)  # 957 samples
    np.testing.assert_array_equal(seq.truth_pose, noiseless.truth_pose)


def _one_circle(beams, xy):
    f = Features.empty(0.0, "paper")
    return dataclasses.replace(
        f,
        circle_params=np.array([[xy[0], xy[1], 0.3]]),
        circle_cov=np.zeros((1, 3, 3)),
        circle_beams=np.array([beams]),
        circle_rms_m=np.zeros(1),
    )


def test_false_detection_rule():
    lm = np.array([[10.0, 0.0, 0.3], [0.0, 10.0, 0.3]])
    labels = np.full(361, -1)
    labels[100:110] = 0  # trunk 0
    labels[200:206] = 5  # a bush
    labels[300:304] = 1
    labels[304:310] = 5
    pose = np.zeros(3)
    assert false_detections(_one_circle((100, 109), (10.0, 0.2)), labels, pose, lm) == (1, 0)
    assert false_detections(_one_circle((100, 109), (10.0, 0.9)), labels, pose, lm) == (1, 1)
    assert false_detections(_one_circle((200, 205), (5.0, 5.0)), labels, pose, lm) == (1, 1)
    assert false_detections(_one_circle((300, 309), (0.0, 10.0)), labels, pose, lm) == (1, 1)
    assert false_detections(Features.empty(), labels, pose, lm) == (0, 0)


@pytest.mark.slow
def test_quick_run_matches_golden_numbers():
    """Tolerances: Table 4 depends only on the seeded simulation and the extractors (1e-6);
    Table 3 and the NEES also on the filter and the association (LP solver, BLAS): 5% and 10%
    relative; map sizes (means over 4 runs) to within one landmark in one run (0.25).
    Regenerate with `python tests/regenerate_golden.py slam` after a deliberate change."""
    golden = json.loads(FILES["slam"].read_text())
    res = monte_carlo(Exp2Config.quick(), slam_rng())
    got = key_figures(res)
    assert got["n_runs"] == golden["n_runs"] and got["n_scans"] == golden["n_scans"]
    for m in ("paper", "geometric", "bailey"):
        g, x = golden[m], got[m]
        np.testing.assert_allclose(x["table4"], g["table4"], atol=1e-6, err_msg=m)
        np.testing.assert_allclose(x["table3_mean"], g["table3_mean"], rtol=0.05, err_msg=m)
        assert x["nees_mean"] == pytest.approx(g["nees_mean"], rel=0.10), m
        assert x["map_size_mean"] == pytest.approx(g["map_size_mean"], abs=0.26), m
        assert x["map_on_trees_mean"] == pytest.approx(g["map_on_trees_mean"], abs=0.26), m
    # the paper's direction holds in this run
    for i in range(3):
        assert got["paper"]["table3_mean"][i] < got["bailey"]["table3_mean"][i]
    # the smoother (each pose informed by the whole run) is at or below the EKF over the runs
    for m in ("paper", "geometric", "bailey"):
        assert sum(got[m]["smoother_table3_mean"]) <= sum(got[m]["table3_mean"]), m


@pytest.mark.slow
def test_experiment2_writes_every_output(tmp_path):
    ctx = RunContext(out_dir=tmp_path, seed=3)
    cfg = Exp2Config(n_runs=2, cycab=CycabParams(n_scans=40), sensitivity=False)
    res = run_experiment2(ctx, cfg)
    assert ctx.deferred  # the recording and the figures are made on the executor
    ctx.finish()
    assert not ctx.deferred
    names = sorted(p.name for p in ctx.outputs)
    for n in (
        "table3.md",
        "table3.csv",
        "table4.md",
        "table4.csv",
        "consistency.md",
        "fig7_slam_path.png",
        "fig10_innovations.png",
        "fig11_pose_errors.png",
        "nees.png",
        "slam.rrd",
        "slam_key_figures.json",
    ):
        assert n in names and (tmp_path / n).stat().st_size > 0, n
    assert ctx.config["table3"]["n_runs"] == 2
    rows = list(csv.DictReader((tmp_path / "table3.csv").open()))
    assert list(rows[0]) == ["source", "method", "estimator", "quantity", "unit", "statistic"] + [
        "value"
    ]
    dx = [r for r in rows if r["quantity"] == "dx" and r["source"] == "simulation"]
    got = {(r["method"], r["estimator"], r["statistic"]): float(r["value"]) for r in dx}
    assert got[("paper", "ekf", "mean")] == res.abs_err["paper"][:, 0].mean()  # full precision
    assert got[("paper", "ekf", "std")] == res.abs_err["paper"][:, 0].std(ddof=1)
    pub = [r for r in rows if r["source"] == "paper_published"]
    assert [float(r["value"]) for r in pub if r["method"] == "paper"] == list(PAPER_TABLE3["paper"])
    t4 = list(csv.DictReader((tmp_path / "table4.csv").open()))
    rates = [r for r in t4 if r["quantity"] == "false_detection_rate"]
    assert {(int(r["first_scan"]), int(r["last_scan"])) for r in rates} == set(SCAN_SETS)
    cons = list(csv.DictReader((tmp_path / "consistency.csv").open()))
    assert float(cons[0]["nees_bound_low"]) < 3 < float(cons[0]["nees_bound_high"])
    # the map's GOSPA against every tree of the scene: run 0's from its map, the column the mean
    trees = res.seq0.truth_landmarks[:, :2]
    for m in ("paper", "bailey"):
        g = gospa(res.logs0[m].landmark_xy, trees, p=2, c=20.0, alpha=2)
        assert res.gospa[m]["gospa_20m"][0] == g.distance
        assert res.gospa[m]["gospa_20m_missed"][0] == 200.0 * g.n_missed
        row = next(r for r in cons if r["method"] == m)
        assert float(row["gospa_20m"]) == pytest.approx(res.gospa[m]["gospa_20m"].mean())
        parts = sum(float(row[f"gospa_1m_{k}"]) for k in ("localisation", "missed", "false"))
        assert parts == pytest.approx(np.mean(res.gospa[m]["gospa_1m"] ** 2))
    assert assert_tidy_tables(tmp_path) == {"table3.csv", "table4.csv", "consistency.csv"}


@pytest.mark.slow
def test_table3_and_table4_are_one_run_with_the_config_under_both_names(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(
        "experiments.paper.slam.Exp2Config.quick",
        classmethod(lambda cls: cls(n_runs=1, cycab=CycabParams(n_scans=20), sensitivity=False)),
    )
    import experiments.paper.slam as exp2

    real = exp2.monte_carlo
    monkeypatch.setattr(exp2, "monte_carlo", lambda *a, **k: calls.append(1) or real(*a, **k))
    run_experiments(["table3", "table4"], tmp_path, quick=True)
    assert len(calls) == 1
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert m["config"]["table4"] == m["config"]["table3"] and m["config"]["table3"]["n_runs"] == 1
    assert "table3 table4" in m["seconds"]


def test_slam_command_writes_trajectory_map_and_summary(tmp_path):
    seq = simulate_cycab_run(np.random.default_rng(4), "tree_park", CycabParams(n_scans=50))
    src = save_sequence(seq, tmp_path / "run.npz")
    out = tmp_path / "out"
    cfg = SlamConfig().with_(**{"features.method": "geometric", "association.method": "ihgr"})
    summary = run_slam_file(src, cfg, out, rerun_path=tmp_path / "run.rrd")
    tum = np.loadtxt(out / "trajectory.tum")
    assert tum.shape == (50, 8)
    np.testing.assert_allclose(tum[:, 0], seq.scan_t)
    np.testing.assert_allclose(np.linalg.norm(tum[:, 4:8], axis=1), 1.0)
    np.testing.assert_allclose(tum[0, 1:3], seq.truth_pose[0, :2], atol=1e-9)  # starts at truth
    yaw = 2 * np.arctan2(tum[:, 6], tum[:, 7])
    rows = list(csv.DictReader((out / "trajectory.csv").open()))
    assert len(rows) == 50 and float(rows[0]["var_x_m2"]) == 0.0
    assert list(rows[0]) == list(TRAJECTORY_COLUMNS)  # point, frame and units in the names
    np.testing.assert_allclose(
        np.cos(yaw), np.cos([float(r["heading_world_rad"]) for r in rows]), atol=1e-6
    )
    lm = list(csv.DictReader((out / "map.csv").open()))
    assert len(lm) == summary["landmarks"] >= 3
    assert list(lm[0]) == list(MAP_COLUMNS)
    # the radius: the circles' median, close to the true tree it sits on (geometric fit)
    matched = 0
    for row in lm:
        xy = np.array([float(row["x_world_m"]), float(row["y_world_m"])])
        d = np.hypot(*(seq.truth_landmarks[:, :2] - xy).T)
        if d.min() < 0.3:
            assert abs(float(row["radius_m"]) - seq.truth_landmarks[d.argmin(), 2]) < 0.05
            matched += 1
    assert matched >= 3
    s = json.loads((out / "summary.json").read_text())
    assert s["features"] == "geometric" and s["association"] == "ihgr" and s["start"] == "truth"
    assert s["truth"]["mean_abs_error"]["dx_m"] < 0.1
    assert set(s["timing"]) >= {"predict", "associate", "update", "total"}
    assert (tmp_path / "run.rrd").stat().st_size > 0


def test_recorders_implement_the_visualiser_interface():
    wanted = {n for n in dir(NullVisualiser) if not n.startswith("_")}
    for cls in (NullRecorder, Recorder):
        missing = wanted - {n for n in dir(cls) if not n.startswith("_")}
        assert not missing, (cls.__name__, missing)
