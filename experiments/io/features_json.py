"""Reading the features JSON that `trunkslam extract` writes (schema trunkslam.features/1), so a
run's circles, from our extractors or anyone's, can drive `trunkslam slam`.

Only the circles are read (centre, radius, covariance, beams, residual, all laser frame); lines,
edges and clutter are not used by the filter. `null` values (non-finite numbers, as the format
says) become NaN. Every problem raises `DataError` naming the file, the scan and the field.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.paths import read_text_file
from experiments.io.writers import FEATURES_SCHEMA
from features.types import Features

__all__ = ["load_features_json"]


def _num(v, where: str) -> float:
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise DataError(f"{where}: expected a number or null, got {v!r}")
    return float(v)


def load_features_json(path: str | Path, n_scans: int, n_beams: int = 0) -> list[Features]:
    """One `Features` per scan (circles only) from a features JSON with exactly n_scans scans
    numbered 0..n_scans - 1 (the scans of the sequence it will drive)."""
    path = Path(path)
    text = read_text_file(path, "features file")
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise DataError(f"{path}: not a features JSON file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("schema") != FEATURES_SCHEMA:
        raise DataError(f"{path}: not a features file (schema should be {FEATURES_SCHEMA!r})")
    scans = doc.get("scans")
    method = doc.get("method")
    if not isinstance(scans, list) or not isinstance(method, str):
        raise DataError(f"{path}: needs a 'method' string and a 'scans' list")
    if len(scans) != n_scans:
        raise DataError(f"{path}: has {len(scans)} scans, the sequence {n_scans}")
    out = []
    for k, s in enumerate(scans):
        where = f"{path}: scans[{k}]"
        if not isinstance(s, dict) or s.get("scan") != k or not isinstance(s.get("circles"), list):
            raise DataError(f"{where}: expected scan number {k} with a 'circles' list")
        params, cov, beams, rms = [], [], [], []
        for i, c in enumerate(s["circles"]):
            w = f"{where}.circles[{i}]"
            try:
                xy, r = c["center_xy"], c["radius_m"]
                cv, b = c["cov"], c["beams"]
            except (KeyError, TypeError):
                raise DataError(f"{w}: needs center_xy, radius_m, cov and beams") from None
            if not isinstance(xy, list) or len(xy) != 2:
                raise DataError(f"{w}.center_xy: expected [x, y]")
            if not (isinstance(cv, list) and len(cv) == 3 and all(len(row) == 3 for row in cv)):
                raise DataError(f"{w}.cov: expected a 3 x 3 list")
            if not (isinstance(b, list) and len(b) == 2 and all(isinstance(x, int) for x in b)):
                raise DataError(f"{w}.beams: expected [first, last] integers")
            x, y = _num(xy[0], f"{w}.center_xy"), _num(xy[1], f"{w}.center_xy")
            params.append([x, y, _num(r, f"{w}.radius_m")])
            cov.append([[_num(x, f"{w}.cov") for x in row] for row in cv])
            beams.append(b)
            rms.append(_num(c.get("rms_residual_m"), f"{w}.rms_residual_m"))
        n = len(params)
        p = np.array(params, dtype=np.float64).reshape(n, 3)
        if not np.all(np.isfinite(p[:, :2])):
            raise DataError(f"{where}: a circle centre is not finite")
        f = Features.empty(_num(s.get("stamp_s"), f"{where}.stamp_s"), method, n_beams)
        out.append(
            dataclasses.replace(
                f,
                circle_params=p,
                circle_cov=np.array(cov, dtype=np.float64).reshape(n, 3, 3),
                circle_beams=np.array(beams, dtype=np.int64).reshape(n, 2),
                circle_rms_m=np.array(rms, dtype=np.float64).reshape(n),
            )
        )
    return out
