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
from dataclasses import asdict, dataclass, fields
from functools import lru_cache
from typing import NamedTuple

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
from features.limits import magnitude_problem, sourced
from features.segmentation import END_NO_RETURN, END_SCAN, max_growth_ratio, segment_kernel
from features.types import Features, Scan

__all__ = ["ExtractorParams", "PAPER_FAITHFUL", "extract_features", "METHODS"]

METHODS = ("paper", "geometric", "kasa", "taubin", "bailey")
_POSITIVE = ("sigma_r_m", "gate", "lrt_threshold", "r_max_m", "lambda0", "max_iter")
MAX_ITER_LIMIT = 10_000  # the fit converges in tens of steps; a fit costs at most this many
_METHOD_CODE = {"paper": 0, "geometric": 1, "kasa": 2, "taubin": 3}
_LINE_TESTS = {"paper": 0, "lrt": 1}


@dataclass(frozen=True)
class ExtractorParams:
    """Parameters of the extractor; defaults are the paper's values where it gives one."""

    # range noise of the EKF (eq. 3) and of the fit tests
    sigma_r_m: float = sourced(0.02, "design: range noise of eq. (3) and of the fit tests, 2 cm")
    # process noise Q of eq. (2) (paper: 1e-4)
    q_m2: float = sourced(1e-4, "paper: Q of eq. (2), 1e-4")
    # delta of eq. (4) (paper: 6.63)
    gate: float = sourced(6.63, "paper: delta of eq. (4), 6.63")
    # degenerate (almost parallel) limit
    max_incidence_deg: float = sourced(
        85.0, "design: beams nearly parallel to a surface are degenerate"
    )
    # join gate-split neighbours that together form a circle
    merge_arcs: bool = sourced(
        True, "design: join gate-split neighbours that together form a circle"
    )
    # a circle's segment ends at depth jumps or no-returns
    isolated_circles: bool = sourced(
        True, "design: a circle's segment ends at depth jumps or no-returns"
    )
    # beams for a segment to be a feature
    min_points: int = sourced(3, "design: beams for a segment to be a feature")
    # beams for a circle (3 points fit any circle exactly)
    min_circle_points: int = sourced(4, "design: 4 beams, as 3 points fit any circle exactly")
    # "lrt" (default, see module doc) or "paper" (eq. 5)
    line_test: str = sourced("lrt", "design: the likelihood-ratio test (see the module doc)")
    # chi-square level of the residual tests
    class_prob: float = sourced(0.99, "design: chi-square level 0.99 of the residual tests")
    # circle-vs-line likelihood-ratio threshold
    lrt_threshold: float = sourced(
        6.63, "design: 6.63, the chi-square(1) 0.99 point, as the paper's gate"
    )
    # surface roughness added to sigma_r in the fit tests
    roughness_m: float = sourced(0.0, "design: 0, smooth surfaces")
    r_min_m: float = sourced(0.05, "design: the smallest trunk radius taken, 5 cm")
    r_max_m: float = sourced(1.0, "design: the largest object modelled, 1 m radius")
    # depth discontinuity that makes an occluding edge
    edge_min_jump_m: float = sourced(0.3, "design: a 0.3 m depth jump makes an occluding edge")
    # paper's modified Gauss-Newton (section 2.2)
    lambda0: float = sourced(0.01, "paper: the modified Gauss-Newton's lambda0 (section 2.2)")
    max_iter: int = sourced(100, "design: 100 steps, the fit converges in tens")
    # relative change of E(p) that stops the iteration
    tol: float = sourced(1e-10, "design: relative change of E(p) that stops the iteration")
    # Short trunks (on by default; the paper's extractor, `PAPER_FAITHFUL`, has them off and
    # needs min_circle_points beams): an isolated segment of 1 to min_circle_points - 1 beams
    # whose chord is under 2 r_max_m and whose end ranges agree within its width becomes a
    # circle (`_short_trunks`); its radius is the width the beams allow, with the radius
    # limits [r_min_m, r_max_m] as the only prior.
    short_trunks: bool = sourced(
        True, "design: on, most real trunks span 1-3 beams (off in the paper's extractor)"
    )
    # No other return of the scan within this distance of a short trunk's centre (0: no test).
    # Default 2 r_max_m (the largest object modelled, 1 m radius): a return nearer than that
    # may be part of the same object, so the segment is not known to be a whole thin object.
    short_trunk_clearance_m: float = sourced(2.0, "design: 2 r_max_m, the largest object modelled")

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
            # finite, 0 or within [PARAM_TINY, PARAM_LIMIT]
            problem = magnitude_problem(v, positive=f.name in _POSITIVE)
            if problem:
                raise FeaturesError(f"{f.name}: {problem}")
            if f.type == "int":
                if v != int(v):
                    raise FeaturesError(f"{f.name}: must be a whole number, got {v!r}")
                object.__setattr__(self, f.name, int(v))
            else:
                object.__setattr__(self, f.name, float(v))
        for name in _POSITIVE:
            if getattr(self, name) <= 0:
                raise FeaturesError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        for name in (
            "q_m2",
            "roughness_m",
            "r_min_m",
            "edge_min_jump_m",
            "tol",
            "short_trunk_clearance_m",
        ):
            if getattr(self, name) < 0:
                raise FeaturesError(f"{name}: must be >= 0, got {getattr(self, name)!r}")
        if self.max_iter > MAX_ITER_LIMIT:
            raise FeaturesError(
                f"max_iter: must be at most {MAX_ITER_LIMIT}, got {self.max_iter!r}"
            )
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


