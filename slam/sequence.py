"""The run `slam.run_slam` consumes (`Sequence`): scans, odometry, GPS and truth, validated.

The fields are flat, as the file stores them; the sub-records `Sequence.odometry`, `.gps`,
`.truth` and the `Vehicle` give them typed names (None where the sequence has none).

Construction checks every field and raises `SlamError` (a `ValueError`) naming it, so a
`Sequence` that exists is one the rest of the package can trust. The file format (one `.npz`,
datasets/FORMAT.md) is read and written by `experiments.io.sequence_file`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from features.types import Scan
from slam.errors import SlamError
from slam.validators import finite, float_array, readonly, times

__all__ = [
    "MAX_ANGLE_RAD",
    "MAX_BEAMS",
    "MAX_COORDINATE_M",
    "MAX_TIME_S",
    "MAX_VARIANCE",
    "MAX_YAW_RATE_RAD_S",
    "MIXED_LABEL",
    "ODOMETRY_KINDS",
    "NO_RETURN_LABEL",
    "OPTIONAL",
    "REQUIRED",
    "VEHICLE_MODELS",
    "GpsTrack",
    "OdometryLog",
    "Sequence",
    "Truth",
    "Vehicle",
]

# Vehicle models and their parameters: name -> (required keys, optional keys with defaults).
VEHICLE_MODELS: dict[str, tuple[tuple[str, ...], dict[str, float]]] = {
    "ackermann": (("wheelbase_m",), {"encoder_offset_m": 0.0}),
    "unicycle": ((), {}),
    "pose-increment": ((), {}),
}
# The odometry of each vehicle model: the fields it needs besides odo_t (datasets/FORMAT.md).
ODOMETRY_KINDS: dict[str, tuple[str, ...]] = {
    "ackermann": ("odo_t", "odo_speed", "odo_steer"),  # encoder speed, front-wheel angle
    "unicycle": ("odo_t", "odo_speed", "odo_yaw_rate"),  # speed and yaw rate (a twist)
    "pose-increment": ("odo_t", "odo_pose"),  # the robot's own integrated odometry poses
}
ODOMETRY_FIELDS = ("odo_t", "odo_speed", "odo_steer", "odo_yaw_rate", "odo_pose")
MAX_YAW_RATE_RAD_S = 20.0  # about 3 turns a second: beyond, the unit is wrong (deg/s?)
# Limits on values, each stated in datasets/FORMAT.md: beyond them a value is a wrong unit or a
# corrupt file, and the arithmetic of the run (squares of positions, sines of angles) loses
# every digit or overflows.
MAX_BEAMS = 100_000  # beams of a scan (2D lasers have up to a few thousand)
MAX_COORDINATE_M = 1e8  # |x|, |y|, ranges, radii: 100,000 km (UTM northings are below 1e7 m)
MAX_ANGLE_RAD = 1e4  # |theta| of a pose, bearings (an unwrapped heading of 1,600 turns)
MAX_TIME_S = 1e12  # |t|: 31,700 years in seconds (nanosecond stamps, 1.7e18, are refused)
MAX_VARIANCE = 1e16  # a variance (m^2, rad^2): a sigma of 1e8

REQUIRED = ("scan_t", "scan_angle_min", "scan_angle_increment", "laser_pose")
OPTIONAL = (
    "scan_ranges",
    "scan_n_beams",
    "scan_max_range",
    "det_scan",
    "det_range",
    "det_bearing",
    "det_radius",
    "det_cov",
    "det_method",
    "odo_t",
    "odo_speed",
    "odo_steer",
    "odo_yaw_rate",
    "odo_pose",
    "vehicle",
    "gps_t",
    "gps_xy",
    "gps_pose",
    "gps_origin",
    "truth_t",
    "truth_pose",
    "truth_landmarks",
    "scan_labels",
    "name",
)
DETECTIONS = ("det_scan", "det_range", "det_bearing", "det_radius")
NO_RETURN_LABEL = -1  # scan_labels: the beam hit nothing (or nothing within range)
MIXED_LABEL = -2  # scan_labels: a mixed return between two objects at a depth jump


def _arr(name: str, value, ndim: int, width: int | None = None) -> np.ndarray:
    return float_array(f"Sequence.{name}", value, ndim, width)


def _t(name: str, value) -> np.ndarray:
    t = times(f"Sequence.{name}", value)
    _bounded(name, t, MAX_TIME_S, "s (seconds; nanoseconds?)")
    return t


def _fin(name: str, a: np.ndarray) -> None:
    finite(f"Sequence.{name}", a)


def _bounded(name: str, a: np.ndarray, bound: float, unit: str) -> None:
    """Every finite value of `a` within +-bound (`SlamError` naming the first one beyond)."""
    with np.errstate(invalid="ignore"):
        bad = np.abs(a) > bound
    if np.any(bad):
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        where = f"[{', '.join(str(int(j)) for j in i)}]" if a.ndim else ""
        raise SlamError(
            f"Sequence.{name}{where}: {float(a[i]):.6g} is beyond the limit of +-{bound:g} {unit}"
        )


def _poses(name: str, a: np.ndarray) -> None:
    """Positions and headings of an (..., 3) array [x, y, theta] within the limits."""
    _bounded(name, a[..., :2], MAX_COORDINATE_M, "m")
    _bounded(name, a[..., 2:], MAX_ANGLE_RAD, "rad")


def _timed_pair(t_name: str, t, v_name: str, v, width: int) -> list[tuple[str, np.ndarray]]:
    """Validate optional times t (N,) with values v (N, width) that must come together;
    returns [(t_name, t), (v_name, v)] checked and converted, or [] when both are absent."""
    if (t is None) != (v is None):
        missing = v_name if v is None else t_name
        raise SlamError(f"Sequence.{missing}: {t_name} and {v_name} go together; {missing} missing")
    if t is None:
        return []
    t_arr = _t(t_name, t)
    if t_arr.size == 0:
        raise SlamError(f"Sequence.{t_name}: empty; leave {t_name} and {v_name} out instead")
    vals = _arr(v_name, v, 2, width=width)
    if vals.shape[0] != t_arr.shape[0]:
        raise SlamError(
            f"Sequence.{v_name}: expected shape ({t_arr.shape[0]}, {width}) like {t_name}, "
            f"got {vals.shape}"
        )
    _fin(v_name, vals)
    if width == 3:
        _poses(v_name, vals)
    else:
        _bounded(v_name, vals, MAX_COORDINATE_M, "m")
    return [(t_name, t_arr), (v_name, vals)]


def _scalar(name: str, value, *, allow_inf: bool = False) -> float:
    if isinstance(value, np.ndarray):
        if value.size != 1:
            raise SlamError(f"Sequence.{name}: expected one number, got shape {value.shape}")
        value = value.reshape(()).item()
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SlamError(f"Sequence.{name}: expected a number, got {value!r}")
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise SlamError(f"Sequence.{name}: must be finite, got {v!r}")
    return v


def _gnss_origin(value, has_gps: bool) -> np.ndarray:
    """gps_origin (3,) [lat deg, lon deg, alt m]: within +-89 deg (the local projection divides
    by the cosine of the latitude), +-180 deg and +-1e5 m; only beside GPS fixes."""
    o = _arr("gps_origin", value, 1)
    if o.shape != (3,):
        raise SlamError(f"Sequence.gps_origin: expected shape (3,) [lat, lon, alt], got {o.shape}")
    _fin("gps_origin", o)
    if not (abs(o[0]) <= 89.0 and abs(o[1]) <= 180.0 and abs(o[2]) <= 1e5):
        raise SlamError(
            "Sequence.gps_origin: latitude within +-89 deg, longitude within +-180 deg and "
            f"altitude within +-1e5 m, got {o.tolist()}"
        )
    if not has_gps:
        raise SlamError("Sequence.gps_origin: the origin of GPS fixes, but there is no gps_t")
    return o


def _pose(name: str, value) -> np.ndarray:
    p = _arr(name, value, 1)
    if p.shape != (3,):
        raise SlamError(f"Sequence.{name}: expected shape (3,) [x, y, theta], got {p.shape}")
    _fin(name, p)
    _poses(name, p)
    return p


MAX_ODO_SPEED_MPS = 100.0  # |odo_speed| above this is a unit error, not a ground vehicle
# |odo_steer| limit: a car's front wheels turn far less (Victoria Park: 0.6 rad); near pi/2 the
# turn rate v tan(alpha) / L and its Jacobian blow up and the filter's covariances with them
MAX_STEER_RAD = 1.4


def _check_readings(seq) -> None:
    """The odometry readings in physical ranges (a wrong unit is the usual cause otherwise)."""
    limits = (
        ("odo_steer", MAX_STEER_RAD, "front-wheel angles must be within +-{} rad (80 degrees)",
         "degrees instead of radians?"),
        ("odo_speed", MAX_ODO_SPEED_MPS, "must be within +-{:g} m/s (a ground vehicle)",
         "wrong unit?"),
        ("odo_yaw_rate", MAX_YAW_RATE_RAD_S, "must be within +-{:g} rad/s", "degrees per second?"),
    )  # fmt: skip
    for name, limit, rule, hint in limits:
        a = getattr(seq, name)
        if a is not None and np.any(np.abs(a) > limit):
            k = int(np.argmax(np.abs(a)))
            raise SlamError(
                f"Sequence.{name}: {rule.format(limit)}, found {float(a[k]):.6g} at sample {k} "
                f"({hint})"
            )


def json_int(text: str) -> int | float:
    """`parse_int` for json.loads: an integer too long for a float is read as inf (and then
    refused as not finite), not as a 400-digit int that overflows later."""
    return int(text) if len(text) < 300 else float(text)


def _number(v) -> float | None:
    """v as a finite float, or None when it is not a finite real number."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


