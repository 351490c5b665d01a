"""Scoring an estimated path against GPS: the antenna point, each fix against the pose at its
time, with and without a rigid alignment, GPS jumps flagged and reported, never dropped silently.

- The GPS antenna is not at the rear axle: on the Victoria Park ute it sits at the laser,
  (3.78, 0.50) m in the vehicle frame. The estimate is compared at that point:
  antenna = pose (+) antenna_pose.
- Each fix is matched to the pose interpolated at the fix's time (`slam.interpolate_poses`,
  heading unwrapped). Fixes outside the run's scan times are not matched (and counted).
- A fix is a jump when reaching it from the previous fix would take more than the vehicle's top
  speed (`max_speed_mps`), with 1 m of slack for the fixes' own noise: such a fix is flagged and
  the figures are given with and without the flagged fixes. The fix after a jump, measured
  against the jump, is also fast; it is flagged only if it is also too far from the last good fix.
- Figures: RMSE, median and 95th percentile of the horizontal distance, as is (the absolute
  error of the run, the start included), and after the rigid 2D transform (rotation and
  translation, no scale) that best maps the estimated antenna track onto the fixes (Kabsch).
- The fixes the odometry vouches for (`experiments.eval.vouched`, issue 27's rule, no SLAM
  output involved): RMSE, median and p95 over them alone, so that every method is scored on
  the same fixes and the GPS's own hops and offsets are not charged to the path.
- The protocol of the published random-finite-set results on Victoria Park: every fix within
  25 ms of a scan time, none dropped (RMSE only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slam import interpolate_poses, se2
from slam.se2 import procrustes_2d

__all__ = [
    "GpsScore",
    "fixes_in_run",
    "flag_jumps",
    "score_against_gps",
    "score_sequence",
    "top_speed",
]


def fixes_in_run(gps_t: np.ndarray, scan_t: np.ndarray) -> np.ndarray:
    """(G,) bool: the fixes a run over scan_t is scored against, those inside its time span
    [scan_t[0], scan_t[-1]] (`trunkslam export-reference` writes the same fixes)."""
    gps_t = np.asarray(gps_t, dtype=np.float64)
    scan_t = np.asarray(scan_t, dtype=np.float64)
    return (gps_t >= scan_t[0]) & (gps_t <= scan_t[-1])


def flag_jumps(t_s: np.ndarray, xy: np.ndarray, max_speed_mps: float, slack_m: float = 1.0):
    """(G,) bool: fixes that could not be reached from the last good fix at `max_speed_mps`."""
    jump = np.zeros(t_s.size, bool)
    last = 0
    for i in range(1, t_s.size):
        reach = max_speed_mps * (t_s[i] - t_s[last]) + slack_m
        if np.hypot(*(xy[i] - xy[last])) > reach:
            jump[i] = True
        else:
            last = i
    return jump


@dataclass(frozen=True)
class GpsScore:
    """Errors of the antenna point against the GPS fixes (metres).

    matched: fixes within the run's time span; jumps: of those, flagged as jumps.
    all_*: over every matched fix; clean_*: without the jumps. *_aligned: after the rigid
    alignment fitted to the clean fixes (rotation_deg, its angle). errors: (matched,) the raw
    distance of each matched fix; t_s its time; jump its flag. vouched, vouched_*: the matched
    fixes the odometry vouches for and the figures over them (0 and NaN when not computed).
    rfs_fixes, rfs_rmse: the fixes within 25 ms of a scan time and their RMSE.
    """

    matched: int
    jumps: int
    unmatched: int
    all_rmse: float
    all_median: float
    all_p95: float
    clean_rmse: float
    clean_median: float
    clean_p95: float
    all_rmse_aligned: float
    clean_rmse_aligned: float
    clean_median_aligned: float
    clean_p95_aligned: float
    rotation_deg: float
    t_s: np.ndarray
    errors: np.ndarray
    jump: np.ndarray
    vouched: int = 0
    vouched_rmse: float = math.nan
    vouched_median: float = math.nan
    vouched_p95: float = math.nan
    rfs_fixes: int = 0
    rfs_rmse: float = math.nan

    def to_dict(self) -> dict:
        """The figures (not the per-fix arrays), to 0.1 mm; a figure that could not be computed
        (no fix to compute it over) is None."""
        out = {k: v for k, v in self.__dict__.items() if not isinstance(v, np.ndarray)}
        return {k: _rounded(v) for k, v in out.items()}


def _rounded(v):
    if isinstance(v, float):
        return round(v, 4) if math.isfinite(v) else None
    return v


def _stats(e: np.ndarray) -> tuple[float, float, float]:
    if e.size == 0:
        return math.nan, math.nan, math.nan
    return (float(np.sqrt(np.mean(e**2))), float(np.median(e)), float(np.percentile(e, 95)))


def score_against_gps(
    scan_t: np.ndarray,
    pose: np.ndarray,
    gps_t: np.ndarray,
    gps_xy: np.ndarray,
    antenna_pose: np.ndarray,
    max_speed_mps: float,
    *,
    vouched: np.ndarray | None = None,
    stamps: np.ndarray | None = None,
) -> GpsScore:
    """Score the rear-axle poses (N, 3) at scan_t (N,) against the fixes gps_xy (G, 2) at gps_t.

    antenna_pose: (3,) the antenna in the vehicle frame. max_speed_mps: the vehicle's top speed
    (fixes implying more are jumps). vouched: (G,) bool, the fixes the odometry vouches for
    (`experiments.eval.vouched`), or None. stamps: (N,) the scans' own time stamps, which choose
    the fixes within 25 ms of a scan (None: scan_t; they differ when the run placed its scans a
    laser latency before their stamps, `vehicle.laser_latency_s`). See the module doc.
    """
    scan_t = np.asarray(scan_t, dtype=np.float64)
    gps_t = np.asarray(gps_t, dtype=np.float64)
    inside = fixes_in_run(gps_t, scan_t)
    t, g = gps_t[inside], np.asarray(gps_xy, dtype=np.float64)[inside]
    jump = flag_jumps(t, g, max_speed_mps)
    P = interpolate_poses(t, scan_t, pose)
    ant = np.array([se2.compose(p, antenna_pose)[:2] for p in P]).reshape(-1, 2)
    e = np.hypot(*(ant - g).T)
    clean = ~jump
    rot = math.nan
    e_al = np.full(e.shape, np.nan)
    if clean.sum() >= 3:
        theta, tr = procrustes_2d(ant[clean], g[clean])
        rot = math.degrees(theta)
        e_al = np.hypot(*(se2.rotate(theta, ant) + tr - g).T)
    a, c = _stats(e), _stats(e[clean])
    ca = _stats(e_al[clean])
    v = None if vouched is None else np.asarray(vouched, bool)[inside]
    vs = _stats(e[v]) if v is not None else (math.nan,) * 3
    stamps = scan_t if stamps is None else np.asarray(stamps, dtype=np.float64)
    if stamps.shape != scan_t.shape:
        raise ValueError(f"stamps: expected {scan_t.shape[0]} scan stamps, got {stamps.shape}")
    near = _near_a_scan(t, stamps, RFS_TOLERANCE_S)
    return GpsScore(
        matched=int(t.size),
        jumps=int(jump.sum()),
        unmatched=int((~inside).sum()),
        all_rmse=a[0],
        all_median=a[1],
        all_p95=a[2],
        clean_rmse=c[0],
        clean_median=c[1],
        clean_p95=c[2],
        all_rmse_aligned=_stats(e_al)[0],
        clean_rmse_aligned=ca[0],
        clean_median_aligned=ca[1],
        clean_p95_aligned=ca[2],
        rotation_deg=rot,
        t_s=t,
        errors=e,
        jump=jump,
        vouched=int(v.sum()) if v is not None else 0,
        vouched_rmse=vs[0],
        vouched_median=vs[1],
        vouched_p95=vs[2],
        rfs_fixes=int(near.sum()),
        rfs_rmse=_stats(e[near])[0],
    )


RFS_TOLERANCE_S = 0.025  # the published RFS results' matching of fixes to scans


def _near_a_scan(t: np.ndarray, scan_t: np.ndarray, tol: float) -> np.ndarray:
    """(len(t),) bool: times within `tol` of a scan time."""
    k = np.clip(np.searchsorted(scan_t, t), 1, scan_t.size - 1) if scan_t.size > 1 else None
    if k is None:
        return np.abs(t - scan_t[0]) <= tol
    return np.minimum(np.abs(t - scan_t[k - 1]), np.abs(t - scan_t[k])) <= tol


def top_speed(seq) -> float:
    """The speed above which a GPS fix counts as a jump: 1.25 times the fastest odometry reading
    of the run (at least 1 m/s); 20 m/s without odometry."""
    if seq.odo_speed is None:
        return 20.0
    return max(1.25 * float(np.max(np.abs(seq.odo_speed))), 1.0)


def score_sequence(
    seq, scan_t: np.ndarray, pose: np.ndarray, antenna=None, vouched=None
) -> GpsScore:
    """`score_against_gps` for a run over `seq`: its GPS, at the antenna `antenna` (the run's
    `SlamLog.antenna_pose`; None: the sequence's gps_pose, else its laser); vouched: (G,) the
    fixes the odometry vouches for (`experiments.eval.vouched.vouched_for_sequence`) or None.
    The fixes within 25 ms of a scan are chosen by the sequence's own stamps of its first
    len(scan_t) scans (the run's scan_t are its poses' times)."""
    if antenna is None:
        antenna = seq.gps_pose if seq.gps_pose is not None else seq.laser_pose
    return score_against_gps(
        scan_t,
        pose,
        seq.gps_t,
        seq.gps_xy,
        antenna_pose=antenna,
        max_speed_mps=top_speed(seq),
        vouched=vouched,
        stamps=_stamps(seq, scan_t),
    )


def _stamps(seq, scan_t) -> np.ndarray | None:
    """The sequence's stamps of the run's scans (its first len(scan_t)), or None when the run
    has more scans than the sequence (then the run's own times choose the fixes)."""
    n = np.asarray(scan_t).shape[0]
    return None if seq.n_scans < n else np.asarray(seq.scan_t, dtype=np.float64)[:n]
