"""GPS scoring by hand, TUM files that evo reads, features JSON driving slam."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.eval.gps import flag_jumps, score_against_gps
from experiments.io.features_json import load_features_json

runner = CliRunner()


def test_gps_score_by_hand_with_a_lever_arm_and_a_jump():
    """The rear axle drives along x at 1 m/s, heading 0; the antenna sits at (1, 0.5). Fixes at
    t = 0..9 s lie 0.3 m north of the antenna, except fix 5 (a 20 m jump). Poses are given every
    2 s, so the fixes at odd seconds need interpolation."""
    scan_t = np.arange(0.0, 10.0, 2.0)  # 0, 2, ..., 8: fix 9 is after the last pose
    pose = np.column_stack([scan_t, np.zeros(5), np.zeros(5)])
    gps_t = np.arange(10.0)
    gps = np.column_stack([gps_t + 1.0, np.full(10, 0.8)])
    gps[5, 0] += 20.0
    s = score_against_gps(scan_t, pose, gps_t, gps, np.array([1.0, 0.5, 0.0]), max_speed_mps=5)
    assert s.matched == 9 and s.unmatched == 1 and s.jumps == 1 and s.jump[5]
    e = np.full(9, 0.3)
    e[5] = math.hypot(20.0, 0.3)
    assert s.all_rmse == pytest.approx(math.sqrt(np.mean(e**2)))
    assert s.all_median == pytest.approx(0.3) and s.clean_rmse == pytest.approx(0.3)
    assert s.clean_rmse_aligned == pytest.approx(0.0, abs=1e-9)  # a pure offset aligns away
    assert s.rotation_deg == pytest.approx(0.0, abs=1e-9)
    # the antenna matters: scoring the rear axle instead is 1 m worse along x
    s0 = score_against_gps(scan_t, pose, gps_t, gps, np.zeros(3), max_speed_mps=5)
    assert s0.clean_rmse == pytest.approx(math.hypot(1.0, 0.8))


def test_jump_flags():
    t = np.arange(6.0)
    xy = np.column_stack([t, np.zeros(6)])
    xy[2, 1] = 30.0  # one fix off
    xy[4:, 1] = 30.0  # a lasting shift: every later fix is a jump from the last good one
    assert flag_jumps(t, xy, 2.0).tolist() == [False, False, True, False, True, True]


def test_reference_and_trajectory_tum_files_are_read_by_evo(tmp_path):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    run = tmp_path / "run.npz"
    assert runner.invoke(app, ["simulate-drive", "--scans", "40", "--out", str(run)]).exit_code == 0
    res = runner.invoke(app, ["export-reference", str(run), "--out", str(tmp_path / "ref")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["slam", str(run), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    truth = file_interface.read_tum_trajectory_file(str(tmp_path / "ref" / "truth.tum"))
    est = file_interface.read_tum_trajectory_file(str(tmp_path / "out" / "trajectory.tum"))
    gps = file_interface.read_tum_trajectory_file(str(tmp_path / "ref" / "gps.tum"))
    ant = file_interface.read_tum_trajectory_file(
        str(tmp_path / "out" / "trajectory_gps_antenna.tum")
    )
    assert est.num_poses == 40 and gps.num_poses > 60
    ref, est = sync.associate_trajectories(truth, est, max_diff=1e-3)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    errs = summary["truth"]["mean_abs_error"]
    assert ape.get_statistic(metrics.StatisticsType.rmse) < 0.05
    assert (
        ape.get_statistic(metrics.StatisticsType.mean)
        <= math.hypot(errs["dx_m"], errs["dy_m"]) * 1.5
    )
    # against the simulated 2 cm DGPS at the antenna, evo and our scorer agree
    g, a = sync.associate_trajectories(gps, ant, max_diff=0.03)
    ape.process_data((g, a))
    assert ape.get_statistic(metrics.StatisticsType.rmse) < 0.1
    assert summary["gps"]["all_rmse"] < 0.1


def test_features_json_drives_slam_like_the_extractor(tmp_path):
    run = tmp_path / "run.npz"
    runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "3", "--out", str(run)])
    feats = tmp_path / "f.json"
    res = runner.invoke(app, ["extract", str(run), "--method", "geometric", "--out", str(feats)])
    assert res.exit_code == 0, res.output
    a = tmp_path / "a"
    b = tmp_path / "b"
    runner.invoke(app, ["slam", str(run), "--features", "geometric", "--out", str(a)])
    res = runner.invoke(app, ["slam", str(run), "--features-file", str(feats), "--out", str(b)])
    assert res.exit_code == 0, res.output
    ta = np.loadtxt(a / "trajectory.tum")
    tb = np.loadtxt(b / "trajectory.tum")
    np.testing.assert_allclose(tb, ta, atol=2e-6)  # the JSON keeps 12 digits of covariance
    assert json.loads((b / "summary.json").read_text())["features"] == "geometric"


def test_features_json_errors_name_the_scan(tmp_path):
    circle = {"center_xy": [1.0, 2.0], "radius_m": 0.3, "cov": [[0.0] * 3] * 3, "beams": [3, 7]}
    scans = [
        {"scan": 0, "stamp_s": 0.0, "circles": [circle]},
        {"scan": 1, "stamp_s": 0.2, "circles": []},
    ]
    good = {"schema": "trunkslam.features/1", "method": "paper", "scans": scans}
    path = tmp_path / "f.json"
    path.write_text(json.dumps(good))
    f = load_features_json(path, 2, 361)
    assert f[0].n_circles == 1 and f[1].n_circles == 0 and f[0].method == "paper"
    assert np.isnan(f[0].circle_rms_m[0])  # absent residual
    with pytest.raises(DataError, match="has 2 scans, the sequence 3"):
        load_features_json(path, 3)
    bad = json.loads(json.dumps(good))
    bad["scans"][0]["circles"][0]["center_xy"] = [None, 2.0]
    path.write_text(json.dumps(bad))
    with pytest.raises(DataError, match=r"scans\[0\]: a circle centre is not finite"):
        load_features_json(path, 2)
    bad["scans"][0]["circles"][0] = {"center_xy": [1, 2]}
    path.write_text(json.dumps(bad))
    with pytest.raises(DataError, match=r"scans\[0\]\.circles\[0\]: needs"):
        load_features_json(path, 2)
    path.write_text("{not json")
    with pytest.raises(DataError, match="not a features JSON"):
        load_features_json(path, 2)


def test_the_25_ms_rule_chooses_fixes_by_the_scans_own_stamps():
    """A run that placed its scans 60 ms before their stamps (a laser latency): the fixes within
    25 ms of a scan are those near the stamps, not near the poses' times."""
    gps_t = np.arange(10) * 0.2
    gps = np.column_stack([gps_t, np.zeros(10)])
    stamps = gps_t[1:-1] + 0.01
    pose_t = stamps - 0.06
    pose = np.column_stack([pose_t, np.zeros((pose_t.size, 2))])
    by_pose = score_against_gps(pose_t, pose, gps_t, gps, np.zeros(3), max_speed_mps=5)
    by_stamp = score_against_gps(
        pose_t, pose, gps_t, gps, np.zeros(3), max_speed_mps=5, stamps=stamps
    )
    assert by_pose.rfs_fixes == 0  # every pose time is 50 ms from a fix
    assert by_stamp.rfs_fixes == by_stamp.matched == 7  # fixes 0.2 .. 1.4 s, in the run's span
    assert by_stamp.all_rmse == by_pose.all_rmse  # the pairing of fixes to poses is unchanged
    with pytest.raises(ValueError, match="stamps"):
        score_against_gps(pose_t, pose, gps_t, gps, np.zeros(3), 5, stamps=stamps[:-1])


def test_a_simulated_runs_true_trees_are_its_reference_map(tmp_path):
    """export-reference writes the true trees as trees.csv, which `slam --reference-map` reads:
    the map's GOSPA against them is in summary.json, its count of trees the scene's."""
    from experiments.io.reference_map import read_reference_map
    from experiments.io.sequence_file import load_sequence

    run = tmp_path / "run.npz"
    assert runner.invoke(app, ["simulate-drive", "--scans", "30", "--out", str(run)]).exit_code == 0
    res = runner.invoke(app, ["export-reference", str(run), "--out", str(tmp_path / "ref")])
    assert res.exit_code == 0, res.output
    trees = read_reference_map(tmp_path / "ref" / "trees.csv")
    np.testing.assert_array_equal(trees, load_sequence(run).truth_landmarks[:, :2])
    out = tmp_path / "out"
    args = ["slam", str(run), "--reference-map", str(tmp_path / "ref" / "trees.csv")]
    res = runner.invoke(app, [*args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    scores = json.loads((out / "summary.json").read_text())["reference_map"]
    assert scores["gospa_20m"]["distance"] > 0 and "GOSPA" in res.output
