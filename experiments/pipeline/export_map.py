"""`trunkslam export-map RUN --format geojson|csv`: a run's map for GIS and plotting tools
(`experiments.io.map_export`)."""

from __future__ import annotations

import json
from pathlib import Path

from experiments.errors import DataError
from experiments.io.map_export import check_origin, map_export_csv, map_geojson, read_map_csv
from experiments.io.outputs import check_outputs
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
    origin=None,
    smoothed: bool = False,
) -> dict:
    """Write the map of the `trunkslam slam` run in `run_dir` (its map.csv, or with `smoothed`
    the smoother's map_smoothed.csv) to `out` as GeoJSON or CSV: in the run's frame, metres,
    or with `origin` (lat, lon[, alt]: the GNSS origin of the sequence's GPS) in WGS84, which
    only a run that started from GPS is in. Ellipses at `confidence` with `vertices` points.
    Returns what was written (file, frame, landmarks). Atomic; a symlink at `out` or a place
    inside the run is refused."""
    if fmt not in MAP_FORMATS:
        raise DataError(f"--format: expected one of {list(MAP_FORMATS)}, got {fmt!r}")
    run_dir, out = Path(run_dir), Path(out)
    if not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a folder (expected the output folder of trunkslam slam)")
    check_outputs("export-map", inputs=[run_dir], files={"--out": out})
    name = "map_smoothed.csv" if smoothed else "map.csv"
    m = read_map_csv(run_dir / name)
    frame = "local"
    about = {"run": str(run_dir), "map": name}
    if origin is not None:
        origin = check_origin(origin)
        start = _start(run_dir)
        if start != "gps":
            raise DataError(
                f"--origin: the run in {run_dir} started from {start!r}, not from GPS: its frame "
                "is not the GPS's, so it has no place on the globe"
            )
        frame = "wgs84"
    if fmt == "geojson":
        text = map_geojson(m, frame, confidence, vertices, origin, about=about)
    else:
        text = map_export_csv(m, frame, confidence, origin)
    write_atomic(out, text)
    return {"out": str(out), "frame": frame, "landmarks": int(m.id.size), "map": name}


def _start(run_dir: Path) -> str:
    try:
        return str(json.loads((run_dir / "summary.json").read_text())["start"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DataError(
            f"{run_dir}/summary.json: not readable ({e}); without it the run's frame is unknown"
        ) from None
