"""The start pose of a run that begins from GPS: dead reckoning fitted to the first fixes.

A single GPS fix gives a position but no heading, and the heading of a short stretch of GPS
motion (the first 2 m, say) is only as good as two noisy fixes: on Victoria Park it was 14
degrees off, which turns the whole map. Instead, the odometry is integrated from a provisional
pose (0, 0, 0) at the first scan, the GPS antenna's path is computed from it, and the rigid
transform (rotation theta, translation t) that best maps that path onto the GPS fixes of the
first `fit_m` metres of driving is found in closed form (2D Procrustes / Kabsch, least
squares). The start pose is then (t, theta): the transform applied to the provisional start.

Dead reckoning keeps its shape for tens of metres only: a steering reading off by a fraction
of a degree curves the track by degrees over a hundred metres, and the fitted heading follows
it. `fit_gps_start_to_track` fits any other track that starts at the origin in the same way;
`slam.run` passes the path of a first pass of the filter (`SlamConfig.gps_start_track =
"slam"`), which the landmarks keep in shape over hundreds of metres, so a longer stretch of GPS
averages the fixes' slowly varying errors away.

Uncertainty: the residuals' variance s^2 = sum r_i^2 / (2 n - 3) and the Gauss-Newton normal
matrix of the same least-squares problem give cov(t_x, t_y, theta) = s^2 (J^T J)^-1 (J_i = [I,
dR/dtheta a_i]). GPS errors and dead-reckoning drift are correlated over the stretch, so this
is a lower bound; the caller applies floors. One pass of outlier rejection (residuals beyond 3 s
and 1 m) drops GPS jumps.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from slam import se2
from slam.errors import SlamError

__all__ = [
    "GpsStart",
    "antenna_of",
    "fit_gps_start",
    "fit_gps_start_to_track",
    "first_pass_wanted",
    "initial_pose",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GpsStart:
    """pose (3,) of the rear-axle centre at the first scan, world frame; cov (3, 3) from the fit;
    n_fixes used (after outlier rejection), n_rejected, distance_m of driving covered,
    rms_m of the fit residuals."""

    pose: np.ndarray
    cov: np.ndarray
    n_fixes: int
    n_rejected: int
    distance_m: float
    rms_m: float


def fit_gps_start(
    scan_t0: float,
    gps_t: np.ndarray,
    gps_xy: np.ndarray,
    *,
    antenna: np.ndarray,
    motion,
    fit_m: float,
    heading_rad: float | None = None,
) -> GpsStart:
    """The start pose at time scan_t0 from the GPS fixes of the first `fit_m` metres of driving,
    with the track dead-reckoned by `motion` (a motion model: `integrate(pose, t0, t1)`).

    antenna: (3,) the GPS antenna in the vehicle frame. heading_rad: a known start heading
    (only the position is fitted then). Raises SlamError when the fixes cannot fix the pose.
    """
    use = np.flatnonzero(gps_t >= scan_t0 - 1e-9)
    if use.size < 3:
        raise SlamError("gps_t: fewer than 3 GPS fixes after the first scan; cannot fit the start")
    pose = np.zeros(3)
    t = float(scan_t0)
    a = []
    for k in use:
        pose, _, _ = motion.integrate(pose, t, float(gps_t[k]))
        t = float(gps_t[k])
        a.append(se2.compose(pose, antenna)[:2])
    return _fit_track(np.array(a), np.asarray(gps_xy, dtype=np.float64)[use], fit_m, heading_rad)


def fit_gps_start_to_track(
    track_t: np.ndarray,
    track_pose: np.ndarray,
    gps_t: np.ndarray,
    gps_xy: np.ndarray,
    antenna: np.ndarray,
    fit_m: float,
    heading_rad: float | None = None,
) -> GpsStart:
    """The start pose at track_t[0] from the GPS fixes of the first `fit_m` metres of a track.

    track_pose (T, 3): rear-axle poses at the times track_t (sorted), in a frame whose origin
    is the first pose (track_pose[0] = (0, 0, 0)): for example the path of a first pass of the
    filter, which keeps its shape over hundreds of metres where dead reckoning drifts. The
    fixes from track_t[0] until the track's antenna has travelled `fit_m` metres (along its
    poses, so gaps in the GPS do not shorten the stretch) are matched to the track's pose at
    their time (interpolated), and the rigid transform that maps its antenna path onto them is
    the start pose, as in `fit_gps_start`. Raises SlamError when the track does not start at
    the origin or the fixes cannot fix the pose.
    """
    track_t = np.asarray(track_t, dtype=np.float64)
    track_pose = np.asarray(track_pose, dtype=np.float64).reshape(-1, 3)
    if track_t.shape != track_pose.shape[:1] or np.any(np.diff(track_t) <= 0):
        raise SlamError(
            f"track_t: expected {track_pose.shape[0]} increasing times, one per pose of the track"
        )
    if np.abs(track_pose[0]).max() > 1e-9:
        raise SlamError(f"track_pose[0]: the track must start at the origin, got {track_pose[0]}")
    path = np.array([se2.compose(p, antenna)[:2] for p in track_pose])
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    t_end = track_t[min(int(np.searchsorted(along, fit_m, side="right")), track_t.size - 1)]
    gps_t = np.asarray(gps_t, dtype=np.float64)
    use = np.flatnonzero((gps_t >= track_t[0] - 1e-9) & (gps_t <= t_end + 1e-9))
    if use.size < 3:
        raise SlamError("gps_t: fewer than 3 GPS fixes along the track; cannot fit the start")
    poses = se2.interpolate_poses(gps_t[use], track_t, track_pose)
    a = np.array([se2.compose(p, antenna)[:2] for p in poses])
    return _fit_track(a, np.asarray(gps_xy, dtype=np.float64)[use], math.inf, heading_rad)


def _fit_track(a: np.ndarray, b: np.ndarray, fit_m: float, heading_rad: float | None) -> GpsStart:
    """The start pose from the antenna track a (n, 2) at the fixes' times, in the frame of a
    start at the origin, and the fixes b (n, 2): the rigid fit over the fixes of the first
    `fit_m` metres of a (measured from fix to fix; module docstring)."""
    dist = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(a, axis=0).T))])
    n = max(int(np.searchsorted(dist, fit_m, side="right")), 3)
    A, B = a[:n], b[:n]
    keep = np.ones(n, bool)
    for _ in range(2):  # fit, then once more without the outliers
        theta, tr = _fit(A[keep], B[keep], heading_rad)
        r = np.hypot(*(B - (se2.rotate(theta, A) + tr)).T)
        s = math.sqrt(np.sum(r[keep] ** 2) / max(2 * keep.sum() - 3, 1))
        keep = r <= max(3.0 * s, 1.0)
        if keep.sum() < 3:
            raise SlamError("gps_xy: the first GPS fixes disagree with the track; no start fit")
    theta, tr = _fit(A[keep], B[keep], heading_rad)
    res = B[keep] - (se2.rotate(theta, A[keep]) + tr)
    m = int(keep.sum())
    s2 = float(np.sum(res**2)) / max(2 * m - 3, 1)
    if heading_rad is None:
        spread = float(np.sum((A[keep] - A[keep].mean(axis=0)) ** 2))
        if spread < 1.0:  # the antenna hardly moved: no heading from the fixes
            raise SlamError(
                f"gps_xy: the antenna moves too little during the first GPS fixes (spread "
                f"{math.sqrt(spread):.2f} m), so the start heading is unknown; give the initial "
                "heading"
            )
        dR = se2.rotate(theta + math.pi / 2, A[keep])  # d(R a)/d theta
        J = np.zeros((2 * m, 3))
        J[0::2, 0] = 1.0
        J[1::2, 1] = 1.0
        J[:, 2] = dR.reshape(-1)
        cov = s2 * np.linalg.inv(J.T @ J)
    else:
        cov = np.diag([s2 / m, s2 / m, 0.0])
    return GpsStart(
        pose=np.array([tr[0], tr[1], float(se2.wrap_angle(theta))]),
        cov=0.5 * (cov + cov.T),
        n_fixes=m,
        n_rejected=int(n - m),
        distance_m=float(dist[n - 1]),
        rms_m=float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
    )


def _fit(A: np.ndarray, B: np.ndarray, heading_rad: float | None) -> tuple[float, np.ndarray]:
    if heading_rad is None:
        return se2.procrustes_2d(A, B)
    return float(heading_rad), (B - se2.rotate(float(heading_rad), A)).mean(axis=0)


def antenna_of(seq, cfg, laser: np.ndarray) -> np.ndarray:
    """The GPS antenna in the vehicle frame: the configuration's, else the sequence's, else the
    laser's position (vehicle.gps_antenna, Sequence.gps_pose)."""
    if cfg.vehicle.gps_antenna is not None:
        return np.array([*cfg.vehicle.gps_antenna, 0.0])
    return np.asarray(seq.gps_pose if seq.gps_pose is not None else laser, dtype=np.float64)