@dataclass(frozen=True)
class Vehicle:
    """The car a sequence was driven with (datasets/FORMAT.md `vehicle`; the file stores it as a
    JSON object).

    model: "ackermann" (a front-steered car moving about its rear-axle centre; odometry: encoder
    speed and steering angle), "unicycle" (odometry: speed and yaw rate, a differential-drive
    robot's or any twist) or "pose-increment" (odometry: the robot's own integrated poses).
    wheelbase_m: L > 0, rear axle to front axle (ackermann only). encoder_offset_m: H, the speed
    encoder's lateral offset from the rear-axle centre (0: at the centre; v_c = v_e / (1 - H/L
    tan alpha); ackermann only).
    """

    model: str
    wheelbase_m: float | None = None
    encoder_offset_m: float = 0.0

    @classmethod
    def of(cls, value) -> Vehicle:
        """A `Vehicle` from itself, a dict or its JSON text, checked (`SlamError` naming the
        key)."""
        if isinstance(value, Vehicle):
            return value
        return cls(**_vehicle(value))

    def to_dict(self) -> dict:
        """The JSON object of the file format."""
        if self.model != "ackermann":
            return {"model": self.model}
        return {"model": self.model, "wheelbase_m": self.wheelbase_m,
                "encoder_offset_m": self.encoder_offset_m}  # fmt: skip


