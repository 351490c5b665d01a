"""`trunkslam smooth RUN_DIR`: re-solve a `trunkslam slam` run with the GTSAM smoother."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.eval.gps import score_sequence
from experiments.eval.missing import null_scores
from experiments.eval.poses import nees, pose_errors
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.config_file import load_slam_config
from experiments.io.outputs import add_to_manifest, check_output_file, lock_folder
from experiments.io.results import map_csv, trajectory_csv, trajectory_tum
from experiments.io.run_log import RUN_LOG_NAME, read_run_log
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import dumps_json, write_atomic
from slam import interpolate_poses
from slam.smoother import MEAS_INIT, Problem, SmootherOptions, SmootherResult, smooth

__all__ = ["smooth_run", "smoother_summary"]


def smooth_run(
    run_dir: Path | str,
    options: SmootherOptions | None = None,
    measurements: str = "ekf",
    progress=None,
) -> dict:
    """Solve the run in `run_dir` (its `run_log.npz`) and write beside it

    trajectory_smoothed.tum   the smoothed rear-axle path (TUM, like trajectory.tum)
    trajectory_smoothed.csv   the same with each pose's marginal covariance (world frame)
    map_smoothed.csv          the smoothed map with marginal covariances (map.csv's columns;
                              first_scan: the scan of its initialising measurement, n_obs: its
                              measurements in the graph)
    smoother.json             solver, chi-square, degrees of freedom, chi-square per degree of
                              freedom, iterations, seconds, pass_variables (the pass landmarks
                              of a run with measurement.pass_offset_model "state", 0 without);
                              errors against GPS and the truth (as summary.json's) when the
                              run's input file is still there

    Returns the smoother.json summary. measurements: "ekf" or "all" (`slam.smoother`).
    progress: callback(stage, done, total), as `slam.smoother.smooth`'s.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a folder (expected the output folder of trunkslam slam)")
    with lock_folder(run_dir, "RUN_DIR"):
        return _smooth_held(run_dir, options, measurements, progress)


# the files the smoother writes beside the run, smoother.json last
SMOOTHED = (
    "trajectory_smoothed.tum",
    "trajectory_smoothed.csv",
    "map_smoothed.csv",
    "smoother.json",
)


def _smooth_held(run_dir: Path, options, measurements: str, progress) -> dict:
    """`smooth_run` with the run folder held (`lock_folder`, so that no other trunkslam command
    replaces the run between reading its log and writing beside it). The files are listed in
    the run's manifest first, and smoother.json, removed first, is written last: present, it
    says the smoothed files beside it are of one smoothing. Before writing, the run is checked
    to be still the one read (the folder and its run log unchanged), in case something other
    than trunkslam replaced it."""
    for name in SMOOTHED:  # before any work: a link or FIFO planted there is refused
        check_output_file(run_dir / name, "RUN_DIR")
    read = _identity(run_dir)
    problem, names = read_run_log(run_dir, measurements)
    result = smooth(problem, options, progress)
    if _identity(run_dir) != read:
        raise DataError(
            f"{run_dir}: the run was replaced while it was being smoothed (its folder or "
            "run_log.npz changed); nothing written, smooth it again"
        )
    add_to_manifest(run_dir, SMOOTHED)
    (run_dir / "smoother.json").unlink(missing_ok=True)
    write_atomic(run_dir / "trajectory_smoothed.tum", trajectory_tum(problem.scan_t, result.pose))
    write_atomic(
        run_dir / "trajectory_smoothed.csv",
        trajectory_csv(problem.scan_t, result.pose, result.pose_cov),
    )
    write_atomic(run_dir / "map_smoothed.csv", _map(problem, result))
    summary = {
        "run_dir": str(run_dir),
        **names,
        "measurements": measurements,
        **smoother_summary(problem, result),
        **_scores(run_dir, problem, result),
    }
    summary = null_scores(summary, ("gps", "truth"), {
        "chi2_per_dof": "no degree of freedom (as many unknowns as residuals)",
        "initial_chi2_per_dof": "no degree of freedom (as many unknowns as residuals)",
        "gps": "no or too few GPS fixes within the run to compute it",
    })  # fmt: skip
    write_atomic(run_dir / "smoother.json", dumps_json(summary))
    return summary


def _identity(run_dir: Path) -> tuple:
    """What changes when the run is replaced: the folder (a swap makes a new one) and its log."""
    folder = os.stat(run_dir)
    try:
        log = os.stat(run_dir / RUN_LOG_NAME)
    except FileNotFoundError:
        return (folder.st_dev, folder.st_ino, None)
    return (folder.st_dev, folder.st_ino, log.st_ino, log.st_size, log.st_mtime_ns)


def smoother_summary(problem: Problem, r: SmootherResult) -> dict:
    """The solve's figures: solver, counts, chi-square per degree of freedom, time."""
    return {
        "solver": r.solver,
        "robust": r.robust,
        "n_scans": problem.n_scans,
        "n_measurements": problem.n_measurements,
        "landmarks": int(problem.landmark_id.size),
        "pass_variables": r.pass_variables,
        "chi2": r.chi2,
        "dof": r.dof,
        "chi2_per_dof": r.chi2_per_dof,
        "initial_chi2_per_dof": r.initial_chi2 / r.dof if r.dof > 0 else None,
        "iterations": r.iterations,
        "seconds": r.seconds,
        "seconds_marginals": r.seconds_marginals,
    }


def _map(problem: Problem, r: SmootherResult) -> str:
    first = np.full(r.landmark_id.size, -1, np.int64)
    n_obs = np.zeros(r.landmark_id.size, np.int64)
    pos = {int(i): j for j, i in enumerate(r.landmark_id)}
    for k, lid, kind in zip(problem.meas_scan, problem.meas_landmark, problem.meas_kind):
        j = pos[int(lid)]
        n_obs[j] += 1
        if kind == MEAS_INIT:
            first[j] = k
    return map_csv(r.landmark_id, r.landmark_xy, r.landmark_cov, first, n_obs)


def _vouched(seq, run_dir: Path):
    """The fixes the run's odometry vouches for (experiments/eval/vouched.py) under the run's
    own configuration (its config.toml: the summary's JSON cannot hold an infinite setting such
    as `measurement.max_range_m`), or None when it cannot be read back."""
    try:
        cfg = load_slam_config(run_dir / "config.toml")
    except (OSError, DataError, ValueError):  # the config errors are ValueErrors
        return None
    return vouched_for_sequence(seq, cfg)


def _scores(run_dir: Path, problem: Problem, r: SmootherResult) -> dict:
    """Errors against the GPS and the truth of the run's input file, when it can be read."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        seq = load_sequence(summary["input"])
    except (OSError, ValueError, KeyError, TypeError, DataError):
        return {"scored": "no: the run's summary.json or its input sequence is not readable"}
    # the run's scan times are the scans' stamps minus its laser latency (`vehicle.laser_latency_s`)
    latency = summary.get("config", {}).get("vehicle", {}).get("laser_latency_s", 0.0)
    latency = latency if isinstance(latency, (int, float)) else 0.0
    if seq.n_scans != problem.n_scans or not np.allclose(seq.scan_t - latency, problem.scan_t):
        return {"scored": f"no: {summary['input']} is not the sequence of this run"}
    out: dict = {"scored": summary["input"]}
    if seq.gps_t is not None:
        out["gps"] = score_sequence(
            seq, problem.scan_t, r.pose, _antenna(seq, problem), vouched=_vouched(seq, run_dir)
        ).to_dict()
    if seq.truth_t is not None:
        t = problem.scan_t  # the poses' own times
        inside = (t >= seq.truth_t[0]) & (t <= seq.truth_t[-1])
        inside[0] = False
        if inside.any():
            truth = interpolate_poses(t, seq.truth_t, seq.truth_pose)
            e = pose_errors(r.pose, truth)[inside]
            out["truth"] = {
                "mean_abs_error": dict(
                    zip(("dx_m", "dy_m", "dtheta_rad"), np.mean(np.abs(e), 0).tolist())
                ),
                "nees_mean": float(np.mean(nees(e, r.pose_cov[inside])))
                if np.isfinite(r.pose_cov).all()
                else None,
                "scans_scored": int(inside.sum()),
            }
    return out


def _antenna(seq, problem) -> np.ndarray:
    """The GPS antenna in the vehicle frame: the sequence's, else the run's laser."""
    return seq.gps_pose if seq.gps_pose is not None else problem.laser_pose
