"""The in-memory run (`Sequence`) and its file format (one `.npz`, see datasets/FORMAT.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from features.types import Scan

__all__ = ["Sequence"]


@dataclass(frozen=True, eq=False)
class Sequence:
    """One run: laser scans plus whatever odometry, GPS and truth came with them.

    Required
      scan_t: (N,) s, strictly increasing.
      scan_ranges: (N, B) m, NaN = no return.
      scan_angle_min, scan_angle_increment: rad, laser frame (0 = laser x-axis, CCW positive).
      laser_pose: (3,) [x, y, theta] of the laser in the vehicle frame (rear-axle centre).
    Optional (None when absent)
      scan_max_range: m; readings at or beyond it are no return (inf when absent).
      odo_t (M,) s, odo_speed (M,) m/s as measured by the encoder, odo_steer (M,) rad front wheel.
      vehicle: dict, e.g. {"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}.
      gps_t (G,) s, gps_xy (G, 2) m world; gps_pose (3,) antenna in the vehicle frame
        (the laser's position when absent).
      truth_t (T,) s, truth_pose (T, 3) [x, y, theta] of the rear-axle centre, world frame.
      truth_landmarks (L, 3) [x, y, r] m.
      scan_labels (N, B) int: id of the object each beam hit, -1 for none.
      name: free text describing the run.
    """

    scan_t: np.ndarray
    scan_ranges: np.ndarray
    scan_angle_min: float
    scan_angle_increment: float
    laser_pose: np.ndarray
    scan_max_range: float = float("inf")
    odo_t: np.ndarray | None = None
    odo_speed: np.ndarray | None = None
    odo_steer: np.ndarray | None = None
    vehicle: dict | None = None
    gps_t: np.ndarray | None = None
    gps_xy: np.ndarray | None = None
    gps_pose: np.ndarray | None = None
    truth_t: np.ndarray | None = None
    truth_pose: np.ndarray | None = None
    truth_landmarks: np.ndarray | None = None
    scan_labels: np.ndarray | None = None
    name: str = ""

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])

    def scan(self, k: int) -> Scan:
        """Scan k as a `features.Scan`."""
        return Scan(
            self.scan_ranges[k],
            self.scan_angle_min,
            self.scan_angle_increment,
            stamp_s=float(self.scan_t[k]),
            max_range_m=self.scan_max_range,
        )
