"""Trunk cross-sections that are not circles: an ellipse with lobes, as a closed polygon.

A real trunk is not a circle, so the centre a circle fit gives depends on the side it is seen
from, and it stays nearly the same while the view changes little (a pass). The simulator's
trunks are circles by default (their fitted centres then have white errors); `TrunkShape`
gives every trunk of a scene the outline

    rho(phi) = (a cos phi, b sin phi) * (1 + lobe_amplitude * cos(lobes * (phi - phase)))

in the trunk's own frame (phi the ellipse's parameter, a / b = aspect), turned by the trunk's
orientation, as a polygon of `n_vertices` vertices. Each trunk draws its orientation (uniform
in [0, pi)) and its lobes' phase (uniform in [0, 2 pi)) from `seed`, in the scene's order of
trunks. The polygon is scaled so that its area is the circle's, pi r^2, and moved so that its
centroid is the circle's centre: the truth tables (`Scene.truth_landmarks`, [x, y, r]) keep the
centre (the cross-section's centroid) and r (its equal-area radius).

With 180 vertices a polygon departs from the smooth curve by r (1 - cos(pi / 180)), 0.05 mm
at r = 0.35 m, far below the laser's 1 cm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from experiments.errors import ConfigError

__all__ = ["TrunkShape", "polygon_area_centroid", "trunk_outline"]

MAX_ASPECT = 4.0
MAX_LOBES = 32
MAX_LOBE_AMPLITUDE = 0.5
VERTEX_RANGE = (16, 4096)


def _number(owner: str, name: str, v: Any) -> float:
    ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
    if not ok or not math.isfinite(v):
        raise ConfigError(f"{owner}.{name}: must be a finite number, got {v!r}")
    return float(v)


def _whole(owner: str, name: str, v: Any, low: int, high: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not low <= v <= high:
        raise ConfigError(f"{owner}.{name}: must be a whole number in [{low}, {high}], got {v!r}")
    return int(v)


@dataclass(frozen=True)
class TrunkShape:
    """The cross-section of every trunk of a scene (module doc).

    aspect: long over short axis of the ellipse, in [1, 4] (1: no ovality).
    lobes: number of lobes, 0 .. 32 (0: none); lobe_amplitude: their relative depth, in
        [0, 0.5] (must be 0 when lobes is 0).
    seed: draws each trunk's orientation and lobe phase (a whole number >= 0).
    n_vertices: vertices of the polygon, 16 .. 4096.
    `is_circle`: aspect 1 and no lobes; such a shape leaves the trunks exact circles.
    """

    aspect: float = 1.0
    lobes: int = 0
    lobe_amplitude: float = 0.0
    seed: int = 0
    n_vertices: int = 180

    def __post_init__(self) -> None:
        owner = "TrunkShape"
        aspect = _number(owner, "aspect", self.aspect)
        if not 1.0 <= aspect <= MAX_ASPECT:
            raise ConfigError(f"{owner}.aspect: must be in [1, {MAX_ASPECT:g}], got {aspect!r}")
        object.__setattr__(self, "aspect", aspect)
        object.__setattr__(self, "lobes", _whole(owner, "lobes", self.lobes, 0, MAX_LOBES))
        amp = _number(owner, "lobe_amplitude", self.lobe_amplitude)
        if not 0.0 <= amp <= MAX_LOBE_AMPLITUDE:
            raise ConfigError(
                f"{owner}.lobe_amplitude: must be in [0, {MAX_LOBE_AMPLITUDE:g}], got {amp!r}"
            )
        if amp > 0 and self.lobes == 0:
            raise ConfigError(f"{owner}.lobe_amplitude: {amp:g} needs lobes >= 1, got lobes 0")
        object.__setattr__(self, "lobe_amplitude", amp)
        object.__setattr__(self, "seed", _whole(owner, "seed", self.seed, 0, 2**63 - 1))
        object.__setattr__(
            self, "n_vertices", _whole(owner, "n_vertices", self.n_vertices, *VERTEX_RANGE)
        )

    @property
    def is_circle(self) -> bool:
        return self.aspect == 1.0 and self.lobe_amplitude == 0.0

    def draws(self, n_trunks: int) -> np.ndarray:
        """(n_trunks, 2) [orientation in [0, pi), lobe phase in [0, 2 pi)], rad, per trunk."""
        rng = np.random.default_rng(self.seed)
        u = rng.random((n_trunks, 2))
        return u * np.array([math.pi, 2.0 * math.pi])


def polygon_area_centroid(pts: np.ndarray) -> tuple[float, np.ndarray]:
    """(signed area m^2, centroid (2,) m) of the closed polygon `pts` (P, 2)."""
    x, y = pts[:, 0], pts[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * float(np.sum(cross))
    c = np.array([np.sum((x + xn) * cross), np.sum((y + yn) * cross)]) / (6.0 * area)
    return area, c


def trunk_outline(
    center_xy: np.ndarray,
    radius_m: float,
    shape: TrunkShape,
    orientation_rad: float,
    phase_rad: float,
) -> np.ndarray:
    """(n_vertices, 2) counter-clockwise vertices of one trunk's outline, m, world frame: area
    pi radius_m^2, centroid `center_xy` (module doc)."""
    phi = 2.0 * math.pi * np.arange(shape.n_vertices) / shape.n_vertices
    a = math.sqrt(shape.aspect)
    scale = 1.0 + shape.lobe_amplitude * np.cos(shape.lobes * (phi - phase_rad))
    local = np.stack([a * np.cos(phi), np.sin(phi) / a], axis=1) * scale[:, None]
    c, s = math.cos(orientation_rad), math.sin(orientation_rad)
    pts = local @ np.array([[c, s], [-s, c]])
    area, centroid = polygon_area_centroid(pts)
    pts = (pts - centroid) * (radius_m * math.sqrt(math.pi / area))
    return pts + np.asarray(center_xy, dtype=np.float64)
