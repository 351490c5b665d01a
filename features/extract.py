"""`extract_features`: one scan in, segments, edges, lines, circles and clutter out.

Pipeline (paper section 2, details in the README's "Feature extraction" section):
1. Segmentation by the planar-model EKF with the chi-square gate (`features.segmentation`).
2. Edges: the end beam of a segment (with >= `min_points` beams) whose neighbouring beam lies
   more than `edge_min_jump_m` farther away is an occluding edge, a point feature. Beams next to a
   no-return beam or the end of the scan are never edges (the far side is unknown). One
   intermediate beam (a mixed pixel) may sit between the edge and the far surface.
3. Classification of each segment with >= `min_points` beams:
   - line_test="lrt" (default): a nested-model likelihood-ratio test. Fit a line (total least
     squares) and a circle (orthogonal distances). The segment is a circle when the circle is
     plausible (see below) and the circle explains the points significantly better than the line,
     (SSR_line - SSR_circle) / sigma^2 > `lrt_threshold` (6.63 = chi-square, 1 dof, 0.99); else a
     line when the line's residuals pass the chi-square test SSR_line / sigma^2 <=
     chi2_(n-2)(class_prob); else clutter.
   - line_test="paper": eq. (5) as printed: a line when |v_bar| <= 3 sqrt(s_bar) from the EKF's
     innovations; otherwise a circle when the circle is plausible, else clutter.
   A circle is plausible when it has >= `min_circle_points` beams, its orthogonal residuals pass
   SSR / sigma^2 <= chi2_(n-3)(class_prob), r_min_m <= r <= r_max_m, and it is convex toward the
   laser (its centre lies at least r/2 beyond the nearest point of the arc).
   sigma^2 = sigma_r_m^2 + roughness_m^2. The decision uses the geometric fit whatever `method`
   is, so that all fitting methods see the same circles.
4. Circle parameters from `method` ("paper": the modified Gauss-Newton of eq. (6)-(9);
   "geometric": orthogonal-distance LM; "kasa", "taubin": algebraic fits for context; "bailey":
   the Victoria Park detector, which replaces steps 1-4). The covariance of (x0, y0, r) is the
   first-order covariance of an orthogonal-distance fit under range noise sigma^2 at the reported
   circle (`features.fitting.circle_covariance`): right for the geometric fit, an approximation
   that ignores the algebraic fits' bias for the others. (The residual test above bounds how far
   the points may stray from that noise model.)
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields
from functools import lru_cache

import numpy as np
from numba import njit

from features.errors import FeaturesError
from features.fitting import (
    circle_covariance,
    circle_ssr,
    fit_circle_geometric,
    fit_circle_kasa,
    fit_circle_paper,
    fit_circle_taubin,
    fit_line_tls,
)
from features.segmentation import END_NO_RETURN, END_SCAN, max_growth_ratio, segment_kernel
from features.types import KIND_CIRCLE, KIND_CLUTTER, Features, Scan

__all__ = ["ExtractorParams", "extract_features", "METHODS"]

METHODS = ("paper", "geometric", "kasa", "taubin", "bailey")
PARAM_LIMIT = 1e9  # no extractor parameter is larger in size (metres, counts, thresholds)
_METHOD_CODE = {"paper": 0, "geometric": 1, "kasa": 2, "taubin": 3}
_LINE_TESTS = {"paper": 0, "lrt": 1}


@dataclass(frozen=True)
class ExtractorParams:
    """Parameters of the extractor; defaults are the paper's values where it gives one."""

    sigma_r_m: float = 0.02  # range noise of the EKF (eq. 3) and of the fit tests
    q_m2: float = 1e-4  # process noise Q of eq. (2) (paper: 1e-4)
    gate: float = 6.63  # delta of eq. (4) (paper: 6.63)
    max_incidence_deg: float = 85.0  # degenerate (almost parallel) limit
    merge_arcs: bool = True  # join gate-split neighbours that together form a circle
    isolated_circles: bool = True  # a circle's segment ends at depth jumps or no-returns
    min_points: int = 3  # beams for a segment to be a feature
    min_circle_points: int = 4  # beams for a circle (3 points fit any circle exactly)
    line_test: str = "lrt"  # "lrt" (default, see module doc) or "paper" (eq. 5)
    class_prob: float = 0.99  # chi-square level of the residual tests
    lrt_threshold: float = 6.63  # circle-vs-line likelihood-ratio threshold
    roughness_m: float = 0.0  # surface roughness added to sigma_r in the fit tests
    r_min_m: float = 0.05
    r_max_m: float = 1.0
    edge_min_jump_m: float = 0.3  # depth discontinuity that makes an occluding edge
    lambda0: float = 0.01  # paper's modified Gauss-Newton (section 2.2)
    max_iter: int = 100
    tol: float = 1e-10  # relative change of E(p) that stops the iteration
    # Short trunks (off by default: the paper's extractor needs min_circle_points beams). On:
    # an isolated segment of 1 to min_circle_points - 1 beams whose chord is under 2 r_max_m
    # and whose end ranges agree within its width becomes a circle (`_short_trunks`).
    short_trunks: bool = False
    short_trunk_radius_m: float = 0.2  # prior radius of a trunk (Victoria Park: median 0.21 m)
    short_trunk_radius_sigma_m: float = 0.1  # its spread

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("merge_arcs", "isolated_circles", "short_trunks"):
                if not isinstance(v, bool):
                    raise FeaturesError(f"{f.name}: must be True or False, got {v!r}")
                continue
            if f.name == "line_test":
                if v not in _LINE_TESTS:
                    raise FeaturesError(
                        f"line_test: must be one of {sorted(_LINE_TESTS)}, got {v!r}"
                    )
                continue
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise FeaturesError(f"{f.name}: must be a finite number, got {v!r}")
            if abs(v) > PARAM_LIMIT:  # squares and int64 kernels must not overflow
                raise FeaturesError(f"{f.name}: must be at most {PARAM_LIMIT:g}, got {v!r}")
            if f.type == "int":
                if v != int(v):
                    raise FeaturesError(f"{f.name}: must be a whole number, got {v!r}")
                object.__setattr__(self, f.name, int(v))
            else:
                object.__setattr__(self, f.name, float(v))
        positive = ("sigma_r_m", "gate", "lrt_threshold", "r_max_m", "lambda0", "max_iter")
        for name in positive:
            if getattr(self, name) <= 0:
                raise FeaturesError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        for name in ("short_trunk_radius_m", "short_trunk_radius_sigma_m"):
            if getattr(self, name) <= 0:
                raise FeaturesError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        for name in ("q_m2", "roughness_m", "r_min_m", "edge_min_jump_m", "tol"):
            if getattr(self, name) < 0:
                raise FeaturesError(f"{name}: must be >= 0, got {getattr(self, name)!r}")
        if not 0 < self.class_prob < 1:
            raise FeaturesError(f"class_prob: must be in (0, 1), got {self.class_prob!r}")
        if not 0 < self.max_incidence_deg < 90:
            raise FeaturesError(
                f"max_incidence_deg: must be in (0, 90), got {self.max_incidence_deg}"
            )
        if self.min_points < 3 or self.min_circle_points < 4:
            raise FeaturesError("min_points must be >= 3 and min_circle_points >= 4")
        if self.r_min_m >= self.r_max_m:
            raise FeaturesError(f"r_min_m ({self.r_min_m}) must be < r_max_m ({self.r_max_m})")

    @classmethod
    def from_kwargs(cls, **params) -> ExtractorParams:
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(params) - names)
        if unknown:
            raise FeaturesError(f"unknown extractor parameter(s) {unknown}; known: {sorted(names)}")
        return cls(**params)

    def to_dict(self) -> dict:
        return asdict(self)


