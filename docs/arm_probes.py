"""Probes behind the lab notebook's entry "The north-west arm's turn: held by the laser data,
not the odometry": what holds the full Victoria Park run's arm where it is, measured on the
smoother.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/arm_probes.py

Runs the full run with loop closure (VP preset, published detections, IHGR), smooths its log
with changed inputs, and prints for each solution the chi-square, the RMSE on the vouched GPS
fixes, the RMSE over 1270-1340 s (the top of the arm), and where the antenna track crosses
y = 120 m and y = 150 m on the way up the arm, beside the GPS's own crossing. Then the same
crossings for GTSAM's own graph (`gtsam/victoria_park.txt`, its own associations and noise),
its path put in our frame twice: by its first pose (the graph starts at the origin, the run
at the preset's start pose), and by the rigid motion that puts its landmarks on the smoother's
landmarks first seen before 1000 s (iterative closest points from the first-pose frame, pairs
within 5 m, then 1 m). About two minutes on one core. Diagnosis only: nothing here sets a
default, and every input changed is named with its size.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import gtsam_graph, load_victoria_park
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam, se2
from slam.se2 import procrustes_2d
from slam.smoother import SmootherOptions, problem_from_log, smooth, solve_graph_file

ARM_TOP = (1270.0, 1340.0)  # s: the top of the arm, where the run's error is largest
LEVELS = (120.0, 150.0)  # m: y of the crossings reported (the way up the arm, x < -100 m)


def crossing(xy: np.ndarray, y: float) -> float:
    """x of the first crossing of the horizontal line y by the track xy (N, 2) west of x = -100 m
    going north (the way up the arm); NaN when it never crosses there."""
    up = (xy[:-1, 1] < y) & (xy[1:, 1] >= y) & (xy[:-1, 0] < -100.0)
    if not up.any():
        return math.nan
    i = int(np.flatnonzero(up)[0])
    f = (y - xy[i, 1]) / (xy[i + 1, 1] - xy[i, 1])
    return float(xy[i, 0] + f * (xy[i + 1, 0] - xy[i, 0]))


def antenna_track(pose: np.ndarray, antenna: np.ndarray) -> np.ndarray:
    return np.array([se2.compose(p, antenna)[:2] for p in pose])


def crossings(track: np.ndarray) -> str:
    return "  ".join(f"x(y={y:.0f}) {crossing(track, y):7.1f}" for y in LEVELS)


def report(name: str, chi2: float, score, track: np.ndarray) -> None:
    top = (score.t_s >= ARM_TOP[0]) & (score.t_s < ARM_TOP[1]) & ~score.jump
    top_rmse = float(np.sqrt(np.mean(score.errors[top] ** 2)))
    print(
        f"{name:44s} chi2 {chi2:9.0f}  vouched {score.vouched_rmse:5.2f} m  "
        f"1270-1340 s {top_rmse:5.2f} m  {crossings(track)}"
    )


def variants(problem):
    """(name, problem) pairs: the log's problem and each changed input."""
    p = problem
    yield "smoother on the log (as run)", p
    c = p.odo_cov.copy()
    c[:, 2, :] *= 4.0
    c[:, :, 2] *= 4.0  # the heading's variance x16, its covariances x4
    yield "odometry heading variance x16", replace(p, odo_cov=c)
    for k in (16.0, 64.0):
        yield f"measurement covariance x{k:.0f}", replace(p, meas_R=p.meas_R * k)
    for d in (-0.5, 0.5):
        lp = p.laser_pose.copy()
        lp[2] += math.radians(d)
        yield f"laser yaw {d:+.1f} deg", replace(p, laser_pose=lp)
    z = p.meas_z.copy()
    z[:, 0] -= 0.1
    yield "ranges 0.1 m shorter", replace(p, meas_z=z)


def icp(src: np.ndarray, dst: np.ndarray, iterations: int = 30) -> tuple[float, np.ndarray]:
    """(theta, t) putting the points src on their nearest points of dst: closest-point pairs
    within 5 m for the first 10 iterations, within 1 m after, each time the least-squares rigid
    motion of the pairs (`slam.start.procrustes_2d`)."""
    from scipy.spatial import cKDTree

    tree, theta, t = cKDTree(dst), 0.0, np.zeros(2)
    for it in range(iterations):
        d, j = tree.query(se2.rotate(theta, src) + t)
        m = d < (5.0 if it < 10 else 1.0)
        theta, t = procrustes_2d(src[m], dst[j[m]])
    return theta, t


def gtsam_rows(log, old_map: np.ndarray) -> None:
    g = solve_graph_file(gtsam_graph())
    start = log.start_pose
    first = np.array([se2.compose(start, q) for q in g.pose])
    a, t = icp(se2.transform_points(start, g.landmark_xy), old_map)
    fitted = np.c_[se2.rotate(a, first[:, :2]) + t, first[:, 2] + a]
    for name, path in (
        ("first pose", first),
        (f"its old map ({math.degrees(a):+.2f} deg)", fitted),
    ):
        track = antenna_track(path, log.antenna_pose)
        print(
            f"{'GTSAM graph, by ' + name:44s} chi2/dof {g.chi2_per_dof:.3f}{'':37s}",
            crossings(track),
        )


def main() -> None:
    threadpool_limits(1)
    seq = load_victoria_park(full=True)
    cfg = run_config("detections", "ihgr").with_(**{"closure.enabled": True})
    vouched = vouched_for_sequence(seq, cfg)
    log = run_slam(seq, cfg)
    print(f"{'GPS':44s} {'':54s}", crossings(seq.gps_xy))
    score = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched)
    report("EKF (closure on)", math.nan, score, antenna_track(log.pose, log.antenna_pose))
    problem = problem_from_log(log)
    old_map = None
    for name, p in variants(problem):
        r = smooth(p, SmootherOptions(marginals=False))
        s = score_sequence(seq, log.scan_t, r.pose, log.antenna_pose, vouched)
        report(name, r.chi2, s, antenna_track(r.pose, log.antenna_pose))
        if old_map is None:
            t_meas = problem.scan_t[problem.meas_scan]
            first = np.array([t_meas[problem.meas_landmark == i].min() for i in r.landmark_id])
            old_map = r.landmark_xy[first < 1000.0]
    gtsam_rows(log, old_map)


if __name__ == "__main__":
    main()
