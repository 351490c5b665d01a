"""The in-memory run (`Sequence`) and its file format (one `.npz`, see datasets/FORMAT.md).

`save_sequence` writes a `Sequence` atomically; `load_sequence` reads one back and says what is
wrong with a bad file (`DataError`, naming the file and the variable).
"""

from __future__ import annotations

import json
import logging
import math
import os
import zipfile
import zlib
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.export import write_atomic
from features.types import Scan

__all__ = [
    "Sequence",
    "save_sequence",
    "load_sequence",
    "VEHICLE_MODELS",
    "REQUIRED",
    "OPTIONAL",
    "NO_RETURN_LABEL",
    "MIXED_LABEL",
]

log = logging.getLogger(__name__)

# Vehicle models and their parameters: name -> (required keys, optional keys with defaults).
VEHICLE_MODELS: dict[str, tuple[tuple[str, ...], dict[str, float]]] = {
    "ackermann": (("wheelbase_m",), {"encoder_offset_m": 0.0}),
}

REQUIRED = ("scan_t", "scan_ranges", "scan_angle_min", "scan_angle_increment", "laser_pose")
OPTIONAL = (
    "scan_max_range",
    "odo_t",
    "odo_speed",
    "odo_steer",
    "vehicle",
    "gps_t",
    "gps_xy",
    "gps_pose",
    "truth_t",
    "truth_pose",
    "truth_landmarks",
    "scan_labels",
    "name",
)
_SCALARS = ("scan_angle_min", "scan_angle_increment", "scan_max_range")
NO_RETURN_LABEL = -1  # scan_labels: the beam hit nothing (or nothing within range)
MIXED_LABEL = -2  # scan_labels: a mixed return between two objects at a depth jump


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _float_array(name: str, value, ndim: int, width: int | None = None) -> np.ndarray:
    """A read-only float64 copy of `value` with `ndim` dimensions (and `width` columns)."""
    try:
        a = np.array(value)
    except Exception as exc:  # ragged lists and the like
        raise DataError(f"Sequence.{name}: cannot be read as an array ({exc})") from None
    if a.dtype.kind not in "fiu":
        raise DataError(f"Sequence.{name}: expected numbers, got dtype {a.dtype}")
    expected = {1: "(n,)", 2: f"(n, {width})" if width else "(n, m)"}.get(ndim, f"{ndim}-D")
    if a.ndim != ndim or (width is not None and a.shape[-1] != width):
        raise DataError(f"Sequence.{name}: expected shape {expected}, got {a.shape}")
    return _readonly(a.astype(np.float64))


def _times(name: str, value) -> np.ndarray:
    t = _float_array(name, value, 1)
    if not np.all(np.isfinite(t)):
        raise DataError(
            f"Sequence.{name}: times must be finite (first bad index "
            f"{int(np.flatnonzero(~np.isfinite(t))[0])})"
        )
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"Sequence.{name}: times must be strictly increasing; {name}[{i + 1}] = "
            f"{t[i + 1]!r} s follows {name}[{i}] = {t[i]!r} s ({bad.size} such step(s))"
        )
    return t


def _timed_pair(t_name: str, t, v_name: str, v, width: int) -> list[tuple[str, np.ndarray]]:
    """Validate optional times t (N,) with values v (N, width) that must come together;
    returns [(t_name, t), (v_name, v)] checked and converted, or [] when both are absent."""
    if (t is None) != (v is None):
        missing = v_name if v is None else t_name
        raise DataError(f"Sequence.{missing}: {t_name} and {v_name} go together; {missing} missing")
    if t is None:
        return []
    times = _times(t_name, t)
    vals = _float_array(v_name, v, 2, width=width)
    if vals.shape[0] != times.shape[0]:
        raise DataError(
            f"Sequence.{v_name}: expected shape ({times.shape[0]}, {width}) like {t_name}, "
            f"got {vals.shape}"
        )
    _finite(v_name, vals)
    return [(t_name, times), (v_name, vals)]


def _finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        raise DataError(f"Sequence.{name}: values must be finite (NaN or inf found)")


