"""The covariance ellipses drawn by the figures and the recordings (`shapes.ellipse_polylines`,
a closed-form 2x2 eigen-decomposition over all the matrices at once) are the ellipses that
LAPACK's `eigh` gives: every vertex lies on the n-sigma contour, the vertices are those of the
polygon drawn from `eigh`'s axes (the same points, perhaps from the other end of the minor
axis), and a float32 drawing is the float64 one rounded."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.render.shapes import ellipse_polyline, ellipse_polylines


def _covs(rng, m: int) -> np.ndarray:
    a = rng.normal(size=(m, 2, 2)) * rng.uniform(0.01, 10.0, size=(m, 1, 1))
    covs = a @ a.transpose(0, 2, 1)
    covs[0] = [[1.0, 0.0], [0.0, 0.0]]  # degenerate: a segment
    covs[1] = [[2.0, 0.0], [0.0, 2.0]]  # a circle: any axes
    covs[2] = [[1e-6, 0.0], [0.0, 1e4]]  # 1e10 between the axes' variances
    covs[3] = [[1.0, 0.999], [0.999, 1.0]]
    return covs


def _eigh_polylines(centers, covs, n_sigma, n):
    """The former drawing: eigh's axes, the unit circle scaled and rotated."""
    w, v = np.linalg.eigh(0.5 * (covs + np.swapaxes(covs, 1, 2)))
    t = np.linspace(0.0, 2.0 * np.pi, n + 1)
    unit = np.stack([np.cos(t), np.sin(t)], axis=1)
    circle = unit[None] * (n_sigma * np.sqrt(np.maximum(w, 0.0)))[:, None, :]
    return centers[:, None, :] + circle @ np.swapaxes(v, 1, 2)


@pytest.mark.parametrize("n", [24, 40])
def test_closed_form_ellipses_are_eighs(n):
    rng = np.random.default_rng(3)
    m = 200
    centers = rng.normal(size=(m, 2)) * 100
    covs = _covs(rng, m)
    ours = ellipse_polylines(centers, covs, n=n)
    ref = _eigh_polylines(centers, covs, 2.4477, n)
    assert ours.shape == ref.shape == (m, n + 1, 2)
    assert np.allclose(ours[:, 0], ours[:, -1], rtol=0, atol=1e-12)  # closed (sin 2 pi: 2e-16)
    for i in range(2, m):  # (0, a segment, and 1, a circle: their vertices have no one order)
        size = 2.4477 * np.sqrt(np.linalg.eigvalsh(covs[i])[-1])  # the semi-major axis
        # the same vertices: each of ours within 1e-9 of the major axis from one of eigh's,
        # in the same cyclic order (or reversed: eigh's eigenvector signs are arbitrary)
        d = np.linalg.norm(ours[i, :-1, None] - ref[i, None, :-1], axis=2)
        nearest = d.argmin(axis=1)
        assert d.min(axis=1).max() <= 1e-9 * size, i
        step = np.diff(nearest) % n
        assert (step == step[0]).all() and step[0] in (1, n - 1), i
    # each vertex on the contour x' inv(P) x = n_sigma^2 (where P is not singular)
    ok = np.linalg.cond(covs) < 1e6
    x = ours[ok] - centers[ok][:, None]
    q = np.einsum("mni,mij,mnj->mn", x, np.linalg.inv(covs[ok]), x)
    assert np.allclose(q, 2.4477**2, rtol=1e-6)


def test_one_ellipse_float32_and_none():
    rng = np.random.default_rng(5)
    centers = rng.normal(size=(30, 2)) * 50
    covs = _covs(rng, 30)
    every = ellipse_polylines(centers, covs)
    one_by_one = np.array([ellipse_polyline(c, p) for c, p in zip(centers, covs)])
    assert np.array_equal(every, one_by_one)
    f32 = ellipse_polylines(centers, covs, dtype=np.float32)
    assert f32.dtype == np.float32 and np.array_equal(f32, every.astype(np.float32))
    assert ellipse_polylines(np.zeros((0, 2)), np.zeros((0, 2, 2))).shape == (0, 41, 2)


def test_a_scan_column_with_no_rows_takes_empty():
    """A scan column taken before any row: no points and one offset (what a batch would send)."""
    from experiments.render.columns import ScanPoints, _ScanColumn

    col = _ScanColumn(ScanPoints())
    points, offsets = col.take()
    assert len(points) == 0 and offsets.tolist() == [0]
    col.put((np.array([1.0, np.nan, 2.0]), 0.0, 0.5))
    points, offsets = col.take()
    assert len(points) == 2 and offsets.tolist() == [0, 2]
