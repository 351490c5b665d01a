"""The Victoria Park tree detector (`detectTreesI16.m`, J. Guivant, ACFR 1999), the baseline.

Implemented from `../shared/datasets/victoria_park/BAILEY_DETECTOR.md` (steps 1-10 below refer to
its section 3). `detect_trees` reproduces the original's output, a (3, n) array [range (m);
bearing (rad, 0..pi, 0 = the first beam); diameter (m)], on all 2000 raw Victoria Park scans to
1e-6, same count in every scan (tests/test_bailey.py). `extract_bailey` wraps it as `Features` in
the laser frame so that experiments can swap it for the paper's extractor
(`extract_features(scan, method="bailey")`).

Two findings needed for the exact reproduction (checked on the 2000 scans):
- The occlusion threshold [daMin2] is 2*pi/360 rad, i.e. **1 deg = two beam steps**; the spec's
  table says "2*pi/360 = 2 deg" and "at most three beam steps", but a 2 deg threshold misses
  the reference in 896 of the 2000 scans (1.5 deg: 574).
- Gaps of exactly two beams (step 4) or ten beams (step 2) sit on the threshold, and the original
  decides them by the floating-point rounding of its angle table i*pi/360 (a[i+2] - a[i] is below
  2*pi/360 for 158 of the 359 positions i). Reproducing that needs that table and plain strict
  comparisons: resolving the ties either way instead breaks 2-345 scans.

Generalisation to other scans (`angles_rad`, used by `extract_bailey` for simulated scans):
- the thresholds stay the original's angles and distances (5 deg break gap, 1 deg occlusion,
  field-of-view margin 5*pi/306 -- "306" is the original's, kept as is);
- the one-beam width added to the diameter (step 8) is the scan's own mean beam spacing;
- the field-of-view margin (step 7) is measured from the scan's own first and last beam angles
  and skipped for a full 360-degree scan, which has no field-of-view border. A full scan is also
  rotated so that its seam falls on a segment break (after the longest run of no-return beams,
  else at the largest range jump), so the seam never cuts a trunk in two; the isolation and
  occlusion tests do not look across that one break.
- threshold ties are resolved deterministically rather than by rounding: angle differences within
  `_ANGLE_TIE_RAD` of the break or occlusion threshold count as equal to it, so neither a break
  nor adjacent (strict inequalities). Angles exactly equal to the original table take the
  original's path.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np
from numba import njit

from features.errors import FeaturesError
from features.limits import PARAM_LIMIT, PARAM_TINY, magnitude_problem, sourced
from features.types import KIND_CIRCLE, KIND_CLUTTER, Features, Scan

__all__ = ["BAILEY_OPTIONS", "BaileyParams", "detect_trees", "extract_bailey", "BAILEY_BEAM_RAD"]

BAILEY_BEAM_RAD = math.pi / 360  # the original's beam spacing (0.5 deg), 361 beams over 0..pi
_ANGLE_TIE_RAD = 1e-9  # angle differences this close to a threshold count as equal to it
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class BaileyParams:
    """The detector's constants; the defaults are the original's (names in brackets)."""

    # [M11] beams with r >= this are invalid (step 1)
    max_range_m: float = sourced(
        75.0, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [M10] a segment's first beam must be farther (step 7)
    min_start_range_m: float = sourced(
        1.0, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [M2] range jump that breaks a segment (step 2)
    break_jump_m: float = sourced(
        1.5, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [M2a] angular gap that breaks a segment (step 2)
    break_gap_rad: float = sourced(
        10 * math.pi / 360, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [M3] end-to-start distance to the next 3 segments (step 3)
    isolation_m: float = sourced(
        3.0, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [daMin2] 1 deg, see the module doc (step 4)
    occlusion_gap_rad: float = sourced(
        2 * math.pi / 360, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [M5] start-to-end distance (step 6)
    max_chord_m: float = sourced(
        1.0, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # [daa] sic, 306 (step 7)
    fov_margin_rad: float = sourced(
        5 * math.pi / 306, "paper: Bailey's detector, the original's constant (bracketed name)"
    )
    # |R_start - R_end| < ratio * diameter (step 9)
    edge_ratio: float = sourced(
        1.0 / 3.0, "paper: Bailey's detector, the original's constant (bracketed name)"
    )

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise FeaturesError(f"BaileyParams.{f.name}: must be a finite number, got {v!r}")
            if not 0 <= v <= PARAM_LIMIT or magnitude_problem(v):
                raise FeaturesError(
                    f"BaileyParams.{f.name}: must be 0 or in [{PARAM_TINY:g}, {PARAM_LIMIT:g}], "
                    f"got {v!r}"
                )


_DEFAULT = BaileyParams()
_DEFAULT_ANGLES = np.arange(361) * math.pi / 360
_DEFAULT_COS = np.cos(_DEFAULT_ANGLES)
_DEFAULT_SIN = np.sin(_DEFAULT_ANGLES)
# Private tables, left writable so the numba kernel sees one array type (no recompilation).


def _check_ranges(ranges_m) -> np.ndarray:
    r = np.asarray(ranges_m)
    if r.dtype.kind not in "fiu":
        raise FeaturesError(f"ranges_m: expected real numbers, got dtype {r.dtype}")
    if r.ndim != 1:
        raise FeaturesError(f"ranges_m: expected shape (B,), got {r.shape}")
    return r.astype(np.float64, copy=False)


def _check_angles(angles_rad, n_beams: int) -> np.ndarray:
    a = np.asarray(angles_rad)
    if a.dtype.kind not in "fiu":
        raise FeaturesError(f"angles_rad: expected real numbers, got dtype {a.dtype}")
    if a.shape != (n_beams,):
        raise FeaturesError(f"angles_rad: expected shape ({n_beams},) like ranges_m, got {a.shape}")
    a = a.astype(np.float64, copy=False)
    if not np.all(np.isfinite(a)):
        raise FeaturesError("angles_rad: must be finite")
    if n_beams > 1 and not np.all(np.diff(a) > 0):
        raise FeaturesError("angles_rad: must be strictly increasing")
    if n_beams > 1 and a[-1] - a[0] >= _TWO_PI:
        raise FeaturesError(
            f"angles_rad: span {a[-1] - a[0]:.6g} rad is 2*pi or more (degrees instead of radians?)"
        )
    return a


# The records below cross into the numba kernel as plain tuples, `tuple(record)`, and are named
# again on the kernel's first line: numba's dispatcher types a plain tuple in C but a NamedTuple
# in Python, which costs about 1.5 us a call.


class _BeamTable(NamedTuple):
    """The beam geometry of one scan as the kernels read it (`_prepare`)."""

    ang: np.ndarray  # (B,) float64 beam angles, rad, increasing (rotated: `_prepare`)
    cos_t: np.ndarray  # (B,) cos(ang)
    sin_t: np.ndarray  # (B,) sin(ang)
    beam_rad: float  # rad, the width added to the diameter (step 8)


class _Limits(NamedTuple):
    """The scan's field of view and tie rule (steps 2, 4 and 7)."""

    check_fov: bool  # apply the field-of-view margin against [fov_lo, fov_hi] (step 7)
    fov_lo: float  # rad, the first beam's angle
    fov_hi: float  # rad, the last beam's angle
    tie: float  # rad: angle differences within it of the break/occlusion thresholds count as equal