def _scalar(name: str, value, *, allow_inf: bool = False) -> float:
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise DataError(f"Sequence.{name}: expected one number, got shape {value.shape}")
        value = value.reshape(()).item()
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise DataError(f"Sequence.{name}: expected a number, got {value!r}")
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise DataError(f"Sequence.{name}: must be finite, got {v!r}")
    return v


def _pose(name: str, value) -> np.ndarray:
    p = _float_array(name, value, 1)
    if p.shape != (3,):
        raise DataError(f"Sequence.{name}: expected shape (3,) [x, y, theta], got {p.shape}")
    _finite(name, p)
    return p


def _vehicle(value) -> dict:
    if isinstance(value, (str, bytes)):
        try:
            value = json.loads(value)
        except json.JSONDecodeError as exc:
            raise DataError(f"Sequence.vehicle: not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise DataError(f"Sequence.vehicle: expected a dict (JSON object), got {value!r}")
    model = value.get("model")
    if model not in VEHICLE_MODELS:
        raise DataError(
            f"Sequence.vehicle: unknown or missing 'model' {model!r}; "
            f"known: {sorted(VEHICLE_MODELS)}"
        )
    required, optional = VEHICLE_MODELS[model]
    unknown = sorted(set(value) - {"model", *required, *optional})
    if unknown:
        raise DataError(f"Sequence.vehicle: unknown key(s) {unknown} for model {model!r}")
    out: dict = {"model": model}
    for key in required:
        if key not in value:
            raise DataError(f"Sequence.vehicle: model {model!r} needs {key!r}")
    for key in (*required, *optional):
        v = value.get(key, optional.get(key))
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise DataError(f"Sequence.vehicle[{key!r}]: must be a finite number, got {v!r}")
        out[key] = float(v)
    if out.get("wheelbase_m", 1.0) <= 0:
        raise DataError(f"Sequence.vehicle['wheelbase_m']: must be > 0, got {out['wheelbase_m']}")
    return out


@dataclass(frozen=True, eq=False)
class Sequence:
    """One run: laser scans plus whatever odometry, GPS and truth came with them.

    Frames: the vehicle frame has its origin at the rear-axle centre, x forward, y left; the laser
    frame is the laser's (0 rad = its x-axis, CCW positive); the world frame is the run's fixed
    frame (GPS, truth). Arrays are stored as read-only float64 (scan_labels: int64) copies.

    Required
      scan_t: (N,) s, strictly increasing.
      scan_ranges: (N, B) m, NaN = no return.
      scan_angle_min, scan_angle_increment: rad, laser frame (0 = laser x-axis, CCW positive);
        increment > 0 and the B beams span less than 360 degrees.
      laser_pose: (3,) [x, y, theta] of the laser in the vehicle frame (rear-axle centre).
    Optional (None when absent)
      scan_max_range: m; readings at or beyond it are no return (inf when absent).
      odo_t (M,) s, odo_speed (M,) m/s as measured by the encoder, odo_steer (M,) rad front wheel
        (|steer| <= pi/2); all three or none.
      vehicle: dict, e.g. {"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
        (a JSON string is accepted and parsed; encoder_offset_m defaults to 0).
      gps_t (G,) s, gps_xy (G, 2) m world, both or neither; gps_pose (3,) antenna in the vehicle
        frame (the laser's position when absent).
      truth_t (T,) s, truth_pose (T, 3) [x, y, theta] of the rear-axle centre, world frame, both
        or neither.
      truth_landmarks (L, 3) [x, y, r] m, world frame, r > 0.
      scan_labels (N, B) int: id of the object each beam hit (landmark k of truth_landmarks has
        label k; other objects have labels >= L), NO_RETURN_LABEL (-1) for none, MIXED_LABEL (-2)
        for a mixed return between two objects at a depth jump.
      name: free text describing the run.
    Construction validates everything and raises `DataError` (a `ValueError`) naming the field.
    """

    scan_t: np.ndarray
    scan_ranges: np.ndarray
    scan_angle_min: float
    scan_angle_increment: float
    laser_pose: np.ndarray
    scan_max_range: float = float("inf")
    odo_t: np.ndarray | None = None
    odo_speed: np.ndarray | None = None
    odo_steer: np.ndarray | None = None
    vehicle: dict | None = None
    gps_t: np.ndarray | None = None
    gps_xy: np.ndarray | None = None
    gps_pose: np.ndarray | None = None
    truth_t: np.ndarray | None = None
    truth_pose: np.ndarray | None = None
    truth_landmarks: np.ndarray | None = None
    scan_labels: np.ndarray | None = None
    name: str = ""

    def __post_init__(self) -> None:
        put = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731

        # Scans.
        scan_t = _times("scan_t", self.scan_t)
        n = scan_t.shape[0]
        if n == 0:
            raise DataError("Sequence.scan_t: no scans (length 0)")
        ranges = _float_array("scan_ranges", self.scan_ranges, 2)
        if ranges.shape[0] != n or ranges.shape[1] == 0:
            raise DataError(
                f"Sequence.scan_ranges: expected shape (N, B) with N = len(scan_t) = {n} and "
                f"B >= 1, got {ranges.shape}"
            )
        put("scan_t", scan_t)
        put("scan_ranges", ranges)
        amin = _scalar("scan_angle_min", self.scan_angle_min)
        inc = _scalar("scan_angle_increment", self.scan_angle_increment)
        if inc <= 0:
            raise DataError(f"Sequence.scan_angle_increment: must be > 0 rad, got {inc!r}")
        n_beams = ranges.shape[1]
        if (n_beams - 1) * inc >= 2 * math.pi:
            raise DataError(
                f"Sequence.scan_angle_increment: {n_beams} beams of {inc!r} rad span "
                f"{(n_beams - 1) * inc:.4g} rad, 360 degrees or more (degrees instead of radians?)"
            )
        put("scan_angle_min", amin)
        put("scan_angle_increment", inc)
        mr = _scalar("scan_max_range", self.scan_max_range, allow_inf=True)
        if mr <= 0:
            raise DataError(f"Sequence.scan_max_range: must be > 0 m (or inf), got {mr!r}")
        put("scan_max_range", mr)
        put("laser_pose", _pose("laser_pose", self.laser_pose))

        # Odometry: all three or none.
        odo = {k: getattr(self, k) for k in ("odo_t", "odo_speed", "odo_steer")}
        present = [k for k, v in odo.items() if v is not None]
        if present and len(present) != 3:
            missing = sorted(set(odo) - set(present))
            raise DataError(
                f"Sequence.{missing[0]}: odometry needs odo_t, odo_speed and odo_steer together; "
                f"missing {missing}"
            )
        if present:
            odo_t = _times("odo_t", odo["odo_t"])
            put("odo_t", odo_t)
            for k in ("odo_speed", "odo_steer"):
                a = _float_array(k, odo[k], 1)
                if a.shape != odo_t.shape:
                    raise DataError(
                        f"Sequence.{k}: expected shape {odo_t.shape} like odo_t, got {a.shape}"
                    )
                _finite(k, a)
                put(k, a)
            if np.any(np.abs(self.odo_steer) > math.pi / 2):
                raise DataError(
                    f"Sequence.odo_steer: front-wheel angles must be within +-pi/2 rad, found "
                    f"{float(np.max(np.abs(self.odo_steer))):.4g} (degrees instead of radians?)"
                )
        if self.vehicle is not None:
            put("vehicle", _vehicle(self.vehicle))

        # GPS.
        for name, v in _timed_pair("gps_t", self.gps_t, "gps_xy", self.gps_xy, 2):
            put(name, v)
        if self.gps_pose is not None:
            put("gps_pose", _pose("gps_pose", self.gps_pose))

        # Truth.
        for name, v in _timed_pair("truth_t", self.truth_t, "truth_pose", self.truth_pose, 3):
            put(name, v)
        if self.truth_landmarks is not None:
            lm = _float_array("truth_landmarks", self.truth_landmarks, 2, width=3)
            _finite("truth_landmarks", lm)
            if np.any(lm[:, 2] <= 0):
                i = int(np.flatnonzero(lm[:, 2] <= 0)[0])
                raise DataError(
                    f"Sequence.truth_landmarks: radius r must be > 0 m, row {i} has {lm[i, 2]!r}"
                )
            put("truth_landmarks", lm)
        if self.scan_labels is not None:
            lab = np.asarray(self.scan_labels)
            if lab.dtype.kind not in "iu":
                raise DataError(f"Sequence.scan_labels: expected integers, got dtype {lab.dtype}")
            if lab.shape != ranges.shape:
                raise DataError(
                    f"Sequence.scan_labels: expected shape {ranges.shape} like scan_ranges, "
                    f"got {lab.shape}"
                )
            if lab.size and lab.min() < MIXED_LABEL:
                raise DataError(
                    f"Sequence.scan_labels: labels must be >= {MIXED_LABEL} (-1 = no return, "
                    f"-2 = mixed return), found {int(lab.min())}"
                )
            put("scan_labels", _readonly(lab.astype(np.int64)))
        if not isinstance(self.name, str):
            raise DataError(f"Sequence.name: expected a string, got {self.name!r}")

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])

    @property
    def n_beams(self) -> int:
        return int(self.scan_ranges.shape[1])

    def scan(self, k: int) -> Scan:
        """Scan k as a `features.Scan`."""
        return Scan(
            self.scan_ranges[k],
            self.scan_angle_min,
            self.scan_angle_increment,
            stamp_s=float(self.scan_t[k]),
            max_range_m=self.scan_max_range,
        )


