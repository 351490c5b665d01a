"""The Victoria Park tree detector (`detectTreesI16.m`, J. Guivant, ACFR 1999), the baseline.

Implemented from `../shared/datasets/victoria_park/BAILEY_DETECTOR.md` (steps 1-10 below refer to
its section 3). `detect_trees` reproduces the original's output, a (3, n) array [range (m);
bearing (rad, 0..pi, 0 = the first beam); diameter (m)], on all 2000 raw Victoria Park scans to
1e-6 (tests/test_bailey.py). `extract_bailey` wraps it as a `Features` in the laser frame so that
experiments can swap it for the paper's extractor (`extract_features(scan, method="bailey")`).

Generalisation beyond the original's fixed 361 beams at i*pi/360 (`angles_rad`):
- all thresholds stay the original's angles and distances (5 deg break gap, 2 deg occlusion,
  field-of-view margin 5*pi/306 -- "306" is the original's, kept as is);
- the one-beam width added to the diameter (step 8) is the scan's own beam spacing;
- the field-of-view margin (step 7) is measured from the scan's own first and last beam angles,
  and is skipped for a full 360-degree scan, which has no field-of-view border; a full scan is
  also rotated so that its seam falls on a segment break (see `_detect`), so a trunk is never cut
  in two by the seam.
- Angle comparisons in steps 2 and 4 treat differences within `_ANGLE_TIE_RAD` of the threshold as
  equal (not beyond it): a gap of exactly ten beams is "nine invalid beams", not a break, however
  the angles were rounded. This is the documented meaning of the original's thresholds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from features.types import KIND_CIRCLE, KIND_CLUTTER, Features, Scan

__all__ = ["BaileyParams", "detect_trees", "extract_bailey", "BAILEY_BEAM_RAD"]

BAILEY_BEAM_RAD = math.pi / 360  # the original's beam spacing (0.5 deg), 361 beams over 0..pi
_ANGLE_TIE_RAD = 1e-9  # angle differences this close to a threshold count as equal to it
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class BaileyParams:
    """The detector's constants; the defaults are the original's (names in brackets)."""

    max_range_m: float = 75.0  # [M11] beams with r >= this are invalid (step 1)
    min_start_range_m: float = 1.0  # [M10] a segment's first beam must be farther (step 7)
    break_jump_m: float = 1.5  # [M2] range jump that breaks a segment (step 2)
    break_gap_rad: float = 10 * math.pi / 360  # [M2a] angular gap that breaks a segment (step 2)
    isolation_m: float = 3.0  # [M3] end-to-start distance to the next 3 segments (step 3)
    occlusion_gap_rad: float = math.radians(2.0)  # [daMin2] 2 deg = 4 beams, adjacency (step 4)
    max_chord_m: float = 1.0  # [M5] start-to-end distance (step 6)
    fov_margin_rad: float = 5 * math.pi / 306  # [daa] sic, 306 (step 7)
    edge_ratio: float = 1.0 / 3.0  # |R_start - R_end| < ratio * diameter (step 9)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"BaileyParams.{f.name}: must be a finite number, got {v!r}")
            if v < 0:
                raise ValueError(f"BaileyParams.{f.name}: must be >= 0, got {v!r}")


_DEFAULT = BaileyParams()
_DEFAULT_ANGLES = np.arange(361) * math.pi / 360
_DEFAULT_COS = np.cos(_DEFAULT_ANGLES)
_DEFAULT_SIN = np.sin(_DEFAULT_ANGLES)
for _a in (_DEFAULT_ANGLES, _DEFAULT_COS, _DEFAULT_SIN):
    _a.setflags(write=False)


def _check_ranges(ranges_m) -> np.ndarray:
    r = np.asarray(ranges_m)
    if r.dtype.kind not in "fiu":
        raise ValueError(f"ranges_m: expected real numbers, got dtype {r.dtype}")
    if r.ndim != 1:
        raise ValueError(f"ranges_m: expected shape (B,), got {r.shape}")
    return r.astype(np.float64, copy=False)


def _check_angles(angles_rad, n_beams: int) -> np.ndarray:
    a = np.asarray(angles_rad)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"angles_rad: expected real numbers, got dtype {a.dtype}")
    if a.shape != (n_beams,):
        raise ValueError(f"angles_rad: expected shape ({n_beams},) like ranges_m, got {a.shape}")
    a = a.astype(np.float64, copy=False)
    if not np.all(np.isfinite(a)):
        raise ValueError("angles_rad: must be finite")
    if n_beams > 1 and not np.all(np.diff(a) > 0):
        raise ValueError("angles_rad: must be strictly increasing")
    if n_beams > 1 and a[-1] - a[0] >= _TWO_PI:
        raise ValueError(
            f"angles_rad: span {a[-1] - a[0]:.6g} rad is 2*pi or more (degrees instead of radians?)"
        )
    return a


def _detect(r: np.ndarray, ang: np.ndarray | None, p: BaileyParams):
    """Run steps 1-10 on one scan.

    r: (B,) float64 ranges, m (NaN = no return). ang: (B,) beam angles (None: i*pi/360, B = 361).
    Returns (out (3, n), seg_first (K,), seg_last (K,), kept (K,) bool, det_seg (n,)): `out` as
    `detect_trees`; seg_first/seg_last/kept describe every step-2 segment by its inclusive raw
    beam indices, in beam order, and whether it became a detection; det_seg[j] is the segment of
    column j. In a rotated full-circle scan a segment across the caller's seam has last >= B
    (its beams are first..last modulo B).
    """
    n_beams = r.shape[0]
    if ang is None:
        if n_beams != 361:
            raise ValueError(
                f"ranges_m: the original detector takes 361 beams at i*pi/360, got {n_beams}; "
                "pass angles_rad for other scans"
            )
        cos_t, sin_t, ang = _DEFAULT_COS, _DEFAULT_SIN, _DEFAULT_ANGLES
        beam_rad, full_circle, fov_lo, fov_hi = BAILEY_BEAM_RAD, False, 0.0, math.pi
        rot = 0
    else:
        beam_rad = (ang[-1] - ang[0]) / (n_beams - 1) if n_beams > 1 else BAILEY_BEAM_RAD
        full_circle = n_beams > 1 and (ang[-1] - ang[0]) + beam_rad >= _TWO_PI - 1e-6
        fov_lo, fov_hi = ang[0], ang[-1]
        rot = 0
        if full_circle:
            rot = _seam(r, p)
            if rot:
                r = np.concatenate((r[rot:], r[:rot]))
                ang = np.concatenate((ang[rot:], ang[:rot] + _TWO_PI))
        cos_t = sin_t = None

    # Step 1: valid beams (NaN < x is False, so NaN is invalid).
    with np.errstate(invalid="ignore"):
        idx = np.flatnonzero(r < p.max_range_m)
    n = idx.size
    empty_i = np.zeros(0, np.int64)
    if n == 0:
        return np.zeros((3, 0)), empty_i, empty_i, np.zeros(0, bool), empty_i
    R = r[idx]
    A = ang[idx]

    # Step 2: segmentation by range jumps and angular gaps.
    brk = (np.abs(np.diff(R)) > p.break_jump_m) | (np.diff(A) > p.break_gap_rad + _ANGLE_TIE_RAD)
    bpos = np.flatnonzero(brk)
    s = np.empty(bpos.size + 1, np.int64)
    e = np.empty(bpos.size + 1, np.int64)
    s[0] = 0
    s[1:] = bpos + 1
    e[:-1] = bpos
    e[-1] = n - 1
    K = s.size
    Rs, Re, As, Ae = R[s], R[e], A[s], A[e]
    if cos_t is not None:
        i_s, i_e = idx[s], idx[e]
        xs, ys = Rs * cos_t[i_s], Rs * sin_t[i_s]
        xe, ye = Re * cos_t[i_e], Re * sin_t[i_e]
    else:
        xs, ys = Rs * np.cos(As), Rs * np.sin(As)
        xe, ye = Re * np.cos(Ae), Re * np.sin(Ae)

    # Steps 3-4 run on all segments.
    remove = np.zeros(K, bool)
    iso2 = p.isolation_m**2
    for d in (1, 2, 3):  # step 3: end of k against the starts of k+1..k+3
        if K <= d:
            break
        close = (xe[:-d] - xs[d:]) ** 2 + (ye[:-d] - ys[d:]) ** 2 < iso2
        remove[:-d] |= close
        remove[d:] |= close
    if K > 1:  # step 4: angularly adjacent neighbours, the farther one is occluded
        adj = As[1:] - Ae[:-1] < p.occlusion_gap_rad - _ANGLE_TIE_RAD
        next_farther = Rs[1:] > Re[:-1]
        remove[1:] |= adj & next_farther
        remove[:-1] |= adj & ~next_farther

    # Steps 5-9: removal, chord, range and field of view, diameter, edge consistency.
    diam = (Ae - As + beam_rad) * (Rs + Re) / 2  # step 8: arc length, one beam width added
    keep = ~remove
    keep &= (xe - xs) ** 2 + (ye - ys) ** 2 < p.max_chord_m**2  # step 6
    keep &= Rs > p.min_start_range_m  # step 7
    if not full_circle:
        keep &= (As - fov_lo > p.fov_margin_rad) & (fov_hi - Ae > p.fov_margin_rad)
    keep &= np.abs(Rs - Re) < p.edge_ratio * diam  # step 9

    # Step 10: centre range (middle beam of the compressed run + radius) and bearing.
    k = np.flatnonzero(keep)
    se = s[k] + e[k]
    r_mid = (R[se // 2] + R[(se + 1) // 2]) / 2
    d_k = diam[k]
    out = np.empty((3, k.size))
    out[0] = r_mid + d_k / 2
    out[1] = (As[k] + Ae[k]) / 2
    out[2] = d_k

    seg_first, seg_last = idx[s], idx[e]
    if rot:  # back to the caller's beam numbering and angle range
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
        out = out[:, col_order]
        det_seg = seg_rank[k[col_order]]
    else:
        det_seg = k
    return out, seg_first, seg_last, keep, det_seg


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


def detect_trees(
    ranges_m, angles_rad=None, params: BaileyParams | None = None
) -> np.ndarray:
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
    if r.shape[0] == 0:
        return np.zeros((3, 0))
    return _detect(r, ang, params or _DEFAULT)[0]


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
        raise ValueError(f"scan: expected a features.Scan, got {type(scan).__name__}")
    for name, v in (
        ("range_sigma_m", range_sigma_m),
        ("range_sigma_per_m", range_sigma_per_m),
        ("bearing_sigma_rad", bearing_sigma_rad),
        ("radius_sigma_m", radius_sigma_m),
    ):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ValueError(f"{name}: must be a finite number >= 0, got {v!r}")
    p = params or _DEFAULT
    if not isinstance(p, BaileyParams):
        raise ValueError(f"params: expected BaileyParams, got {type(params).__name__}")

    inc = scan.angle_increment_rad
    n_beams = scan.n_beams
    if n_beams == 361 and inc == BAILEY_BEAM_RAD:
        ang = None  # the original's angle table
    else:
        ang = np.arange(n_beams) * inc
        if n_beams > 1 and ang[-1] >= _TWO_PI:
            raise ValueError(f"scan: {n_beams} beams of {inc} rad cover more than 360 degrees")
    out, seg_first, seg_last, kept, det_seg = _detect(scan.ranges_m, ang, p)

    rng = out[0]
    bearing = scan.angle_min_rad + out[1]
    c, s_ = np.cos(bearing), np.sin(bearing)
    n = rng.size
    params_xyr = np.empty((n, 3))
    params_xyr[:, 0] = rng * c
    params_xyr[:, 1] = rng * s_
    params_xyr[:, 2] = out[2] / 2

    var_along = (range_sigma_m + range_sigma_per_m * rng) ** 2
    var_across = (rng * math.sin(bearing_sigma_rad)) ** 2
    cov = np.zeros((n, 3, 3))
    cov[:, 0, 0] = var_along * c * c + var_across * s_ * s_
    cov[:, 1, 1] = var_along * s_ * s_ + var_across * c * c
    cov[:, 0, 1] = cov[:, 1, 0] = (var_along - var_across) * c * s_
    cov[:, 2, 2] = radius_sigma_m**2 + (rng * inc) ** 2 / 24

    seg_beams = np.stack([seg_first, seg_last], axis=1).astype(np.int64)
    circle_beams = seg_beams[det_seg]
    kind = np.where(kept, KIND_CIRCLE, KIND_CLUTTER).astype(np.int64)
    z = np.zeros
    return Features(
        stamp_s=scan.stamp_s,
        circle_params=params_xyr, circle_cov=cov, circle_beams=circle_beams,
        circle_rms_m=np.full(n, np.nan),
        line_params=z((0, 2)), line_cov=z((0, 2, 2)), line_endpoints=z((0, 2, 2)),
        line_beams=z((0, 2), np.int64), line_rms_m=z(0),
        edge_xy=z((0, 2)), edge_cov=z((0, 2, 2)), edge_beam=z(0, np.int64),
        segment_beams=seg_beams, segment_kind=kind, segment_innov=np.full((kind.size, 2), np.nan),
        method="bailey",
    )  # fmt: skip
