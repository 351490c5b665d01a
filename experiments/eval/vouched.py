"""The GPS fixes the wheel odometry vouches for: a fairer reference than every fix.

Victoria Park's GPS has single-sample hops, a fix 130 m off the track, and offset stretches
after dropouts; scored against every fix, a path pays for the GPS's errors as much as for its
own. The rule (issue 27) keeps a fix only when the odometry, independently of any SLAM output,
agrees with the fixes around it, so that every method is scored on the same fixes:

For each fix i: dead-reckon the GPS antenna from the odometry alone (the car's model with its
steering calibration, each sample integrated as an arc; `dead_reckoned_antenna`); take the
fixes within +-`window_s` of fix i; find the rigid 2D transform that puts the most of them
within `tol_m` of the dead-reckoned track (hypotheses from pairs of fixes at least
`min_pair_m` apart along the track, then a least-squares refit on the inliers, twice; a
translation only when the track spans less than `min_span_m`); keep fix i when at least
`min_inliers` fixes and at least half of the window are inliers and fix i itself is one.

The pairs: every pair among up to `PAIR_POOL` fixes spread evenly over the window (all of them
in a window of that size or less), a fixed, deterministic set: a window of 10 s of 5 Hz GPS
holds about 100 fixes, whose 4,950 pairs would cost 25 times the 190 used and find the same
consensus (the inliers are most of the window when the fix is good).

Its limit: a stretch of offset fixes shorter than the window is caught, but an offset of a few
metres at a window's end can be absorbed by a slightly turned fit (the tests use 8 m offsets);
the rule removes gross GPS faults, not every small one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam import se2
from slam.se2 import procrustes_2d

__all__ = [
    "PAIR_POOL",
    "VouchRule",
    "dead_reckoned_antenna",
    "vouched_fixes",
    "vouched_for_sequence",
]

PAIR_POOL = 20


class VouchRule:
    """The rule's constants (issue 27's): window_s 10, tol_m 1.0, min_pair_m 3.0, min_span_m
    2.0, min_inliers 15, min_share 0.5."""

    window_s = 10.0
    tol_m = 1.0
    min_pair_m = 3.0
    min_span_m = 2.0
    min_inliers = 15
    min_share = 0.5


def dead_reckoned_antenna(motion, antenna, t_s: np.ndarray) -> np.ndarray:
    """(G, 2) the antenna point dead-reckoned by `motion` (a motion model of the run's vehicle,
    e.g. `slam.components.make_motion`) from the origin at t_s[0], at every time of t_s
    (increasing): the odometry's track in its own frame."""
    pose = np.zeros(3)
    out = np.empty((t_s.size, 2))
    t_prev = float(t_s[0])
    for k, t in enumerate(t_s):
        pose, _, _ = motion.integrate(pose, t_prev, float(t))
        t_prev = float(t)
        out[k] = se2.compose(pose, antenna)[:2]
    return out


def vouched_fixes(t_s: np.ndarray, gps_xy: np.ndarray, track_xy: np.ndarray, rule=VouchRule):
    """(G,) bool: the fixes the odometry vouches for. t_s (G,) increasing fix times, gps_xy
    (G, 2) the fixes, track_xy (G, 2) the dead-reckoned antenna at the same times."""
    t_s = np.asarray(t_s, np.float64)
    B = np.asarray(gps_xy, np.float64)
    A = np.asarray(track_xy, np.float64)
    keep = np.zeros(t_s.size, bool)
    lo = np.searchsorted(t_s, t_s - rule.window_s, side="left")
    hi = np.searchsorted(t_s, t_s + rule.window_s, side="right")
    for i in range(t_s.size):
        a, b = A[lo[i] : hi[i]], B[lo[i] : hi[i]]
        n = a.shape[0]
        if n < rule.min_inliers:
            continue
        inlier = _consensus(a, b, rule)
        count = int(inlier.sum())
        if count >= rule.min_inliers and count >= rule.min_share * n and inlier[i - lo[i]]:
            keep[i] = True
    return keep


