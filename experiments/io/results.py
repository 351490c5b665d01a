"""The files of a SLAM run: trajectory (TUM and CSV with covariance) and map (CSV).

Each function returns the file's text; `experiments.io.writers.write_atomic` writes it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["map_csv", "trajectory_csv", "trajectory_tum"]


def trajectory_tum(t_s: np.ndarray, pose: np.ndarray) -> str:
    """`t x y z qx qy qz qw` per line (z = 0, rotation about z by theta): evo reads it."""
    lines = (
        f"{t:.6f} {x:.6f} {y:.6f} 0.0 0.0 0.0 {math.sin(a / 2):.9f} {math.cos(a / 2):.9f}"
        for t, x, y, a in zip(t_s, pose[:, 0], pose[:, 1], pose[:, 2])
    )
    return "\n".join(lines) + "\n"


def trajectory_csv(t_s: np.ndarray, pose: np.ndarray, pose_cov: np.ndarray) -> str:
    """t, x, y, theta and the upper triangle of each pose's covariance."""
    lines = ["t_s,x_m,y_m,theta_rad,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta"]
    for t, p, C in zip(t_s, pose, pose_cov):
        vals = (t, *p, C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2])
        lines.append(",".join(f"{v:.9g}" for v in vals))
    return "\n".join(lines) + "\n"


def map_csv(ids, xy, cov, first_scan, n_obs) -> str:
    """id, x, y, covariance (xx, xy, yy), the scan it joined the map, scans it was seen in."""
    lines = ["id,x_m,y_m,cov_xx,cov_xy,cov_yy,first_scan,n_obs"]
    for i, p, C, f, n in zip(ids, xy, cov, first_scan, n_obs):
        lines.append(f"{i},{p[0]:.6f},{p[1]:.6f},{C[0, 0]:.9g},{C[0, 1]:.9g},{C[1, 1]:.9g},{f},{n}")
    return "\n".join(lines) + "\n"