@lru_cache(maxsize=64)
def _chi2_tables(n_max: int, prob: float) -> tuple[np.ndarray, np.ndarray]:
    """chi2_(n-2)(prob) and chi2_(n-3)(prob) indexed by the number of points n (NaN if dof < 1)."""
    from scipy.stats import chi2

    n = np.arange(n_max + 1)
    with np.errstate(invalid="ignore"):
        line = np.where(n - 2 >= 1, chi2.ppf(prob, np.maximum(n - 2, 1)), np.nan)
        circ = np.where(n - 3 >= 1, chi2.ppf(prob, np.maximum(n - 3, 1)), np.nan)
    line.setflags(write=False)
    circ.setflags(write=False)
    return line, circ


@njit(cache=True, nogil=True, error_model="numpy")
def _fit_method(code, x, y, lambda0, max_iter, tol):
    if code == 0:
        x0, y0, r, ok, _ = fit_circle_paper(x, y, lambda0, max_iter, tol)
    elif code == 1:
        x0, y0, r, ok, _ = fit_circle_geometric(x, y)
    elif code == 2:
        x0, y0, r, ok = fit_circle_kasa(x, y)
    else:
        x0, y0, r, ok = fit_circle_taubin(x, y)
    return x0, y0, r, ok


@njit(cache=True, nogil=True, error_model="numpy")
def _points(ranges, angle_min, gamma, a, b, xbuf, ybuf):
    """Cartesian points of beams a..b (views into the scratch buffers) and their least range."""
    m = b - a + 1
    x = xbuf[:m]
    y = ybuf[:m]
    rmin = np.inf
    for i in range(m):
        rr = ranges[a + i]
        th = angle_min + gamma * (a + i)
        x[i] = rr * math.cos(th)
        y[i] = rr * math.sin(th)
        rmin = min(rmin, rr)
    return x, y, rmin


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_plausible(x, y, rmin, chi2_circ, sigma2, r_min, r_max):
    """A circle is plausible when the geometric fit's residuals pass the chi-square test, its
    radius is within bounds, and it is convex toward the laser. Returns (ok, ssr, x0, y0, r)."""
    m = x.shape[0]
    dx = x[m - 1] - x[0]
    dy = y[m - 1] - y[0]
    if dx * dx + dy * dy > 4.0 * r_max * r_max * 1.0001 + 36.0 * sigma2:
        return False, np.inf, 0.0, 0.0, 0.0  # the chord alone rules out r <= r_max
    gx, gy, gr, gok, _ = fit_circle_geometric(x, y)
    if not gok or not (r_min <= gr <= r_max):
        return False, np.inf, gx, gy, gr
    ssr = circle_ssr(x, y, gx, gy, gr)
    convex = math.sqrt(gx * gx + gy * gy) >= rmin + 0.5 * gr
    return convex and ssr <= sigma2 * chi2_circ[x.shape[0]], ssr, gx, gy, gr


