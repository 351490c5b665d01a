"""The components of a run, chosen once from its configuration (kiss-icp's `get_*` factories):
the source of its measurements (`slam.sources`), the associator, the vehicle's motion
(`slam.vehicle.Motion`), the laser's mounting and what the laser sees
(`slam.map_managers.View`), and the sections the loop builds its per-run parts from (map
manager, pruning, loop closure): the loop (`slam.loop.Slam`) reads these, never the whole
configuration."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slam.checks import check_fit, check_runnable, check_types
from slam.config import AssociationConfig, ClosureConfig, MapPolicy, SlamConfig
from slam.errors import SlamError
from slam.map_managers import View
from slam.motion import AckermannMotion, IncrementMotion, UnicycleMotion
from slam.sequence import Sequence
from slam.sources import make_source
from slam.start import antenna_of
from slam.vehicle import AckermannModel, Odometry

__all__ = ["Components", "components", "laser_pose", "make_motion"]


def laser_pose(seq: Sequence, cfg: SlamConfig) -> np.ndarray:
    """T_vehicle_laser (3,): the configuration's mounting, else the sequence's."""
    given = cfg.vehicle.laser_pose
    return np.asarray(seq.laser_pose if given is None else given, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Components:
    """What a run is made of, chosen once from its configuration (`components`): the source of
    its measurements, the associator, the vehicle's motion, the laser's and the GPS antenna's
    mounting (T_vehicle_laser, T_vehicle_antenna), what the laser sees; and the settings of
    the parts the loop makes for each pass (`slam.loop.Slam.start`): the association and map
    policy sections (map manager, pruning), the closure section, `vehicle.min_travel_m` and
    `filter.first_estimates_jacobians`; the pass offset of the update's measurements
    (`measurement.pass_offset_sd_m`, `measurement.pass_gap_s`, `measurement.pass_offset_model`,
    `measurement.pass_offset_corr_rad`)."""

    seq: Sequence
    source: object  # slam.sources: (k, scan) -> (Features, z, R); method, model, count, needs_scan
    associator: object  # association.associate's signature minus `method`, with .method
    motion: object  # slam.vehicle.Motion or a model of slam.motion: integrate, distance
    T_vehicle_laser: np.ndarray
    T_vehicle_antenna: np.ndarray
    view: View
    association: AssociationConfig
    map_policy: MapPolicy
    closure: ClosureConfig
    min_travel_m: float
    first_estimates: bool
    pass_offset_sd_m: tuple[float, float] = (0.0, 0.0)
    pass_gap_s: float = 2.0
    pass_offset_model: str = "inflation"
    pass_offset_corr_rad: float = math.inf


def components(seq: Sequence, cfg: SlamConfig, features=None, association=None) -> Components:
    """The run's components; `features` and `association` are the caller's own (a list of
    Features or a callable; a callable), None for the configuration's."""
    check_types(seq, cfg)  # before the source reads the sequence
    source = make_source(seq, cfg, features)
    steer = check_runnable(seq, cfg, source.count)
    check_fit(seq, cfg)
    a0, da = float(seq.scan_angle_min), float(seq.scan_angle_increment)
    laser = laser_pose(seq, cfg)
    return Components(
        seq=seq,
        source=source,
        associator=_associator(cfg, association),
        motion=make_motion(seq, cfg, steer),
        T_vehicle_laser=laser,
        T_vehicle_antenna=antenna_of(seq, cfg, laser),
        association=cfg.association,
        map_policy=cfg.map_policy,
        closure=cfg.closure,
        min_travel_m=cfg.vehicle.min_travel_m,
        first_estimates=cfg.filter.first_estimates_jacobians,
        pass_offset_sd_m=cfg.measurement.pass_offset_sd_m,
        pass_gap_s=cfg.measurement.pass_gap_s,
        pass_offset_model=cfg.measurement.pass_offset_model,
        pass_offset_corr_rad=cfg.measurement.pass_offset_corr_rad,
        view=View(
            fov=(a0, a0 + da * (seq.n_beams - 1)),
            max_range=min(float(seq.scan_max_range), cfg.measurement.max_range_m),
            margin_m=cfg.association.view_margin_m,
            margin_rad=cfg.association.view_margin_rad,
        ),
    )


def _associator(cfg: SlamConfig, given=None):
    """A callable with `associate`'s signature minus `method`, carrying `.method` (its name);
    the configured method's, or the caller's `given` callable."""
    if given is not None:
        if not callable(given):
            raise SlamError(f"association: expected a method name or a callable, got {given!r}")

        def custom(*args, **kwargs):
            return given(*args, **kwargs)

        custom.method = getattr(given, "__name__", "custom")
        return custom
    from association import associate

    method = "ihgr" if cfg.association.windowed else cfg.association.method

    def call(z, R, z_hat, H, P, *, gate_prob, **params):
        # The loop's inputs are valid by construction (finite, P symmetric PSD as the filter
        # keeps it): the trusted path, without the checks that would cost more than the solve.
        return associate(
            z, R, z_hat, H, P, method=method, gate_prob=gate_prob, validate=False, **params
        )

    call.method = cfg.association.method
    return call


def make_motion(seq: Sequence, cfg: SlamConfig, steer=None):
    """The motion model of the sequence's vehicle, with the configuration's noise for it: an
    "ackermann" car (`slam.vehicle.Motion`; `steer`: its calibrated steering readings), a
    "unicycle" or a "pose-increment" robot (`slam.motion`)."""
    odo, model = seq.odometry, seq.vehicle.model
    if model == "unicycle":
        return UnicycleMotion(
            odo.t_s, odo.speed_mps, odo.yaw_rate_rad_s, cfg.vehicle.unicycle_noise
        )
    if model == "pose-increment":
        return IncrementMotion(odo.t_s, odo.pose, cfg.vehicle.increment_noise)
    return AckermannMotion(
        AckermannModel.from_vehicle(seq.vehicle),
        Odometry(odo.t_s, odo.speed_mps, odo.steer_rad if steer is None else steer),
        cfg.vehicle.odometry_noise,
    )
