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
3. The same innovations fitted per window, on both sides together and per side, as a
   rotation plus an along-track shift d and a sideways shift l of the car (innovation =
   rotation + d sin(bearing) / range + l cos(bearing) / range: a car further ahead than the
   filter predicts sees every tree further back), with standard errors clustered by blocks
   of 25 scans, beside the mean speed. A heading error of the car is not a pure rotation
   here: with the laser 3.78 m ahead it adds a sideways term too.

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
ARM = ((1000, 1110), (1240, 1400))  # s: the arm's two visits (the first visit proper: 1040-1072)
BLOCK_SCANS = 25  # scans: the blocks the fit's standard errors are clustered by
GROUPS = {
    "left": lambda z: z[:, 1] > 0,
    "right": lambda z: z[:, 1] <= 0,
    "left, under 20 m": lambda z: (z[:, 1] > 0) & (z[:, 0] < 20),
}


def jumps(log, scan, lm, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The jumps over 2 m between consecutive sightings (< 1 s apart) of a landmark: (their
    times, lengths (m), the later sighting's range (m))."""
    keep = lm >= 0
    scan, lm, z = scan[keep], lm[keep], z[keep]
    w = observed_points(log.pose[scan], z, log.laser_pose)
    o = np.lexsort((scan, lm))
    scan, lm, w, z = scan[o], lm[o], w[o], z[o]
    t = log.scan_t[scan]
    step = np.linalg.norm(np.diff(w, axis=0), axis=1)
    big = (lm[1:] == lm[:-1]) & (np.diff(t) < 1.0) & (step > 2.0)
    return t[1:][big], step[big], z[1:, 0][big]


def print_jumps(log, name: str, jumped) -> None:
    t, length, range_m = jumped
    arm = sum(int(((t >= a) & (t < b)).sum()) for a, b in ARM)
    share = sum(min(b, log.scan_t[-1]) - a for a, b in ARM) / (log.scan_t[-1] - log.scan_t[0])
    line = (
        f"{name}: {len(t)} jumps over 2 m, {arm} on the arm's two visits ({share:.1%} of the run)"
    )
    if len(t):
        pl, pr = np.percentile(length, [25, 50, 75]), np.percentile(range_m, [5, 50, 95])
        line += (
            f"; length quartiles {pl[0]:.1f} / {pl[1]:.1f} / {pl[2]:.1f} m (max "
            f"{length.max():.1f}), range 5/50/95% {pr[0]:.0f} / {pr[1]:.0f} / {pr[2]:.0f} m"
        )
    print(line)


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


def clustered_fit(A: np.ndarray, y: np.ndarray, block: np.ndarray):
    """Least squares y ~ A c with standard errors clustered by `block` (residuals correlated
    within a block of scans, independent between blocks)."""
    c = np.linalg.lstsq(A, y, rcond=None)[0]
    e = y - A @ c
    bread = np.linalg.inv(A.T @ A)
    g = np.zeros((np.unique(block).size, A.shape[1]))
    np.add.at(g, np.unique(block, return_inverse=True)[1], A * e[:, None])
    return c, np.sqrt(np.diag(bread @ (g.T @ g) @ bread))


def along_track(log) -> None:
    """Bearing innovation = rotation + d sin(b) / r + l cos(b) / r (a car further ahead by d
    sees a tree's bearing grow by d sin(b) / r; a car further left by l, by l cos(b) / r),
    fitted per window on both sides together and per side; standard errors clustered by
    blocks of BLOCK_SCANS scans."""
    s, z = log.obs_scan, log.obs_z
    t = log.scan_t[s]
    step = np.hypot(log.odo_delta[:, 0], log.odo_delta[:, 1])
    speed = np.r_[np.nan, step[1:] / np.diff(log.scan_t)][s]
    sides = {"both": lambda z: np.ones(len(z), bool)} | dict(list(GROUPS.items())[:2])
    for lo, hi in WINDOWS:
        for name, group in sides.items():
            q = (t >= lo) & (t < hi) & group(z) & np.isfinite(speed)
            r, b = z[q, 0], z[q, 1]
            A = np.c_[np.ones(q.sum()), np.sin(b) / r, np.cos(b) / r]
            c, se = clustered_fit(A, log.obs_innov[q, 1], s[q] // BLOCK_SCANS)
            print(
                f"{lo}-{hi} s {name}: rotation {np.degrees(c[0]):+.3f} deg (se "
                f"{np.degrees(se[0]):.3f}), along-track {100 * c[1]:+.2f} cm (se "
                f"{100 * se[1]:.2f}), sideways {100 * c[2]:+.2f} cm (se {100 * se[2]:.2f}), "
                f"mean speed {speed[q].mean():.2f} m/s"
            )


def main() -> None:
    threadpool_limits(1)
    log = run_slam(load_victoria_park(full=True), run_config("detections", "ihgr"))
    print_jumps(log, "every logged sighting", jumps(log, log.meas_scan, log.meas_track, log.meas_z))
    print_jumps(log, "the filter's updates", jumps(log, log.obs_scan, log.obs_landmark, log.obs_z))
    innovations(log)
    along_track(log)


if __name__ == "__main__":
    main()