@njit(cache=True, nogil=True, error_model="numpy")
def _continuous(ranges, bounds, k, side, edge_jump, cyclic):
    """Does segment k continue, at its start (side 0) or end (side 1), into a neighbouring
    surface at a similar range (no depth jump)? A one-beam neighbouring segment that is itself cut
    off on its far side is taken for a mixed pixel and looked past. `cyclic`: the scan covers
    360 deg and its last beam neighbours its first."""
    n = ranges.shape[0]
    ns = bounds.shape[0]
    e = bounds[k, 0] if side == 0 else bounds[k, 1]
    step = -1 if side == 0 else 1
    nb = e + step
    if cyclic:
        nb %= n
    if nb < 0 or nb >= n or not (ranges[nb] == ranges[nb]):
        return False
    if abs(ranges[nb] - ranges[e]) >= edge_jump:
        return False
    kn = k + step
    if cyclic:
        kn %= ns
    if 0 <= kn < ns and bounds[kn, 0] == bounds[kn, 1]:
        far = nb + step  # beyond the singleton
        if cyclic:
            far %= n
        if far < 0 or far >= n or not (ranges[far] == ranges[far]):
            return True
        if abs(ranges[far] - ranges[nb]) >= edge_jump and ranges[far] > ranges[e]:
            return False  # nb sits between this surface and a farther one: a mixed pixel
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _extract_kernel(
    ranges,
    angle_min,
    gamma,
    sigma_r,
    q,
    gate,
    max_growth,
    merge,
    isolate,
    cyclic,
    method,
    line_test,
    min_points,
    min_circle_points,
    chi2_line,
    chi2_circ,
    lrt_threshold,
    sigma2,
    r_min,
    r_max,
    edge_jump,
    lambda0,
    max_iter,
    tol,
):
    bounds0, reason, innov, svar = segment_kernel(
        ranges, math.cos(gamma), sigma_r, q, gate, max_growth
    )
    n_beams = ranges.shape[0]
    xbuf = np.empty(n_beams)
    ybuf = np.empty(n_beams)
    # --- merge pass: neighbouring segments split by the gate without a depth jump (the planar
    # model breaking on a curved surface) are joined when together they form a plausible circle
    bounds = np.empty_like(bounds0)
    ns = 0
    k = 0
    while k < bounds0.shape[0]:
        a = bounds0[k, 0]
        b = bounds0[k, 1]
        while merge and k + 1 < bounds0.shape[0]:
            if reason[k] == END_NO_RETURN or reason[k] == END_SCAN:
                break
            if abs(ranges[b + 1] - ranges[b]) >= edge_jump:
                break
            b2 = bounds0[k + 1, 1]
            if b2 - a + 1 < min_circle_points:
                b = b2
                k += 1
                continue
            x, y, rmin = _points(ranges, angle_min, gamma, a, b2, xbuf, ybuf)
            ok, _, _, _, _ = _circle_plausible(x, y, rmin, chi2_circ, sigma2, r_min, r_max)
            if not ok:
                break
            b = b2
            k += 1
        bounds[ns, 0] = a
        bounds[ns, 1] = b
        ns += 1
        k += 1
    bounds = bounds[:ns]
    kind = np.zeros(ns, np.int64)
    seg_innov = np.full((ns, 2), np.nan)
    circ = np.empty((ns, 3))
    circ_cov = np.empty((ns, 3, 3))
    circ_beams = np.empty((ns, 2), np.int64)
    circ_rms = np.empty(ns)
    nc = 0
    line = np.empty((ns, 2))
    line_cov = np.empty((ns, 2, 2))
    line_end = np.empty((ns, 2, 2))
    line_beams = np.empty((ns, 2), np.int64)
    line_rms = np.empty(ns)
    nl = 0
    edge_xy = np.empty((2 * ns, 2))
    edge_cov = np.empty((2 * ns, 2, 2))
    edge_beam = np.empty(2 * ns, np.int64)
    ne = 0
    for k in range(ns):
        a = bounds[k, 0]
        b = bounds[k, 1]
        m = b - a + 1
        # eq. (5): mean innovation and its variance over the beams the filter validated
        # (M - 2 of them for an unmerged segment)
        sv = 0.0
        ss = 0.0
        nv = 0
        for i in range(a, b + 1):
            if innov[i] == innov[i]:
                sv += innov[i]
                ss += svar[i]
                nv += 1
        if nv > 0:
            seg_innov[k, 0] = sv / nv
            seg_innov[k, 1] = ss / (nv * nv)
        if m < min_points:
            continue
        x, y, rmin = _points(ranges, angle_min, gamma, a, b, xbuf, ybuf)
        circle_ok = False
        ssr_c = np.inf
        isolated = not isolate or (
            not _continuous(ranges, bounds, k, 0, edge_jump, cyclic)
            and not _continuous(ranges, bounds, k, 1, edge_jump, cyclic)
        )
        if m >= min_circle_points and isolated:
            circle_ok, ssr_c, _, _, _ = _circle_plausible(
                x, y, rmin, chi2_circ, sigma2, r_min, r_max
            )
        alpha, rho, lcov, lend, ssr_l, lok = fit_line_tls(x, y, sigma2)
        if line_test == 1:
            if circle_ok and (ssr_l - ssr_c) / sigma2 > lrt_threshold:
                kind[k] = 2
            elif lok and ssr_l <= sigma2 * chi2_line[m]:
                kind[k] = 1
        else:
            if nv > 0 and abs(seg_innov[k, 0]) <= 3.0 * math.sqrt(seg_innov[k, 1]):
                kind[k] = 1 if lok else 0
            elif circle_ok:
                kind[k] = 2
        if kind[k] == 2:
            cx, cy, cr, cok = _fit_method(method, x, y, lambda0, max_iter, tol)
            cov_ok = False
            if cok:
                ssr = circle_ssr(x, y, cx, cy, cr)
                cov, cov_ok = circle_covariance(x, y, cx, cy, cr, sigma2)
            if not cov_ok:
                kind[k] = 0
            else:
                circ[nc, 0] = cx
                circ[nc, 1] = cy
                circ[nc, 2] = cr
                circ_cov[nc] = cov
                circ_beams[nc, 0] = a
                circ_beams[nc, 1] = b
                circ_rms[nc] = math.sqrt(ssr / m)
                nc += 1
        elif kind[k] == 1:
            line[nl, 0] = alpha
            line[nl, 1] = rho
            line_cov[nl] = lcov
            line_end[nl] = lend
            line_beams[nl, 0] = a
            line_beams[nl, 1] = b
            line_rms[nl] = math.sqrt(ssr_l / m)
            nl += 1
        # --- occluding edges at either end of the segment
        for side in range(2):
            e = a if side == 0 else b
            step = -1 if side == 0 else 1
            is_edge = False
            for j in range(1, 3):  # the neighbour, or the one after a mixed pixel
                nb = e + step * j
                if cyclic:
                    nb %= n_beams
                if nb < 0 or nb >= n_beams or not (ranges[nb] == ranges[nb]):
                    break
                if ranges[nb] - ranges[e] > edge_jump:
                    is_edge = True
                    break
                if ranges[nb] < ranges[e]:
                    break
            if is_edge:
                th = angle_min + gamma * e + 0.5 * step * gamma  # mid-way towards the far side
                rr = ranges[e]
                c = math.cos(th)
                s = math.sin(th)
                var_th = gamma * gamma / 12.0  # uniform over one beam step
                vr = sigma_r * sigma_r
                edge_xy[ne, 0] = rr * c
                edge_xy[ne, 1] = rr * s
                # J diag(var_r, var_th) J^T, J = [[c, -r s], [s, r c]]
                edge_cov[ne, 0, 0] = c * c * vr + rr * rr * s * s * var_th
                edge_cov[ne, 0, 1] = c * s * vr - rr * rr * s * c * var_th
                edge_cov[ne, 1, 0] = edge_cov[ne, 0, 1]
                edge_cov[ne, 1, 1] = s * s * vr + rr * rr * c * c * var_th
                edge_beam[ne] = e
                ne += 1
    return (
        bounds,
        kind,
        seg_innov,
        circ[:nc],
        circ_cov[:nc],
        circ_beams[:nc],
        circ_rms[:nc],
        line[:nl],
        line_cov[:nl],
        line_end[:nl],
        line_beams[:nl],
        line_rms[:nl],
        edge_xy[:ne],
        edge_cov[:ne],
        edge_beam[:ne],
    )