# The paper's extractor as published: no short trunks (a circle needs min_circle_points beams).
# The simulated experiments that reproduce the paper's tables run it; the default adds short
# trunks, which real trunks need (most span 1-3 beams of a 0.5 deg laser).
PAPER_FAITHFUL = ExtractorParams(short_trunks=False)


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


# The records below cross into the numba kernel as plain tuples, `tuple(record)`, and are named
# again on the kernel's first line: numba's dispatcher types a plain tuple in C but a NamedTuple
# in Python, which costs about 1.5 us a call (5% of a scan). The small helpers that take them
# are inlined into the kernel (inline="always"): called, they cost about 0.5 us a scan.


class _Beams(NamedTuple):
    """One scan as the kernel reads it. A 360 deg scan is rotated to start at a break (`_seam`)
    so that no segment crosses its seam: kernel beam k is the scan's beam (k + shift) mod B."""

    ranges: np.ndarray  # (B,) m, NaN = no return, in kernel beam order
    angle_min: float  # rad, laser-frame bearing of kernel beam 0
    gamma: float  # rad, angle between successive beams
    cyclic: bool  # the scan covers 360 deg: its last beam neighbours its first
    shift: int  # the scan's number of kernel beam 0


class _Settings(NamedTuple):
    """`ExtractorParams` resolved for one scan and method, as the kernel reads them."""

    sigma_r: float  # m, range noise of the segmentation EKF (eq. 3) and of the edges
    q: float  # m^2, process noise Q of eq. (2)
    gate: float  # delta of eq. (4)
    max_growth: float  # largest ratio of successive ranges on a plane (degenerate case)
    merge: bool  # merge_arcs
    isolate: bool  # isolated_circles
    edge_jump: float  # m, edge_min_jump_m
    min_points: int
    min_circle_points: int
    line_test: int  # `_LINE_TESTS` code
    lrt_threshold: float
    sigma2: float  # m^2, sigma_r^2 + roughness^2: the noise of the fit tests
    chi2_line: np.ndarray  # (B + 1,) chi2_(n-2)(class_prob) by number of points n
    chi2_circ: np.ndarray  # (B + 1,) chi2_(n-3)(class_prob)
    r_min: float  # m
    r_max: float  # m
    method: int  # `_METHOD_CODE` of the circle fit
    lambda0: float
    max_iter: int
    tol: float
    short_trunks: bool
    clearance: float  # m, short_trunk_clearance_m


