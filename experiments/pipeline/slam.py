"""`trunkslam slam`: read a sequence file, run EKF-SLAM, write the trajectory, map and summary."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from experiments.eval.poses import nees, pose_errors
from experiments.io.results import map_csv, trajectory_csv, trajectory_tum
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import dumps_json, json_types, write_atomic
from experiments.render.viz import open_recording
from slam import Sequence, SlamConfig, SlamLog, interpolate_poses
from slam import run as slam_run

__all__ = ["run_slam", "summarise"]


def run_slam(
    input_path: Path | str,
    features: str = "paper",
    association: str = "ihgr",
    out_dir: Path | str = Path("slam_out"),
    rerun_path: Path | str | None = None,
    initial_heading: float | None = None,
    *,
    config: SlamConfig | None = None,
) -> dict:
    """Run EKF-SLAM over the sequence file `input_path` and write the results into out_dir.

    trajectory.tum   the rear-axle centre at the scan times, `t x y z qx qy qz qw` (z = 0,
                     rotation about z by theta), readable by evo
    trajectory.csv   t, x, y, theta and the upper triangle of the pose covariance
    map.csv          id, x, y, covariance (xx, xy, yy), scan it joined the map, scans seen in
    summary.json     input, methods, start, counts, timings (mean, median, p95, max per phase),
                     the configuration, and when the sequence has truth the Table-3 errors and
                     the mean NEES
    Returns the summary. initial_heading: start heading in radians (GPS starts). config: the
    filter's settings (default `SlamConfig()`: the simulated Cycab's odometry noise and the
    calibrated measurement noise of the tree park).
    """
    seq = load_sequence(input_path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec = open_recording(rerun_path)
    t0 = time.perf_counter()
    lg = slam_run(
        seq,
        features=features,
        association=association,
        config=config,
        visualiser=rec,
        initial_heading_rad=initial_heading,
    )
    seconds = time.perf_counter() - t0
    rec.close()
    write_atomic(out / "trajectory.tum", trajectory_tum(lg.scan_t, lg.pose))
    write_atomic(out / "trajectory.csv", trajectory_csv(lg.scan_t, lg.pose, lg.pose_cov))
    write_atomic(
        out / "map.csv",
        map_csv(
            lg.landmark_id,
            lg.landmark_xy,
            lg.landmark_cov,
            lg.landmark_first_scan,
            lg.landmark_n_obs,
        ),
    )
    summary = summarise(lg, seq, seconds)
    summary = {"input": str(input_path), **summary}
    write_atomic(out / "summary.json", dumps_json(summary))
    return summary


def summarise(lg: SlamLog, seq: Sequence, seconds: float) -> dict:
    """Counts, timings per phase, the configuration, and errors against the truth (scans the
    truth covers, the first left out since the run may start there)."""
    timing = {}
    for k, v in lg.timing_s.items():
        timing[k] = {
            "mean_ms": 1e3 * float(np.mean(v)),
            "median_ms": 1e3 * float(np.median(v)),
            "p95_ms": 1e3 * float(np.percentile(v, 95)),
            "max_ms": 1e3 * float(np.max(v)),
            "total_s": float(np.sum(v)),
        }
    summary = {
        "features": lg.features_method,
        "association": lg.association_method,
        "n_scans": lg.n_scans,
        "start": lg.start,
        "landmarks": int(lg.landmark_xy.shape[0]),
        "circles_per_scan": float(lg.n_features.mean()),
        "associated_per_scan": float(lg.n_associated.mean()),
        "seconds": seconds,
        "timing": timing,
        "config": json_types(lg.config),
    }
    inside = (
        np.zeros(seq.n_scans, bool)
        if seq.truth_t is None
        else (seq.scan_t >= seq.truth_t[0]) & (seq.scan_t <= seq.truth_t[-1])
    )
    inside[0] = False  # the run may start at the truth
    if inside.any():  # score only the scans the truth covers
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        e = pose_errors(lg.pose, truth)[inside]
        covs = lg.pose_cov[inside]
        ok = np.linalg.det(covs) > 0
        n = nees(e[ok], covs[ok])
        summary["truth"] = {
            "mean_abs_error": dict(
                zip(("dx_m", "dy_m", "dtheta_rad"), np.mean(np.abs(e), 0).tolist())
            ),
            "nees_mean": float(np.mean(n)) if n.size else None,
            "scans_scored": int(inside.sum()),
        }
    return summary
