"""Victoria Park: the steering calibration from dead reckoning against GPS stretches.

The turn rate of the Ackermann model is v tan(alpha) / L with alpha the steering reading. On the
ute it is not: with the steering as read, the filter's updates on scans 1-2000 turned the heading
on top of the odometry by a mean +0.62 deg a scan in left turns above 0.4 rad (13% of the
odometry's 4.6 deg a scan) and -0.14 deg in right ones, and by +0.04 deg a scan when driving
straight. `slam.SteeringCalibration` maps the reading r to alpha = offset + gain r + cubic r^3.

Its three parameters are fitted here, outside the filter, to what the odometry alone says about
the path's shape (the approach of odometry calibration against an external reference): the GPS
fixes of the first 2000 scans are cut into stretches of `STRETCH_S` seconds; in each, the
antenna track dead-reckoned from the steering and speed readings is fitted rigidly (rotation and
translation, `slam.se2.procrustes_2d`) to the fixes, and the objective is the mean squared
distance left, each capped at `CAP_M` (GPS multipath) and without the fixes flagged as jumps.
Stretches in which the antenna moves less than `MIN_EXTENT_M` say nothing of the shape and are
not used. Nelder-Mead from the identity minimises it. The same figure on the stretches of scans
2001-7249, which the fit never sees, is reported beside it. No SLAM run enters, and no GPS error
of one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from experiments.errors import DataError
from experiments.eval.gps import flag_jumps, top_speed
from slam import AckermannModel, Odometry, SteeringCalibration, se2
from slam.se2 import procrustes_2d
from slam.vehicle import integrate

__all__ = ["STRETCH_S", "SteeringFit", "dead_reckoning_mse", "fit_steering", "stretches"]

STRETCH_S = 60.0  # seconds of GPS per stretch
CAP_M = 5.0  # a fix's distance counts at most this much (GPS multipath, reflections)
MIN_EXTENT_M = 20.0  # the antenna's travel across a stretch (x and y extent summed)
MIN_FIXES = 10
EVALUATIONS = 150


@dataclass(frozen=True)
class SteeringFit:
    """The fitted calibration and the dead-reckoning error (mean squared distance to the fixes
    after each stretch's rigid fit, m^2) before and after it, on the stretches fitted and on the
    held-out ones."""

    steering: SteeringCalibration
    fit_stretches: int
    held_out_stretches: int
    fit_mse_before: float
    fit_mse_after: float
    held_out_mse_before: float
    held_out_mse_after: float
    evaluations: int


def stretches(seq, t0: float, t1: float, length_s: float = STRETCH_S) -> list[np.ndarray]:
    """Indices of the GPS fixes (jumps left out) of each whole `length_s` stretch in [t0, t1)."""
    if seq.gps_t is None or seq.odo_t is None or seq.vehicle is None:
        raise DataError("sequence: the steering fit needs GPS, odometry and a vehicle model")
    good = ~flag_jumps(seq.gps_t, seq.gps_xy, top_speed(seq))
    out = []
    for a in np.arange(t0, t1 - length_s + 1e-9, length_s):
        idx = np.flatnonzero(good & (seq.gps_t >= a) & (seq.gps_t < a + length_s))
        if idx.size >= MIN_FIXES:
            out.append(idx)
    return out


def dead_reckoning_mse(seq, steering: SteeringCalibration, groups: list[np.ndarray]) -> tuple:
    """(mean squared capped distance, stretches used) of the dead-reckoned antenna track against
    the fixes of each group after its rigid fit."""
    model = AckermannModel.from_vehicle(seq.vehicle)
    odo = Odometry(seq.odo_t, seq.odo_speed, steering.apply(seq.odo_steer))
    antenna = np.asarray(seq.gps_pose, dtype=np.float64)
    total, count, used = 0.0, 0, 0
    for idx in groups:
        pose, t, track = np.zeros(3), float(seq.gps_t[idx[0]]), []
        for k in idx:
            pose = integrate(model, pose, odo, t, float(seq.gps_t[k]))[0]
            t = float(seq.gps_t[k])
            track.append(se2.compose(pose, antenna)[:2])
        A, B = np.array(track), seq.gps_xy[idx]
        if np.ptp(A[:, 0]) + np.ptp(A[:, 1]) < MIN_EXTENT_M:
            continue
        theta, tr = procrustes_2d(A, B)
        d = np.minimum(np.hypot(*(B - (se2.rotate(theta, A) + tr)).T), CAP_M)
        total, count, used = total + float(np.sum(d**2)), count + d.size, used + 1
    return (total / count if count else math.nan), used


def fit_steering(seq, fit_scans: int, evaluations: int = EVALUATIONS) -> SteeringFit:
    """The steering calibration of `seq` from the GPS stretches of its first `fit_scans` scans
    (offset, gain and cubic term; see the module doc); held out: the stretches after them."""
    split = float(seq.scan_t[min(fit_scans, seq.n_scans - 1)])
    fit = stretches(seq, float(seq.scan_t[0]), split)
    held = stretches(seq, split, float(seq.scan_t[-1]))

    def cal(p) -> SteeringCalibration:
        return SteeringCalibration(
            offset_rad=float(p[0]), gain=math.exp(float(p[1])), cubic_per_rad2=float(p[2])
        )

    def f(p) -> float:
        mse, used = dead_reckoning_mse(seq, cal(p), fit)
        if not used:
            raise DataError(
                f"gps: no stretch of the first {fit_scans} scans has {MIN_FIXES} good fixes and "
                f"{MIN_EXTENT_M} m of travel; the steering cannot be fitted"
            )
        return mse

    simplex = np.array([[0, 0, 0], [0.003, 0, 0], [0, 0.03, 0], [0, 0, 0.1]], dtype=float)
    res = minimize(
        f,
        simplex[0],
        method="Nelder-Mead",
        options={"initial_simplex": simplex, "maxfev": evaluations, "xatol": 1e-5, "fatol": 1e-4},
    )
    best, ident = cal(res.x), SteeringCalibration()
    fit_after, n_fit = dead_reckoning_mse(seq, best, fit)
    held_after, n_held = dead_reckoning_mse(seq, best, held) if held else (math.nan, 0)
    return SteeringFit(
        steering=best,
        fit_stretches=n_fit,
        held_out_stretches=n_held,
        fit_mse_before=dead_reckoning_mse(seq, ident, fit)[0],
        fit_mse_after=fit_after,
        held_out_mse_before=dead_reckoning_mse(seq, ident, held)[0] if held else math.nan,
        held_out_mse_after=held_after,
        evaluations=int(res.nfev),
    )
