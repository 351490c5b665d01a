"""Circle accuracy: the paper's CE and RE, and the Cramer-Rao lower bound of circle fitting.

CE, eq. (10): centre error relative to the pillar's distance from the sensor.
RE, eq. (11): radius error relative to the true radius.
`circle_crlb`: the Cramer-Rao lower bound on (x0, y0, r) from range readings along known beams,
each with independent Gaussian range noise.
"""

from __future__ import annotations

import numpy as np

from experiments.errors import ConfigError

__all__ = ["center_error", "radius_error", "circle_crlb", "beam_range_jacobian"]


def center_error(true_xy, est_xy) -> np.ndarray:
    """eq. (10): |c_true - c_est| / |c_true|, c in the sensor frame (sensor at the origin).

    true_xy, est_xy: (..., 2) metres. Returns (...,) dimensionless.
    """
    true_xy = np.asarray(true_xy, float)
    est_xy = np.asarray(est_xy, float)
    if true_xy.shape[-1] != 2 or est_xy.shape[-1] != 2:
        raise ConfigError(
            f"center_error: expected (..., 2) arrays, got {true_xy.shape}, {est_xy.shape}"
        )
    dist = np.linalg.norm(true_xy, axis=-1)
    if np.any(dist == 0):
        raise ConfigError("center_error: a true centre at the sensor has no relative error")
    return np.linalg.norm(true_xy - est_xy, axis=-1) / dist


def radius_error(true_r, est_r) -> np.ndarray:
    """eq. (11): |r_true - r_est| / r_true."""
    true_r = np.asarray(true_r, float)
    if np.any(true_r <= 0):
        raise ConfigError("radius_error: true radius must be > 0")
    return np.abs(true_r - np.asarray(est_r, float)) / true_r


def beam_range_jacobian(center_xy, radius_m: float, angles_rad) -> np.ndarray:
    """d(range)/d(x0, y0, r) for beams from the origin that hit the circle: (K, 3).

    The range along unit direction u is rho = u.c - sqrt(r^2 - t^2), t = u x c; so
    d rho / d c = u + (t / q) (-u_y, u_x) and d rho / d r = -r / q, q = sqrt(r^2 - t^2).
    Beams that miss (t^2 >= r^2) raise ValueError.
    """
    c = np.asarray(center_xy, float)
    a = np.asarray(angles_rad, float)
    ux, uy = np.cos(a), np.sin(a)
    t = ux * c[1] - uy * c[0]
    q2 = radius_m**2 - t * t
    if np.any(q2 <= 0):
        raise ConfigError("beam_range_jacobian: a beam misses the circle")
    q = np.sqrt(q2)
    return np.column_stack([ux - (t / q) * uy, uy + (t / q) * ux, -radius_m / q])


def circle_crlb(center_xy, radius_m: float, angles_rad, sigma_m: float) -> np.ndarray:
    """(3, 3) Cramer-Rao lower bound on the covariance of an unbiased (x0, y0, r) estimate from
    range readings with noise sigma_m along the given beams (sensor at the origin).

    The bound is local: it ignores which beams hit changing with the circle, and it is reached
    only where the range model is nearly linear over the noise (grazing beams are not).
    """
    J = beam_range_jacobian(center_xy, radius_m, angles_rad)
    if J.shape[0] < 3:
        raise ConfigError(f"circle_crlb: needs >= 3 beams on the circle, got {J.shape[0]}")
    fisher = J.T @ J / sigma_m**2
    return np.linalg.solve(fisher, np.eye(3))