def save_sequence(seq: Sequence, path: str | os.PathLike) -> Path:
    """Write `seq` to one compressed `.npz` at `path` (exactly that name), atomically.

    The file is written to a temporary file in the same folder and renamed over `path`, so a
    crash never leaves a half-written sequence. Absent optional fields are not stored; `vehicle`
    is stored as a JSON string. Returns the path written.
    """
    if not isinstance(seq, Sequence):
        raise ValueError(f"seq: expected a Sequence, got {type(seq).__name__}")
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for f in fields(seq):
        v = getattr(seq, f.name)
        if v is None:
            continue
        if f.name == "vehicle":
            arrays["vehicle"] = np.array(json.dumps(v, sort_keys=True))
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
    path = Path(path)
    if not path.exists():
        raise DataError(f"sequence file not found: {path}")
    if not path.is_file():
        raise DataError(f"sequence file {path} is not a file")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise DataError(f"{path}: cannot be read ({exc})") from None
    if magic.startswith(b"\x93NUMPY"):
        raise DataError(f"{path}: is a single .npy array, not an .npz sequence file")
    if not magic.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # zip: member, or empty
        raise DataError(f"{path}: not a readable .npz sequence file (not a zip archive)")
    try:
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path}: not a readable .npz sequence file ({exc})") from None
    values: dict[str, object] = {}
    with npz:
        keys = set(npz.files)
        missing = [k for k in REQUIRED if k not in keys]
        if missing:
            raise DataError(
                f"{path}: missing required variable(s) {missing} (has: {sorted(keys)}); "
                "see datasets/FORMAT.md"
            )
        unknown = sorted(keys - set(REQUIRED) - set(OPTIONAL))
        if unknown:
            log.warning("%s: ignoring unknown variable(s) %s", path, unknown)
        for k in (*REQUIRED, *OPTIONAL):
            if k not in keys:
                continue
            try:
                a = npz[k]
            except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
                raise DataError(
                    f"{path}: variable {k!r} is corrupt or unreadable ({exc})"
                ) from None
            if k in ("vehicle", "name"):
                if a.dtype.kind != "U" or a.ndim != 0:
                    raise DataError(
                        f"{path}: variable {k!r} must be a string, got dtype {a.dtype} "
                        f"shape {a.shape}"
                    )
                values[k] = str(a)
            elif k in _SCALARS:
                if a.size != 1:
                    raise DataError(
                        f"{path}: variable {k!r} must be one number, got shape {a.shape}"
                    )
                values[k] = a
            else:
                values[k] = a
    try:
        return Sequence(**values)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None