@dataclass(frozen=True, eq=False)
class OdometryLog:
    """A sequence's odometry samples (zero-order hold between samples): t_s (M,) s, and as its
    vehicle's kind has them, speed_mps (M,) as the encoder reads it, steer_rad (M,) the front
    wheel's angle, yaw_rate_rad_s (M,), pose (M, 3) integrated odometry poses (None: absent)."""

    t_s: np.ndarray
    speed_mps: np.ndarray | None
    steer_rad: np.ndarray | None
    yaw_rate_rad_s: np.ndarray | None = None
    pose: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class GpsTrack:
    """A sequence's GPS fixes: t_s (G,) s, xy_m (G, 2) world frame, T_vehicle_antenna (3,) the
    antenna in the vehicle frame (None: at the laser)."""

    t_s: np.ndarray
    xy_m: np.ndarray
    T_vehicle_antenna: np.ndarray | None


@dataclass(frozen=True, eq=False)
class Truth:
    """A simulated sequence's truth: t_s (T,) s, pose_world_rear_axle (T, 3) [x, y, theta],
    landmarks_xyr (L, 3) [x, y, r] world frame (None when not given)."""

    t_s: np.ndarray
    pose_world_rear_axle: np.ndarray
    landmarks_xyr: np.ndarray | None


def _vehicle(value) -> dict:
    if isinstance(value, Vehicle):
        value = value.to_dict()
    if isinstance(value, (str, bytes)):
        try:
            value = json.loads(value, parse_int=json_int)
        except json.JSONDecodeError as exc:
            raise SlamError(f"Sequence.vehicle: not valid JSON ({exc})") from None
        except RecursionError:
            raise SlamError("Sequence.vehicle: JSON nested too deeply to be a vehicle") from None
    if not isinstance(value, dict):
        raise SlamError(f"Sequence.vehicle: expected a dict (JSON object), got {value!r}")
    model = value.get("model")
    if not isinstance(model, str) or model not in VEHICLE_MODELS:
        shown = model if isinstance(model, (str, type(None))) else type(model).__name__
        raise SlamError(
            f"Sequence.vehicle: unknown or missing 'model' {shown!r}; "
            f"known: {sorted(VEHICLE_MODELS)}"
        )
    required, optional = VEHICLE_MODELS[model]
    unknown = sorted(set(value) - {"model", *required, *optional})
    if unknown:
        raise SlamError(f"Sequence.vehicle: unknown key(s) {unknown} for model {model!r}")
    out: dict = {"model": model}
    for key in required:
        if key not in value:
            raise SlamError(f"Sequence.vehicle: model {model!r} needs {key!r}")
    for key in (*required, *optional):
        v = value.get(key, optional.get(key))
        f = _number(v)
        if f is None:
            shown = v if not isinstance(v, int) or abs(v) < 10**20 else f"{str(v)[:12]}..."
            raise SlamError(f"Sequence.vehicle[{key!r}]: must be a finite number, got {shown!r}")
        out[key] = f
    if out.get("wheelbase_m", 1.0) <= 0:
        raise SlamError(f"Sequence.vehicle['wheelbase_m']: must be > 0, got {out['wheelbase_m']}")
    return out