def first_pass_wanted(seq, cfg) -> tuple[np.ndarray, float] | None:
    """(cov0 (3, 3), fit_m) of the pass of the filter from the origin that `initial_pose` needs
    (a GPS start fitted to the filter's track, `gps_track = "slam"`), None when it needs none:
    the caller runs it over the scans until the antenna has covered fit_m metres."""
    start = cfg.start
    if _truth_covers(seq) or seq.gps_t is None or start.gps_track != "slam":
        return None
    floors = np.array([start.gps_sigma_m, start.gps_sigma_m, start.heading_sigma_rad]) ** 2
    return np.diag(floors), start.gps_fit_m


def _truth_covers(seq) -> bool:
    """Whether the sequence's truth covers its first scan."""
    t0, truth_t = float(seq.scan_t[0]), seq.truth_t
    return truth_t is not None and bool(truth_t[0] <= t0 <= truth_t[-1])


def initial_pose(seq, cfg, motion, laser: np.ndarray, track=None):
    """(pose (3,), covariance (3, 3), how) of the filter's prior at the first scan, how being
    "truth", "gps" or "origin" (`SlamConfig.start`).

    motion: the run's motion model (`slam.motion`), for a dead-reckoned GPS fit; track: (scan times,
    poses) of the pass of the filter from the origin that `first_pass_wanted` asked for (for
    `gps_track = "slam"`)."""
    start = cfg.start
    t0 = float(seq.scan_t[0])
    truth_t = seq.truth_t
    if truth_t is not None and not truth_t[0] <= t0 <= truth_t[-1]:
        log.warning(
            "the truth (%.3f .. %.3f s) does not cover the first scan (%.3f s); not starting "
            "from it",
            truth_t[0],
            truth_t[-1],
            t0,
        )
        truth_t = None
    if truth_t is not None:
        pose = se2.interpolate_poses(t0, seq.truth_t, seq.truth_pose)[0]
        if start.initial_heading_rad is not None:
            log.warning("start.initial_heading_rad ignored: the run starts from the truth")
        return pose, np.diag(np.square(start.initial_pose_sigma)), "truth"
    if seq.gps_t is not None:
        return _gps_start(seq, cfg, motion, antenna_of(seq, cfg, laser), track)
    th = 0.0 if start.initial_heading_rad is None else float(start.initial_heading_rad)
    return np.array([0.0, 0.0, th]), np.diag(np.square(start.initial_pose_sigma)), "origin"