class _Found(NamedTuple):
    """What the kernel found, beams in kernel order: the `Features` arrays of the same names."""

    segment_beams: np.ndarray  # (S, 2) int64, inclusive [first, last] beams
    segment_kind: np.ndarray  # (S,) int64, KIND_*
    segment_innov: np.ndarray  # (S, 2) eq. (5)'s mean innovation (m) and its variance (m^2)
    circle_params: np.ndarray  # (C, 3) [x0, y0, r], m, laser frame
    circle_cov: np.ndarray  # (C, 3, 3)
    circle_beams: np.ndarray  # (C, 2) int64
    circle_rms_m: np.ndarray  # (C,)
    line_params: np.ndarray  # (L, 2) [alpha rad, rho m]
    line_cov: np.ndarray  # (L, 2, 2)
    line_endpoints: np.ndarray  # (L, 2, 2) m, laser frame
    line_beams: np.ndarray  # (L, 2) int64
    line_rms_m: np.ndarray  # (L,)
    edge_xy: np.ndarray  # (E, 2) m, laser frame
    edge_cov: np.ndarray  # (E, 2, 2)
    edge_beam: np.ndarray  # (E,) int64


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _copy_block(out, k, block):
    """out[k] = block for a 2-d `block`, element by element. The kernels assign no array to an
    array's slice: numba compiles that assignment's shape-mismatch error message (f-strings,
    str.join, int to str) once per process and per rank, about 5 s of CPU in every process that
    compiles a kernel holding one (lab notebook, 2026-11-29). A block of another shape raises
    (a constant message: cheap to compile), as the slice's assignment did."""
    if block.shape[0] != out.shape[1] or block.shape[1] != out.shape[2]:
        raise ValueError("_copy_block: the blocks differ in shape")
    for r in range(block.shape[0]):
        for q in range(block.shape[1]):
            out[k, r, q] = block[r, q]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _fit_method(cfg, x, y):
    """The circle fit of `cfg.method` (a `_Settings`) to the points: (x0, y0, r, ok)."""
    if cfg.method == 0:
        x0, y0, r, ok, _ = fit_circle_paper(x, y, cfg.lambda0, cfg.max_iter, cfg.tol)
    elif cfg.method == 1:
        x0, y0, r, ok, _ = fit_circle_geometric(x, y)
    elif cfg.method == 2:
        x0, y0, r, ok = fit_circle_kasa(x, y)
    else:
        x0, y0, r, ok = fit_circle_taubin(x, y)
    return x0, y0, r, ok


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _points(beams, a, b, buf):
    """Cartesian points of beams a..b of a `_Beams` (views into the scratch buffers
    buf = (x, y)) and their least range."""
    m = b - a + 1
    x = buf[0][:m]
    y = buf[1][:m]
    rmin = np.inf
    for i in range(m):
        rr = beams.ranges[a + i]
        th = beams.angle_min + beams.gamma * (a + i)
        x[i] = rr * math.cos(th)
        y[i] = rr * math.sin(th)
        rmin = min(rmin, rr)
    return x, y, rmin


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _circle_plausible(x, y, rmin, cfg):
    """A circle is plausible when the geometric fit's residuals pass the chi-square test, its
    radius is within bounds, and it is convex toward the laser (bounds and test: the `_Settings`
    cfg). Returns (ok, ssr, x0, y0, r)."""
    sigma2, r_min, r_max = cfg.sigma2, cfg.r_min, cfg.r_max
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
    return convex and ssr <= sigma2 * cfg.chi2_circ[x.shape[0]], ssr, gx, gy, gr


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _continuous(beams, bounds, k, side, edge_jump):
    """Does segment k continue, at its start (side 0) or end (side 1), into a neighbouring
    surface at a similar range (no depth jump)? A one-beam neighbouring segment that is itself cut
    off on its far side is taken for a mixed pixel and looked past. On a cyclic `_Beams` (360
    deg) the last beam neighbours the first."""
    ranges, cyclic = beams.ranges, beams.cyclic
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
def _merge_arcs(beams, cfg, bounds0, reason, buf):
    """The merge pass: neighbouring segments split by the gate without a depth jump (the planar
    model breaking on a curved surface) are joined when together they form a plausible circle.
    bounds0 (S, 2), reason (S,): `segment_kernel`'s segments. Returns the merged bounds."""
    ranges = beams.ranges
    bounds = np.empty_like(bounds0)
    ns = 0
    k = 0
    while k < bounds0.shape[0]:  # bounded: every pass of either loop advances k, S passes
        a = bounds0[k, 0]
        b = bounds0[k, 1]
        while cfg.merge and k + 1 < bounds0.shape[0]:
            if reason[k] == END_NO_RETURN or reason[k] == END_SCAN:
                break
            if abs(ranges[b + 1] - ranges[b]) >= cfg.edge_jump:
                break
            b2 = bounds0[k + 1, 1]
            if b2 - a + 1 < cfg.min_circle_points:
                b = b2
                k += 1
                continue
            x, y, rmin = _points(beams, a, b2, buf)
            ok, _, _, _, _ = _circle_plausible(x, y, rmin, cfg)
            if not ok:
                break
            b = b2
            k += 1
        bounds[ns, 0] = a
        bounds[ns, 1] = b
        ns += 1
        k += 1
    return bounds[:ns]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _mean_innovation(innov, svar, a, b, out):
    """eq. (5): mean innovation and its variance over the beams a..b the filter validated (M - 2
    of them for an unmerged segment), into out (2,) when there is one; returns their number."""
    sv = 0.0
    ss = 0.0
    nv = 0
    for i in range(a, b + 1):
        if innov[i] == innov[i]:
            sv += innov[i]
            ss += svar[i]
            nv += 1
    if nv > 0:
        out[0] = sv / nv
        out[1] = ss / (nv * nv)
    return nv


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _is_edge(beams, e, step, edge_jump):
    """Is beam e, the first (step -1) or last (step +1) beam of a segment, an occluding edge: is
    its neighbour on that side, or the one after a mixed pixel, farther by more than edge_jump?"""
    ranges = beams.ranges
    n_beams = ranges.shape[0]
    for j in range(1, 3):  # the neighbour, or the one after a mixed pixel
        nb = e + step * j
        if beams.cyclic:
            nb %= n_beams
        if nb < 0 or nb >= n_beams or not (ranges[nb] == ranges[nb]):
            return False
        if ranges[nb] - ranges[e] > edge_jump:
            return True
        if ranges[nb] < ranges[e]:
            return False
    return False


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _edge_point(beams, e, step, sigma_r, out):
    """The occluding edge at beam e, mid-way towards the far side (step -1 or +1): its point
    into out[0] (2,) and covariance into out[1] (2, 2), range noise sigma_r along the beam."""
    xy, cov = out
    th = beams.angle_min + beams.gamma * e + 0.5 * step * beams.gamma
    rr = beams.ranges[e]
    c = math.cos(th)
    s = math.sin(th)
    var_th = beams.gamma * beams.gamma / 12.0  # uniform over one beam step
    vr = sigma_r * sigma_r
    xy[0] = rr * c
    xy[1] = rr * s
    # J diag(var_r, var_th) J^T, J = [[c, -r s], [s, r c]]
    cov[0, 0] = c * c * vr + rr * rr * s * s * var_th
    cov[0, 1] = c * s * vr - rr * rr * s * c * var_th
    cov[1, 0] = cov[0, 1]
    cov[1, 1] = s * s * vr + rr * rr * c * c * var_th


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _segment_edges(beams, a, b, cfg, out, ne):
    """The occluding edges at either end of segment a..b appended to out = (edge_xy, edge_cov,
    edge_beam) from row ne; returns the new row count."""
    edge_xy, edge_cov, edge_beam = out
    for step in (-1, 1):
        e = a if step == -1 else b
        if _is_edge(beams, e, step, cfg.edge_jump):
            _edge_point(beams, e, step, cfg.sigma_r, (edge_xy[ne], edge_cov[ne]))
            edge_beam[ne] = e
            ne += 1
    return ne


