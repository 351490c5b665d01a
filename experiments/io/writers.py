"""Writing results: the features JSON of `trunkslam extract`, Markdown/CSV tables, atomic files."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from experiments.errors import DataError
from features.types import Features

__all__ = [
    "FEATURES_SCHEMA",
    "dumps_json",
    "features_to_dict",
    "json_types",
    "markdown_table",
    "write_atomic",
    "write_table",
]

FEATURES_SCHEMA = "trunkslam.features/1"


def _f(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def features_to_dict(f: Features, scan_index: int) -> dict:
    """One scan's features as plain JSON types (laser frame, metres, radians)."""
    return {
        "scan": scan_index,
        "stamp_s": f.stamp_s,
        "method": f.method,
        "circles": [
            {
                "center_xy": [_f(p[0]), _f(p[1])],
                "radius_m": _f(p[2]),
                "cov": np.asarray(c).round(12).tolist(),
                "beams": [int(b[0]), int(b[1])],
                "rms_residual_m": _f(s),
            }
            for p, c, b, s in zip(f.circle_params, f.circle_cov, f.circle_beams, f.circle_rms_m)
        ],
        "lines": [
            {
                "alpha_rad": _f(p[0]),
                "rho_m": _f(p[1]),
                "cov": np.asarray(c).round(12).tolist(),
                "endpoints_xy": np.asarray(e).round(6).tolist(),
                "beams": [int(b[0]), int(b[1])],
                "rms_residual_m": _f(s),
            }
            for p, c, e, b, s in zip(
                f.line_params, f.line_cov, f.line_endpoints, f.line_beams, f.line_rms_m
            )
        ],
        "edges": [
            {
                "point_xy": [_f(p[0]), _f(p[1])],
                "cov": np.asarray(c).round(12).tolist(),
                "beam": int(b),
            }
            for p, c, b in zip(f.edge_xy, f.edge_cov, f.edge_beam)
        ],
        "clutter": [
            {"beams": [int(b[0]), int(b[1])]}
            for b, k in zip(f.segment_beams, f.segment_kind)
            if k == 0
        ],
    }


def write_atomic(path: Path | str, data: str | bytes | Callable[[BinaryIO], object]) -> Path:
    """Write `data` (text, bytes, or a function writing to a binary file) to `path` atomically:
    into a temporary file in the same folder, flushed to disk, made readable by all (0644), then
    renamed over `path`; a crash never leaves a half-written file. The folder must exist."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise DataError(f"cannot write {path}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data.encode() if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes files owner-only
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _cell(v) -> str:
    if isinstance(v, float):
        if not math.isfinite(v):
            return "n/a"
        return f"{v:.4g}" if abs(v) < 1e4 else f"{v:.3e}"
    return str(v)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(_cell(v) for v in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


def write_table(stem: Path, header, rows, title: str = "", notes: str = "") -> list[Path]:
    """Write `stem`.md (title, table, notes) and `stem`.csv; returns both paths."""
    md = (f"# {title}\n\n" if title else "") + markdown_table(header, rows)
    if notes:
        md += "\n" + notes.strip() + "\n"
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    stem = Path(stem)
    return [
        write_atomic(stem.with_suffix(".md"), md),
        write_atomic(stem.with_suffix(".csv"), buf.getvalue()),
    ]


def dumps_json(obj) -> str:
    """`obj` as indented JSON; NaN and inf are refused (convert them first, `json_types`)."""
    return json.dumps(obj, indent=1, allow_nan=False)


def json_types(obj):
    """Dicts, lists, tuples and numpy scalars as plain JSON types; non-finite floats as strings."""
    if isinstance(obj, dict):
        return {k: json_types(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_types(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    return obj
