"""Checks: the input checks shared by the run's data types (`Sequence`, `Odometry`), one place
for each rule, each taking the qualified name of what it checks (e.g. "Sequence.scan_t"); and
what a run needs beyond a valid `Sequence` and `SlamConfig` (`check_runnable`, before any work)
and the one check the loop makes on every scan (`check_noise`). Errors are `SlamError` (a
`ValueError`) naming the field and what to change.
"""

from __future__ import annotations

import logging
import math
from dataclasses import fields

import numpy as np

from slam.errors import SlamError

__all__ = [
    "SETTING_TINY",
    "SIGMA_LIMIT",
    "check_fit",
    "check_noise",
    "check_runnable",
    "check_types",
    "finite",
    "float_array",
    "nonnegative_fields",
    "readonly",
    "setting",
    "times",
]

# The range where the kernels' maths holds for a setting that feeds them (noise sigmas, floors,
# poses, calibrations): a finite number whose size is 0 or within [SETTING_TINY, its limit].
# Above the limit its square leaves the sequence file's range for variances (its squares and
# their products overflow long before 1e300); below SETTING_TINY its square underflows to a
# subnormal or 0 (a covariance that is singular by rounding). Subnormals are refused.
SETTING_TINY = 1e-150  # (1e-150)^2 > 2.2e-308, the least normal double
SIGMA_LIMIT = 1e8  # m, rad, m/s, ...: sqrt(slam.sequence.MAX_VARIANCE), the file's largest sigma


