"""The files of a SLAM run: trajectory (TUM and CSV with covariance) and map (CSV).

Each function returns the file's text; `experiments.io.writers.write_atomic` writes it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MAP_COLUMNS", "TRAJECTORY_COLUMNS", "map_csv", "trajectory_csv", "trajectory_tum"]


def trajectory_tum(t_s: np.ndarray, pose: np.ndarray) -> str:
    """`t x y z qx qy qz qw` per line (z = 0, rotation about z by theta): evo reads it."""
    lines = (
        f"{t:.6f} {x:.6f} {y:.6f} 0.0 0.0 0.0 {math.sin(a / 2):.9f} {math.cos(a / 2):.9f}"
        for t, x, y, a in zip(t_s, pose[:, 0], pose[:, 1], pose[:, 2])
    )
    return "\n".join(lines) + "\n"


# the column names say the point (the rear-axle centre), the frame (world) and each unit
TRAJECTORY_COLUMNS = (
    "t_s",
    "rear_axle_x_world_m",
    "rear_axle_y_world_m",
    "heading_world_rad",
    "var_x_m2",
    "cov_xy_m2",
    "cov_x_heading_m_rad",
    "var_y_m2",
    "cov_y_heading_m_rad",
    "var_heading_rad2",
)
MAP_COLUMNS = (
    "id",
    "x_world_m",
    "y_world_m",
    "radius_m",
    "var_x_m2",
    "cov_xy_m2",
    "var_y_m2",
    "first_scan",
    "n_obs",
)


def trajectory_csv(t_s: np.ndarray, pose: np.ndarray, pose_cov: np.ndarray) -> str:
    """`TRAJECTORY_COLUMNS`: time, the rear-axle centre's pose in the world frame and the upper
    triangle of its covariance."""
    lines = [",".join(TRAJECTORY_COLUMNS)]
    for t, p, C in zip(t_s, pose, pose_cov):
        vals = (t, *p, C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2])
        lines.append(",".join(f"{v:.9g}" for v in vals))
    return "\n".join(lines) + "\n"


def map_csv(ids, xy, cov, first_scan, n_obs, radius_m=None) -> str:
    """`MAP_COLUMNS`: id, the centre in the world frame, the radius (median of the circles
    associated with it; empty when the features have no radius), the centre's covariance
    (xx, xy, yy), the scan it joined the map and the scans it was seen in."""
    lines = [",".join(MAP_COLUMNS)]
    radius_m = np.full(len(ids), np.nan) if radius_m is None else np.asarray(radius_m, float)
    for i, p, r, C, f, n in zip(ids, xy, radius_m, cov, first_scan, n_obs):
        rad = f"{r:.4f}" if np.isfinite(r) else ""
        cells = f"{C[0, 0]:.9g},{C[0, 1]:.9g},{C[1, 1]:.9g}"
        lines.append(f"{i},{p[0]:.6f},{p[1]:.6f},{rad},{cells},{f},{n}")
    return "\n".join(lines) + "\n"
