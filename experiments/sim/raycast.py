"""Exact 2D ray casting against a `Scene`, vectorised over beams and objects.

Each beam is the half-line origin + t (cos a, sin a), t > 0, in the world frame. Its range is the
smallest t at which it meets any object in the scan plane: a circle (closed-form root of
|o + t d - c|^2 = r^2, in the cancellation-free form t = c / (-b + sqrt(b^2 - c))), or a wall
segment or bush polygon edge (Cramer's rule on o + t d = p + s e, 0 <= s <= 1). The nearest hit
wins, so occlusion is exact.

`raycast` first finds, for every object, the interval of bearings it subtends from the origin
and pairs it only with the beams inside that interval (a sorted-angle search), so the work grows
with the number of (beam, object) pairs that can actually meet rather than beams x objects.
`raycast_dense` tests every beam against every object; it is the simple oracle the tests
compare `raycast` with.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from experiments.errors import ConfigError
from experiments.sim.scene import NO_RETURN_LABEL, Scene

__all__ = ["raycast", "raycast_dense"]

_TWO_PI = 2.0 * np.pi
_PAD_RAD = 1e-7  # widen every object's bearing interval by this; the exact test decides


def _check(origin_xy: Any, angles_world_rad: Any) -> tuple[float, float, np.ndarray]:
    o = np.asarray(origin_xy, dtype=np.float64)
    if o.shape != (2,) or not np.all(np.isfinite(o)):
        raise ConfigError(f"raycast.origin_xy: expected 2 finite numbers, got {origin_xy!r}")
    a = np.asarray(angles_world_rad, dtype=np.float64)
    if a.ndim != 1 or not np.all(np.isfinite(a)):
        raise ConfigError(
            f"raycast.angles_world_rad: expected a finite (B,) array, got shape {a.shape}"
        )
    return float(o[0]), float(o[1]), a


def _circle_t(origin: tuple[float, float], d: tuple, circ_xyr: np.ndarray) -> np.ndarray:
    """Distance along beams from `origin` (ox, oy) in directions d = (dx, dy) to their first
    crossing of circles `circ_xyr` (N, 3) [cx, cy, r].

    The beams' arrays broadcast against the circles' (pairs, or (B, 1) against (N,)); inf where
    the beam misses.
    """
    ox, oy = origin
    dx, dy = d
    cx, cy, r = circ_xyr[:, 0], circ_xyr[:, 1], circ_xyr[:, 2]
    ocx = ox - cx
    ocy = oy - cy
    cc = ocx * ocx + ocy * ocy - r * r  # > 0 when the origin is outside the circle
    b = dx * ocx + dy * ocy  # roots t = -b +- sqrt(b^2 - cc)
    with np.errstate(invalid="ignore", divide="ignore"):
        far = np.sqrt(b * b - cc) - b  # the far root, NaN when the line misses
        near = cc / far  # the near root without cancellation
    # Outside: the near root, if ahead (far > 0 <=> b < 0 here). Inside: the beam leaves
    # through the far root.
    with np.errstate(invalid="ignore"):
        t = np.where(cc > 0, near, far)
        return np.where((far > 0) & (t > 0), t, np.inf)


def _segment_t(
    origin: tuple[float, float], d: tuple, seg_p: np.ndarray, seg_e: np.ndarray
) -> np.ndarray:
    """Distance along beams from `origin` in directions d = (dx, dy) to segments p + s e,
    s in [0, 1] (`seg_p`, `seg_e`: (N, 2)); inf where missed. Broadcasts as `_circle_t`.

    o + t d = p + s e  =>  t = (w x e) / (d x e), s = (w x d) / (d x e), w = p - o.
    """
    ox, oy = origin
    dx, dy = d
    px, py, ex, ey = seg_p[:, 0], seg_p[:, 1], seg_e[:, 0], seg_e[:, 1]
    wx = px - ox
    wy = py - oy
    den = dx * ey - dy * ex
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / den  # a beam parallel to the segment gives inf/NaN and fails below
        t = (wx * ey - wy * ex) * inv
        s = (wx * dy - wy * dx) * inv
        hit = (t > 0) & (s >= 0) & (s <= 1)
    return np.where(hit, t, np.inf)


def raycast_dense(
    scene: Scene, origin_xy: Any, angles_world_rad: Any, *, plane_height_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Same contract as `raycast`, testing every beam against every object ((B, N) arrays)."""
    ox, oy, a = _check(origin_xy, angles_world_rad)
    geo = scene.geometry(plane_height_m)
    dx, dy = np.cos(a)[:, None], np.sin(a)[:, None]
    c, p, e = geo["circ_xyr"], geo["seg_p"], geo["seg_e"]
    t = np.concatenate(
        [_circle_t((ox, oy), (dx, dy), c), _segment_t((ox, oy), (dx, dy), p, e)], axis=1
    )
    lab = np.concatenate([geo["circ_label"], geo["seg_label"], [NO_RETURN_LABEL]])
    j = np.argmin(t, axis=1) if t.shape[1] else np.zeros(a.shape[0], dtype=np.int64)
    r = t[np.arange(a.shape[0]), j] if t.shape[1] else np.full(a.shape[0], np.inf)
    j[~np.isfinite(r)] = lab.shape[0] - 1
    return r, lab[j].astype(np.int64)