class _Constants(NamedTuple):
    """The `BaileyParams` values as the kernels read them: the same names, in field order."""

    max_range_m: float
    min_start_range_m: float
    break_jump_m: float
    break_gap_rad: float
    isolation_m: float
    occlusion_gap_rad: float
    max_chord_m: float
    fov_margin_rad: float
    edge_ratio: float


# `_Constants` of a BaileyParams, as a plain tuple (dataclasses.astuple deep-copies: 25x slower)
_constants = operator.attrgetter(*_Constants._fields)


class _Detection(NamedTuple):
    """What steps 1-10 found in one scan (`_detect`)."""

    trees: np.ndarray  # (3, n) [range m; bearing rad; diameter m], as `detect_trees`
    seg_first: np.ndarray  # (K,) int64 first raw beam of every step-2 segment, in beam order
    seg_last: np.ndarray  # (K,) int64 its last beam (inclusive)
    kept: np.ndarray  # (K,) bool: the segment became a detection
    det_seg: np.ndarray  # (n,) int64: det_seg[j] is the segment of detection (column) j


# The original's scan: strict floating-point comparisons on the i*pi/360 table, no tie rule.
_DEFAULT_TABLE = _BeamTable(_DEFAULT_ANGLES, _DEFAULT_COS, _DEFAULT_SIN, BAILEY_BEAM_RAD)
_DEFAULT_LIMITS = _Limits(True, 0.0, math.pi, 0.0)


