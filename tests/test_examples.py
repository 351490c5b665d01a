"""Every script in examples/ runs, and prints the numbers it should."""

from __future__ import annotations

import json
import math
import re
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.sim import CycabParams, load_scene, sensor_preset, simulate_scan

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
GOLDEN_SLAM = json.loads(
    (Path(__file__).parent / "golden" / "exp_slam_quick.json").read_text(encoding="utf-8")
)
# A single run's Table-3 errors are bounded by 3 times the mean of the quick Monte Carlo
# (tests/golden/exp_slam_quick.json, `paper` features: about 0.015 m, 0.008 m, 0.0013 rad);
# dead reckoning on the same drive is 4-10 times that mean (0.061 m, 0.078 m, 0.013 rad).
RUN_BOUND = 3.0


def run_example(name: str, monkeypatch, capsys, *args: str) -> str:
    path = EXAMPLES / name
    monkeypatch.setattr(sys, "argv", [str(path), *map(str, args)])
    runpy.run_path(str(path), run_name="__main__")
    return capsys.readouterr().out


def table3(out: str, label: str = "") -> np.ndarray:
    m = re.search(
        rf"{label}\s*mean absolute error: dx ([\d.]+) m, dy ([\d.]+) m, dtheta ([\d.]+) rad", out
    )
    assert m, out
    return np.array([float(v) for v in m.groups()])


def test_extract_one_scan(tmp_path, monkeypatch, capsys):
    out = run_example("extract_one_scan.py", monkeypatch, capsys, tmp_path)
    # the pillars the scan hits with at least 5 beams (the fits need 4 beams on the arc; 5
    # leaves one for a beam lost at the arc's edge): the same scan, the same seed
    scene = load_scene("pillar_court")
    sensor = sensor_preset("pls200", back_to_back=True)
    _, labels = simulate_scan(scene, scene.scan_positions[3], sensor, np.random.default_rng(0))
    names = [c.name for c in scene.circles]
    hits = np.bincount(labels[labels >= 0], minlength=len(names))[: len(names)]
    visible = {n for n, h in zip(names, hits) if h >= 5}
    assert len(visible) >= 6
    saved = json.loads((tmp_path / "features.json").read_text())
    pillar = re.compile(
        r"^\s+(paper|geometric)\s+(\S+)\s+range\s+[\d.]+ m\s+centre error ([\d.]+) m "
        r"\(sigma ([\d.]+)\)",
        re.M,
    )
    for method in ("paper", "geometric"):
        found = [(n, float(e), float(s)) for m, n, e, s in pillar.findall(out) if m == method]
        assert visible <= {n for n, _, _ in found}, (method, found)
        # each centre within 4 sigma of its pillar, sigma along the widest axis of the fit's own
        # covariance: a Gaussian error goes beyond it with probability exp(-8) = 3e-4
        for n, err, sigma in found:
            assert err <= 4 * sigma, (method, n, err, sigma)
        others = re.findall(rf"^\s+{method}\s+\S+\s+range .* not a circle", out, re.M)
        n_printed = len(found) + len(others)
        assert n_printed == len(saved[method]["circles"])
        assert f"{method}: {n_printed} circles" in out


@pytest.mark.slow
def test_slam_simulated_drive(tmp_path, monkeypatch, capsys):
    out = run_example("slam_simulated_drive.py", monkeypatch, capsys, tmp_path)
    err = table3(out)
    bound = RUN_BOUND * np.array(GOLDEN_SLAM["paper"]["table3_mean"])
    assert np.all(err < bound), (err, bound)
    tum = np.loadtxt(tmp_path / "trajectory.tum")
    assert tum.shape == (240, 8) and (tmp_path / "run.npz").is_file()


@pytest.mark.slow
def test_smooth_a_run(tmp_path, monkeypatch, capsys):
    out = run_example("smooth_a_run.py", monkeypatch, capsys, tmp_path)
    ekf, smoothed = table3(out, "ekf"), table3(out, "smoothed")
    golden = GOLDEN_SLAM["paper"]
    assert np.all(ekf < RUN_BOUND * np.array(golden["table3_mean"])), ekf
    assert np.all(smoothed < RUN_BOUND * np.array(golden["smoother_table3_mean"])), smoothed
    # Levenberg-Marquardt starts at the EKF's estimate and never raises the cost
    m = re.search(r"chi2 ([\d.]+) at the EKF's estimate -> ([\d.]+) \((\d+) dof", out)
    assert m, out
    assert float(m[2]) < float(m[1])
    for name in ("ekf", "smoothed"):
        assert np.loadtxt(tmp_path / f"trajectory_{name}.tum").shape == (240, 8)