def _pairs(
    sorted_m: np.ndarray, lo: np.ndarray, width: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(beam position in `sorted_m`, object) for every beam inside an object's interval.

    sorted_m: (B,) beam bearings mod 2 pi, ascending. lo, width: (N,) each object's bearing
    interval [lo, lo + width], rad; width >= 2 pi means every beam.
    """
    n = sorted_m.shape[0]
    start = np.mod(lo - _PAD_RAD, _TWO_PI)
    stop = np.minimum(start + (width + 2 * _PAD_RAD), start + _TWO_PI)
    # Each interval is at most two runs of sorted beams: [start, min(stop, 2 pi)] and, when it
    # wraps past 2 pi, [0, stop - 2 pi].
    ends = np.searchsorted(
        sorted_m, np.concatenate([start, np.minimum(stop, _TWO_PI), stop - _TWO_PI])
    )
    m = lo.shape[0]
    i0, i1, j1 = ends[:m], ends[m : 2 * m], ends[2 * m :]
    i1 = np.where(stop >= _TWO_PI, n, i1)  # (searchsorted "left" misses a beam at exactly 2 pi)
    # Runs ordered by object (first run, wrapped run), so pairs come out grouped by object.
    first = np.zeros(2 * m, dtype=np.int64)
    first[0::2] = i0
    count = np.empty(2 * m, dtype=np.int64)
    count[0::2] = i1 - i0
    count[1::2] = np.minimum(j1, i0)  # the wrapped run never overlaps the first
    obj = np.repeat(np.arange(m), 2)
    keep = count > 0
    first, count, obj = first[keep], count[keep], obj[keep]
    offset = np.cumsum(count) - count
    pos = np.arange(offset[-1] + count[-1] if count.size else 0) - np.repeat(offset - first, count)
    return pos, np.repeat(obj, count)


def raycast(
    scene: Scene, origin_xy: Any, angles_world_rad: Any, *, plane_height_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Exact ranges and truth labels of beams from one point.

    origin_xy: (2,) m, world frame. angles_world_rad: (B,) beam directions in the world frame,
        any order.
    plane_height_m: height of the scan plane above the ground; objects whose `height_m` is not
        above it are invisible (0 = every object counts).
    Returns ranges_m (B,) float64, +inf where nothing is hit (there is no maximum range here), and
    labels (B,) int64: the hit object's label (scene label order) or NO_RETURN_LABEL (-1).
    """
    ox, oy, a = _check(origin_xy, angles_world_rad)
    g = scene.geometry(plane_height_m)
    n = a.shape[0]
    best = np.full(n, np.inf)
    label = np.full(n, NO_RETURN_LABEL, dtype=np.int64)
    nc, ns = g["circ_xyr"].shape[0], g["seg_p"].shape[0]
    if n == 0 or nc + ns == 0:
        return best, label
    with np.errstate(all="ignore"):  # misses and parallel beams make inf/NaN, masked below
        # Per object, relative to the origin: circle centres, segment starts and ends.
        rel_x = g["pts_x"] - ox
        rel_y = g["pts_y"] - oy
        bearing = np.arctan2(rel_y, rel_x)
        # Circles: bearing interval centre +- asin(r / distance); all beams if the origin is inside.
        ccx, ccy = rel_x[:nc], rel_y[:nc]
        cc = ccx * ccx + ccy * ccy - g["circ_r2"]  # > 0 outside
        half = np.arcsin(np.sqrt(g["circ_r2"] / (cc + g["circ_r2"])))
        w_c = np.where(cc > 0, 2 * half, np.inf)
        # Segments: the shorter arc between the bearings of the two ends (all beams if the origin
        # is on the segment's line, where that view is degenerate).
        b0, b1 = bearing[nc : nc + ns], bearing[nc + ns :]
        sweep = np.mod(b1 - b0 + np.pi, _TWO_PI) - np.pi
        wx, wy = rel_x[nc : nc + ns], rel_y[nc : nc + ns]
        ex, ey = g["seg_ex"], g["seg_ey"]
        w_cross_e = wx * ey - wy * ex  # (p - o) x e
        w_s = np.where(np.abs(w_cross_e) > g["seg_tol"], np.abs(sweep), np.inf)
        lo = np.concatenate([bearing[:nc] - half, b0 + np.minimum(sweep, 0.0)])
        am = np.mod(a, _TWO_PI)
        order = np.argsort(am, kind="stable")
        pos, obj = _pairs(am[order], lo, np.concatenate([w_c, w_s]))
        beam = order[pos]
        dx, dy = np.cos(a), np.sin(a)
        # Circle pairs: roots of t^2 + 2 b t + cc = 0, b = d . (o - c); near root cc / (-b + sqrt).
        k = np.searchsorted(obj, nc)  # pairs are grouped by object, circles first
        bc, oc = beam[:k], obj[:k]
        b = -(dx[bc] * ccx[oc] + dy[bc] * ccy[oc])
        ccp = cc[oc]
        far = np.sqrt(b * b - ccp) - b
        tc = np.where(ccp > 0, ccp / far, far)  # inside a circle: leave through the far root
        tc = np.where((far > 0) & (tc > 0), tc, np.inf)
        # Segment pairs: t = (w x e) / (d x e), s = (w x d) / (d x e).
        bs, os_ = beam[k:], obj[k:] - nc
        dxs, dys = dx[bs], dy[bs]
        inv = 1.0 / (dxs * ey[os_] - dys * ex[os_])
        ts = w_cross_e[os_] * inv
        ss = (wx[os_] * dys - wy[os_] * dxs) * inv
        ts = np.where((ts > 0) & (ss >= 0) & (ss <= 1), ts, np.inf)
    t = np.concatenate([tc, ts])
    np.minimum.at(best, beam, t)  # nearest hit per beam
    win = np.isfinite(t) & (t == best[beam])
    label[beam[win]] = g["obj_label"][obj[win]]
    return best, label