def _prepare(r: np.ndarray, ang: np.ndarray | None, p: BaileyParams):
    """The kernels' view of one scan: (ranges (B,), `_BeamTable`, `_Limits`, rot), a full
    circle rotated by `rot` beams so that its seam is a segment break (`_seam`); see `_detect`."""
    n_beams = r.shape[0]
    if ang is None or (n_beams == 361 and np.array_equal(ang, _DEFAULT_ANGLES)):
        if n_beams != 361:
            raise FeaturesError(
                f"ranges_m: the original detector takes 361 beams at i*pi/360, got {n_beams}; "
                "pass angles_rad for other scans"
            )
        return r, _DEFAULT_TABLE, _DEFAULT_LIMITS, 0
    beam_rad = (ang[-1] - ang[0]) / (n_beams - 1) if n_beams > 1 else BAILEY_BEAM_RAD
    full_circle = n_beams > 1 and (ang[-1] - ang[0]) + beam_rad >= _TWO_PI - 1e-6
    cos_t, sin_t = np.cos(ang), np.sin(ang)
    limits = _Limits(not full_circle, float(ang[0]), float(ang[-1]), _ANGLE_TIE_RAD)
    rot = _seam(r, p) if full_circle else 0
    if rot:
        r = np.concatenate((r[rot:], r[:rot]))
        ang = np.concatenate((ang[rot:], ang[:rot] + _TWO_PI))
        cos_t = np.concatenate((cos_t[rot:], cos_t[:rot]))
        sin_t = np.concatenate((sin_t[rot:], sin_t[:rot]))
    ang = np.array(ang, dtype=np.float64)  # contiguous and writable: one numba specialisation
    return r, _BeamTable(ang, cos_t, sin_t, beam_rad), limits, rot


def _detect(r: np.ndarray, ang: np.ndarray | None, p: BaileyParams, kernel=None) -> _Detection:
    """Run steps 1-10 on one scan.

    r: (B,) float64 ranges, m (NaN = no return), B >= 1. ang: (B,) beam angles, or None for the
    original's i*pi/360 (B = 361). kernel: `_kernel_numba` (default) or its twin `_kernel_numpy`.
    Returns a `_Detection`: trees (3, n) as `detect_trees`; seg_first/seg_last/kept describe
    every step-2 segment by its inclusive raw beam indices, in beam order, and whether it became
    a detection; det_seg[j] is the segment of column j. In a rotated full-circle scan a segment
    across the caller's seam has last >= B (its beams are first..last modulo B).
    """
    n_beams = r.shape[0]
    r = np.array(r, dtype=np.float64)  # contiguous and writable: one numba specialisation
    r, table, limits, rot = _prepare(r, ang, p)
    kernel = kernel or _kernel_numba
    det = _Detection._make(kernel(r, tuple(table), tuple(limits), _constants(p)))
    if rot:
        det = _unrotate(det, rot, n_beams, limits.fov_lo)
    return det