def _consensus(a: np.ndarray, b: np.ndarray, rule) -> np.ndarray:
    """(n,) bool: the inliers of the rigid transform a -> b with the most inliers (see the
    module doc), after two least-squares refits on them."""
    d = a[:, None, :] - a[None, :, :]
    rotate = float(np.sqrt(np.max(np.sum(d * d, axis=2)))) >= rule.min_span_m  # the track's span
    pool = np.unique(np.linspace(0, a.shape[0] - 1, min(PAIR_POOL, a.shape[0])).astype(np.int64))
    theta, t = _best_hypothesis(a, b, pool, rule.tol_m, rule.min_pair_m if rotate else -1.0)
    inlier = _inliers(a, b, theta, t, rule.tol_m)
    for _ in range(2):  # least-squares refit on the inliers, twice
        if inlier.sum() < 2:
            break
        if rotate:
            theta, t = procrustes_2d(a[inlier], b[inlier])
        else:
            theta, t = 0.0, np.mean(b[inlier] - a[inlier], axis=0)
        inlier = _inliers(a, b, theta, t, rule.tol_m)
    return inlier


def _inliers(a, b, theta, t, tol):
    c, s = np.cos(theta), np.sin(theta)
    x = c * a[:, 0] - s * a[:, 1] + t[0] - b[:, 0]
    y = s * a[:, 0] + c * a[:, 1] + t[1] - b[:, 1]
    return x * x + y * y <= tol * tol


@njit(cache=True)
def _best_hypothesis(a, b, pool, tol, min_pair):
    """(theta, t (2,)) with the most inliers among the hypotheses: rigid transforms from the
    pairs of `pool` at least `min_pair` apart on the track (min_pair < 0: translations from
    single fixes)."""
    n = a.shape[0]
    best, best_th, best_t = -1, 0.0, np.zeros(2)
    tol2 = tol * tol
    for p in range(pool.size):
        for q in range(p, pool.size):
            i, j = pool[p], pool[q]
            if min_pair < 0.0:
                if i != j:
                    continue
                th, c, s = 0.0, 1.0, 0.0
            else:
                if i == j:
                    continue
                dax, day = a[j, 0] - a[i, 0], a[j, 1] - a[i, 1]
                if dax * dax + day * day < min_pair * min_pair:
                    continue
                dbx, dby = b[j, 0] - b[i, 0], b[j, 1] - b[i, 1]
                th = np.arctan2(dby, dbx) - np.arctan2(day, dax)
                c, s = np.cos(th), np.sin(th)
            tx = b[i, 0] - (c * a[i, 0] - s * a[i, 1])
            ty = b[i, 1] - (s * a[i, 0] + c * a[i, 1])
            count = 0
            for k in range(n):
                x = c * a[k, 0] - s * a[k, 1] + tx - b[k, 0]
                y = s * a[k, 0] + c * a[k, 1] + ty - b[k, 1]
                if x * x + y * y <= tol2:
                    count += 1
            if count > best:
                best, best_th = count, th
                best_t[0], best_t[1] = tx, ty
    return best_th, best_t


def vouched_for_sequence(seq, cfg) -> np.ndarray:
    """(G,) bool over all of `seq`'s GPS fixes: those its odometry vouches for, dead-reckoned
    with the vehicle model and steering calibration of the configuration `cfg` (no SLAM run)."""
    from slam.checks import check_runnable
    from slam.components import laser_pose, make_motion
    from slam.start import antenna_of

    motion = make_motion(seq, cfg, check_runnable(seq, cfg))
    antenna = antenna_of(seq, cfg, laser_pose(seq, cfg))
    track = dead_reckoned_antenna(motion, antenna, seq.gps_t)
    return vouched_fixes(seq.gps_t, seq.gps_xy, track)
