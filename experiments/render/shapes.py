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
    w, v = np.linalg.eigh(0.5 * (np.asarray(cov_2x2) + np.asarray(cov_2x2).T))
    circle = _unit_circle(n) * (n_sigma * np.sqrt(np.maximum(w, 0.0)))
    return np.asarray(center_xy, float) + circle @ v.T


def ellipse_polylines(centers_xy, covs_2x2, n_sigma: float = 2.4477, n: int = 40) -> np.ndarray:
    """(m, n + 1, 2) the `ellipse_polyline` of each of m Gaussians, centres (m, 2) and
    covariances (m, 2, 2), at once (a recording draws every landmark's at every scan)."""
    centers = np.asarray(centers_xy, float).reshape(-1, 2)
    covs = np.asarray(covs_2x2, float).reshape(-1, 2, 2)
    w, v = np.linalg.eigh(0.5 * (covs + np.swapaxes(covs, 1, 2)))
    circle = _unit_circle(n)[None] * (n_sigma * np.sqrt(np.maximum(w, 0.0)))[:, None, :]
    return centers[:, None, :] + circle @ np.swapaxes(v, 1, 2)
