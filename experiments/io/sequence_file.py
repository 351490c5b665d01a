"""The sequence file: one run as one `.npz` (datasets/FORMAT.md), read and written.

`save_sequence` writes a `slam.Sequence` atomically; `load_sequence` reads one back and says
what is wrong with a bad file (`DataError`, naming the file and the variable). The run's data
type and its validation live in `slam.sequence`.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import fields
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.npz import Var, check_method_name, read_npz
from experiments.io.writers import write_atomic
from slam import Sequence, SlamError
from slam.sequence import OPTIONAL, REQUIRED

__all__ = ["SCHEMA", "load_sequence", "save_sequence"]

log = logging.getLogger(__name__)

# The format's schema (datasets/FORMAT.md): each variable's kind and dimensions, checked before
# any value is read; N scans of B beams, D detections, M odometry samples, G GPS fixes, T truth
# poses, L landmarks. The values (finite, in range, sorted) are `slam.Sequence`'s to check.
SCHEMA: dict[str, Var] = {
    "scan_t": Var("float", ("N",), required=True),
    "scan_angle_min": Var("float", (), required=True),
    "scan_angle_increment": Var("float", (), required=True),
    "laser_pose": Var("float", (3,), required=True),
    "scan_ranges": Var("float", ("N", "B")),
    "scan_n_beams": Var("float", ()),
    "scan_max_range": Var("float", ()),
    "det_scan": Var("int", ("D",)),
    "det_range": Var("float", ("D",)),
    "det_bearing": Var("float", ("D",)),
    "det_radius": Var("float", ("D",)),
    "det_cov": Var("float", ("D", 2, 2)),
    "det_method": Var("str"),
    "odo_t": Var("float", ("M",)),
    "odo_speed": Var("float", ("M",)),
    "odo_steer": Var("float", ("M",)),
    "odo_yaw_rate": Var("float", ("M",)),
    "odo_pose": Var("float", ("M", 3)),
    "vehicle": Var("str"),
    "gps_t": Var("float", ("G",)),
    "gps_xy": Var("float", ("G", 2)),
    "gps_pose": Var("float", (3,)),
    "gps_origin": Var("float", (3,)),
    "truth_t": Var("float", ("T",)),
    "truth_pose": Var("float", ("T", 3)),
    "truth_landmarks": Var("float", ("L", 3)),
    "scan_labels": Var("int", ("N", "B")),
    "name": Var("str"),
}
assert set(SCHEMA) == set(REQUIRED) | set(OPTIONAL)


def save_sequence(seq: Sequence, path: str | os.PathLike) -> Path:
    """Write `seq` to one compressed `.npz` at `path` (exactly that name), atomically.

    The file is written to a temporary file in the same folder and renamed over `path`, so a
    crash never leaves a half-written sequence. Absent optional fields are not stored; `vehicle`
    is stored as a JSON string. Returns the path written.
    """
    if not isinstance(seq, Sequence):
        raise DataError(f"seq: expected a slam.Sequence, got {type(seq).__name__}")
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for f in fields(seq):
        v = getattr(seq, f.name)
        if v is None:
            continue
        if f.name == "vehicle":
            arrays["vehicle"] = np.array(json.dumps(v.to_dict(), sort_keys=True))
        elif f.name == "name":
            arrays["name"] = np.array(v)
        else:
            arrays[f.name] = np.asarray(v)
    return write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays))


def load_sequence(path: str | os.PathLike) -> Sequence:
    """Read a sequence file written by `save_sequence` (format: datasets/FORMAT.md).

    Raises `DataError` naming the file and the problem: missing file, not an `.npz` or corrupt,
    a required variable missing, wrong shapes, unsorted times, inconsistent variables. Optional
    variables that are absent become None; unknown variables are ignored with a logged warning.
    """
    arrays = read_npz(path, SCHEMA, "sequence file", across=False, logger=log)
    values: dict[str, object] = {}
    for k, a in arrays.items():
        values[k] = str(a) if SCHEMA[k].kind == "str" else a
    if "det_method" in values:  # (names the detections' noise model)
        check_method_name(path, "det_method", values["det_method"])
    try:
        return Sequence(**values)
    except SlamError as exc:
        raise DataError(f"{path}: {exc}") from None
