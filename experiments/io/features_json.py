"""Reading the features JSON that `trunkslam extract` writes (schema trunkslam.features/1), so a
run's circles, from our extractors or anyone's, can drive `trunkslam slam`.

Only the circles are read (centre, radius, covariance, beams, residual, all laser frame); lines,
edges and clutter are not used by the filter. `null` values (non-finite numbers, as the format
says) become NaN. Every problem raises `DataError` naming the file, the scan and the field.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.npz import check_input_file
from experiments.io.paths import read_text_file
from experiments.io.schema import AnyTable, ListOf, Number, String, Table, check, parse_json
from experiments.io.writers import FEATURES_SCHEMA
from features.types import Features
from slam.sequence import MAX_ANGLE_RAD, MAX_BEAMS, MAX_COORDINATE_M, MAX_TIME_S

__all__ = ["SCHEMA", "load_features_json"]

# The format (docs/formats.md), every key checked before any number is used. Beam indices may
# reach 2 B - 1 (a run crossing the seam of a 360 deg scan); `load_features_json` checks them
# against the sequence's B.
_XY_OR_NULL = ListOf(Number(nullable=True, low=-MAX_COORDINATE_M, high=MAX_COORDINATE_M), 2)
_VAR = Number(nullable=True)  # a degenerate fit's variances may be huge (1e300): kept as they are
_COV2, _COV3 = ListOf(ListOf(_VAR, 2), 2), ListOf(ListOf(_VAR, 3), 3)
_BEAM = Number(integer=True, low=0, high=2 * MAX_BEAMS)
_BEAMS = ListOf(_BEAM, 2)
_RMS = Number(nullable=True, low=0, high=MAX_COORDINATE_M)
_CIRCLE = Table(
    {"center_xy": _XY_OR_NULL, "radius_m": Number(nullable=True, low=0, high=MAX_COORDINATE_M),
     "cov": _COV3, "beams": _BEAMS},
    {"rms_residual_m": _RMS},
)  # fmt: skip
_LINE = Table(
    {"alpha_rad": Number(nullable=True, low=-MAX_ANGLE_RAD, high=MAX_ANGLE_RAD),
     "rho_m": Number(nullable=True, low=-MAX_COORDINATE_M, high=MAX_COORDINATE_M),
     "cov": _COV2, "endpoints_xy": ListOf(_XY_OR_NULL, 2), "beams": _BEAMS},
    {"rms_residual_m": _RMS},
)  # fmt: skip
_EDGE = Table({"point_xy": _XY_OR_NULL, "cov": _COV2, "beam": _BEAM})
_SCAN = Table(
    {"scan": Number(integer=True, low=0, high=2**53), "circles": ListOf(_CIRCLE)},
    {"stamp_s": Number(nullable=True, low=-MAX_TIME_S, high=MAX_TIME_S), "method": String(),
     "lines": ListOf(_LINE), "edges": ListOf(_EDGE), "clutter": ListOf(Table({"beams": _BEAMS}))},
)  # fmt: skip
SCHEMA = Table(
    {"schema": String(choices=[FEATURES_SCHEMA]), "method": String(), "scans": ListOf(_SCAN)},
    {"input": String(nonempty=False), "params": AnyTable(), "frame": String(choices=["laser"])},
)


MAX_FEATURES_BYTES = 1 << 30  # a features JSON is read whole: at most 1 GiB


def load_features_json(path: str | Path, n_scans: int, n_beams: int = 0) -> list[Features]:
    """One `Features` per scan (circles only) from a features JSON with exactly n_scans scans
    numbered 0..n_scans - 1 (the scans of the sequence it will drive, of n_beams beams; 0: not
    checked). The whole file is checked against `SCHEMA` first."""
    path = check_input_file(Path(path), "features file")
    text = read_text_file(path, "features file", MAX_FEATURES_BYTES)
    doc = check(SCHEMA, parse_json(text, str(path), "features JSON file"), str(path))
    method, scans = doc["method"], doc["scans"]
    if len(scans) != n_scans:
        raise DataError(f"{path}: scans: has {len(scans)} scans, the sequence {n_scans}")
    out = []
    for k, s in enumerate(scans):
        where = f"{path}: scans[{k}]"
        if s["scan"] != k:
            raise DataError(f"{where}.scan: expected scan number {k}, got {s['scan']}")
        if s.get("method", method) != method:
            raise DataError(f"{where}.method: {s['method']!r}, the file's method is {method!r}")
        _check_beams(s, where, n_beams)
        circles = s["circles"]
        n = len(circles)
        p = np.array([[*c["center_xy"], c["radius_m"]] for c in circles], float).reshape(n, 3)
        if not np.all(np.isfinite(p[:, :2])):
            i = int(np.flatnonzero(~np.isfinite(p[:, :2]).all(axis=1))[0])
            raise DataError(f"{where}: a circle centre is not finite (circles[{i}].center_xy)")
        f = Features.empty(s.get("stamp_s", math.nan), method, n_beams)
        out.append(
            dataclasses.replace(
                f,
                circle_params=p,
                circle_cov=np.array([c["cov"] for c in circles], float).reshape(n, 3, 3),
                circle_beams=np.array([c["beams"] for c in circles], np.int64).reshape(n, 2),
                circle_rms_m=np.array(
                    [c.get("rms_residual_m", math.nan) for c in circles], float
                ).reshape(n),
            )
        )
    return out


def _check_beams(scan: dict, where: str, n_beams: int) -> None:
    """Every [first, last] in order and within the scan's beams (last < 2 B at the seam)."""
    for kind in ("circles", "lines", "clutter"):
        for i, c in enumerate(scan.get(kind, [])):
            first, last = c["beams"]
            if first > last or (n_beams and (first >= n_beams or last >= 2 * n_beams)):
                raise DataError(
                    f"{where}.{kind}[{i}].beams: [{first}, {last}] is not a run of the "
                    f"sequence's {n_beams} beams"
                )
    for i, e in enumerate(scan.get("edges", [])):
        if n_beams and e["beam"] >= n_beams:
            raise DataError(
                f"{where}.edges[{i}].beam: {e['beam']} is not a beam of the sequence's {n_beams}"
            )