def _short_trunks(ranges, angle_min, gamma, bounds, kind, p: ExtractorParams):
    """Circles for trunks too narrow to fit (1 to min_circle_points - 1 beams).

    A segment qualifies when it is not already a line or circle, its neighbours on both sides
    are no-returns or farther by more than edge_min_jump_m (an occluding, isolated object), its
    chord is under 2 r_max_m, and its end ranges differ by less than a third of its width (a
    convex face, Bailey's test). Its radius combines the width estimate w / 2, w = (span + one
    beam) x mean range, with the prior N(short_trunk_radius_m, sigma^2) (variance of the width
    estimate: half a beam of range-width on each side, (r gamma / 2)^2 / 3); the centre lies that
    radius behind the segment's mean range, on its mean bearing. Covariance of (x0, y0, r): the
    mean range's noise sigma_r^2 / m plus the radius variance along the beam, a uniform one-beam
    bearing error across it, and the radius variance.
    Returns (params (k, 3), cov (k, 3, 3), beams (k, 2), segment indices (k,)).
    """
    n = ranges.shape[0]
    out_p, out_c, out_b, out_k = [], [], [], []
    r0, s0 = p.short_trunk_radius_m, p.short_trunk_radius_sigma_m
    for k, (a, b) in enumerate(bounds):
        m = b - a + 1
        if kind[k] != KIND_CLUTTER or m >= p.min_circle_points:
            continue
        left = ranges[a - 1] if a > 0 else np.nan
        right = ranges[b + 1] if b + 1 < n else np.nan
        if not (_farther(left, ranges[a], p) and _farther(right, ranges[b], p)):
            continue
        seg = ranges[a : b + 1]
        rm = float(np.mean(seg))
        th_a, th_b = angle_min + gamma * a, angle_min + gamma * b
        dx = ranges[b] * math.cos(th_b) - ranges[a] * math.cos(th_a)
        chord = math.hypot(dx, ranges[b] * math.sin(th_b) - ranges[a] * math.sin(th_a))
        width = (th_b - th_a + gamma) * rm
        if chord >= 2 * p.r_max_m or abs(ranges[b] - ranges[a]) >= width / 3.0:
            continue
        var_w = (rm * gamma / 2.0) ** 2 / 3.0 / 4.0  # of the half width
        w_r = 1.0 / var_w + 1.0 / s0**2
        r = (0.5 * width / var_w + r0 / s0**2) / w_r
        var_r = 1.0 / w_r
        th = 0.5 * (th_a + th_b)
        rng = rm + r
        c, s = math.cos(th), math.sin(th)
        var_rng = p.sigma_r_m**2 / m + var_r
        var_th = gamma * gamma / 12.0
        J = np.array([[c, -rng * s], [s, rng * c]])
        cov = np.zeros((3, 3))
        cov[:2, :2] = J @ np.diag([var_rng, var_th]) @ J.T
        cov[:2, 2] = cov[2, :2] = np.array([c, s]) * var_r  # the centre moves back with r
        cov[2, 2] = var_r
        out_p.append([rng * c, rng * s, r])
        out_c.append(cov)
        out_b.append([a, b])
        out_k.append(k)
    return (
        np.array(out_p).reshape(-1, 3),
        np.array(out_c).reshape(-1, 3, 3),
        np.array(out_b, np.int64).reshape(-1, 2),
        np.array(out_k, np.int64),
    )