@pytest.mark.slow
def test_score_against_gps(tmp_path, monkeypatch, capsys):
    """The example scores a `trunkslam slam` run exactly as its summary.json does, and its own
    simulated run is the CLI's `simulate-drive tree_park --scans 240 --seed 0` run with the
    cycab preset."""
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for args in (
        "simulate-drive tree_park --scans 240 --seed 0 --out run.npz",
        "slam run.npz --config cycab --out slam_out",
    ):
        res = runner.invoke(app, args.split())
        assert res.exit_code == 0, res.output
    ours = json.loads(Path("slam_out/summary.json").read_text())["gps"]
    pattern = r"all fixes:\s+RMSE ([\d.]+) m, median ([\d.]+) m, p95 ([\d.]+) m"

    out = run_example("score_against_gps.py", monkeypatch, capsys, "run.npz", "slam_out")
    figures = [float(v) for v in re.search(pattern, out).groups()]
    expected = [ours["all_rmse"], ours["all_median"], ours["all_p95"]]
    np.testing.assert_allclose(figures, expected, atol=1e-4)  # both rounded to 4 decimals
    assert f"{ours['matched']} fixes in the run's time span" in out
    assert json.loads(Path("slam_out/gps_score.json").read_text())["all_rmse"] == ours["all_rmse"]

    out = run_example("score_against_gps.py", monkeypatch, capsys, "own")  # a single OUT_DIR
    figures = [float(v) for v in re.search(pattern, out).groups()]
    np.testing.assert_allclose(figures, expected, atol=1e-4)
    assert json.loads(Path("own/gps_score.json").read_text())["all_rmse"] == ours["all_rmse"]
    # no path beats the DGPS noise: each fix carries 2D noise of RMS sqrt(2) sigma, so the RMSE
    # over 478 fixes is at least that less 4 standard errors (about 2% each)
    assert figures[0] > math.sqrt(2) * CycabParams().dgps_sigma_m * 0.9


@pytest.mark.slow
def test_rosbag_round_trip(tmp_path, monkeypatch, capsys):
    """The example's errors are those of the same drive built in memory as the bag holds it
    (a unicycle's twist, float32 ranges and angles): the bag changes nothing; and they are
    within a run's bound of the car's Monte Carlo mean (a unicycle on the car's drive does as
    well as the car's own model, tests/slam/test_motion.py)."""
    from experiments.sim import simulate_cycab_run
    from slam import Sequence, interpolate_poses, run_slam, se2

    out = run_example("rosbag_round_trip.py", monkeypatch, capsys, tmp_path)
    assert (tmp_path / "drive" / "metadata.yaml").is_file()
    assert "120 scans, 477 odometry samples (twist); laser pose (1.55, 0, 0) from /tf_static" in out
    drive = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=120))
    f32 = np.float32
    robot = Sequence(
        scan_t=np.round(drive.scan_t * 1e9) / 1e9,
        scan_ranges=drive.scan_ranges.astype(f32).astype(float),
        scan_angle_min=float(f32(drive.scan_angle_min)),
        scan_angle_increment=float(f32(drive.scan_angle_increment)),
        scan_max_range=float(f32(drive.scan_max_range)),
        laser_pose=drive.laser_pose,
        odo_t=np.round(drive.odo_t * 1e9) / 1e9,
        odo_speed=drive.odo_speed,
        odo_yaw_rate=drive.odo_speed * np.tan(drive.odo_steer) / drive.vehicle.wheelbase_m,
        vehicle={"model": "unicycle"},
    )
    log = run_slam(robot, features="paper")
    truth = interpolate_poses(drive.scan_t, drive.truth_t, drive.truth_pose)
    rel = np.array([se2.compose(se2.inverse(truth[0]), p) for p in truth])
    err = (log.pose - rel)[1:]
    err[:, 2] = se2.wrap_angle(err[:, 2])
    err = np.abs(err)
    printed = table3(out)
    np.testing.assert_allclose(printed, err.mean(axis=0), atol=6e-5)  # printed to 4-5 decimals
    assert np.all(printed < RUN_BOUND * np.array(GOLDEN_SLAM["paper"]["table3_mean"])), printed