def _gps_start(seq, cfg, motion, antenna: np.ndarray, track):
    start = cfg.start
    t0 = float(seq.scan_t[0])
    if float(seq.gps_t[0]) - t0 > 1.0:
        log.warning(
            "first GPS fix at %.3f s is %.3f s after the first scan",
            float(seq.gps_t[0]),
            float(seq.gps_t[0]) - t0,
        )
    floors = np.array([start.gps_sigma_m, start.gps_sigma_m, start.heading_sigma_rad]) ** 2
    heading = start.initial_heading_rad
    if start.gps_track == "slam":
        if track is None:
            raise SlamError("start.gps_track = 'slam': needs the first pass's track")
        track_t, track_pose = track
        fit = fit_gps_start_to_track(
            track_t,
            track_pose,
            seq.gps_t,
            seq.gps_xy,
            antenna=antenna,
            fit_m=start.gps_fit_m,
            heading_rad=heading,
        )
        how = f"a first pass over {track_t.size} scans"
    else:
        fit = fit_gps_start(
            t0,
            seq.gps_t,
            seq.gps_xy,
            antenna=antenna,
            motion=motion,
            fit_m=start.gps_fit_m,
            heading_rad=heading,
        )
        how = "dead reckoning"
    cov = fit.cov + np.diag(np.maximum(floors - np.diag(fit.cov), 0.0))
    log.info(
        "start from GPS (%s): %d fixes over %.1f m (%d rejected), rms %.2f m, heading %.2f deg",
        how,
        fit.n_fixes,
        fit.distance_m,
        fit.n_rejected,
        fit.rms_m,
        math.degrees(fit.pose[2]),
    )
    return fit.pose, cov, "gps"