def _beam_count(value, ranges: np.ndarray | None) -> int:
    """B from scan_n_beams or from scan_ranges (equal when both are given)."""
    if value is None:
        if ranges is None:
            raise SlamError(
                "Sequence.scan_n_beams: needed when there is no scan_ranges (it sets the field of "
                "view of the detections)"
            )
        return int(ranges.shape[1])
    v = _scalar("scan_n_beams", value)
    if v != int(v) or v < 1:
        raise SlamError(f"Sequence.scan_n_beams: must be a whole number >= 1, got {value!r}")
    if ranges is not None and int(v) != ranges.shape[1]:
        raise SlamError(
            f"Sequence.scan_n_beams: {int(v)} but scan_ranges has {ranges.shape[1]} beams"
        )
    return int(v)


def _detections(seq, n_scans: int) -> dict:
    """The checked detection fields (empty dict when absent) plus `_det_bounds`."""
    given = {k: getattr(seq, k) for k in DETECTIONS}
    present = [k for k, v in given.items() if v is not None]
    if not present:
        for k in ("det_cov", "det_method"):
            if getattr(seq, k) is not None:
                raise SlamError(f"Sequence.{k}: given without the detections (det_scan, ...)")
        return {}
    if len(present) != len(DETECTIONS):
        missing = sorted(set(DETECTIONS) - set(present))
        raise SlamError(
            f"Sequence.{missing[0]}: detections need {list(DETECTIONS)}; missing {missing}"
        )
    scan = np.asarray(given["det_scan"])
    if scan.ndim != 1 or (scan.size and scan.dtype.kind not in "iu"):
        raise SlamError(f"Sequence.det_scan: expected (D,) integers, got {scan.dtype} {scan.shape}")
    scan = scan.astype(np.int64)
    D = scan.size
    if D and (scan.min() < 0 or scan.max() >= n_scans):
        raise SlamError(f"Sequence.det_scan: scan indices must be in 0..{n_scans - 1}")
    if np.any(np.diff(scan) < 0):
        raise SlamError("Sequence.det_scan: must be sorted by scan (non-decreasing)")
    out = {"det_scan": readonly(scan)}
    for k in ("det_range", "det_bearing", "det_radius"):
        a = _arr(k, given[k], 1)
        if a.shape != (D,):
            raise SlamError(f"Sequence.{k}: expected shape ({D},) like det_scan, got {a.shape}")
        out[k] = a
    _fin("det_range", out["det_range"])
    _fin("det_bearing", out["det_bearing"])
    if D and out["det_range"].min() <= 0:
        raise SlamError("Sequence.det_range: ranges must be > 0 m")
    _bounded("det_range", out["det_range"], MAX_COORDINATE_M, "m")
    _bounded("det_bearing", out["det_bearing"], MAX_ANGLE_RAD, "rad")
    if np.any(out["det_radius"] < 0) or np.any(np.isinf(out["det_radius"])):
        raise SlamError("Sequence.det_radius: radii must be finite and >= 0 m (NaN when unknown)")
    _bounded("det_radius", out["det_radius"], MAX_COORDINATE_M, "m")
    if seq.det_cov is not None:
        cov = _arr("det_cov", seq.det_cov, 3)
        if cov.shape != (D, 2, 2):
            raise SlamError(f"Sequence.det_cov: expected shape ({D}, 2, 2), got {cov.shape}")
        _fin("det_cov", cov)
        _bounded("det_cov", cov, MAX_VARIANCE, "(m^2, rad^2)")
        a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
        if (
            np.any(np.abs(b - cov[:, 1, 0]) > 1e-9 * (a + c))
            or np.any(a <= 0)
            or np.any(a * c - b * b <= 0)
        ):
            raise SlamError("Sequence.det_cov: each covariance must be symmetric positive definite")
        out["det_cov"] = readonly(cov.copy())
    method = seq.det_method if seq.det_method is not None else "other"
    if not isinstance(method, str) or not method:
        raise SlamError(f"Sequence.det_method: expected a non-empty string, got {seq.det_method!r}")
    out["det_method"] = method
    out["_det_bounds"] = np.searchsorted(scan, np.arange(n_scans + 1))
    return out


