"""Probes behind the lab notebook's entry "The north-west arm: the associations hold, the laser
turns the car where the trees stand on one side": what the laser does to the heading on the full
Victoria Park run (VP preset, published detections, IHGR, closure off).

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/arm_side_probes.py

Prints, in order (about four minutes on one core):

1. GPS-projected sightings. Poses from the wheel odometry alone, dead-reckoned and fitted
   rigidly to the vouched GPS fixes of a 30 s window around each scan (no laser); every sighting
   used in an update projected through them. For the landmarks seen on both visits of the arm
   (1040-1110 s and 1240-1400 s): how far apart the two visits' projected centroids are, and
   how far the run's map puts the landmark from them.
2. The laser's heading correction (the filter's heading change beyond the odometry's) per 4 s
   over the arm's first visit, beside the odometry's own turn.
3. On straight 4 s stretches (odometry turn under 5 deg, at least 10 m and 10 sightings): the
   laser's heading correction per 100 m against the share of sightings on the left, fitted as
   a + b (share - 0.5), over the whole run and over scans 1-2000 (t < 450 s).
4. Scans 1-2000: the vouched RMSE and the GPS displacement error over 10/30/60 s for the
   measurement sigmas scaled by k (the criterion a derivation there could use).
5. The full run with a range bias a subtracted from every range (a in m).

Diagnosis only: nothing here sets a default.
"""

from __future__ import annotations

import math

import numpy as np
from arm_probes import antenna_track  # docs/, beside this script
from threadpoolctl import threadpool_limits

from experiments.eval.gps import score_sequence
from experiments.eval.vouched import vouched_for_sequence
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam, se2
from slam.se2 import procrustes_2d

FIRST, SECOND = (1040.0, 1110.0), (1240.0, 1400.0)  # s: the arm's two visits
WINDOW_S, STEP_S, BIN_S = 30.0, 5.0, 4.0


def dead_reckoned(log) -> np.ndarray:
    pose = np.zeros_like(log.pose)
    pose[0] = log.pose[0]
    for k in range(1, pose.shape[0]):
        pose[k] = se2.compose(pose[k - 1], log.odo_delta[k])
    return pose


def gps_dr_poses(seq, log, vouched) -> np.ndarray:
    """(N, 3) each scan's pose: the dead-reckoned pose moved by the rigid fit of the
    dead-reckoned antenna to the vouched fixes within WINDOW_S / 2 (NaN without a fit)."""
    t, dr = log.scan_t, dead_reckoned(log)
    a = antenna_track(dr, log.antenna_pose)
    gt, gxy = seq.gps_t[vouched], seq.gps_xy[vouched]
    ag = np.c_[np.interp(gt, t, a[:, 0]), np.interp(gt, t, a[:, 1])]
    out = np.full_like(dr, np.nan)
    for c in np.arange(t[0], t[-1] + STEP_S, STEP_S):
        fix = np.abs(gt - c) < WINDOW_S / 2
        scans = np.abs(t - c) < STEP_S / 2
        if fix.sum() < 20 or np.ptp(ag[fix], axis=0).max() < 10.0:
            continue
        th, tr = procrustes_2d(ag[fix], gxy[fix])
        out[scans, :2] = se2.rotate(th, dr[scans, :2]) + tr
        out[scans, 2] = dr[scans, 2] + th
    return out