def setting(path: str, v, *, signed: bool = False, limit: float = SIGMA_LIMIT) -> None:
    """`v` a setting that feeds a kernel: a real number whose size is 0 or within
    [SETTING_TINY, limit], and >= 0 unless `signed`; a `SlamError` naming `path` and the
    allowed range otherwise."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SlamError(f"{path}: must be a finite number, got {v!r}")
    if not signed and v < 0:
        raise SlamError(f"{path}: must be a finite number >= 0, got {v!r}")
    if abs(v) > limit or (v != 0 and abs(v) < SETTING_TINY):
        size = "of size " if signed else ""
        raise SlamError(
            f"{path}: must be 0 or a number {size}in [{SETTING_TINY:g}, {limit:g}], got {v!r}"
        )


def nonnegative_fields(owner: str, obj) -> None:
    """Every field of the dataclass `obj` a finite real number >= 0 (noise sigmas) in the range
    of `setting`; a `SlamError` naming `owner`.field otherwise."""
    for f in fields(obj):
        setting(f"{owner}.{f.name}", getattr(obj, f.name))


def readonly(a: np.ndarray) -> np.ndarray:
    """`a`, made read-only (returned for chaining)."""
    a.setflags(write=False)
    return a


def float_array(name: str, value, ndim: int, width: int | None = None) -> np.ndarray:
    """A read-only float64 copy of `value` with `ndim` dimensions (and `width` columns)."""
    try:
        a = np.array(value)
    except Exception as exc:  # ragged lists and the like
        raise SlamError(f"{name}: cannot be read as an array ({exc})") from None
    if a.dtype.kind not in "fiu":
        raise SlamError(f"{name}: expected numbers, got dtype {a.dtype}")
    expected = {1: "(n,)", 2: f"(n, {width})" if width else "(n, m)"}.get(ndim, f"{ndim}-D")
    if a.ndim != ndim or (width is not None and a.shape[-1] != width):
        raise SlamError(f"{name}: expected shape {expected}, got {a.shape}")
    return readonly(a.astype(np.float64))


def finite(name: str, a: np.ndarray) -> None:
    """Raise unless every value of `a` is finite."""
    if not np.all(np.isfinite(a)):
        raise SlamError(f"{name}: values must be finite (NaN or inf found)")


def times(name: str, value) -> np.ndarray:
    """`value` as read-only float64 times (n,), checked finite and strictly increasing."""
    t = float_array(name, value, 1)
    if not np.all(np.isfinite(t)):
        raise SlamError(
            f"{name}: times must be finite (first bad index "
            f"{int(np.flatnonzero(~np.isfinite(t))[0])})"
        )
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        short = name.rsplit(".", 1)[-1]
        raise SlamError(
            f"{name}: times must be strictly increasing; {short}[{i + 1}] = "
            f"{t[i + 1]!r} s follows {short}[{i}] = {t[i]!r} s ({bad.size} such step(s))"
        )
    return t


log = logging.getLogger(__name__)

# ---- a run's checks ----------------------------------------------------------------------------


def check_types(seq, cfg) -> None:
    """A `Sequence` and a `SlamConfig`, named when not."""
    from slam.config import SlamConfig
    from slam.sequence import Sequence

    if not isinstance(seq, Sequence):
        raise SlamError(f"sequence: expected a slam.Sequence, got {type(seq).__name__}")
    if not isinstance(cfg, SlamConfig):
        raise SlamError(f"config: expected a SlamConfig, got {type(cfg).__name__}")


def check_runnable(seq, cfg, n_features: int | None = None) -> np.ndarray:
    """Odometry, a vehicle, a steering calibration that keeps the angles physical, no long
    odometry gaps, one precomputed feature set per scan (`n_features`, when given). Returns the
    steering readings through `cfg.vehicle.steering` (an "ackermann" car's; None otherwise)."""
    check_types(seq, cfg)
    if seq.odo_t is None:
        raise SlamError(
            "sequence: missing odometry (odo_t, odo_speed, odo_steer); EKF-SLAM needs it"
        )
    if seq.vehicle is None:
        raise SlamError("sequence.vehicle: missing vehicle model (needed to use the odometry)")
    steer = None
    if seq.vehicle.model == "ackermann":
        steer = cfg.vehicle.steering.apply(seq.odo_steer)
        _check_steering(seq, cfg, steer)
    _check_gaps(seq, cfg.vehicle.max_odometry_gap_s)
    if n_features is not None and n_features != seq.n_scans:
        raise SlamError(f"features: {n_features} precomputed feature sets for {seq.n_scans} scans")
    return steer


def _check_steering(seq, cfg, steer: np.ndarray) -> None:
    from slam.sequence import MAX_STEER_RAD

    if not cfg.vehicle.steering.is_identity and np.any(np.abs(steer) > MAX_STEER_RAD):
        i = int(np.argmax(np.abs(steer)))
        raise SlamError(
            f"vehicle.steering: turns odo_steer[{i}] = {float(seq.odo_steer[i]):.6g} rad into "
            f"{float(steer[i]):.6g} rad, beyond +-{MAX_STEER_RAD} rad; check the calibration"
        )
    veh = seq.vehicle
    k = veh.encoder_offset_m / veh.wheelbase_m
    den = 1.0 - k * np.tan(steer)
    if np.any(den <= 0):  # v_c = v_e / (1 - (H/L) tan(alpha)) would be infinite or negative
        i = int(np.flatnonzero(den <= 0)[0])
        raise SlamError(
            f"sequence.vehicle: encoder_offset_m / wheelbase_m = {k:.3g} with odo_steer[{i}] = "
            f"{float(seq.odo_steer[i]):.3g} rad (calibrated: {float(steer[i]):.3g} rad) makes "
            "the encoder-to-axle speed correction infinite or negative; check the vehicle "
            "parameters and the steering units"
        )


def _check_gaps(seq, max_gap_s: float) -> None:
    """The longest stretch of the run [scan_t[0], scan_t[-1]] on stale (held) odometry."""
    scan_t, odo_t = seq.scan_t, seq.odo_t
    lead = max(0.0, float(odo_t[0] - scan_t[0]))
    tail = max(0.0, float(scan_t[-1] - odo_t[-1]))
    clipped = np.clip(odo_t, scan_t[0], scan_t[-1])
    steps = np.diff(clipped)
    inner = float(steps.max()) if steps.size else 0.0
    if max(lead, tail, inner) <= max_gap_s:
        return
    if lead > max_gap_s:
        where = f"odometry starts at {odo_t[0]:.3f} s, {lead:.3f} s after the first scan"
    elif tail > max_gap_s:
        where = f"odometry ends at {odo_t[-1]:.3f} s, {tail:.3f} s before the last scan"
    else:
        i = int(np.argmax(steps))
        where = f"no odometry from {clipped[i]:.3f} s to {clipped[i + 1]:.3f} s"
    raise SlamError(
        f"sequence.odo_t: missing odometry: {where} (vehicle.max_odometry_gap_s = {max_gap_s} s)"
    )


def check_fit(seq, cfg) -> str | None:
    """Whether the configuration was made for this sequence's vehicle: a warning (logged, and
    returned) when `cfg.vehicle.calibrated_for` names another car than the sequence's, whose
    odometry noise and geometry it then does not describe (the simulated Cycab's settings on the
    Victoria Park ute gave 11.8 m against GPS where the ute's preset gives 3.7 m)."""
    claim = cfg.vehicle.calibrated_for
    if claim is None or seq.vehicle is None or seq.vehicle.model != "ackermann":
        return None  # the claim is a car's geometry (a robot's own odometry has its own noise)
    have = (seq.vehicle.wheelbase_m, seq.vehicle.encoder_offset_m)
    if all(abs(a - b) <= 1e-6 * max(1.0, abs(b)) for a, b in zip(have, claim)):
        return None
    name = f" ({seq.name})" if seq.name else ""
    msg = (
        f"the configuration's vehicle settings were made for a car of wheelbase {claim[0]:g} m "
        f"(encoder offset {claim[1]:g} m); this sequence's{name} has {have[0]:g} m "
        f"({have[1]:g} m): its odometry noise is not this car's. Use a preset made for it "
        "(`trunkslam presets`) or set [vehicle] calibrated_for once its noise is calibrated"
    )
    log.warning(msg)
    return msg


def check_noise(k: int, R: np.ndarray, usable: np.ndarray, model: str) -> None:
    """Every usable measurement's R is finite and positive definite. The association gets the
    loop's inputs unchecked (its trusted path), so a degenerate R (the "fit" model of a
    degenerate fit with no floors) is named here rather than failing inside the solver."""
    a, b, c = R[:, 0, 0], 0.5 * (R[:, 0, 1] + R[:, 1, 0]), R[:, 1, 1]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(R).all(axis=(1, 2)) & (a > 0) & (c > 0) & (a * c - b * b > 0)
    bad = np.flatnonzero(usable & ~ok)
    if bad.size:
        i = int(bad[0])
        raise SlamError(
            f"measurement noise: scan {k}, feature {i} has a covariance R that is not positive "
            f"definite ({R[i].tolist()}; noise model {model!r}); give the fit floors "
            "(measurement.fit_floor_range_m, fit_floor_bearing_rad) or a constant noise model"
        )