@dataclass(frozen=True, eq=False)
class Sequence:
    """One run: laser scans plus whatever odometry, GPS and truth came with them.

    Frames: the vehicle frame has its origin at the rear-axle centre, x forward, y left; the laser
    frame is the laser's (0 rad = its x-axis, CCW positive); the world frame is the run's fixed
    frame (GPS, truth). Arrays are stored as read-only float64 (scan_labels: int64) copies.

    Required
      scan_t: (N,) s, strictly increasing.
      scan_angle_min, scan_angle_increment: rad, laser frame (0 = laser x-axis, CCW positive);
        increment > 0 and the B beams span less than 360 degrees.
      laser_pose: (3,) [x, y, theta] of the laser in the vehicle frame (rear-axle centre).
      and the raw scans, or precomputed detections, or both:
      scan_ranges: (N, B) m, NaN = no return.
      det_scan (D,) int scan index (non-decreasing, 0..N-1), det_range (D,) m (> 0) and
        det_bearing (D,) rad of each detected trunk's centre in the laser frame, det_radius (D,) m
        (>= 0, NaN when unknown); det_cov (D, 2, 2) optional covariance of (range, bearing);
        det_method: the extractor that made them ("bailey", ...), which names the noise model.
    Optional (None when absent)
      scan_n_beams: B, the beams of a scan; needed without scan_ranges (the field of view is
        B beams from scan_angle_min), checked against scan_ranges otherwise.
      scan_max_range: m; readings at or beyond it are no return (inf when absent).
      odometry, of the vehicle's kind (`ODOMETRY_KINDS`): odo_t (M,) s with, for an
        "ackermann" car, odo_speed (M,) m/s as measured by the encoder and odo_steer (M,) rad
        front wheel (|steer| <= 1.4 rad, |speed| <= 100 m/s); for a "unicycle", odo_speed and
        odo_yaw_rate (M,) rad/s counter-clockwise (|rate| <= 20 rad/s); for "pose-increment",
        odo_pose (M, 3) [x, y, theta], the robot's integrated odometry in its own frame.
      vehicle: a `Vehicle`; a dict such as {"model": "ackermann", "wheelbase_m": 2.83,
        "encoder_offset_m": 0.76} or its JSON text is accepted and made one (encoder_offset_m
        defaults to 0).
      gps_t (G,) s, gps_xy (G, 2) m world, both or neither; gps_pose (3,) antenna in the vehicle
        frame (the laser's position when absent); gps_origin (3,) [latitude deg, longitude deg,
        altitude m] (WGS84) that gps_xy's east and north metres are measured from, with gps_t.
      truth_t (T,) s, truth_pose (T, 3) [x, y, theta] of the rear-axle centre, world frame, both
        or neither.
      truth_landmarks (L, 3) [x, y, r] m, world frame, r > 0.
      scan_labels (N, B) int: id of the object each beam hit (landmark k of truth_landmarks has
        label k; other objects have labels >= L), NO_RETURN_LABEL (-1) for none, MIXED_LABEL (-2)
        for a mixed return between two objects at a depth jump.
      name: free text describing the run.
    Construction validates everything and raises `SlamError` (a `ValueError`) naming the field.
    """

    scan_t: np.ndarray
    scan_angle_min: float
    scan_angle_increment: float
    laser_pose: np.ndarray
    scan_ranges: np.ndarray | None = None
    scan_n_beams: int | None = None
    scan_max_range: float = float("inf")
    det_scan: np.ndarray | None = None
    det_range: np.ndarray | None = None
    det_bearing: np.ndarray | None = None
    det_radius: np.ndarray | None = None
    det_cov: np.ndarray | None = None
    det_method: str | None = None
    odo_t: np.ndarray | None = None
    odo_speed: np.ndarray | None = None
    odo_steer: np.ndarray | None = None
    odo_yaw_rate: np.ndarray | None = None
    odo_pose: np.ndarray | None = None
    vehicle: Vehicle | None = None
    gps_t: np.ndarray | None = None
    gps_xy: np.ndarray | None = None
    gps_pose: np.ndarray | None = None
    gps_origin: np.ndarray | None = None
    truth_t: np.ndarray | None = None
    truth_pose: np.ndarray | None = None
    truth_landmarks: np.ndarray | None = None
    scan_labels: np.ndarray | None = None
    name: str = ""

    def __post_init__(self) -> None:
        ranges = self._check_scans()
        self._check_odometry()
        self._check_vehicle()
        self._check_gps_and_truth()
        self._check_labels(ranges)
        if not isinstance(self.name, str):
            raise SlamError(f"Sequence.name: expected a string, got {self.name!r}")

    def _put(self, name: str, value) -> None:
        object.__setattr__(self, name, value)

    def _check_scans(self) -> np.ndarray | None:
        """Times, raw ranges, beam geometry, laser pose and detections; returns the ranges."""
        put = self._put
        scan_t = _t("scan_t", self.scan_t)
        n = scan_t.shape[0]
        if n == 0:
            raise SlamError("Sequence.scan_t: no scans (length 0)")
        put("scan_t", scan_t)
        if self.scan_ranges is None and self.det_scan is None:
            raise SlamError(
                "Sequence.scan_ranges: a sequence needs raw scans (scan_ranges) or precomputed "
                "detections (det_scan, det_range, det_bearing, det_radius), or both"
            )
        ranges = None
        if self.scan_ranges is not None:
            ranges = _arr("scan_ranges", self.scan_ranges, 2)
            if ranges.shape[0] != n or ranges.shape[1] == 0:
                raise SlamError(
                    f"Sequence.scan_ranges: expected shape (N, B) with N = len(scan_t) = {n} "
                    f"and B >= 1, got {ranges.shape}"
                )
            put("scan_ranges", ranges)
        n_beams = _beam_count(self.scan_n_beams, ranges)
        if n_beams > MAX_BEAMS:
            raise SlamError(
                f"Sequence.scan_ranges: {n_beams} beams a scan, more than the limit of "
                f"{MAX_BEAMS} (slam.sequence.MAX_BEAMS; datasets/FORMAT.md)"
            )
        put("scan_n_beams", n_beams)
        amin = _scalar("scan_angle_min", self.scan_angle_min)
        inc = _scalar("scan_angle_increment", self.scan_angle_increment)
        if inc <= 0:
            raise SlamError(f"Sequence.scan_angle_increment: must be > 0 rad, got {inc!r}")
        if abs(amin) > 2 * math.pi:
            raise SlamError(
                f"Sequence.scan_angle_min: must be within +-2 pi rad, got {amin!r} (degrees "
                "instead of radians?)"
            )
        if max(n_beams - 1, 1) * inc >= 2 * math.pi:
            raise SlamError(
                f"Sequence.scan_angle_increment: {n_beams} beams of {inc!r} rad span "
                f"{(n_beams - 1) * inc:.4g} rad, 360 degrees or more (degrees instead of radians?)"
            )
        put("scan_angle_min", amin)
        put("scan_angle_increment", inc)
        mr = _scalar("scan_max_range", self.scan_max_range, allow_inf=True)
        if mr <= 0:
            raise SlamError(f"Sequence.scan_max_range: must be > 0 m (or inf), got {mr!r}")
        put("scan_max_range", mr)
        put("laser_pose", _pose("laser_pose", self.laser_pose))
        for name, v in _detections(self, n).items():
            put(name, v)

        return ranges

    def _check_odometry(self) -> None:
        """odo_t with the readings of one odometry kind (`ODOMETRY_KINDS`), in physical ranges."""
        given = [k for k in ODOMETRY_FIELDS if getattr(self, k) is not None]
        if not given:
            return
        kinds = [m for m, need in ODOMETRY_KINDS.items() if set(need) <= set(given)]
        if not kinds:
            options = "; ".join(f"{m}: {', '.join(need)}" for m, need in ODOMETRY_KINDS.items())
            missing = sorted(set(ODOMETRY_KINDS["ackermann"]) - set(given))
            raise SlamError(
                f"Sequence.{missing[0] if missing else given[0]}: odometry needs odo_t together "
                f"with the readings of one kind ({options}); given {given}"
            )
        odo_t = _t("odo_t", self.odo_t)
        if odo_t.size == 0:
            raise SlamError("Sequence.odo_t: empty; leave the odometry out instead")
        self._put("odo_t", odo_t)
        for k in given[1:]:
            width = 3 if k == "odo_pose" else None
            a = _arr(k, getattr(self, k), 2 if width else 1, width=width)
            expected = (odo_t.shape[0], 3) if width else odo_t.shape
            if a.shape != expected:
                raise SlamError(
                    f"Sequence.{k}: expected shape {expected} like odo_t, got {a.shape}"
                )
            _fin(k, a)
            if k == "odo_pose":
                _poses(k, a)
            self._put(k, a)
        _check_readings(self)

    def _check_vehicle(self) -> None:
        """The vehicle description, that the odometry is of its kind, and that the encoder
        correction it implies stays finite."""
        put = self._put
        if self.vehicle is not None:
            put("vehicle", Vehicle.of(self.vehicle))
            need = ODOMETRY_KINDS[self.vehicle.model]
            if self.odo_t is not None and any(getattr(self, k) is None for k in need):
                raise SlamError(
                    f"Sequence.vehicle: a {self.vehicle.model!r} vehicle's odometry is "
                    f"{', '.join(need)}; this sequence has "
                    f"{[k for k in ODOMETRY_FIELDS if getattr(self, k) is not None]}"
                )
            if self.vehicle.model != "ackermann":
                return
            h_over_l = self.vehicle.encoder_offset_m / self.vehicle.wheelbase_m
            if self.odo_steer is not None and h_over_l != 0.0:
                # v_c = v_e / (1 - (H / L) tan(alpha)) needs a positive denominator
                denom = 1.0 - h_over_l * np.tan(self.odo_steer)
                if np.any(denom <= 1e-3):
                    k = int(np.argmin(denom))
                    h = self.vehicle.encoder_offset_m
                    raise SlamError(
                        f"Sequence.odo_steer: {float(self.odo_steer[k]):.6g} rad at sample {k} "
                        f"turns so sharply that the speed encoder (vehicle encoder_offset_m = "
                        f"{h} m) would stand still or run backwards (1 - (H / L) tan(alpha) "
                        "must stay above 0.001, datasets/FORMAT.md)"
                    )

    def _check_gps_and_truth(self) -> None:
        put = self._put
        for name, v in _timed_pair("gps_t", self.gps_t, "gps_xy", self.gps_xy, 2):
            put(name, v)
        if self.gps_pose is not None:
            put("gps_pose", _pose("gps_pose", self.gps_pose))
        if self.gps_origin is not None:
            put("gps_origin", _gnss_origin(self.gps_origin, self.gps_t is not None))

        for name, v in _timed_pair("truth_t", self.truth_t, "truth_pose", self.truth_pose, 3):
            put(name, v)
        if self.truth_landmarks is not None:
            lm = _arr("truth_landmarks", self.truth_landmarks, 2, width=3)
            _fin("truth_landmarks", lm)
            _bounded("truth_landmarks", lm, MAX_COORDINATE_M, "m")
            if np.any(lm[:, 2] <= 0):
                i = int(np.flatnonzero(lm[:, 2] <= 0)[0])
                raise SlamError(
                    f"Sequence.truth_landmarks: radius r must be > 0 m, row {i} has {lm[i, 2]!r}"
                )
            put("truth_landmarks", lm)

    def _check_labels(self, ranges: np.ndarray | None) -> None:
        """Per-beam truth labels, one per raw range."""
        n, n_beams = self.n_scans, self.n_beams
        if self.scan_labels is not None:
            lab = np.asarray(self.scan_labels)
            if lab.dtype.kind not in "iu":
                raise SlamError(f"Sequence.scan_labels: expected integers, got dtype {lab.dtype}")
            if ranges is None or lab.shape != ranges.shape:
                raise SlamError(
                    f"Sequence.scan_labels: expected shape {(n, n_beams)} like scan_ranges, "
                    f"got {lab.shape}" + ("" if ranges is not None else " (no scan_ranges)")
                )
            if lab.size and lab.min() < MIXED_LABEL:
                raise SlamError(
                    f"Sequence.scan_labels: labels must be >= {MIXED_LABEL} (-1 = no return, "
                    f"-2 = mixed return), found {int(lab.min())}"
                )
            self._put("scan_labels", readonly(lab.astype(np.int64)))

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])

    @property
    def n_beams(self) -> int:
        return int(self.scan_n_beams)

    @property
    def odometry(self) -> OdometryLog | None:
        """The odometry samples, or None."""
        if self.odo_t is None:
            return None
        return OdometryLog(
            self.odo_t, self.odo_speed, self.odo_steer, self.odo_yaw_rate, self.odo_pose
        )

    @property
    def gps(self) -> GpsTrack | None:
        """The GPS fixes, or None."""
        if self.gps_t is None:
            return None
        return GpsTrack(self.gps_t, self.gps_xy, self.gps_pose)

    @property
    def truth(self) -> Truth | None:
        """The simulated truth (poses; landmarks when given), or None without poses."""
        if self.truth_t is None:
            return None
        return Truth(self.truth_t, self.truth_pose, self.truth_landmarks)

    @property
    def has_ranges(self) -> bool:
        return self.scan_ranges is not None

    @property
    def has_detections(self) -> bool:
        return self.det_scan is not None

    def detections(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Scan k's precomputed detections: z (m, 2) [range_m, bearing_rad] (laser frame),
        radius (m,) m, and their (m, 2, 2) covariance or None."""
        if self.det_scan is None:
            raise SlamError(f"Sequence.det_scan: the sequence {self.name!r} has no detections")
        a, b = self._det_bounds[k], self._det_bounds[k + 1]
        z = np.stack([self.det_range[a:b], self.det_bearing[a:b]], axis=1)
        cov = None if self.det_cov is None else self.det_cov[a:b]
        return z, self.det_radius[a:b], cov

    def scan(self, k: int) -> Scan:
        """Scan k as a `features.Scan` (every beam a no-return when there are no raw scans)."""
        ranges = (
            self.scan_ranges[k] if self.scan_ranges is not None else np.full(self.n_beams, np.nan)
        )
        return Scan(
            ranges,
            self.scan_angle_min,
            self.scan_angle_increment,
            stamp_s=float(self.scan_t[k]),
            max_range_m=self.scan_max_range,
        )
