"""Probe behind the lab notebook's entry "The full run's figure: how far it moves when nothing
that matters changes" (its second part): what the filter's own innovations and the tentatives'
chains show on the north-west arm's first visit (VP preset, published detections, IHGR,
closure off, 3.237 m vouched).

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/arm_innovation_probe.py

Prints (one full run, about a minute on one core):

1. Jumps between consecutive sightings of one landmark less than 1 s apart, each projected
   through the filter's pose of its scan: in every measurement row the run logs (tentative
   chains included, as re-tracked when a tentative joins) and in the filter's own updates.
2. The mean bearing innovation of the filter's updates by window, side and range.
3. The same innovations fitted per window and side as a rotation plus an along-track shift d
   (innovation = rotation + d sin(bearing) / range: a car further ahead than the filter
   predicts sees every tree further back), beside the mean speed.

Diagnosis only: nothing here sets a default.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam
from slam.se2 import observed_points

WINDOWS = ((0, 450), (1000, 1040), (1040, 1072), (1072, 1110), (1270, 1400))  # s
ARM = ((1000, 1110), (1240, 1400))  # s: the arm's two visits
GROUPS = {
    "left": lambda z: z[:, 1] > 0,
    "right": lambda z: z[:, 1] <= 0,
    "left, under 20 m": lambda z: (z[:, 1] > 0) & (z[:, 0] < 20),
}


def jumps(log, scan, lm, z) -> np.ndarray:
    """Times of the jumps over 2 m between consecutive sightings (< 1 s apart) of a landmark."""
    keep = lm >= 0
    scan, lm, z = scan[keep], lm[keep], z[keep]
    w = observed_points(log.pose[scan], z, log.laser_pose)
    o = np.lexsort((scan, lm))
    scan, lm, w = scan[o], lm[o], w[o]
    t = log.scan_t[scan]
    same = (lm[1:] == lm[:-1]) & (np.diff(t) < 1.0)
    big = same & (np.linalg.norm(np.diff(w, axis=0), axis=1) > 2.0)
    return t[1:][big]


def print_jumps(name: str, t: np.ndarray) -> None:
    arm = sum(int(((t >= a) & (t < b)).sum()) for a, b in ARM)
    print(f"{name}: {len(t)} jumps over 2 m, {arm} of them on the arm's two visits")


def innovations(log) -> None:
    t = log.scan_t[log.obs_scan]
    b = np.degrees(log.obs_innov[:, 1])
    sd = np.degrees(np.sqrt(log.obs_innov_cov[:, 1, 1]))
    for lo, hi in WINDOWS:
        for name, group in GROUPS.items():
            q = (t >= lo) & (t < hi) & group(log.obs_z)
            print(
                f"{lo}-{hi} s {name}: {q.sum()} updates, mean bearing innovation "
                f"{b[q].mean():+.3f} deg (se {b[q].std() / np.sqrt(q.sum()):.3f}), "
                f"normalised {np.mean(b[q] / sd[q]):+.2f}"
            )


def along_track(log) -> None:
    s, z = log.obs_scan, log.obs_z
    t = log.scan_t[s]
    step = np.hypot(log.odo_delta[:, 0], log.odo_delta[:, 1])
    speed = np.r_[np.nan, step[1:] / np.diff(log.scan_t)][s]
    for lo, hi in WINDOWS:
        for name, group in list(GROUPS.items())[:2]:
            q = (t >= lo) & (t < hi) & group(z) & np.isfinite(speed)
            A = np.c_[np.ones(q.sum()), np.sin(z[q, 1]) / z[q, 0]]
            c = np.linalg.lstsq(A, log.obs_innov[q, 1], rcond=None)[0]
            se = np.sqrt(np.diag(np.linalg.inv(A.T @ A)) * np.var(log.obs_innov[q, 1] - A @ c))
            print(
                f"{lo}-{hi} s {name}: rotation {np.degrees(c[0]):+.3f} deg (se "
                f"{np.degrees(se[0]):.3f}), along-track {100 * c[1]:+.2f} cm (se "
                f"{100 * se[1]:.2f}), mean speed {speed[q].mean():.2f} m/s"
            )


def main() -> None:
    threadpool_limits(1)
    log = run_slam(load_victoria_park(full=True), run_config("detections", "ihgr"))
    print_jumps("every logged sighting", jumps(log, log.meas_scan, log.meas_track, log.meas_z))
    print_jumps("the filter's updates", jumps(log, log.obs_scan, log.obs_landmark, log.obs_z))
    innovations(log)
    along_track(log)


if __name__ == "__main__":
    main()
