"""evo_ape run on our outputs exactly as the README documents it (issue 25).

Victoria Park: the GPS fixes are fewer than the scans, so `--sync_method interpolation` makes evo
resample the run at each fix's time, the pairing of our scorer (`experiments.eval.gps`), and
`--t_max_diff 0.11` lets every fix match (a fix inside the run is within half the longest scan
interval, 0.1075 s, of a scan). evo's figures must then be ours up to the antenna lever arm (see
`experiments.pipeline.reference`). Simulated drive: evo against truth.tum is our pose error at
every scan; against the 10 Hz GPS, denser than the scans, evo compares each scan with the GPS
interpolated there, which averages part of the GPS noise away.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from experiments.cli import app
from experiments.eval.gps import fixes_in_run, score_sequence
from experiments.eval.poses import pose_errors
from experiments.io.sequence_file import load_sequence
from experiments.sim.trajectory import CycabParams
from slam import interpolate_poses

EVO_APE = Path(sys.executable).parent / "evo_ape"
EVO_SYNC = "--sync_method interpolation --t_max_diff 0.11"

VP_RECIPE = [  # scans 1-2000; the README's --full run follows the same steps
    "trunkslam convert victoria-park --out vp.npz",
    "trunkslam slam vp.npz --features detections --config victoria_park_ute --out vp_out",
    "trunkslam export-reference vp.npz --out vp_ref",
]
VP_EVO = f"evo_ape tum vp_ref/gps.tum vp_out/trajectory_gps_antenna.tum {EVO_SYNC}"
VP_EVO_CLEAN = f"evo_ape tum vp_ref/gps_clean.tum vp_out/trajectory_gps_antenna.tum {EVO_SYNC}"

SIM_RECIPE = [
    "trunkslam simulate-drive tree_park --scans 240 --seed 0 --out run.npz",
    "trunkslam slam run.npz --out slam_out",
    "trunkslam export-reference run.npz --out ref",
]
SIM_EVO_TRUTH = f"evo_ape tum ref/truth.tum slam_out/trajectory.tum {EVO_SYNC}"
SIM_EVO_GPS = f"evo_ape tum ref/gps.tum slam_out/trajectory_gps_antenna.tum {EVO_SYNC}"

ROUNDING_M = 1e-5  # our files keep positions to 1e-6 m (TUM) and 9 digits (CSV)
SUMMARY_ROUNDING_M = 5e-5  # summary.json rounds the GPS figures to 4 decimals


def _trunkslam(command: str) -> str:
    args = shlex.split(command)
    assert args[0] == "trunkslam"
    res = CliRunner().invoke(app, args[1:])
    assert res.exit_code == 0, res.output
    return res.output


def _evo_ape(command: str, results: Path):
    """Run the documented evo_ape command (the venv's) and read what it saved: (stats, stamps,
    per-pose errors)."""
    from evo.tools import file_interface

    args = shlex.split(command)
    assert args[0] == "evo_ape"
    proc = subprocess.run(
        [str(EVO_APE), *args[1:], "--save_results", str(results), "--no_warnings"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    res = file_interface.load_res_file(str(results))
    return res.stats, res.np_arrays["timestamps"], res.np_arrays["error_array"]


def _trajectory(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    tr = np.loadtxt(run_dir / "trajectory.csv", delimiter=",", skiprows=1)
    return tr[:, 0], tr[:, 1:4]


@pytest.mark.slow
@pytest.mark.data
def test_evo_ape_on_victoria_park_equals_our_gps_score(vp_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for command in VP_RECIPE:
        _trunkslam(command)
    ours = json.loads(Path("vp_out/summary.json").read_text())["gps"]
    seq = load_sequence("vp.npz")
    stats, stamps, errors = _evo_ape(VP_EVO, tmp_path / "gps.zip")

    # the same fixes: every fix inside the run, none outside (1139 of the 4466 for scans 1-2000)
    inside = fixes_in_run(seq.gps_t, seq.scan_t)
    assert errors.size == ours["matched"] == inside.sum() == 1139
    np.testing.assert_allclose(stamps, seq.gps_t[inside], atol=1e-6)

    # the same pairing, fix by fix: ours interpolates the pose and places the antenna on it, evo
    # interpolates the antenna point; the two differ by at most |a| (1 - cos(dtheta / 2)) for
    # the heading change dtheta across the fix's scan interval (the chord against the arc)
    scan_t, pose = _trajectory(Path("vp_out"))
    mine = score_sequence(seq, scan_t, pose)
    assert mine.all_rmse == pytest.approx(ours["all_rmse"], abs=SUMMARY_ROUNDING_M)
    k = np.clip(np.searchsorted(scan_t, stamps), 1, scan_t.size - 1)
    heading = np.unwrap(pose[:, 2])
    lever = np.hypot(*seq.gps_pose[:2]) * (1 - np.cos((heading[k] - heading[k - 1]) / 2))
    assert np.all(np.abs(errors - mine.errors) <= lever + ROUNDING_M)

    # so the RMSE differs by at most the RMS of those bounds (under 2 mm here), the median by
    # at most their largest (the median moves no more than any one error)
    rms_bound = float(np.sqrt(np.mean(lever**2)))
    assert rms_bound < 2e-3
    tol = rms_bound + ROUNDING_M + SUMMARY_ROUNDING_M
    assert stats["rmse"] == pytest.approx(ours["all_rmse"], abs=tol)
    assert stats["median"] == pytest.approx(ours["all_median"], abs=lever.max() + tol)

    # gps_clean.tum: the fixes the scorer keeps after flagging jumps, and its clean RMSE
    stats_c, _, errors_c = _evo_ape(VP_EVO_CLEAN, tmp_path / "clean.zip")
    assert errors_c.size == ours["matched"] - ours["jumps"]
    assert ours["jumps"] > 0  # the clean file really leaves fixes out
    assert stats_c["rmse"] == pytest.approx(ours["clean_rmse"], abs=tol)


@pytest.mark.slow
def test_evo_ape_on_a_simulated_drive(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    printed = [_trunkslam(command) for command in SIM_RECIPE]
    summary = json.loads(Path("slam_out/summary.json").read_text())
    # the run prints the truth RMSE and export-reference the evo call that gives it back
    assert f"{summary['truth']['rmse_m']:.3f} m RMS from truth" in printed[1]
    assert "evo_ape tum ref/truth.tum RUN/trajectory.tum --sync_method interpolation" in printed[2]
    seq = load_sequence("run.npz")
    scan_t, pose = _trajectory(Path("slam_out"))

    # against truth: every scan, each with its pose error as our summary computes it (truth
    # interpolated at the scan's time); scan 0 starts at the truth, the summary leaves it out
    stats, stamps, errors = _evo_ape(SIM_EVO_TRUTH, tmp_path / "truth.zip")
    assert errors.size == seq.n_scans == summary["truth"]["scans_scored"] + 1 == 240
    np.testing.assert_allclose(stamps, seq.scan_t, atol=1e-6)
    e = pose_errors(pose, interpolate_poses(scan_t, seq.truth_t, seq.truth_pose))
    mean_abs = np.mean(np.abs(e[1:, :2]), axis=0)
    ours_mean = summary["truth"]["mean_abs_error"]
    np.testing.assert_allclose(mean_abs, [ours_mean["dx_m"], ours_mean["dy_m"]], atol=1e-7)
    np.testing.assert_allclose(errors, np.hypot(e[:, 0], e[:, 1]), atol=ROUNDING_M)
    assert errors[0] == 0.0
    assert stats["rmse"] == pytest.approx(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)), abs=1e-6)
    assert stats["rmse"] == pytest.approx(summary["truth"]["rmse_m"], abs=ROUNDING_M)

    # against the GPS: 478 fixes at 10 Hz against 240 scans, so evo interpolates the GPS at each
    # scan; the interpolation averages the fixes' independent noise (variance 2 sigma^2 in 2D) to
    # between half and all of it, so evo's mean square is below ours, by at most 2 sigma^2
    stats, stamps, errors = _evo_ape(SIM_EVO_GPS, tmp_path / "gps.zip")
    ours = summary["gps"]
    assert ours["matched"] == seq.gps_t.size == 478
    assert errors.size == seq.n_scans
    np.testing.assert_allclose(stamps, seq.scan_t, atol=1e-6)
    sigma = CycabParams().dgps_sigma_m
    assert stats["rmse"] < ours["all_rmse"]
    assert ours["all_rmse"] ** 2 - stats["rmse"] ** 2 < 2 * sigma**2
