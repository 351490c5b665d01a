"""Data types of one laser scan and the features extracted from it.

Frames: everything here is in the **laser frame**: x along the laser's 0-rad beam, y to its left,
angles counter-clockwise positive. Units are metres and radians, and names say so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np

from features.errors import FeaturesError

__all__ = ["Scan", "Segment", "Circle", "Line", "Edge", "Features", "SegmentKind"]

SegmentKind = Literal["line", "circle", "clutter"]

# Integer codes used by the numba kernels and the struct-of-arrays `Features`.
KIND_CLUTTER, KIND_LINE, KIND_CIRCLE = 0, 1, 2
KIND_NAMES: tuple[SegmentKind, ...] = ("clutter", "line", "circle")


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Scan:
    """One 2D laser scan.

    ranges_m: (B,) float64, metres along each beam. On construction every reading that is not a
        return (NaN, +-inf, zero, negative, or at or beyond `max_range_m`) becomes NaN, so
        `ranges_m` holds either a valid range or NaN; `raw_ranges_m` keeps what was given.
    angle_min_rad: bearing of beam 0 in the laser frame (0 = laser x-axis, CCW positive).
    angle_increment_rad: bearing step between beams, > 0; the B beams span less than 360
        degrees ((B - 1) * increment < 2 pi).
    stamp_s: acquisition time, seconds.
    max_range_m: readings at or beyond this are "no return" (inf = no limit).
    """

    ranges_m: np.ndarray
    angle_min_rad: float
    angle_increment_rad: float
    stamp_s: float = 0.0
    max_range_m: float = math.inf

    def __post_init__(self) -> None:
        raw = self.ranges_m
        if not isinstance(raw, np.ndarray):
            try:
                raw = np.asarray(raw)
            except Exception as exc:  # ragged lists and the like
                raise FeaturesError(f"Scan.ranges_m: cannot be read as an array ({exc})") from None
        if raw.dtype.kind not in "fiu":
            raise FeaturesError(
                f"Scan.ranges_m: expected real numbers (float64), got dtype {raw.dtype}"
            )
        if raw.ndim != 1:
            raise FeaturesError(f"Scan.ranges_m: expected shape (B,), got {raw.shape}")
        if raw.size == 0:
            raise FeaturesError("Scan.ranges_m: empty scan (0 beams)")
        for name in ("angle_min_rad", "angle_increment_rad", "stamp_s"):
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise FeaturesError(f"Scan.{name}: must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.angle_increment_rad <= 0.0:
            raise FeaturesError(
                f"Scan.angle_increment_rad: must be > 0, got {self.angle_increment_rad!r}"
            )
        span = (raw.size - 1) * self.angle_increment_rad
        if span >= 2.0 * math.pi:  # the sequence file's rule (datasets/FORMAT.md)
            raise FeaturesError(
                f"Scan.angle_increment_rad: {raw.size} beams of {self.angle_increment_rad!r} rad "
                f"span {span:.4g} rad, 360 degrees or more (a beam would be seen twice)"
            )
        mr = self.max_range_m
        if not isinstance(mr, (int, float, np.integer, np.floating)) or not mr > 0:
            raise FeaturesError(f"Scan.max_range_m: must be a positive number or inf, got {mr!r}")
        object.__setattr__(self, "max_range_m", float(mr))
        raw64 = np.array(raw, dtype=np.float64)  # copy: the scan owns its data
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(raw64) | (raw64 <= 0.0) | (raw64 >= self.max_range_m)
        clean = raw64.copy()
        clean[bad] = np.nan
        object.__setattr__(self, "raw_ranges_m", _readonly(raw64))
        object.__setattr__(self, "ranges_m", _readonly(clean))

    raw_ranges_m: np.ndarray = field(init=False, repr=False)

    @property
    def n_beams(self) -> int:
        return int(self.ranges_m.shape[0])

    @cached_property
    def angles_rad(self) -> np.ndarray:
        """(B,) bearing of each beam in the laser frame."""
        return _readonly(self.angle_min_rad + self.angle_increment_rad * np.arange(self.n_beams))

    @cached_property
    def valid(self) -> np.ndarray:
        """(B,) bool, True where the beam has a return."""
        return _readonly(np.isfinite(self.ranges_m))

    @cached_property
    def points_xy(self) -> np.ndarray:
        """(B, 2) Cartesian points in the laser frame; NaN rows for no return."""
        a = self.angles_rad
        return _readonly(np.stack([self.ranges_m * np.cos(a), self.ranges_m * np.sin(a)], axis=1))


class _BeamRun:
    """Mixin for features fitted to the consecutive beams first_beam..last_beam.

    On a full 360 deg scan a run may cross the scan's seam: then last_beam >= n_beams and the
    beams are first_beam..last_beam modulo n_beams (`beam_indices` does the modulo).
    """

    first_beam: int
    last_beam: int
    n_beams: int

    @property
    def beam_indices(self) -> np.ndarray:
        idx = np.arange(self.first_beam, self.last_beam + 1)
        return idx % self.n_beams if self.n_beams > 0 else idx


@dataclass(frozen=True, eq=False)
class Segment(_BeamRun):
    """A maximal run of beams the planar EKF kept together.

    first_beam, last_beam: inclusive beam indices; the segment's beams are first..last.
    kind: "line", "circle" or "clutter" (the classification).
    mean_innovation_m, mean_innovation_var_m2: eq. (5)'s v-bar and s-bar (NaN with < 3 beams).
    """

    first_beam: int
    last_beam: int
    kind: SegmentKind
    mean_innovation_m: float
    mean_innovation_var_m2: float
    n_beams: int = 0

    @property
    def size(self) -> int:
        """Number of beams in the segment."""
        return self.last_beam - self.first_beam + 1


@dataclass(frozen=True, eq=False)
class Circle(_BeamRun):
    """A circle (tree trunk, pillar) in the laser frame.

    center_xy: (2,) metres. radius_m: metres.
    cov: (3, 3) covariance of (x0, y0, r), m^2.
    first_beam, last_beam: inclusive beam indices of the arc it was fitted to.
    rms_residual_m: RMS orthogonal distance of the arc's points to the circle.
    """

    center_xy: np.ndarray
    radius_m: float
    cov: np.ndarray
    first_beam: int
    last_beam: int
    rms_residual_m: float
    n_beams: int = 0

    @property
    def range_m(self) -> float:
        return float(np.hypot(self.center_xy[0], self.center_xy[1]))

    @property
    def bearing_rad(self) -> float:
        return float(np.arctan2(self.center_xy[1], self.center_xy[0]))


@dataclass(frozen=True, eq=False)
class Line(_BeamRun):
    """An infinite line x cos(alpha) + y sin(alpha) = rho fitted to a segment, in the laser frame.

    alpha_rad: direction of the line's normal, in (-pi, pi]. rho_m: distance from the laser, >= 0.
    cov: (2, 2) covariance of (alpha, rho).
    endpoints_xy: (2, 2) the first and last points projected onto the line, metres.
    """

    alpha_rad: float
    rho_m: float
    cov: np.ndarray
    endpoints_xy: np.ndarray
    first_beam: int
    last_beam: int
    rms_residual_m: float
    n_beams: int = 0

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.endpoints_xy[1] - self.endpoints_xy[0]))


@dataclass(frozen=True, eq=False)
class Edge:
    """An occluding edge (breakpoint) as a point feature, in the laser frame.

    point_xy: (2,) the end point of the nearer segment at a depth discontinuity, metres.
    cov: (2, 2) its covariance, m^2 (range noise along the beam, a uniform one-beam bearing
        uncertainty across it).
    beam: index of the beam that measured it.
    """

    point_xy: np.ndarray
    cov: np.ndarray
    beam: int

    @property
    def beam_indices(self) -> np.ndarray:
        return np.array([self.beam])


@dataclass(frozen=True, eq=False)
class Features:
    """Everything extracted from one scan, stored as arrays; per-feature objects on demand.

    Struct-of-arrays keeps extraction fast (no Python object per feature); the `circles`,
    `lines`, `edges`, `segments` and `clutter` properties build the dataclasses when asked.

    stamp_s: the scan's time.
    circle_params: (C, 3) [x0, y0, r], m. circle_cov: (C, 3, 3). circle_beams: (C, 2) inclusive
        [first, last] beam. circle_rms_m: (C,).
    line_params: (L, 2) [alpha, rho]. line_cov: (L, 2, 2). line_endpoints: (L, 2, 2).
        line_beams: (L, 2). line_rms_m: (L,).
    edge_xy: (E, 2). edge_cov: (E, 2, 2). edge_beam: (E,).
    segment_beams: (S, 2) inclusive [first, last]. segment_kind: (S,) 0 clutter, 1 line,
        2 circle. segment_innov: (S, 2) eq. (5)'s [v-bar, s-bar].
    method: the circle-fitting method that produced it.
    n_beams: beams in the scan. Beam runs ([first, last] above) have 0 <= first < n_beams; on a
        full 360 deg scan a run that crosses the seam has last >= n_beams and means the beams
        first..last modulo n_beams (`Features.beams(first, last)`).
    """

    stamp_s: float
    circle_params: np.ndarray
    circle_cov: np.ndarray
    circle_beams: np.ndarray
    circle_rms_m: np.ndarray
    line_params: np.ndarray
    line_cov: np.ndarray
    line_endpoints: np.ndarray
    line_beams: np.ndarray
    line_rms_m: np.ndarray
    edge_xy: np.ndarray
    edge_cov: np.ndarray
    edge_beam: np.ndarray
    segment_beams: np.ndarray
    segment_kind: np.ndarray
    segment_innov: np.ndarray
    method: str
    n_beams: int = 0

    def beams(self, first: int, last: int) -> np.ndarray:
        """Beam indices of the run first..last (modulo n_beams across a 360 deg scan's seam)."""
        idx = np.arange(first, last + 1)
        return idx % self.n_beams if self.n_beams > 0 else idx

    @classmethod
    def empty(cls, stamp_s: float = 0.0, method: str = "", n_beams: int = 0) -> Features:
        z = np.zeros
        return cls(
            stamp_s=stamp_s,
            circle_params=z((0, 3)),
            circle_cov=z((0, 3, 3)),
            circle_beams=z((0, 2), np.int64),
            circle_rms_m=z(0),
            line_params=z((0, 2)),
            line_cov=z((0, 2, 2)),
            line_endpoints=z((0, 2, 2)),
            line_beams=z((0, 2), np.int64),
            line_rms_m=z(0),
            edge_xy=z((0, 2)),
            edge_cov=z((0, 2, 2)),
            edge_beam=z(0, np.int64),
            segment_beams=z((0, 2), np.int64),
            segment_kind=z(0, np.int64),
            segment_innov=z((0, 2)),
            method=method,
            n_beams=n_beams,
        )

    @property
    def n_circles(self) -> int:
        return int(self.circle_params.shape[0])

    @cached_property
    def circles(self) -> tuple[Circle, ...]:
        return tuple(
            Circle(
                center_xy=p[:2].copy(),
                radius_m=float(p[2]),
                cov=c,
                first_beam=int(b[0]),
                last_beam=int(b[1]),
                rms_residual_m=float(s),
                n_beams=self.n_beams,
            )
            for p, c, b, s in zip(
                self.circle_params, self.circle_cov, self.circle_beams, self.circle_rms_m
            )
        )

    @cached_property
    def lines(self) -> tuple[Line, ...]:
        return tuple(
            Line(
                alpha_rad=float(p[0]),
                rho_m=float(p[1]),
                cov=c,
                endpoints_xy=e,
                first_beam=int(b[0]),
                last_beam=int(b[1]),
                rms_residual_m=float(s),
                n_beams=self.n_beams,
            )
            for p, c, e, b, s in zip(
                self.line_params,
                self.line_cov,
                self.line_endpoints,
                self.line_beams,
                self.line_rms_m,
            )
        )

    @cached_property
    def edges(self) -> tuple[Edge, ...]:
        return tuple(
            Edge(p.copy(), c, int(b))
            for p, c, b in zip(self.edge_xy, self.edge_cov, self.edge_beam)
        )

    @cached_property
    def segments(self) -> tuple[Segment, ...]:
        return tuple(
            Segment(
                first_beam=int(b[0]),
                last_beam=int(b[1]),
                kind=KIND_NAMES[int(k)],
                mean_innovation_m=float(v[0]),
                mean_innovation_var_m2=float(v[1]),
                n_beams=self.n_beams,
            )
            for b, k, v in zip(self.segment_beams, self.segment_kind, self.segment_innov)
        )

    @property
    def clutter(self) -> tuple[Segment, ...]:
        """Segments that are neither lines nor circles."""
        return tuple(s for s in self.segments if s.kind == "clutter")
