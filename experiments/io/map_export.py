"""A run's map for GIS and plotting tools (`trunkslam export-map`): GeoJSON or CSV, the frame
named, each landmark's covariance as an ellipse polygon at a chosen confidence.

Frames:
- "local": the run's world frame, metres (x, y). With a GPS start that is the GPS's local
  frame, x east and y north of the sequence's GPS origin (`experiments.io.rosbag.local_metres`).
  GeoJSON (RFC 7946) expects longitude and latitude: such a file names its frame in a foreign
  member `frame` and is for plotting tools, not for a map on the globe.
- "wgs84": longitude and latitude (degrees), from the local frame by the exact inverse of the
  rosbag converter's projection about the GNSS origin (lat0, lon0, h0) the fixes were measured
  about. Only a run that started from GPS is in that frame.

An ellipse at confidence q is {p : (p - c)^T C^-1 (p - c) <= chi2_2(q)} (chi2_2(q) = -2 ln(1 - q)
for two degrees of freedom), drawn as `vertices` points counter-clockwise (RFC 7946's exterior
ring), closed.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.results import MAP_COLUMNS
from experiments.io.rosbag import WGS84_A_M, WGS84_E2

__all__ = [
    "MAP_FRAMES",
    "MapRows",
    "ellipse_polygon",
    "map_export_csv",
    "map_geojson",
    "read_map_csv",
    "wgs84_from_local",
]

MAP_FRAMES = ("local", "wgs84")


@dataclass(frozen=True, eq=False)
class MapRows:
    """A map.csv (`experiments.io.results.MAP_COLUMNS`): L landmarks. id (L,), xy (L, 2) m,
    radius_m (L,) (NaN: none), cov (L, 2, 2) m^2, first_scan (L,), n_obs (L,)."""

    id: np.ndarray
    xy: np.ndarray
    radius_m: np.ndarray
    cov: np.ndarray
    first_scan: np.ndarray
    n_obs: np.ndarray


def read_map_csv(path: Path | str) -> MapRows:
    """The map of a run's map.csv (or map_smoothed.csv); `DataError` naming the file and the
    line for other columns, a cell that is not a number, a non-finite centre or covariance, or
    a covariance that is not positive semi-definite."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such map file (a run folder holds map.csv)")
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or tuple(lines[0].split(",")) != MAP_COLUMNS:
        raise DataError(f"{path} line 1: expected the columns {','.join(MAP_COLUMNS)}")
    rows = []
    for n, line in enumerate(lines[1:], start=2):
        cells = line.split(",")
        if len(cells) != len(MAP_COLUMNS):
            raise DataError(f"{path} line {n}: {len(cells)} cells, {len(MAP_COLUMNS)} expected")
        try:
            v = [float(c) if c else math.nan for c in cells]
        except ValueError as e:
            raise DataError(f"{path} line {n}: {e}") from None
        if not all(math.isfinite(x) for i, x in enumerate(v) if i != 3):
            raise DataError(f"{path} line {n}: NaN or infinite value")
        C = np.array([[v[4], v[5]], [v[5], v[6]]])
        if np.linalg.eigvalsh(C).min() < -1e-12 * max(abs(v[4]), abs(v[6]), 1e-300):
            raise DataError(f"{path} line {n}: the covariance is not positive semi-definite")
        rows.append(v)
    a = np.array(rows, dtype=np.float64).reshape(-1, len(MAP_COLUMNS))
    return MapRows(
        id=a[:, 0].astype(np.int64),
        xy=a[:, 1:3],
        radius_m=a[:, 3],
        cov=np.stack([a[:, [4, 5]], a[:, [5, 6]]], axis=1),
        first_scan=a[:, 7].astype(np.int64),
        n_obs=a[:, 8].astype(np.int64),
    )


def wgs84_from_local(xy, origin: tuple[float, ...]) -> np.ndarray:
    """(K, 2) [longitude, latitude] degrees of local points xy (K, 2) [x east, y north] m about
    origin (lat0, lon0[, h0 m]): the exact inverse of `experiments.io.rosbag.local_metres`."""
    lat0, lon0 = float(origin[0]), float(origin[1])
    h0 = float(origin[2]) if len(origin) > 2 else 0.0
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    w = 1.0 - WGS84_E2 * math.sin(math.radians(lat0)) ** 2
    n0 = WGS84_A_M / math.sqrt(w)
    m0 = n0 * (1.0 - WGS84_E2) / w
    lat = lat0 + np.degrees(p[:, 1] / (m0 + h0))
    lon = lon0 + np.degrees(p[:, 0] / ((n0 + h0) * math.cos(math.radians(lat0))))
    lon = (lon + 180.0) % 360.0 - 180.0
    return np.stack([lon, lat], axis=-1)


def check_origin(origin) -> tuple[float, ...]:
    """(lat, lon[, h]) in range: latitude within +-89 degrees (the projection divides by its
    cosine), longitude within +-180, altitude finite."""
    o = tuple(float(v) for v in origin)
    if len(o) not in (2, 3) or not all(math.isfinite(v) for v in o):
        raise DataError(f"origin: expected LAT,LON[,ALT] as finite numbers, got {origin!r}")
    if not (abs(o[0]) <= 89.0 and abs(o[1]) <= 180.0):
        raise DataError(f"origin: latitude within +-89 and longitude within +-180, got {o[:2]}")
    return o


def _axes(cov: np.ndarray, confidence: float):
    """(semi-major m, semi-minor m, major axis angle rad from x, counter-clockwise)."""
    s = -2.0 * math.log(1.0 - confidence)  # chi2 quantile, 2 dof
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 0.0)
    angle = math.atan2(V[1, 1], V[0, 1])
    return math.sqrt(s * w[1]), math.sqrt(s * w[0]), angle