def _farther(neighbour: float, own: float, p: ExtractorParams) -> bool:
    """A segment end is cut off: no return beside it, or the neighbour is behind a depth jump."""
    return not (neighbour == neighbour) or neighbour - own > p.edge_min_jump_m


@lru_cache(maxsize=32)
def _cached_params(items: tuple) -> ExtractorParams:
    """ExtractorParams from ((name, type name, value), ...)."""
    return ExtractorParams.from_kwargs(**{k: v for k, _, v in items})


def _params(params: dict) -> ExtractorParams:
    """ExtractorParams from keyword arguments, cached (building one costs ~10 us per scan)."""
    # the value's type is part of the key: 1 == True and 0.5 == Fraction(1, 2) hash alike
    items = tuple(sorted((k, type(v).__name__, v) for k, v in params.items()))
    try:
        hash(items)
    except TypeError:
        return ExtractorParams.from_kwargs(**params)  # an unhashable value: validation says why
    return _cached_params(items)


def extract_features(scan: Scan, method: str = "paper", **params) -> Features:
    """Extract segments, edges, lines, circles and clutter from one scan (laser frame).

    method: "paper" (modified Gauss-Newton, eq. 6-9), "geometric" (orthogonal-distance LM with
        covariance), "kasa", "taubin", or "bailey" (the Victoria Park detector; `params` then go
        to `features.bailey.extract_bailey`).
    params: fields of `ExtractorParams` (e.g. sigma_r_m=0.01, line_test="paper").
    """
    if not isinstance(scan, Scan):
        raise FeaturesError(f"scan: expected a features.Scan, got {type(scan).__name__}")
    if method == "bailey":
        from features.bailey import BAILEY_OPTIONS, extract_bailey

        unknown = sorted(set(params) - set(BAILEY_OPTIONS))
        if unknown:
            raise FeaturesError(
                f"{unknown}: not parameters of method 'bailey' (allowed: {list(BAILEY_OPTIONS)})"
            )
        return extract_bailey(scan, **params)
    if method not in _METHOD_CODE:
        raise FeaturesError(f"method: must be one of {list(METHODS)}, got {method!r}")
    p = _params(params)
    gamma = scan.angle_increment_rad
    if gamma >= math.pi / 2 - math.radians(p.max_incidence_deg):
        raise FeaturesError(
            f"angle_increment_rad: {gamma} is too coarse for the planar model "
            f"with max_incidence_deg={p.max_incidence_deg}"
        )
    growth = max_growth_ratio(gamma, math.radians(p.max_incidence_deg))
    n = scan.n_beams
    chi2_line, chi2_circ = _chi2_tables(n, p.class_prob)
    ranges, angle_min, shift = scan.ranges_m, scan.angle_min_rad, 0
    cyclic = n > 2 and abs(n * gamma - 2.0 * math.pi) < 0.5 * gamma
    if cyclic:  # 360 deg: start the scan at a break so that no segment crosses the seam
        shift = _seam(ranges)
        ranges = np.roll(ranges, -shift)
        angle_min = angle_min + shift * gamma
    out = _extract_kernel(
        ranges,
        angle_min,
        gamma,
        p.sigma_r_m,
        p.q_m2,
        p.gate,
        growth,
        p.merge_arcs,
        p.isolated_circles,
        cyclic,
        _METHOD_CODE[method],
        _LINE_TESTS[p.line_test],
        p.min_points,
        p.min_circle_points,
        chi2_line,
        chi2_circ,
        p.lrt_threshold,
        p.sigma_r_m**2 + p.roughness_m**2,
        p.r_min_m,
        p.r_max_m,
        p.edge_min_jump_m,
        p.lambda0,
        p.max_iter,
        p.tol,
    )
    (
        bounds,
        kind,
        seg_innov,
        circ,
        circ_cov,
        circ_beams,
        circ_rms,
        line,
        line_cov,
        line_end,
        line_beams,
        line_rms,
        edge_xy,
        edge_cov,
        edge_beam,
    ) = out
    if p.short_trunks:
        short = _short_trunks(ranges, angle_min, gamma, bounds, kind, p)
        if short[0].shape[0]:
            circ = np.concatenate([circ, short[0]])
            circ_cov = np.concatenate([circ_cov, short[1]])
            circ_beams = np.concatenate([circ_beams, short[2]])
            circ_rms = np.concatenate([circ_rms, np.full(short[0].shape[0], np.nan)])
            kind = kind.copy()
            kind[short[3]] = KIND_CIRCLE
    if shift:  # back to the scan's own beam numbers; a run across the seam keeps last >= n
        for runs in (bounds, circ_beams, line_beams):
            runs += shift
            runs -= n * (runs[:, :1] >= n)
        edge_beam = (edge_beam + shift) % n
    return Features(
        stamp_s=scan.stamp_s,
        circle_params=circ,
        circle_cov=circ_cov,
        circle_beams=circ_beams,
        circle_rms_m=circ_rms,
        line_params=line,
        line_cov=line_cov,
        line_endpoints=line_end,
        line_beams=line_beams,
        line_rms_m=line_rms,
        edge_xy=edge_xy,
        edge_cov=edge_cov,
        edge_beam=edge_beam,
        segment_beams=bounds,
        segment_kind=kind,
        segment_innov=seg_innov,
        method=method,
        n_beams=n,
    )


def _seam(ranges: np.ndarray) -> int:
    """Where to cut a 360 deg scan: at its first no-return beam, else before its largest jump."""
    nan = np.flatnonzero(np.isnan(ranges))
    if nan.size:
        return int(nan[0])
    return int(np.argmax(np.abs(ranges - np.roll(ranges, 1))))
