"""Smooth an EKF run: EKF-SLAM on a simulated tree-park drive, then the GTSAM smoother
(`slam.smoother`) re-solves the same problem (the EKF's odometry, measurements and
associations) as nonlinear least squares. Both are scored against the exact truth, as in the
paper's Table 3.

    python examples/smooth_a_run.py [OUT_DIR]

Writes trajectory_ekf.tum and trajectory_smoothed.tum into OUT_DIR (default: a temp dir).
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from experiments.eval.poses import pose_errors
from experiments.io.config_file import load_slam_config
from experiments.io.results import trajectory_tum
from experiments.sim import CycabParams, simulate_cycab_run
from slam import interpolate_poses, run_slam
from slam.smoother import SmootherOptions, problem_from_log, smooth

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="trunkslam_"))
out.mkdir(parents=True, exist_ok=True)

seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=240))
cfg = load_slam_config("cycab")  # the simulated Cycab's calibration (experiment 2's filter)
log = run_slam(seq, cfg, features="paper")  # the paper's extractor, IHGR association
result = smooth(problem_from_log(log), SmootherOptions(solver="batch"))

truth = interpolate_poses(log.scan_t, seq.truth_t, seq.truth_pose)
for name, pose in (("ekf", log.pose), ("smoothed", result.pose)):
    err = pose_errors(pose, truth)[1:]  # from the second scan: the run starts at the truth
    dx, dy, dtheta = np.mean(np.abs(err), axis=0)
    rms = np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2))
    print(
        f"{name:9s} mean absolute error: dx {dx:.4f} m, dy {dy:.4f} m, dtheta {dtheta:.5f} rad;"
        f" position RMS {rms:.4f} m"
    )
    (out / f"trajectory_{name}.tum").write_text(trajectory_tum(log.scan_t, pose))
print(
    f"smoother: chi2 {result.initial_chi2:.1f} at the EKF's estimate -> {result.chi2:.1f}"
    f" ({result.dof} dof, {result.iterations} iterations, {result.seconds:.2f} s)"
)
print(f"-> {out}/trajectory_ekf.tum, trajectory_smoothed.tum")