def _unrotate(det: _Detection, rot: int, n_beams: int, fov_lo: float) -> _Detection:
    """`det` of a full circle rotated by `rot` beams (`_prepare`) back to the caller's beam
    numbering and angle range (first beam at fov_lo rad), segments in beam order and detections
    in increasing bearing."""
    out, seg_first, seg_last, keep, det_seg = det
    K = seg_first.size
    seg_first = seg_first + rot
    seg_last = seg_last + rot
    wrap = seg_first >= n_beams  # wholly past the caller's last beam: renumber from 0
    seg_first[wrap] -= n_beams
    seg_last[wrap] -= n_beams  # a segment across the caller's seam keeps last >= B
    out[1] = np.where(out[1] >= fov_lo + _TWO_PI, out[1] - _TWO_PI, out[1])
    seg_order = np.argsort(seg_first, kind="stable")
    seg_rank = np.empty_like(seg_order)
    seg_rank[seg_order] = np.arange(K)
    seg_first, seg_last, keep = seg_first[seg_order], seg_last[seg_order], keep[seg_order]
    col_order = np.argsort(out[1], kind="stable")  # increasing bearing
    out = out.take(col_order, axis=1)  # C order, as the kernel's own: one signature of `_circles`
    det_seg = seg_rank[det_seg[col_order]]
    return _Detection(out, seg_first, seg_last, keep, det_seg)