@njit(cache=True, nogil=True, error_model="numpy")
def _extract_kernel(beams, settings):
    """Steps 1-4 of the module doc on one scan. beams: a `_Beams`, settings: a `_Settings`, both
    as plain tuples (see above). Returns the fields of a `_Found`, in its order."""
    beams = _Beams(*beams)
    cfg = _Settings(*settings)
    bounds0, reason, innov, svar = segment_kernel(
        beams.ranges,
        math.cos(beams.gamma),
        sigma_r=cfg.sigma_r,
        q=cfg.q,
        gate=cfg.gate,
        max_growth=cfg.max_growth,
    )
    n_beams = beams.ranges.shape[0]
    buf = (np.empty(n_beams), np.empty(n_beams))
    bounds = _merge_arcs(beams, cfg, bounds0, reason, buf)
    ns = bounds.shape[0]
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
    sigma2 = cfg.sigma2
    for k in range(ns):
        a = bounds[k, 0]
        b = bounds[k, 1]
        m = b - a + 1
        nv = _mean_innovation(innov, svar, a, b, seg_innov[k])
        if (
            cfg.short_trunks
            and m < cfg.min_circle_points
            and _short_trunk(beams, a, b, cfg, circ[nc], circ_cov[nc])
        ):
            kind[k] = 2
            circ_beams[nc, 0] = a
            circ_beams[nc, 1] = b
            circ_rms[nc] = np.nan  # no fit
            nc += 1
            if m >= cfg.min_points:
                ne = _segment_edges(beams, a, b, cfg, (edge_xy, edge_cov, edge_beam), ne)
            continue
        if m < cfg.min_points:
            continue
        x, y, rmin = _points(beams, a, b, buf)
        circle_ok = False
        ssr_c = np.inf
        isolated = not cfg.isolate or (
            not _continuous(beams, bounds, k, 0, cfg.edge_jump)
            and not _continuous(beams, bounds, k, 1, cfg.edge_jump)
        )
        if m >= cfg.min_circle_points and isolated:
            circle_ok, ssr_c, _, _, _ = _circle_plausible(x, y, rmin, cfg)
        alpha, rho, lcov, lend, ssr_l, lok = fit_line_tls(x, y, sigma2)
        if cfg.line_test == 1:
            if circle_ok and (ssr_l - ssr_c) / sigma2 > cfg.lrt_threshold:
                kind[k] = 2
            elif lok and ssr_l <= sigma2 * cfg.chi2_line[m]:
                kind[k] = 1
        else:
            if nv > 0 and abs(seg_innov[k, 0]) <= 3.0 * math.sqrt(seg_innov[k, 1]):
                kind[k] = 1 if lok else 0
            elif circle_ok:
                kind[k] = 2
        if kind[k] == 2:
            cx, cy, cr, cok = _fit_method(cfg, x, y)
            cov_ok = False
            if cok:
                ssr = circle_ssr(x, y, cx, cy, cr)
                cov, cov_ok = circle_covariance(x, y, cx, cy, cr, sigma2=sigma2)
            if not cov_ok:
                kind[k] = 0
            else:
                circ[nc, 0] = cx
                circ[nc, 1] = cy
                circ[nc, 2] = cr
                _copy_block(circ_cov, nc, cov)
                circ_beams[nc, 0] = a
                circ_beams[nc, 1] = b
                circ_rms[nc] = math.sqrt(ssr / m)
                nc += 1
        elif kind[k] == 1:
            line[nl, 0] = alpha
            line[nl, 1] = rho
            _copy_block(line_cov, nl, lcov)
            _copy_block(line_end, nl, lend)
            line_beams[nl, 0] = a
            line_beams[nl, 1] = b
            line_rms[nl] = math.sqrt(ssr_l / m)
            nl += 1
        ne = _segment_edges(beams, a, b, cfg, (edge_xy, edge_cov, edge_beam), ne)
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


