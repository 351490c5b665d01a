"""`trunkslam export-map RUN --format geojson|csv`: a run's map for GIS and plotting tools
(`experiments.io.map_export`)."""

from __future__ import annotations

import json
from pathlib import Path

from experiments.errors import DataError
from experiments.io.map_export import check_origin, map_export_csv, map_geojson, read_map_csv
from experiments.io.outputs import check_run_export
from experiments.io.writers import write_atomic

__all__ = ["MAP_FORMATS", "export_map"]

MAP_FORMATS = ("geojson", "csv")


def export_map(
    run_dir: Path | str,
    out: Path | str,
    fmt: str = "geojson",
    *,
    confidence: float = 0.95,
    vertices: int = 36,
    frame: str = "local",
    origin=None,
    smoothed: bool = False,
) -> dict:
    """Write the map of the `trunkslam slam` run in `run_dir` (its map.csv, or with `smoothed`
    the smoother's map_smoothed.csv) to `out` as GeoJSON or CSV: in the run's frame, metres
    (frame "local"), or in WGS84 (frame "wgs84", which only a run that started from GPS is
    in) about `origin` (lat, lon[, alt]: the GNSS origin of the sequence's GPS), by default
    the run's input sequence's `gps_origin` (the rosbag converter keeps it). Ellipses at
    `confidence` with `vertices` points. Returns what was written (file, frame, landmarks).
    Atomic; a symlink at `out` or a place inside the run is refused."""
    if fmt not in MAP_FORMATS:
        raise DataError(f"--format: expected one of {list(MAP_FORMATS)}, got {fmt!r}")
    run_dir, out = check_run_export("export-map", run_dir, out)
    name = "map_smoothed.csv" if smoothed else "map.csv"
    m = read_map_csv(run_dir / name)
    about = {"run": str(run_dir), "map": name}
    if frame not in ("local", "wgs84"):
        raise DataError(f"--frame: expected 'local' or 'wgs84', got {frame!r}")
    if origin is not None and frame != "wgs84":
        raise DataError("--origin: the origin of the WGS84 frame; give --frame wgs84 with it")
    if frame == "wgs84":
        summary = _summary(run_dir)
        start = summary.get("start")
        if start != "gps":
            raise DataError(
                f"--frame wgs84: the run in {run_dir} started from {start!r}, not from GPS: its "
                "frame is not the GPS's, so it has no place on the globe"
            )
        origin = check_origin(origin if origin is not None else _sequence_origin(summary))
    if fmt == "geojson":
        text = map_geojson(m, frame, confidence, vertices, origin, about=about)
    else:
        text = map_export_csv(m, frame, confidence, origin)
    write_atomic(out, text)
    return {"out": str(out), "frame": frame, "landmarks": int(m.id.size), "map": name}


def _summary(run_dir: Path) -> dict:
    try:
        return dict(json.loads((run_dir / "summary.json").read_text()))
    except (OSError, ValueError, TypeError) as e:
        raise DataError(
            f"{run_dir}/summary.json: not readable ({e}); without it the run's frame is unknown"
        ) from None


def _sequence_origin(summary: dict):
    """The gps_origin of the run's input sequence (`summary["input"]`)."""
    from experiments.io.sequence_file import load_sequence

    where = summary.get("input")
    try:
        seq = load_sequence(where)
    except (OSError, DataError, TypeError, ValueError) as e:
        raise DataError(
            f"--frame wgs84: the run's sequence {where} is not readable ({e}); give its GNSS "
            "origin with --origin LAT,LON[,ALT]"
        ) from None
    if seq.gps_origin is None:
        raise DataError(
            f"--frame wgs84: the run's sequence {where} has no gps_origin (its GPS is in local "
            "metres of an unknown origin); give it with --origin LAT,LON[,ALT]"
        )
    return tuple(float(v) for v in seq.gps_origin)