def _kernel_numpy(r, table, limits, consts):
    """Steps 1-10 vectorised with numpy: the test oracle of `_kernel_numba` (same arithmetic,
    same arguments).

    r: (B,) ranges, m. table: a `_BeamTable` (beam angles, their cos/sin, the width added to
    the diameter), limits: a `_Limits` (field of view, tie rule), consts: a `_Constants` (the
    `BaileyParams` values), each as a plain tuple or the record itself.
    Returns the fields of a `_Detection`.
    """
    tab, lim, par = _BeamTable(*table), _Limits(*limits), _Constants(*consts)
    ang, cos_t, sin_t = tab.ang, tab.cos_t, tab.sin_t
    # Step 1: valid beams (NaN < x is False, so NaN is invalid).
    with np.errstate(invalid="ignore"):
        idx = np.flatnonzero(r < par.max_range_m)
    n = idx.size
    if n == 0:
        z = np.zeros(0, np.int64)
        return np.zeros((3, 0)), z, z.copy(), np.zeros(0, np.bool_), z.copy()
    R = r[idx]
    A = ang[idx]

    # Step 2: segmentation by range jumps and angular gaps.
    brk = (np.abs(R[1:] - R[:-1]) > par.break_jump_m) | (
        A[1:] - A[:-1] > par.break_gap_rad + lim.tie
    )
    bpos = np.flatnonzero(brk)
    s = np.empty(bpos.size + 1, np.int64)
    e = np.empty(bpos.size + 1, np.int64)
    s[0] = 0
    s[1:] = bpos + 1
    e[:-1] = bpos
    e[-1] = n - 1
    K = s.size
    i_s, i_e = idx[s], idx[e]
    Rs, Re, As, Ae = R[s], R[e], A[s], A[e]
    xs, ys = Rs * cos_t[i_s], Rs * sin_t[i_s]
    xe, ye = Re * cos_t[i_e], Re * sin_t[i_e]

    # Steps 3-4 run on all segments.
    remove = np.zeros(K, np.bool_)
    for d in (1, 2, 3):  # step 3: end of k against the starts of k+1..k+3
        if K <= d:
            break
        dx = xe[:-d] - xs[d:]
        dy = ye[:-d] - ys[d:]
        close = dx * dx + dy * dy < par.isolation_m * par.isolation_m
        remove[:-d] |= close
        remove[d:] |= close
    if K > 1:  # step 4: angularly adjacent neighbours, the farther one is occluded
        adj = As[1:] - Ae[:-1] < par.occlusion_gap_rad - lim.tie
        next_farther = Rs[1:] > Re[:-1]
        remove[1:] |= adj & next_farther
        remove[:-1] |= adj & ~next_farther

    # Steps 5-9: removal, chord, range and field of view, diameter, edge consistency.
    diam = (Ae - As + tab.beam_rad) * (Rs + Re) / 2  # step 8: arc length, one beam width added
    dx = xe - xs
    dy = ye - ys
    keep = ~remove
    keep &= dx * dx + dy * dy < par.max_chord_m * par.max_chord_m  # step 6
    keep &= Rs > par.min_start_range_m  # step 7
    if lim.check_fov:
        keep &= (As - lim.fov_lo > par.fov_margin_rad) & (lim.fov_hi - Ae > par.fov_margin_rad)
    keep &= np.abs(Rs - Re) < par.edge_ratio * diam  # step 9

    # Step 10: centre range (middle of the compressed run + the radius) and bearing.
    k = np.flatnonzero(keep)
    se = s[k] + e[k]
    d_k = diam[k]
    out = np.empty((3, k.size))
    out[0] = (R[se // 2] + R[(se + 1) // 2]) / 2 + d_k / 2
    out[1] = (As[k] + Ae[k]) / 2
    out[2] = d_k
    return out, i_s, i_e, keep, k


@njit(cache=True, nogil=True)
def _kernel_numba(r, table, limits, consts):
    """Steps 1-10 as loops (numba); `_kernel_numpy` is its oracle. Same arguments and results
    (the records as plain tuples, see above)."""
    tab, lim, par = _BeamTable(*table), _Limits(*limits), _Constants(*consts)
    ang, cos_t, sin_t = tab.ang, tab.cos_t, tab.sin_t
    n_beams = r.shape[0]
    idx = np.empty(n_beams, np.int64)
    n = 0
    for i in range(n_beams):  # step 1
        if r[i] < par.max_range_m:
            idx[n] = i
            n += 1
    if n == 0:
        return (
            np.zeros((3, 0)),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            np.zeros(0, np.bool_),
            np.zeros(0, np.int64),
        )
    s = np.empty(n, np.int64)
    e = np.empty(n, np.int64)
    s[0] = 0
    K = 0
    for j in range(n - 1):  # step 2
        a, b = idx[j], idx[j + 1]
        if abs(r[b] - r[a]) > par.break_jump_m or ang[b] - ang[a] > par.break_gap_rad + lim.tie:
            e[K] = j
            K += 1
            s[K] = j + 1
    e[K] = n - 1
    K += 1
    i_s = np.empty(K, np.int64)
    i_e = np.empty(K, np.int64)
    xs = np.empty(K)
    ys = np.empty(K)
    xe = np.empty(K)
    ye = np.empty(K)
    for k in range(K):
        a, b = idx[s[k]], idx[e[k]]
        i_s[k], i_e[k] = a, b
        xs[k], ys[k] = r[a] * cos_t[a], r[a] * sin_t[a]
        xe[k], ye[k] = r[b] * cos_t[b], r[b] * sin_t[b]
    remove = np.zeros(K, np.bool_)
    for d in range(1, 4):  # step 3
        for k in range(K - d):
            dx = xe[k] - xs[k + d]
            dy = ye[k] - ys[k + d]
            if dx * dx + dy * dy < par.isolation_m * par.isolation_m:
                remove[k] = True
                remove[k + d] = True
    for k in range(K - 1):  # step 4
        if ang[i_s[k + 1]] - ang[i_e[k]] < par.occlusion_gap_rad - lim.tie:
            if r[i_s[k + 1]] > r[i_e[k]]:
                remove[k + 1] = True
            else:
                remove[k] = True
    keep = np.zeros(K, np.bool_)
    diam = np.empty(K)
    nk = 0
    for k in range(K):  # steps 5-9
        a, b = i_s[k], i_e[k]
        rs, re, as_, ae = r[a], r[b], ang[a], ang[b]
        diam[k] = (ae - as_ + tab.beam_rad) * (rs + re) / 2
        dx = xe[k] - xs[k]
        dy = ye[k] - ys[k]
        ok = (
            not remove[k]
            and dx * dx + dy * dy < par.max_chord_m * par.max_chord_m
            and rs > par.min_start_range_m
        )
        if ok and lim.check_fov:
            ok = as_ - lim.fov_lo > par.fov_margin_rad and lim.fov_hi - ae > par.fov_margin_rad
        if ok:
            ok = abs(rs - re) < par.edge_ratio * diam[k]
        keep[k] = ok
        nk += ok
    out = np.empty((3, nk))
    det = np.empty(nk, np.int64)
    c = 0
    for k in range(K):  # step 10
        if keep[k]:
            se = s[k] + e[k]
            d_k = diam[k]
            out[0, c] = (r[idx[se // 2]] + r[idx[(se + 1) // 2]]) / 2 + d_k / 2
            out[1, c] = (ang[i_s[k]] + ang[i_e[k]]) / 2
            out[2, c] = d_k
            det[c] = k
            c += 1
    return out, i_s, i_e, keep, det


def _seam(r: np.ndarray, p: BaileyParams) -> int:
    """For a full 360-degree scan: the beam to start from so that the seam is a segment break.

    The first beam after the longest run of invalid beams if there is one, otherwise the beam
    after the largest range jump (cyclically). 0 when the scan already starts there.
    """
    with np.errstate(invalid="ignore"):
        invalid = ~(r < p.max_range_m)
    b = r.shape[0]
    if invalid.all():
        return 0
    if invalid.any():
        # Rotate so that a valid beam comes first, then find the longest invalid run.
        first_valid = int(np.argmax(~invalid))
        inv = np.concatenate((invalid[first_valid:], invalid[:first_valid]))
        edges = np.diff(np.concatenate(([0], inv.astype(np.int8), [0])))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)  # exclusive
        longest = int(np.argmax(ends - starts))
        return int((ends[longest] + first_valid) % b)
    jump = np.abs(r - np.roll(r, 1))  # jump[i] = |r[i] - r[i-1]|, cyclic
    return int(np.argmax(jump))


def detect_trees(ranges_m, angles_rad=None, params: BaileyParams | None = None) -> np.ndarray:
    """The Victoria Park tree detector: trunks in one scan, exactly as `detectTreesI16.m`.

    ranges_m: (B,) ranges, metres (the 13-bit-masked raw words / 100; NaN, or anything not below
        `params.max_range_m` = 75 m, is no return). Without `angles_rad`, B must be 361.
    angles_rad: optional (B,) strictly increasing beam angles, rad, measured from the first beam
        (default: i*pi/360, the Victoria Park SICK). See the module doc for what changes.
    params: the detector's constants (default: the original's).
    Returns (3, n) float64 [range to the trunk centre (m); bearing (rad, in the frame of
        `angles_rad`, 0..pi by default, 0 = the vehicle's right); diameter (m)], one column per
        detection in increasing bearing; shape (3, 0) when there is none.
    """
    r = _check_ranges(ranges_m)
    ang = None if angles_rad is None else _check_angles(angles_rad, r.shape[0])
    p = params or _DEFAULT
    if not isinstance(p, BaileyParams):
        raise FeaturesError(f"params: expected BaileyParams, got {type(params).__name__}")
    if r.shape[0] == 0:
        return np.zeros((3, 0))
    return _detect(r, ang, p).trees


BAILEY_OPTIONS = (
    "range_sigma_m",
    "range_sigma_per_m",
    "bearing_sigma_rad",
    "radius_sigma_m",
    "params",
)  # the keyword arguments of `extract_bailey`


def extract_bailey(
    scan: Scan,
    *,
    range_sigma_m: float = 0.05,
    range_sigma_per_m: float = 0.01,
    bearing_sigma_rad: float = math.radians(0.5),
    radius_sigma_m: float = 0.05,
    params: BaileyParams | None = None,
) -> Features:
    """The Victoria Park detector as `Features`: one circle per detection, in the laser frame.

    Geometry: the detector's bearing is measured from the scan's first beam, so the laser-frame
    bearing is `scan.angle_min_rad + bearing`; centre = range * (cos, sin); radius = diameter / 2.
    circle_beams: the raw beam indices [first, last] of the detection's segment (inclusive; in a
    full 360-degree scan a segment across the scan's seam has last >= B: beams first..last mod B).

    Covariance (a constant model, not a fit): the Zaragoza SLAM-school noise model of these
    detections, range std `range_sigma_m + range_sigma_per_m * range` along the beam and
    cross-range std `range * sin(bearing_sigma_rad)` across it (diag((0.05 + 0.01 r)^2,
    (r sin 0.5 deg)^2) by default), rotated into x-y. Radius variance
    `radius_sigma_m^2 + (range * beam)^2 / 24`: a constant model error plus the beam quantisation
    of the diameter's arc (each edge uniform over one beam width, `beam` = the angle increment:
    var(d) = range^2 beam^2 / 6, r = d / 2). Centre and radius are taken as uncorrelated.

    Segments: every break-separated run of valid beams (step 2 of the detector), kind 2 (circle)
    when it became a detection and 0 (clutter) otherwise; segment_innov is NaN (no EKF here).
    No lines and no edges; circle_rms_m is NaN (no fit).
    """
    if not isinstance(scan, Scan):
        raise FeaturesError(f"scan: expected a features.Scan, got {type(scan).__name__}")
    noise = _noise_model(range_sigma_m, range_sigma_per_m, bearing_sigma_rad, radius_sigma_m)
    p = params or _DEFAULT
    if not isinstance(p, BaileyParams):
        raise FeaturesError(f"params: expected BaileyParams, got {type(params).__name__}")
    det = _detect(scan.ranges_m, _beam_angles(scan, p), p)
    circ, cov = _circles(det.trees, scan.angle_min_rad, scan.angle_increment_rad, noise)
    return _as_features(scan, det, circ, cov)


class _NoiseModel(NamedTuple):
    """The constant covariance model of `extract_bailey`'s circles (see there)."""

    range_sigma_m: float  # m, range std along the beam at range 0
    range_sigma_per_m: float  # its growth with range, m per m
    sin_bearing_sigma: float  # sin(bearing_sigma_rad): the cross-range std per metre of range
    radius_sigma_m: float  # m, the radius model error


def _noise_model(range_sigma_m, range_sigma_per_m, bearing_sigma_rad, radius_sigma_m) -> tuple:
    """The checked options of `extract_bailey` as a `_NoiseModel`, in the plain tuple that
    `_circles` takes."""
    for name, v in (
        ("range_sigma_m", range_sigma_m),
        ("range_sigma_per_m", range_sigma_per_m),
        ("bearing_sigma_rad", bearing_sigma_rad),
        ("radius_sigma_m", radius_sigma_m),
    ):
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or not math.isfinite(v)
            or not 0 <= v <= PARAM_LIMIT
            or magnitude_problem(v)
        ):
            raise FeaturesError(
                f"{name}: must be 0 or a number in [{PARAM_TINY:g}, {PARAM_LIMIT:g}], got {v!r}"
            )
    noise = _NoiseModel(
        range_sigma_m, range_sigma_per_m, math.sin(bearing_sigma_rad), radius_sigma_m
    )
    return tuple(noise)


def _beam_angles(scan: Scan, p: BaileyParams) -> np.ndarray | None:
    """The detector's beam angles for `scan` (B,), rad from its first beam, or None for the
    original's i*pi/360 table (361 beams 0.5 deg apart)."""
    inc = scan.angle_increment_rad
    n_beams = scan.n_beams
    if inc >= p.break_gap_rad:
        raise FeaturesError(
            f"scan.angle_increment_rad: {inc:.4g} rad is not below the detector's break gap "
            f"(break_gap_rad = {p.break_gap_rad:.4g} rad): every beam would be a segment of its own"
        )
    if n_beams == 361 and inc == BAILEY_BEAM_RAD:
        return None  # the original's angle table
    ang = np.arange(n_beams) * inc
    if n_beams > 1 and ang[-1] >= _TWO_PI:
        raise FeaturesError(f"scan: {n_beams} beams of {inc} rad cover more than 360 degrees")
    return ang


def _as_features(scan: Scan, det: _Detection, circ: np.ndarray, cov: np.ndarray) -> Features:
    """`extract_bailey`'s answer: the circles (n, 3), their covariances (n, 3, 3) and the
    detection's segments."""
    seg_beams = np.empty((det.seg_first.size, 2), np.int64)
    seg_beams[:, 0] = det.seg_first
    seg_beams[:, 1] = det.seg_last
    kind = np.where(det.kept, KIND_CIRCLE, KIND_CLUTTER).astype(np.int64)
    return Features(
        stamp_s=scan.stamp_s,
        circle_params=circ,
        circle_cov=cov,
        circle_beams=seg_beams[det.det_seg],
        circle_rms_m=np.full(circ.shape[0], np.nan),
        line_params=_NO_LINES[0],
        line_cov=_NO_LINES[1],
        line_endpoints=_NO_LINES[2],
        line_beams=_NO_LINES[3],
        line_rms_m=_NO_LINES[4],
        edge_xy=_NO_EDGES[0],
        edge_cov=_NO_EDGES[1],
        edge_beam=_NO_EDGES[2],
        segment_beams=seg_beams,
        segment_kind=kind,
        segment_innov=np.full((kind.size, 2), np.nan),
        method="bailey",
        n_beams=scan.n_beams,
    )


def _empty(*shape, dtype=np.float64) -> np.ndarray:
    a = np.zeros(shape, dtype)
    a.setflags(write=False)
    return a


# Shared read-only empty arrays for the features the detector never produces.
_NO_LINES = (
    _empty(0, 2),
    _empty(0, 2, 2),
    _empty(0, 2, 2),
    _empty(0, 2, dtype=np.int64),
    _empty(0),
)
_NO_EDGES = (_empty(0, 2), _empty(0, 2, 2), _empty(0, dtype=np.int64))


@njit(cache=True, nogil=True)
def _circles(out, angle_min, inc, noise):
    """Detections (3, n) [range; bearing from the first beam; diameter] -> laser-frame circles.

    angle_min: rad, laser-frame bearing of the first beam; inc: rad, beam spacing; noise: a
    `_NoiseModel` as a plain tuple (see the note above `_BeamTable`).
    Returns circle_params (n, 3) [x0, y0, r] and circle_cov (n, 3, 3); see `extract_bailey`.
    """
    noise = _NoiseModel(*noise)
    n = out.shape[1]
    circ = np.empty((n, 3))
    cov = np.zeros((n, 3, 3))
    for j in range(n):
        rng = out[0, j]
        bearing = angle_min + out[1, j]
        c = np.cos(bearing)
        s = np.sin(bearing)
        circ[j, 0] = rng * c
        circ[j, 1] = rng * s
        circ[j, 2] = out[2, j] / 2
        # range noise along the beam, bearing noise across it
        var_along = (noise.range_sigma_m + noise.range_sigma_per_m * rng) ** 2
        var_across = (rng * noise.sin_bearing_sigma) ** 2
        cov[j, 0, 0] = var_along * c * c + var_across * s * s
        cov[j, 1, 1] = var_along * s * s + var_across * c * c
        cov[j, 0, 1] = (var_along - var_across) * c * s
        cov[j, 1, 0] = cov[j, 0, 1]
        # model error + beam quantisation
        cov[j, 2, 2] = noise.radius_sigma_m**2 + (rng * inc) ** 2 / 24
    return circ, cov
