"""A run's preflight checks: what a run needs beyond a valid `Sequence` and `SlamConfig`
(`check_runnable`, before any work), whether the configuration was made for the sequence's
vehicle (`check_fit`), and the one check the loop makes on every scan (`check_noise`). Errors are
`SlamError` (a `ValueError`) naming the field and what to change. The leaf validators the data
types and settings share are `slam.validators` (this module imports the configuration; they
import nothing of `slam`).
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from slam.config import SlamConfig
from slam.errors import SlamError
from slam.sequence import MAX_STEER_RAD, Sequence

__all__ = ["check_fit", "check_noise", "check_runnable", "check_types"]

log = logging.getLogger(__name__)

# ---- a run's checks ----------------------------------------------------------------------------


def check_types(seq, cfg) -> None:
    """A `Sequence` and a `SlamConfig`, named when not."""
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
    i = _first_bad_noise(np.ascontiguousarray(R, np.float64), np.asarray(usable, np.bool_))
    if i >= 0:
        raise SlamError(
            f"measurement noise: scan {k}, feature {i} has a covariance R that is not positive "
            f"definite ({R[i].tolist()}; noise model {model!r}); give the fit floors "
            "(measurement.fit_floor_range_m, fit_floor_bearing_rad) or a constant noise model"
        )


@njit(cache=True)
def _first_bad_noise(R: np.ndarray, usable: np.ndarray) -> int:
    """The first usable measurement whose R (m, 2, 2) is not finite and positive definite
    (a > 0, c > 0, a c - b^2 > 0 with b the mean of the off-diagonal pair), or -1 (one pass:
    the check runs every scan)."""
    for i in range(R.shape[0]):
        if not usable[i]:
            continue
        a, c = R[i, 0, 0], R[i, 1, 1]
        b = 0.5 * (R[i, 0, 1] + R[i, 1, 0])
        finite = np.isfinite(a) and np.isfinite(c) and np.isfinite(R[i, 0, 1])
        finite = finite and np.isfinite(R[i, 1, 0])
        if not (finite and a > 0 and c > 0 and a * c - b * b > 0):
            return i
    return -1