# the mean depth of a circle's face behind its nearest point, in radii, for hits spread
# uniformly across its width (E[sqrt(r^2 - y^2)] = pi r / 4), and that depth's variance in r^2
_DEPTH = math.pi / 4.0
_DEPTH_VAR = 2.0 / 3.0 - math.pi**2 / 16.0


@njit(cache=True, nogil=True, error_model="numpy")
def _short_trunk(beams, a, b, cfg, out_p, out_c):
    """Whether segment a..b of kernel beams (1 to min_circle_points - 1 beams: too few to fit)
    is a short trunk, its circle (x0, y0, r) written to out_p (3,) and covariance to out_c (3, 3).

    A segment qualifies, a line included (no circle is tested on so few beams, and a thin
    pole's 3 beams fit a line within the noise), when its neighbours on both sides
    are no-returns or farther by more than edge_min_jump_m (an occluding, isolated object), its
    chord is under 2 r_max_m, and its end ranges differ by less than a third of its width (a
    convex face, Bailey's test), and no other return of the scan lies within
    short_trunk_clearance_m of its centre (a whole thin object, not a fragment of a larger
    one: the nearest other surface is farther than the largest object modelled); a segment at
    the border of a scan that is not a full circle is not known to end there. Its radius
    combines the width estimate w / 2, w = (span + one beam) x mean range (each edge is
    somewhere in half a beam of range-width, uniformly: variance of w / 2 is
    2 (rho gamma / 2)^2 / 3 / 4), with the radius limits as a prior: the moments of the uniform
    distribution on [r_min_m, r_max_m] (no site's trunk sizes). The centre lies pi r / 4 behind the
    segment's mean range (the mean depth of a circle's face over hits spread across its width),
    on its mean bearing. Covariance of (x0, y0, r): along the beam, the mean range's noise
    sigma_r^2 / m, the radius variance and the face depth's spread (2/3 - pi^2/16) r^2 / m;
    across it, a uniform one-beam bearing error; and the radius variance. (The caller's
    segments of fewer than min_circle_points beams are never circles of the fit.)
    """
    ranges, gamma = beams.ranges, beams.gamma
    n = ranges.shape[0]
    m = b - a + 1
    r_min, r_max = cfg.r_min, cfg.r_max
    # a segment at the border of a scan that is not a full circle may go on outside it:
    # not known to be a whole object (a 360 deg scan's first beam neighbours its last)
    if not beams.cyclic and (a == 0 or b == n - 1):
        return False
    # each end cut off: no return beside it, or the neighbour behind a depth jump
    left, right = ranges[(a - 1) % n], ranges[(b + 1) % n]
    if not (left != left or left - ranges[a] > cfg.edge_jump):
        return False
    if not (right != right or right - ranges[b] > cfg.edge_jump):
        return False
    rm = 0.0
    for i in range(a, b + 1):
        rm += ranges[i]
    rm /= m
    th_a, th_b = beams.angle_min + gamma * a, beams.angle_min + gamma * b
    dx = ranges[b] * math.cos(th_b) - ranges[a] * math.cos(th_a)
    chord = math.hypot(dx, ranges[b] * math.sin(th_b) - ranges[a] * math.sin(th_a))
    width = (th_b - th_a + gamma) * rm
    if chord >= 2 * r_max or abs(ranges[b] - ranges[a]) >= width / 3.0:
        return False
    r0, var0 = 0.5 * (r_min + r_max), (r_max - r_min) ** 2 / 12.0  # uniform on the limits
    var_w = 2.0 * (rm * gamma / 2.0) ** 2 / 3.0 / 4.0  # of the half width: two edges
    # the two combined by their variances (this form stays finite when var_w underflows)
    r = (0.5 * width * var0 + r0 * var_w) / (var0 + var_w)
    var_r = var_w * var0 / (var0 + var_w)
    th = 0.5 * (th_a + th_b)
    # the beams hit the face across its whole width: a hit at lateral offset y lies
    # sqrt(r^2 - y^2) in front of the centre, pi r / 4 on average over y uniform on
    # (-r, r), with variance (2/3 - pi^2/16) r^2 (over m beams: / m)
    rng = rm + _DEPTH * r
    c, s = math.cos(th), math.sin(th)
    cx, cy = rng * c, rng * s
    if cfg.clearance > 0 and _crowded(
        ranges, beams.angle_min, gamma, a, b, cx, cy, cfg.clearance, beams.cyclic
    ):
        return False
    var_rng = cfg.sigma_r**2 / m + _DEPTH**2 * var_r + _DEPTH_VAR * r * r / m
    var_th = gamma * gamma / 12.0
    # J diag(var_rng, var_th) J^T, J = [[c, -rng s], [s, rng c]]
    out_c[0, 0] = c * c * var_rng + rng * rng * s * s * var_th
    out_c[0, 1] = out_c[1, 0] = c * s * var_rng - rng * rng * s * c * var_th
    out_c[1, 1] = s * s * var_rng + rng * rng * c * c * var_th
    out_c[0, 2] = out_c[2, 0] = c * _DEPTH * var_r  # moves back with r
    out_c[1, 2] = out_c[2, 1] = s * _DEPTH * var_r
    out_c[2, 2] = var_r
    out_p[0], out_p[1], out_p[2] = cx, cy, r
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _crowded(ranges, angle_min, gamma, a, b, cx, cy, clearance, cyclic):
    """Whether a return of the scan outside beams a..b lies within `clearance` of (cx, cy).
    Only the beams whose bearing is within asin(clearance / |c|) of the centre's can (all of
    them when the centre is nearer than the clearance); a 360 deg scan wraps around."""
    n = ranges.shape[0]
    dist = math.hypot(cx, cy)
    lo, hi = 0, n - 1
    if dist > clearance:
        half = math.asin(clearance / dist) / gamma  # in beams
        middle = angle_min + 0.5 * gamma * (n - 1)  # the scan's middle bearing
        d = math.atan2(cy, cx) - middle
        d -= 2.0 * math.pi * math.floor((d + math.pi) / (2.0 * math.pi))  # in [-pi, pi)
        mid = 0.5 * (n - 1) + d / gamma  # the centre's beam (fractional)
        lo, hi = int(math.floor(mid - half)) - 1, int(math.ceil(mid + half)) + 1
        if not cyclic:
            lo, hi = max(lo, 0), min(hi, n - 1)
        elif hi - lo + 1 >= n:
            lo, hi = 0, n - 1
    c2 = clearance * clearance
    for j in range(lo, hi + 1):
        i = j % n
        if a <= i <= b or ranges[i] != ranges[i]:
            continue
        bi = angle_min + gamma * i
        ex, ey = ranges[i] * math.cos(bi) - cx, ranges[i] * math.sin(bi) - cy
        if ex * ex + ey * ey < c2:
            return True
    return False


