"""Outlines drawn by both the figures and the recordings: circles and covariance ellipses."""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["circle_polylines", "ellipse_polyline", "ellipse_polylines"]


@functools.cache
def _unit_circle(n: int) -> np.ndarray:
    """(n + 1, 2) [cos t, sin t] at n + 1 angles t from 0 to 2 pi (read only: shared)."""
    t = np.linspace(0.0, 2.0 * np.pi, n + 1)
    unit = np.stack([np.cos(t), np.sin(t)], axis=1)
    unit.flags.writeable = False
    return unit


def circle_polylines(circles_xyr, n: int = 48) -> np.ndarray:
    """(m, n + 1, 2) closed polylines of m circles (m, 3) [x, y, r], n sides each."""
    c = np.asarray(circles_xyr, float).reshape(-1, 3)
    unit = _unit_circle(n)
    return c[:, None, :2] + c[:, 2:, None] * unit[None]


def ellipse_polyline(center_xy, cov_2x2, n_sigma: float = 2.4477, n: int = 40) -> np.ndarray:
    """(n + 1, 2) closed polyline of the n_sigma ellipse of a 2D Gaussian (2.4477: 95%)."""
    return ellipse_polylines(center_xy, cov_2x2, n_sigma, n)[0]


def ellipse_polylines(
    centers_xy, covs_2x2, n_sigma: float = 2.4477, n: int = 40, dtype=np.float64
) -> np.ndarray:
    """(m, n + 1, 2) the `ellipse_polyline` of each of m Gaussians, centres (m, 2) and
    covariances (m, 2, 2), at once, as `dtype` (a recording draws thousands a batch).

    The 2x2 eigen-decomposition in closed form, elementwise over the m matrices (no per-matrix
    LAPACK call, no batched matmul): for the symmetric part [[a, b], [b, c]], the semi-axes are
    n_sigma sqrt(l) with l = (a + c)/2 +- hypot((a - c)/2, b), the major axis at the angle
    atan2(b, (a - c)/2)/2 (negative eigenvalues, from rounding, count as 0). Point i is
    centre + minor * cos(t_i) + major * sin(t_i), t_i = 2 pi i/n: it starts on the minor
    axis (as `eigh`'s ascending order did), at the end (-sin, cos) of the major axis' normal."""
    centers = np.asarray(centers_xy, float).reshape(-1, 2)
    covs = np.asarray(covs_2x2, float).reshape(-1, 2, 2)
    a, c = covs[:, 0, 0], covs[:, 1, 1]
    b = 0.5 * (covs[:, 0, 1] + covs[:, 1, 0])
    mid, half = 0.5 * (a + c), 0.5 * (a - c)
    r = np.hypot(half, b)
    major = n_sigma * np.sqrt(np.maximum(mid + r, 0.0))
    minor = n_sigma * np.sqrt(np.maximum(mid - r, 0.0))
    angle = 0.5 * np.arctan2(b, half)
    cos, sin = np.cos(angle), np.sin(angle)
    unit = _unit_circle(n)
    ct, st = unit[None, :, 0], unit[None, :, 1]
    out = np.empty((len(centers), n + 1, 2), dtype)
    out[:, :, 0] = centers[:, :1] - (minor * sin)[:, None] * ct + (major * cos)[:, None] * st
    out[:, :, 1] = centers[:, 1:] + (minor * cos)[:, None] * ct + (major * sin)[:, None] * st
    return out