def ellipse_polygon(xy, cov, confidence: float = 0.95, vertices: int = 36) -> np.ndarray:
    """(vertices + 1, 2) the closed ring of the covariance ellipse of `cov` (2, 2) about xy at
    `confidence`, counter-clockwise from the major axis."""
    a, b, angle = _axes(np.asarray(cov, dtype=np.float64), confidence)
    t = np.linspace(0.0, 2.0 * math.pi, vertices + 1)
    t[-1] = 0.0  # the ring closes exactly
    c, s = math.cos(angle), math.sin(angle)
    u, v = a * np.cos(t), b * np.sin(t)
    return np.stack([xy[0] + c * u - s * v, xy[1] + s * u + c * v], axis=-1)


def _check(confidence: float, vertices: int, frame: str, origin) -> None:
    if not 0.0 < confidence < 1.0:
        raise DataError(f"confidence: expected a number in (0, 1), got {confidence!r}")
    if isinstance(vertices, bool) or not isinstance(vertices, int) or not 3 <= vertices <= 1000:
        raise DataError(f"vertices: expected an integer in [3, 1000], got {vertices!r}")
    if frame not in MAP_FRAMES:
        raise DataError(f"frame: expected one of {list(MAP_FRAMES)}, got {frame!r}")
    if (frame == "wgs84") != (origin is not None):
        raise DataError("frame: 'wgs84' needs the GNSS origin, 'local' takes none")


def map_geojson(
    m: MapRows,
    frame: str = "local",
    confidence: float = 0.95,
    vertices: int = 36,
    origin=None,
    about: dict | None = None,
) -> str:
    """A GeoJSON FeatureCollection: per landmark a Point (its centre) and a Polygon (its
    ellipse), with id, radius, covariance, ellipse axes, first scan and sightings as
    properties; `frame` and `about` (e.g. the run) as foreign members."""
    _check(confidence, vertices, frame, origin)

    def place(p: np.ndarray) -> list:
        q = wgs84_from_local(p, origin) if frame == "wgs84" else np.asarray(p).reshape(-1, 2)
        return [[round(float(x), 10), round(float(y), 10)] for x, y in q]

    features = []
    for j in range(m.id.size):
        a, b, angle = _axes(m.cov[j], confidence)
        props = {
            "id": int(m.id[j]),
            "x_m": float(m.xy[j, 0]),
            "y_m": float(m.xy[j, 1]),
            "radius_m": None if not math.isfinite(m.radius_m[j]) else float(m.radius_m[j]),
            "var_x_m2": float(m.cov[j, 0, 0]),
            "cov_xy_m2": float(m.cov[j, 0, 1]),
            "var_y_m2": float(m.cov[j, 1, 1]),
            "first_scan": int(m.first_scan[j]),
            "n_obs": int(m.n_obs[j]),
        }
        centre = {"type": "Point", "coordinates": place(m.xy[j])[0]}
        features.append({"type": "Feature", "geometry": centre, "properties": props})
        ring = place(ellipse_polygon(m.xy[j], m.cov[j], confidence, vertices))
        ellipse = {
            "id": int(m.id[j]),
            "confidence": confidence,
            "semi_major_m": a,
            "semi_minor_m": b,
            "orientation_deg": math.degrees(angle),
        }
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": ellipse,
            }
        )
    doc = {"type": "FeatureCollection", "frame": _frame_doc(frame, origin), **(about or {})}
    doc["features"] = features
    return json.dumps(doc, indent=1) + "\n"


def _frame_doc(frame: str, origin) -> dict:
    if frame == "wgs84":
        return {
            "name": "wgs84",
            "coordinates": "longitude, latitude (degrees)",
            "gnss_origin_lat_lon_alt": list(origin) + [0.0] * (3 - len(origin)),
        }
    return {"name": "local", "coordinates": "x, y (metres, the run's world frame)"}


def map_export_csv(m: MapRows, frame: str = "local", confidence: float = 0.95, origin=None) -> str:
    """One landmark per line: id, x_m, y_m (the run's frame; with frame "wgs84" also lon_deg,
    lat_deg), radius_m, the ellipse at `confidence` (semi-major and semi-minor m, orientation
    of the major axis in degrees from x, counter-clockwise), first_scan, n_obs."""
    _check(confidence, 3, frame, origin)
    head = ["id", "x_m", "y_m"] + (["lon_deg", "lat_deg"] if frame == "wgs84" else [])
    head += ["radius_m", "semi_major_m", "semi_minor_m", "orientation_deg", "confidence"]
    lines = [",".join([*head, "first_scan", "n_obs"])]
    lonlat = wgs84_from_local(m.xy, origin) if frame == "wgs84" else None
    for j in range(m.id.size):
        a, b, angle = _axes(m.cov[j], confidence)
        cells = [str(int(m.id[j])), f"{m.xy[j, 0]:.6f}", f"{m.xy[j, 1]:.6f}"]
        if lonlat is not None:
            cells += [f"{lonlat[j, 0]:.10f}", f"{lonlat[j, 1]:.10f}"]
        r = m.radius_m[j]
        cells += [f"{r:.4f}" if math.isfinite(r) else "", f"{a:.6g}", f"{b:.6g}"]
        cells += [f"{math.degrees(angle):.4f}", f"{confidence:g}"]
        cells += [str(int(m.first_scan[j])), str(int(m.n_obs[j]))]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"