def projected(log, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(landmark id, time, world point) of every sighting used in an update whose scan has a
    pose in `poses`."""
    ok = ~np.isnan(poses[log.obs_scan, 0])
    s, z = log.obs_scan[ok], log.obs_z[ok]
    sensor = np.array([se2.compose(poses[k], log.laser_pose) for k in s])
    ang = sensor[:, 2] + z[:, 1]
    w = sensor[:, :2] + z[:, :1] * np.c_[np.cos(ang), np.sin(ang)]
    return log.obs_landmark[ok], log.scan_t[s], w


def visits(log, lid, t, w) -> None:
    ids = {int(i): k for k, i in enumerate(log.landmark_id)}
    apart, off = [], []
    for i in np.unique(lid):
        a = (lid == i) & (t >= FIRST[0]) & (t < FIRST[1])
        b = (lid == i) & (t >= SECOND[0]) & (t < SECOND[1])
        if a.sum() < 3 or b.sum() < 3 or int(i) not in ids:
            continue
        ca, cb = w[a].mean(axis=0), w[b].mean(axis=0)
        apart.append(np.linalg.norm(ca - cb))
        off.append(np.linalg.norm(log.landmark_xy[ids[int(i)]] - 0.5 * (ca + cb)))
    p = np.percentile
    print(f"1. landmarks seen on both visits of the arm: {len(apart)}")
    print(
        f"   the visits' projected centroids apart: median {p(apart, 50):.2f} m, "
        f"90% {p(apart, 90):.2f} m"
    )
    print(
        f"   the map from their mean: median {p(off, 50):.2f} m, 90% {p(off, 90):.2f} m, "
        f"max {max(off):.2f} m"
    )


def corrections(log) -> np.ndarray:
    dh = se2.wrap_angle(np.diff(log.pose[:, 2]))
    return np.r_[0.0, dh - log.odo_delta[1:, 2]]


def first_visit(log) -> None:
    c, t = corrections(log), log.scan_t
    print("2. the laser's heading correction over the arm's first visit (deg per 4 s)")
    for a in np.arange(FIRST[0], FIRST[1], BIN_S):
        q = (t >= a) & (t < a + BIN_S)
        used = np.isin(log.obs_scan, np.flatnonzero(q))
        print(
            f"   {a:6.0f} s  laser {math.degrees(c[q].sum()):+6.2f}  odometry turn "
            f"{math.degrees(log.odo_delta[q, 2].sum()):+7.2f}  sightings {used.sum():3d}  "
            f"left {np.mean(log.obs_z[used, 1] > 0) if used.any() else math.nan:.2f}"
        )


def side_fit(log, t_hi: float = math.inf) -> tuple[float, float, float, int]:
    """(a, b, standard error of b, bins): laser correction (deg/100 m) = a + b (left - 0.5)."""
    c, t, od = corrections(log), log.scan_t, log.odo_delta
    dist = np.r_[0.0, np.hypot(od[1:, 0], od[1:, 1])]
    rows = []
    for a in np.arange(t[0], min(t[-1], t_hi), BIN_S):
        q = (t >= a) & (t < a + BIN_S)
        used = np.isin(log.obs_scan, np.flatnonzero(q))
        if dist[q].sum() < 10 or abs(od[q, 2].sum()) >= math.radians(5) or used.sum() < 10:
            continue
        rows.append(
            (math.degrees(c[q].sum()) / dist[q].sum() * 100, np.mean(log.obs_z[used, 1] > 0))
        )
    y, x = np.array(rows).T
    A = np.c_[np.ones_like(x), x - 0.5]
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    se = math.sqrt(r @ r / (len(y) - 2) * np.linalg.inv(A.T @ A)[1, 1])
    return float(coef[0]), float(coef[1]), se, len(y)


def side(log) -> None:
    print(
        "3. laser heading correction (deg/100 m) = a + b (left share - 0.5), straight 4 s stretches"
    )
    for name, hi in (("whole run", math.inf), ("scans 1-2000", 450.0)):
        a, b, se, n = side_fit(log, hi)
        print(f"   {name:13s} a {a:+6.2f}  b {b:+6.2f} +- {se:.2f}  ({n} stretches)")


def displacement_errors(seq, log, vouched, spans=(10.0, 30.0, 60.0)) -> str:
    a = antenna_track(log.pose, log.antenna_pose)
    keep = vouched & (seq.gps_t >= log.scan_t[0]) & (seq.gps_t <= log.scan_t[-1])
    gt, g = seq.gps_t[keep], seq.gps_xy[keep]
    ag = np.c_[np.interp(gt, log.scan_t, a[:, 0]), np.interp(gt, log.scan_t, a[:, 1])]
    out = []
    for T in spans:
        j = np.searchsorted(gt, gt + T)
        i = np.flatnonzero(j < len(gt))
        j = j[i]
        i, j = i[np.abs(gt[j] - gt[i] - T) < 0.5], j[np.abs(gt[j] - gt[i] - T) < 0.5]
        e = (ag[j] - ag[i]) - (g[j] - g[i])
        out.append(f"{T:.0f} s {math.sqrt(np.mean(np.sum(e**2, axis=1))):.3f} m")
    return ", ".join(out)


def scaled(cfg, k: float):
    noise = {
        n: {
            "range_sigma_m": v.range_sigma_m * k,
            "range_sigma_per_m": v.range_sigma_per_m * k,
            "bearing_sigma_rad": v.bearing_sigma_rad * k,
            "cross_range_sigma_m": v.cross_range_sigma_m * k,
        }
        for n, v in cfg.measurement.constant_noise.items()
    }
    return cfg.with_(**{"measurement.constant_noise": noise})


def k_scan(cfg) -> None:
    seq = load_victoria_park()
    vouched = vouched_for_sequence(seq, cfg)
    print("4. scans 1-2000, measurement sigmas x k: vouched RMSE; GPS displacement error")
    for k in (1.0, 3.0, 10.0):
        log = run_slam(seq, scaled(cfg, k))
        s = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched)
        print(
            f"   k {k:4.1f}  vouched {s.vouched_rmse:.3f} m  "
            f"over {displacement_errors(seq, log, vouched)}"
        )


def range_bias(seq, cfg, vouched) -> None:
    print("5. the full run with a range bias a subtracted from every range")
    for a in (-0.1, 0.1, 0.2):
        bias = {n: (a, 0.0) for n in cfg.measurement.range_bias}
        log = run_slam(seq, cfg.with_(**{"measurement.range_bias": bias}))
        s = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched)
        _, b, se, _ = side_fit(log)
        print(
            f"   a {a:+.2f} m  vouched {s.vouched_rmse:.3f} m  side slope b {b:+6.2f} +- {se:.2f}"
        )


def main() -> None:
    threadpool_limits(1)
    seq = load_victoria_park(full=True)
    cfg = run_config("detections", "ihgr")
    vouched = vouched_for_sequence(seq, cfg)
    log = run_slam(seq, cfg)
    s = score_sequence(seq, log.scan_t, log.pose, log.antenna_pose, vouched)
    print(f"the run: vouched {s.vouched_rmse:.3f} m")
    visits(log, *projected(log, gps_dr_poses(seq, log, vouched)))
    first_visit(log)
    side(log)
    k_scan(cfg)
    range_bias(seq, cfg, vouched)


if __name__ == "__main__":
    main()