def _resolve(params: dict, method: str, scan: Scan) -> tuple[ExtractorParams, tuple]:
    """The `ExtractorParams` of keyword arguments `params` and the kernel's settings for
    `method` and `scan`'s beams (`_settings`), cached (building them costs ~12 us per scan)."""
    gamma, n_beams = scan.angle_increment_rad, scan.n_beams
    items = _items(params)
    if items is None:
        p = ExtractorParams.from_kwargs(**params)  # an unhashable value: validation says why
        return p, _settings(p, method, gamma, n_beams)
    return _cached_resolve(items, method, gamma, n_beams)


def _resolve_params(
    params: ExtractorParams, overrides: dict, method: str, scan: Scan
) -> tuple[ExtractorParams, tuple]:
    """`_resolve` of an `ExtractorParams` (its fields the cache key, as keyword arguments')
    with `overrides` replacing some of its fields."""
    if overrides:
        names = {f.name for f in fields(ExtractorParams)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise FeaturesError(f"unknown extractor parameter(s) {unknown}; known: {sorted(names)}")
        return _resolve({**params.to_dict(), **overrides}, method, scan)
    gamma, n_beams = scan.angle_increment_rad, scan.n_beams
    return _cached_params(params, method, gamma, n_beams)


@lru_cache(maxsize=64)
def _cached_params(p: ExtractorParams, method: str, gamma: float, n_beams: int):
    """The kernel's settings of a (validated, frozen) `ExtractorParams`: the same as
    `_cached_resolve` of its fields as keyword arguments."""
    return p, _settings(p, method, gamma, n_beams)


def _items(params: dict) -> tuple | None:
    """The cache key of keyword arguments, None when a value is unhashable."""
    # the value's type is part of the key: 1 == True and 0.5 == Fraction(1, 2) hash alike
    items = tuple(sorted((k, type(v).__name__, v) for k, v in params.items()))
    try:
        hash(items)
    except TypeError:
        return None
    return items


@lru_cache(maxsize=64)
def _cached_resolve(items: tuple, method: str, gamma: float, n_beams: int):
    """`_resolve` of the keyword arguments ((name, type name, value), ...)."""
    p = ExtractorParams.from_kwargs(**{k: v for k, _, v in items})
    return p, _settings(p, method, gamma, n_beams)


def _settings(p: ExtractorParams, method: str, gamma: float, n_beams: int) -> tuple:
    """`p` and `method` resolved for a scan of `n_beams` beams `gamma` rad apart: a `_Settings`
    as the plain tuple the kernel takes. Raises when the beams are too coarse for the planar
    model at p.max_incidence_deg."""
    if gamma >= math.pi / 2 - math.radians(p.max_incidence_deg):
        raise FeaturesError(
            f"angle_increment_rad: {gamma} is too coarse for the planar model "
            f"with max_incidence_deg={p.max_incidence_deg}"
        )
    max_growth = max_growth_ratio(gamma, math.radians(p.max_incidence_deg))
    chi2_line, chi2_circ = _chi2_tables(n_beams, p.class_prob)
    settings = _Settings(
        sigma_r=p.sigma_r_m,
        q=p.q_m2,
        gate=p.gate,
        max_growth=max_growth,
        merge=p.merge_arcs,
        isolate=p.isolated_circles,
        edge_jump=p.edge_min_jump_m,
        min_points=p.min_points,
        min_circle_points=p.min_circle_points,
        line_test=_LINE_TESTS[p.line_test],
        lrt_threshold=p.lrt_threshold,
        sigma2=p.sigma_r_m**2 + p.roughness_m**2,
        chi2_line=chi2_line,
        chi2_circ=chi2_circ,
        r_min=p.r_min_m,
        r_max=p.r_max_m,
        method=_METHOD_CODE[method],
        lambda0=p.lambda0,
        max_iter=p.max_iter,
        tol=p.tol,
        short_trunks=p.short_trunks,
        clearance=p.short_trunk_clearance_m,
    )
    return tuple(settings)


def _kernel_beams(scan: Scan) -> _Beams:
    """`scan` in kernel beam order: a 360 deg scan starts at its `_seam`."""
    n, gamma = scan.n_beams, scan.angle_increment_rad
    if not (n > 2 and abs(n * gamma - 2.0 * math.pi) < 0.5 * gamma):
        return _Beams(scan.ranges_m, scan.angle_min_rad, gamma, False, 0)
    shift = _seam(scan.ranges_m)
    ranges = np.roll(scan.ranges_m, -shift)
    # read-only as `Scan.ranges_m` is: numba types a read-only array apart, and a writable one
    # here compiled the kernel and its callees a second time (some 16 s of a cold warm-up)
    ranges.flags.writeable = False
    return _Beams(ranges, scan.angle_min_rad + shift * gamma, gamma, True, shift)


def _in_scan_order(found: _Found, beams: _Beams) -> _Found:
    """`found` with the scan's own beam numbers (in place); a run across the seam keeps
    last >= B."""
    shift, n = beams.shift, beams.ranges.shape[0]
    for runs in (found.segment_beams, found.circle_beams, found.line_beams):
        runs += shift
        runs -= n * (runs[:, :1] >= n)
    return found._replace(edge_beam=(found.edge_beam + shift) % n)


def _features(scan: Scan, method: str, found: _Found) -> Features:
    """The answer of `extract_features`: `found`, in the scan's beam order, as `Features`."""
    return Features(
        stamp_s=scan.stamp_s,
        circle_params=found.circle_params,
        circle_cov=found.circle_cov,
        circle_beams=found.circle_beams,
        circle_rms_m=found.circle_rms_m,
        line_params=found.line_params,
        line_cov=found.line_cov,
        line_endpoints=found.line_endpoints,
        line_beams=found.line_beams,
        line_rms_m=found.line_rms_m,
        edge_xy=found.edge_xy,
        edge_cov=found.edge_cov,
        edge_beam=found.edge_beam,
        segment_beams=found.segment_beams,
        segment_kind=found.segment_kind,
        segment_innov=found.segment_innov,
        method=method,
        n_beams=scan.n_beams,
    )


def _extract_bailey(scan: Scan, params: dict) -> Features:
    """`extract_features(scan, "bailey", **params)`: `params` must be options of
    `features.bailey.extract_bailey`."""
    from features.bailey import BAILEY_OPTIONS, extract_bailey

    unknown = sorted(set(params) - set(BAILEY_OPTIONS))
    if unknown:
        raise FeaturesError(
            f"{unknown}: not parameters of method 'bailey' (allowed: {list(BAILEY_OPTIONS)})"
        )
    return extract_bailey(scan, **params)


def extract_features(scan: Scan, method: str = "paper", params=None, **overrides) -> Features:
    """Extract segments, edges, lines, circles and clutter from one scan (laser frame).

    method: "paper" (modified Gauss-Newton, eq. 6-9), "geometric" (orthogonal-distance LM with
        covariance), "kasa", "taubin", or "bailey" (the Victoria Park detector).
    params: the `ExtractorParams` (None: the defaults), which reach the kernel as they are; for
        "bailey" the detector's `features.bailey.BaileyParams` (`extract_bailey`'s `params`).
    overrides: fields of `ExtractorParams` replacing those of `params` (e.g. sigma_r_m=0.01,
        line_test="paper"); for "bailey" the options of `features.bailey.extract_bailey`.
    """
    if not isinstance(scan, Scan):
        raise FeaturesError(f"scan: expected a features.Scan, got {type(scan).__name__}")
    if method == "bailey":
        return _extract_bailey(
            scan, overrides if params is None else {**overrides, "params": params}
        )
    if method not in _METHOD_CODE:
        raise FeaturesError(f"method: must be one of {list(METHODS)}, got {method!r}")
    if params is not None and not isinstance(params, ExtractorParams):
        raise FeaturesError(
            f"params: expected a features.ExtractorParams, got {type(params).__name__}"
        )
    if params is None:
        p, settings = _resolve(overrides, method, scan)
    else:
        p, settings = _resolve_params(params, overrides, method, scan)
    beams = _kernel_beams(scan)
    found = _Found._make(_extract_kernel(tuple(beams), settings))
    if beams.shift:
        found = _in_scan_order(found, beams)
    return _features(scan, method, found)


def _seam(ranges: np.ndarray) -> int:
    """Where to cut a 360 deg scan: at its first no-return beam, else before its largest jump."""
    nan = np.flatnonzero(np.isnan(ranges))
    if nan.size:
        return int(nan[0])
    return int(np.argmax(np.abs(ranges - np.roll(ranges, 1))))
