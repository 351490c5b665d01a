"""Victoria Park: how many metres of GPS the start pose is fitted to, derived from scans 1-2000.

Nothing in a SLAM run observes the map's global heading: the start fixes it for the whole run
(first-estimates Jacobians keep it so), and one degree is 3.5 m at 200 m from the start. The
start is a rigid fit of a track to the GPS fixes of its first `gps_start_fit_m` metres
(`slam.start`). A dead-reckoned track bends with the steering calibration (the preset's
0.3 deg offset alone turns it by 5 deg over 50 m) and the fitted heading with it; GPS errors
vary slowly (multipath near trees), so a short stretch follows them too. The preset therefore
fits the path of a first pass of the filter itself (`gps_start_track = "slam"`), which the
trees keep in shape, over a stretch long enough for the GPS errors to average out.

The rule (`derive`): run the filter over scans 1-2000 (with the fitted configuration), fit its
path to the GPS over the first D metres for D = 50, 100, ... up to the path's length, and take
the shortest D from which every longer fit gives a heading within `TOLERANCE_DEG` of the fit
over the whole stretch. It uses the fixes of scans 1-2000 only and no GPS error of a run; the
start itself then uses the fixes of the first D metres.
"""

from __future__ import annotations

import math

import numpy as np

from experiments.errors import DataError
from slam import SlamConfig, run_slam, se2
from slam.start import fit_gps_start_to_track

__all__ = ["STEP_M", "TOLERANCE_DEG", "derive", "headings"]

STEP_M = 50.0
TOLERANCE_DEG = 0.3


def headings(seq, cfg: SlamConfig, step_m: float = STEP_M) -> list[tuple[float, float, int]]:
    """[(D metres, start heading in degrees, fixes used)] of the start fitted to the GPS over
    the first D metres of the filter's path over `seq` (published detections, IHGR), for
    D = step_m, 2 step_m, ... and last the whole path."""
    if seq.gps_t is None:
        raise DataError("sequence: the start stretch needs GPS fixes")
    lg = run_slam(seq, cfg, features="detections", association="ihgr")
    inv = se2.inverse(lg.start_pose)
    track = np.array([se2.compose(inv, p) for p in lg.pose])
    track[0] = 0.0  # the track starts at the prior's mean (the first scan has no update)
    ant = lg.antenna_pose
    path = np.array([se2.compose(p, ant)[:2] for p in track])
    length = float(np.sum(np.hypot(*np.diff(path, axis=0).T)))
    out = []
    for d in [*np.arange(step_m, length, step_m), length]:
        fit = fit_gps_start_to_track(
            lg.scan_t, track, seq.gps_t, seq.gps_xy, antenna=ant, fit_m=float(d)
        )
        out.append((float(d), math.degrees(fit.pose[2]), fit.n_fixes))
    return out


def derive(rows: list[tuple[float, float, int]], tolerance_deg: float = TOLERANCE_DEG) -> float:
    """The shortest D of `headings` rows from which every longer fit is within `tolerance_deg`
    of the last (whole-path) one."""
    ref = rows[-1][1]
    d = rows[-1][0]
    for dist, heading, _ in reversed(rows):
        if abs(heading - ref) > tolerance_deg:
            break
        d = dist
    return d
