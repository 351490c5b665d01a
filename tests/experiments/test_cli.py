"""The command line: simulate -> extract round trip, reproduce --quick, clear errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from support import simulated_scan_file
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.io.sequence_file import load_sequence

runner = CliRunner()


@pytest.mark.slow
def test_simulate_then_extract_finds_the_pillars(tmp_path):
    scan = tmp_path / "scan.npz"
    res = runner.invoke(
        app,
        [
            "simulate",
            "pillar_court",
            "--pose",
            "0,0,0",
            "--back-to-back",
            "--out",
            str(scan),
            "--seed",
            "3",
        ],
    )
    assert res.exit_code == 0, res.output
    seq = load_sequence(scan)
    assert seq.n_scans == 1 and seq.scan_ranges.shape[1] == 720
    out = tmp_path / "features.json"
    rrd = tmp_path / "run.rrd"
    res = runner.invoke(
        app, ["extract", str(scan), "--method", "geometric", "--out", str(out), "--rerun", str(rrd)]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["schema"] == "trunkslam.features/1" and doc["frame"] == "laser"
    circles = doc["scans"][0]["circles"]
    truth = seq.truth_landmarks
    labels = seq.scan_labels[0]
    found = set()
    for c in circles:
        a, b = c["beams"]
        lab = np.bincount(labels[np.arange(a, b + 1) % labels.size] + 2).argmax() - 2  # majority
        cov = np.array(c["cov"])
        assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)
        if 0 <= lab < len(truth):  # on a pillar (laser frame == world frame at pose 0,0,0)
            assert np.hypot(*(np.array(c["center_xy"]) - truth[lab, :2])) < 0.1
            assert abs(c["radius_m"] - truth[lab, 2]) < 0.05
            found.add(int(lab))
    # every pillar seen with >= 6 beams is extracted
    seen = {k for k in range(len(truth)) if np.sum(labels == k) >= 6}
    assert len(seen) >= 3 and seen <= found
    assert rrd.stat().st_size > 1000


def test_extract_bailey_method(tmp_path):
    scan = simulated_scan_file(tmp_path)
    out = tmp_path / "f.json"
    res = runner.invoke(app, ["extract", str(scan), "--method", "bailey", "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    circles = doc["scans"][0]["circles"]
    seq = load_sequence(scan)
    truth = seq.truth_landmarks
    assert doc["method"] == "bailey" and len(circles) >= 5
    near = [np.min(np.hypot(*(truth[:, :2] - c["center_xy"]).T)) for c in circles]
    assert np.median(near) < 0.15  # Bailey's centres land on the true trunks
    assert all(math.isfinite(c["radius_m"]) for c in circles)


def test_errors_are_one_line_and_exit_1(tmp_path):
    res = runner.invoke(app, ["extract", str(tmp_path / "missing.npz")])
    assert res.exit_code == 1 and "missing.npz" in res.output
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    res = runner.invoke(app, ["extract", str(bad)])
    assert res.exit_code == 1 and "Traceback" not in res.output
    res = runner.invoke(app, ["simulate", "no_such_scene", "--pose", "0,0,0"])
    assert res.exit_code == 1 and "no_such_scene" in res.output


def test_bad_option_values_are_usage_errors_naming_the_option(tmp_path):
    """Choices are typed: a wrong value is click's usage error (exit 2) naming the option and
    listing the choices; nothing runs."""
    scan = simulated_scan_file(tmp_path)
    cases = [
        (["extract", str(scan), "--method", "hough"], "--method", "geometric"),
        (["extract", str(scan), "--line-test", "eq5"], "--line-test", "lrt"),
        (["slam", str(scan), "--features", "kasa"], "--features", "bailey"),
        (["slam", str(scan), "--association", "hungarian"], "--association", "jcbb"),
        (["simulate", "test_yard", "--pose", "1,2"], "--pose", "3 comma-separated"),
        (["simulate", "test_yard", "--pose", "0,0,0", "--sensor", "lidar"], "--sensor", "lms200"),
        (["reproduce", "no_such_experiment", "--out", str(tmp_path)], "names", "circle-sweep"),
    ]
    for args, option, choice in cases:
        res = runner.invoke(app, args)
        out = " ".join(res.output.split())  # the usage box wraps lines
        assert res.exit_code == 2, (args, res.output)
        assert option in out and choice in out, (args, res.output)
    assert not (tmp_path / "manifest.json").exists()


def test_the_cli_choices_are_the_library_names():
    import typer.main

    from association import METHODS as ASSOCIATION_METHODS
    from experiments import cli
    from experiments.paper.runner import EXPERIMENTS
    from experiments.sim import SENSOR_PRESETS
    from features import METHODS as FEATURE_METHODS
    from features.extract import ExtractorParams

    assert tuple(m.value for m in cli.ExtractMethod) == FEATURE_METHODS
    assert tuple(m.value for m in cli.Association) == (
        ASSOCIATION_METHODS[:1] + ("ihgr-window",) + ASSOCIATION_METHODS[1:]
    )
    assert {m.value for m in cli.SlamFeatures} - {"detections"} <= set(FEATURE_METHODS)
    assert tuple(m.value for m in cli.ExperimentName) == tuple(EXPERIMENTS)
    assert {m.value for m in cli.Sensor} == set(SENSOR_PRESETS)
    for v in cli.LineTest:
        ExtractorParams(line_test=v.value)  # accepted
    assert typer.main.get_command(cli.app)  # the app builds


def test_a_bug_is_not_turned_into_a_one_line_message(tmp_path, monkeypatch):
    """Only the project's own errors (and OSError) become `error: ...`; anything else from
    deep inside is a bug and keeps its traceback."""
    import experiments.pipeline.extract as pipeline

    def broken(*args, **kwargs):
        raise ValueError("operands could not be broadcast together")

    monkeypatch.setattr(pipeline, "run_extract", broken)
    (tmp_path / "x.npz").write_bytes(b"")  # there: the command checks that before its work
    res = runner.invoke(app, ["extract", str(tmp_path / "x.npz")])
    assert res.exit_code != 0 and isinstance(res.exception, ValueError)
    assert "error: operands" not in res.output


def test_convert_victoria_park_round_trip(tmp_path, vp_dir):
    out = tmp_path / "vp.npz"
    res = runner.invoke(app, ["convert", "victoria-park", "--data", str(vp_dir), "--out", str(out)])
    assert res.exit_code == 0, res.output
    seq = load_sequence(out)
    assert seq.scan_ranges.shape == (2000, 361)
    assert abs(seq.scan_t[0] - 21.819) < 1e-9 and abs(seq.scan_t[-1] - 448.865) < 1e-9
    assert seq.vehicle.wheelbase_m == 2.83
    np.testing.assert_allclose(seq.laser_pose, [3.78, 0.50, 0.0])


def test_output_errors_and_option_checks(tmp_path):
    scan = simulated_scan_file(tmp_path)
    for out in (tmp_path, tmp_path / "missing_dir" / "f.json"):
        res = runner.invoke(app, ["extract", str(scan), "--out", str(out)])
        assert res.exit_code == 1 and "error:" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "missing_dir").exists()
    res = runner.invoke(app, ["extract", str(scan), "--method", "bailey", "--sigma-r", "0.5"])
    assert res.exit_code == 1 and "bailey" in res.output
    res = runner.invoke(app, ["reproduce", "--seed", "-1", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "seed" in res.output


def test_features_json_records_resolved_parameters_and_files_are_readable(tmp_path):
    scan = simulated_scan_file(tmp_path)
    out = tmp_path / "f.json"
    res = runner.invoke(app, ["extract", str(scan), "--sigma-r", "0.015", "--out", str(out)])
    assert res.exit_code == 0, res.output
    params = json.loads(out.read_text())["params"]
    assert params["sigma_r_m"] == 0.015 and params["gate"] == 6.63 and params["q_m2"] == 1e-4
    assert out.stat().st_mode & 0o777 == 0o644
    assert scan.stat().st_mode & 0o777 == 0o644


@pytest.mark.slow
def test_simulate_drive_then_slam(tmp_path):
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "60", "--seed", "2", "--out", str(run)])
    assert res.exit_code == 0, res.output
    seq = load_sequence(run)
    assert seq.n_scans == 60 and seq.odo_t is not None and seq.truth_landmarks.shape == (8, 3)
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--features", "geometric", "--out", str(out)])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["start"] == "truth" and s["landmarks"] >= 3 and s["scans_skipped"] == 0
    assert max(s["truth"]["mean_abs_error"].values()) < 0.05
    # a scan every 0.5 m of driving (about every other scan), with either association
    cfg = tmp_path / "sparse.toml"
    cfg.write_text("[vehicle]\nmin_travel_m = 0.5\n")
    for extra in ([], ["--window", "2"]):
        res = runner.invoke(
            app, ["slam", str(run), "--config", str(cfg), "--out", str(out), *extra]
        )
        assert res.exit_code == 0, res.output
        s = json.loads((out / "summary.json").read_text())
        assert 20 <= s["scans_skipped"] <= 40 and s["config"]["vehicle"]["min_travel_m"] == 0.5
        assert s["landmarks"] >= 3 and max(s["truth"]["mean_abs_error"].values()) < 0.05


@pytest.mark.slow
def test_slam_with_loop_closure_reports_its_matches(tmp_path):
    """[closure] in a configuration file turns loop closure on: the summary counts the
    constellation matches by outcome. A lap and a half of the tree park maps every tree on
    the first lap and re-finds them with the per-scan gate, so nothing is recent when the car
    is back: no match is tried, nothing merged (no tree mapped twice for the duplicate sweep
    either), and the run stays on its truth."""
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "360", "--seed", "2", "--out", str(run)])
    assert res.exit_code == 0, res.output
    cfg = tmp_path / "closure.toml"
    cfg.write_text("[closure]\nenabled = true\nold_s = 20.0\nrecent_s = 10.0\nmin_pairs = 3\n")
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--config", str(cfg), "--out", str(out)])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    c = s["closures"]
    parts = ("accepted", "not_jointly_compatible", "beyond_dead_reckoning", "no_margin", "too_few")
    assert c["tried"] == sum(c[k] for k in parts) == 0 and c["landmarks_merged"] == 0
    assert c["duplicates_merged"] == 0
    assert len(c["accepted_closures"]) == c["accepted"] and s["config"]["closure"]["enabled"]
    assert max(s["truth"]["mean_abs_error"].values()) < 0.05
    res = runner.invoke(app, ["slam", str(run), "--out", str(out)])
    assert "closures" not in json.loads((out / "summary.json").read_text())


def test_slam_with_the_ihgr_window(tmp_path):
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "2", "--out", str(run)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--window", "2", "--out", str(out)])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["association"] == "ihgr-window" and s["config"]["association"]["window_scans"] == 2
    assert s["window"]["K"] == 2 and s["window"]["steps"] == 40 and s["landmarks"] >= 3
    assert "window_scans = 2" in (out / "config.toml").read_text()
    res = runner.invoke(app, ["slam", str(run), "--association", "ihgr-window", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads((out / "summary.json").read_text())["window"]["K"] == 3
    res = runner.invoke(
        app, ["slam", str(run), "--window", "2", "--association", "jcbb", "--out", str(out)]
    )
    assert res.exit_code != 0 and "--window" in res.output


def test_a_run_with_a_laser_latency_is_scored_and_smoothed_at_its_poses_times(tmp_path):
    """[vehicle] laser_latency_s: the EKF's and the smoother's truth errors are taken at the
    poses' own times (stamps minus the latency), and the smoother still recognises the run's
    input sequence."""
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "4", "--out", str(run)])
    assert res.exit_code == 0, res.output
    cfg = tmp_path / "latency.toml"
    cfg.write_text("[vehicle]\nlaser_latency_s = 0.05\n")
    out = tmp_path / "out"
    res = runner.invoke(
        app, ["slam", str(run), "--config", str(cfg), "--out", str(out), "--smooth"]
    )
    assert res.exit_code == 0, res.output
    ekf, sm = (json.loads((out / n).read_text()) for n in ("summary.json", "smoother.json"))
    assert ekf["config"]["vehicle"]["laser_latency_s"] == 0.05
    assert sm["scored"] == str(run) and sm["truth"]["scans_scored"] == ekf["truth"]["scans_scored"]
    assert sum(sm["truth"]["mean_abs_error"].values()) < 1.0


def test_slam_smooth_and_smooth_after_the_fact(tmp_path):
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "80", "--seed", "4", "--out", str(run)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--out", str(out), "--smooth"])
    assert res.exit_code == 0, res.output
    assert "smoothed (batch): chi2/dof" in res.output
    for name in (
        "run_log.npz",
        "trajectory_smoothed.tum",
        "trajectory_smoothed.csv",
        "map_smoothed.csv",
        "smoother.json",
    ):
        assert (out / name).stat().st_size > 100, name
    ekf, sm = (json.loads((out / n).read_text()) for n in ("summary.json", "smoother.json"))
    assert sm["solver"] == "batch" and sm["landmarks"] == ekf["landmarks"]
    assert 0.2 < sm["chi2_per_dof"] < 3 and sm["chi2_per_dof"] < sm["initial_chi2_per_dof"]
    assert sm["scored"] == str(run) and sm["truth"]["scans_scored"] == 79
    # scored against the same truth as the EKF (smoother vs EKF over several runs: test_paper_slam;
    # on one 80-scan run either can be ahead)
    assert sm["truth"]["mean_abs_error"].keys() == ekf["truth"]["mean_abs_error"].keys()
    assert sum(sm["truth"]["mean_abs_error"].values()) < 0.1
    rows = (out / "trajectory_smoothed.csv").read_text().splitlines()
    assert len(rows) == 81 and rows[0].startswith("t_s,rear_axle_x_world_m")
    # after the fact, with the other solver and all measurements
    res = runner.invoke(
        app, ["smooth", str(out), "--solver", "isam2", "--polish", "--measurements", "all"]
    )
    assert res.exit_code == 0, res.output
    again = json.loads((out / "smoother.json").read_text())
    assert again["solver"] == "isam2+polish" and again["measurements"] == "all"
    assert again["n_measurements"] > sm["n_measurements"]


def test_smooth_without_or_with_a_corrupt_run_log_is_a_clear_error(tmp_path):
    res = runner.invoke(app, ["smooth", str(tmp_path / "nowhere")])
    assert res.exit_code == 1 and "not a folder" in res.output
    res = runner.invoke(app, ["smooth", str(tmp_path)])
    assert res.exit_code == 1 and "no run log" in res.output
    (tmp_path / "run_log.npz").write_bytes(b"PK\x03\x04 not really a zip")
    res = runner.invoke(app, ["smooth", str(tmp_path)])
    assert res.exit_code == 1 and "not a readable .npz run log" in res.output
    np.savez(tmp_path / "run_log.npz", format=np.array("something else"))
    res = runner.invoke(app, ["smooth", str(tmp_path)])
    assert res.exit_code == 1 and "not a run log" in res.output
    np.savez(tmp_path / "run_log.npz", format=np.array("trunkslam.run_log/1"), scan_t=np.ones(3))
    res = runner.invoke(app, ["smooth", str(tmp_path)])
    assert res.exit_code == 1 and "missing required variable(s)" in res.output
    res = runner.invoke(app, ["smooth", str(tmp_path), "--robust", "tukey"])
    assert res.exit_code == 2


def test_run_log_round_trip_and_inconsistent_content(tmp_path):
    from experiments.io.run_log import read_run_log, write_run_log
    from slam import run_slam
    from slam.smoother import MEAS_TENTATIVE

    path = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "1", "--out", str(path)])
    assert res.exit_code == 0, res.output
    log = run_slam(load_sequence(path), features="geometric")
    write_run_log(tmp_path / "run_log.npz", log)
    ekf, names = read_run_log(tmp_path)
    everything, _ = read_run_log(tmp_path / "run_log.npz", measurements="all")
    assert names == {"features": "geometric", "association": "ihgr"}
    assert not np.any(ekf.meas_kind == MEAS_TENTATIVE)
    assert everything.n_measurements > ekf.n_measurements
    np.testing.assert_array_equal(ekf.init_pose, log.pose)
    np.testing.assert_array_equal(ekf.odo_cov, log.odo_cov)
    data = dict(np.load(tmp_path / "run_log.npz"))
    data["meas_landmark"] = data["meas_landmark"] + 10_000
    np.savez(tmp_path / "run_log.npz", **data)
    with pytest.raises(DataError, match="meas_landmark"):
        read_run_log(tmp_path)


def test_extract_with_a_configuration_takes_its_extractor_parameters(tmp_path):
    """`extract --config cycab --method geometric` extracts as a run of that preset does
    (paper-faithful: no short trunks), records those parameters, and --sigma-r still replaces one; a
    config file is an input (never an output), and a bad one is an error naming it."""
    from experiments.io.config_file import load_slam_config
    from features import extract_features

    scene = tmp_path / "pole.json"  # a 0.1 m pole 15 m away: 2 beams, a short trunk
    scene.write_text(
        json.dumps({"circles": [{"name": "p", "center_xy": [15, 0], "radius_m": 0.1}]})
    )
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate", str(scene), "--pose", "0,0,0", "--out", str(run)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "f.json"
    # the cycab preset's extractor is the paper-faithful one: no short trunks
    args = ["extract", str(run), "--method", "geometric", "--config", "cycab"]
    res = runner.invoke(app, [*args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["params"]["short_trunks"] is False and doc["params"]["short_trunk_clearance_m"] == 2
    params = load_slam_config("cycab").features.extractor
    seq = load_sequence(run)
    want = [extract_features(seq.scan(k), "geometric", params) for k in range(seq.n_scans)]
    assert [len(s["circles"]) for s in doc["scans"]] == [f.n_circles for f in want]
    assert sum(f.n_circles for f in want) < sum(
        extract_features(seq.scan(k), "geometric").n_circles for k in range(seq.n_scans)
    )  # the preset's setting is really used: the default finds the pole
    res = runner.invoke(app, [*args, "--sigma-r", "0.03", "--out", str(out)])
    assert res.exit_code == 0 and json.loads(out.read_text())["params"]["sigma_r_m"] == 0.03
    cfg = tmp_path / "my.toml"
    cfg.write_text('[features.extractor]\nshort_trunks = "yes"\n')
    res = runner.invoke(app, ["extract", str(run), "--config", str(cfg), "--out", str(out)])
    assert res.exit_code == 1 and "short_trunks" in res.output and str(cfg) in res.output
    cfg.write_text("[features.extractor]\nshort_trunks = true\n")
    res = runner.invoke(app, ["extract", str(run), "--config", str(cfg), "--out", str(cfg)])
    assert res.exit_code == 1 and "input" in res.output
    assert cfg.read_text() == "[features.extractor]\nshort_trunks = true\n"


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "pillar_court", "--pose", "0,0,0", "--noise", "1e300"],
        ["simulate", "pillar_court", "--pose", "0,0,0", "--noise", "-1"],
        ["slam", "run.npz", "--ellipse-scale", "inf"],
    ],
)
def test_options_out_of_their_range_are_refused_by_name(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.replace("│", " ").split())  # rich's box, its lines joined
    assert any(f"'{option}'" in text for option in ("--noise", "--ellipse-scale")), text
    assert "equal to" in text, text  # the allowed range, said
    assert not list(tmp_path.iterdir())  # nothing written
