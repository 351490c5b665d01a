"""What a run on the built-in settings is told: which of them are neutral, which keep the
simulated Cycab's values (its odometry noise has no neutral value), and, when the sequence is
the simulated Cycab, that the `cycab` preset holds its calibration (`--config cycab`).

A configuration that claims no car (`vehicle.calibrated_for` None, the built-in value; a preset
made for a car claims it, and `slam.checks.check_fit` warns when it is another car) gets the
note; `trunkslam slam` logs it and writes it into summary.json (`built_in_settings`).
"""

from __future__ import annotations

import logging

from slam import Sequence, SlamConfig

__all__ = ["CYCAB_ODOMETRY", "NEUTRAL", "built_in_note"]

log = logging.getLogger(__name__)

# The built-in settings that assume no site, and what each means (docs/configuration.md).
NEUTRAL = {
    "measurement.constant_noise": "one constant model for every extractor, 0.05 m + 1%, 0.5 deg",
    "measurement.fit_floor_range_m": "the circle fit's own covariance, no floor",
    "measurement.fit_floor_bearing_rad": "the circle fit's own covariance, no floor",
    "measurement.range_bias": "no range correction",
}
# The odometry noise of each vehicle model: no neutral value exists, the built-in is the
# simulated Cycab's.
CYCAB_ODOMETRY = {
    "ackermann": "vehicle.odometry_noise",
    "unicycle": "vehicle.unicycle_noise",
    "pose-increment": "vehicle.increment_noise",
}


def _at(cfg: SlamConfig, path: str):
    value = cfg
    for name in path.split("."):
        value = getattr(value, name)
    return value


def built_in_note(seq: Sequence, cfg: SlamConfig) -> dict | None:
    """The note of a run of `cfg` over `seq` (None when `cfg` claims a car): the neutral
    settings it leaves at their built-in values, the odometry noise it leaves at the simulated
    Cycab's, and the message (logged as a warning)."""
    if cfg.vehicle.calibrated_for is not None:
        return None
    from experiments.io.config_file import load_slam_config

    base = SlamConfig()
    neutral = [p for p in NEUTRAL if _at(cfg, p) == _at(base, p)]
    model = seq.vehicle.model if seq.vehicle is not None else None
    odometry = CYCAB_ODOMETRY.get(model)
    cycab_values = [odometry] if odometry and _at(cfg, odometry) == _at(base, odometry) else []
    parts = []
    if neutral:
        parts.append(
            "Neutral built-in settings, no site's calibration: "
            + "; ".join(f"{p} ({NEUTRAL[p]})" for p in neutral)
        )
    if cycab_values:
        parts.append(
            f"{cycab_values[0]} is the simulated Cycab's (a car's odometry noise has no neutral "
            "value): give your vehicle's"
        )
    cycab = load_slam_config("cycab").vehicle.calibrated_for
    is_cycab = model == "ackermann" and all(
        abs(a - b) <= 1e-6 * max(1.0, abs(b))  # as slam.checks.check_fit compares cars
        for a, b in zip((seq.vehicle.wheelbase_m, seq.vehicle.encoder_offset_m), cycab)
    )
    if is_cycab:
        parts.append(
            "This sequence's vehicle is the simulated Cycab's: `--config cycab` runs with its "
            "calibration (the settings of experiment 2)"
        )
    if not parts:
        return None
    message = "the configuration claims no car (vehicle.calibrated_for): " + ". ".join(parts)
    log.warning(message)
    return {
        "neutral": neutral,
        "simulated_cycab": cycab_values,
        "suggested_preset": "cycab" if is_cycab else None,
        "message": message,
    }
