"""The protocol of the published random-finite-set results on Victoria Park, exactly.

PHD-SLAM 3.0 (Kaltiokallio et al., IEEE T-RO 40, 2024; github.com/okaltiok/PHD-SLAM-3.0 at
35a64de0ea5cb285da82bb3a0b86c3a150073a26, `Victoria Park/simulation_setup.m`,
`Victoria Park/performance_summary.m`, `Victoria Park/MonteCarloSimulations.m`,
`Victoria Park/f_func.m`) and GM-PHD-PMAU-SLAM (github.com/baizhiyuan/GM-PHD-PMAU-SLAM at
e5ba03432ee15d9c935c13be78d4ba36d68238b6, the same files, copied from PHD-SLAM 3.0) make and
score their Victoria Park runs this way:

- **Detections.** The tree detector on every scan of the raw laser; a scan where it finds
  nothing is left out altogether. Of a scan's detections those within `fov_range_m` (50 m)
  and `fov_angle_rad` (+-85 deg) of the laser are kept (`fov_cut`).
- **Clutter.** To every scan with detections, a Poisson number (mean `clutter_rate`, 5) of
  false detections, range uniform in [0, 50] m and bearing uniform in [-85, 85] deg, from a
  generator seeded by the draw's number (`poisson_clutter`; theirs: `rng(file_idx,
  'twister')`, `poissrnd`, `rand`).
- **Start.** Fixed, in the GPS frame: the laser at (-67.6493, -41.7142) m, heading 35.5 deg,
  with zero covariance (`sim.x0`, `sim.P0`). Their vehicle state is the laser's pose
  (`f_func.m` moves the point a = 3.78 m ahead of and b = 0.5 m beside the rear axle, and
  `h_func` measures from it along its heading: their model has no laser yaw).
- **Score.** At every scan with detections, the estimate against the GPS fix nearest in
  time, when it is within 25 ms of the scan (`performance_summary.m`); the distance is taken
  at the laser, which is their state (`score_at_scans`). The RMSE is pooled over the scans
  of all 100 draws (`MonteCarloSimulations.m`: `sqrt(mean(pos_e.^2, 'all', 'omitnan'))`;
  `pooled_rmse`).

Their filters' own noise (1 m and 1 deg on the laser, 1 m/s and 4 deg on the controls) is part
of their method, not of the protocol: a run under this protocol keeps its own configuration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "RfsProtocol",
    "fov_cut",
    "nearest_fix",
    "poisson_clutter",
    "pooled_rmse",
    "score_at_scans",
]


@dataclass(frozen=True)
class RfsProtocol:
    """The protocol's constants (the source of each: the module doc).

    fov_range_m, fov_angle_rad: the detections kept (range <= 50 m, |bearing| <= 85 deg).
    clutter_rate: mean number of false detections added to a scan with detections.
    start_laser: (x_m, y_m, heading_rad) of the laser at the start, GPS frame.
    tolerance_s: a scan is scored when the nearest fix is within this of its time.
    draws: the clutter draws the RMSE is pooled over.
    """

    fov_range_m: float = 50.0
    fov_angle_rad: float = math.radians(85.0)
    clutter_rate: float = 5.0
    start_laser: tuple[float, float, float] = (-67.6493, -41.7142, math.radians(35.5))
    tolerance_s: float = 0.025
    draws: int = 100

    def __post_init__(self) -> None:
        for name in ("fov_range_m", "fov_angle_rad", "tolerance_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"RfsProtocol.{name}: must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.clutter_rate) and self.clutter_rate >= 0):
            raise ValueError(f"RfsProtocol.clutter_rate: must be >= 0, got {self.clutter_rate!r}")
        if self.fov_angle_rad > math.pi:
            raise ValueError(f"RfsProtocol.fov_angle_rad: must be <= pi, got {self.fov_angle_rad}")
        if isinstance(self.draws, bool) or not isinstance(self.draws, int) or self.draws < 1:
            raise ValueError(f"RfsProtocol.draws: must be an integer >= 1, got {self.draws!r}")


def fov_cut(range_m: np.ndarray, bearing_rad: np.ndarray, protocol: RfsProtocol) -> np.ndarray:
    """(D,) bool: the detections (laser frame) the protocol keeps: range <= fov_range_m and
    |bearing| <= fov_angle_rad."""
    r = np.asarray(range_m, dtype=np.float64)
    b = np.asarray(bearing_rad, dtype=np.float64)
    return (r <= protocol.fov_range_m) & (np.abs(b) <= protocol.fov_angle_rad)


def poisson_clutter(
    rng: np.random.Generator, scans: np.ndarray, protocol: RfsProtocol
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(scan (C,), range_m (C,), bearing_rad (C,)): the false detections of one draw, for each
    scan of `scans` (increasing) a Poisson number with mean `clutter_rate`, range uniform in
    [0, fov_range_m] and bearing uniform in [-fov_angle_rad, fov_angle_rad] (their
    `rand * fov_range`, `rand * 2 fov_angle - fov_angle`: uniform in range, not in area)."""
    scans = np.asarray(scans, dtype=np.int64)
    counts = rng.poisson(protocol.clutter_rate, scans.size)
    scan = np.repeat(scans, counts)
    range_m = rng.uniform(0.0, protocol.fov_range_m, scan.size)
    bearing = rng.uniform(-protocol.fov_angle_rad, protocol.fov_angle_rad, scan.size)
    return scan, range_m, bearing


def nearest_fix(scan_t: np.ndarray, gps_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index (N,), |dt| (N,) s) of the fix nearest in time to each scan time (gps_t
    increasing); on a tie the earlier fix (MATLAB's `min` returns the first)."""
    scan_t = np.asarray(scan_t, dtype=np.float64)
    gps_t = np.asarray(gps_t, dtype=np.float64)
    if gps_t.size == 0:
        raise ValueError("nearest_fix: no GPS fixes")
    hi = np.clip(np.searchsorted(gps_t, scan_t), 0, gps_t.size - 1)
    lo = np.clip(hi - 1, 0, gps_t.size - 1)
    d_lo, d_hi = np.abs(scan_t - gps_t[lo]), np.abs(gps_t[hi] - scan_t)
    idx = np.where(d_lo <= d_hi, lo, hi)
    return idx, np.minimum(d_lo, d_hi)


def score_at_scans(
    scan_t: np.ndarray,
    laser_xy: np.ndarray,
    gps_t: np.ndarray,
    gps_xy: np.ndarray,
    tolerance_s: float = RfsProtocol.tolerance_s,
) -> np.ndarray:
    """(N,) the distance (m) of the estimated laser position `laser_xy` (N, 2) at each scan time
    `scan_t` (N,) to the GPS fix nearest in time, NaN where that fix is more than `tolerance_s`
    away (performance_summary.m: `[val, l] = min(abs(gps_time - o_time{j}))`, scored when
    `val <= 0.025`)."""
    laser_xy = np.asarray(laser_xy, dtype=np.float64).reshape(-1, 2)
    idx, dt = nearest_fix(scan_t, gps_t)
    gps = np.asarray(gps_xy, dtype=np.float64)[idx]
    err = np.hypot(*(laser_xy - gps).T)
    return np.where(dt <= tolerance_s, err, np.nan)


def pooled_rmse(errors: list[np.ndarray]) -> float:
    """The RMSE over every finite error of every draw together (not the mean of the draws'
    RMSEs): `sqrt(mean(pos_e.^2, 'all', 'omitnan'))`. NaN when there is none."""
    e = np.concatenate([np.asarray(x, dtype=np.float64).ravel() for x in errors] or [[]])
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2))) if e.size else math.nan
