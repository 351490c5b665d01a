"""A reference map: the landmark positions a run's map is scored against (`trunkslam slam
--reference-map FILE`), in the run's world frame, metres.

Format: CSV, one landmark per line, two columns `x,y` (m). An optional first line of column
names (cells that are not numbers, e.g. `x_m,y_m`), blank lines and lines starting with `#` are
skipped. Anything else (a line with other than two columns, a cell that is not a number, NaN or
an infinite coordinate, no landmark at all) raises `DataError` naming the file and the line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from experiments.errors import DataError

__all__ = ["read_reference_map"]


def read_reference_map(path: Path | str) -> np.ndarray:
    """(T, 2) the reference landmarks of the CSV at `path`; see the module doc."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such reference map (expected a CSV of x,y in metres)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise DataError(f"{path}: not a text file (expected a CSV of x,y in metres)") from e
    points: list[tuple[float, float]] = []
    named = False  # the column names were read
    for n, line in enumerate(text.splitlines(), start=1):
        cells = [c.strip() for c in line.split(",")]
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if len(cells) != 2:
            raise DataError(
                f"{path} line {n}: expected 2 columns (x,y in metres), got {len(cells)}"
            )
        values = [_number(c) for c in cells]
        if None in values:
            if not (points or named) and all(v is None for v in values):
                named = True
                continue  # the column names
            bad = cells[values.index(None)]
            raise DataError(f"{path} line {n}: {bad!r} is not a number")
        if not all(math.isfinite(v) for v in values):
            raise DataError(f"{path} line {n}: NaN or infinite coordinate ({line.strip()})")
        points.append((values[0], values[1]))
    if not points:
        raise DataError(f"{path}: no landmark (expected lines of x,y in metres)")
    return np.array(points, dtype=np.float64)


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None
