"""EKF-SLAM with car-like odometry: the run's data, vehicle model, filter steps, map management,
the run loop.

    from slam import run_slam, Sequence, SlamConfig
    log = run_slam(sequence, SlamConfig())   # the configuration says everything about the run
    log = run_slam(sequence, features="geometric", association="jcbb")   # methods replaced

`slam` imports `features` and `association` only (never `experiments`).
"""

from slam.config import (
    DEFAULT_CONSTANT_NOISE,
    MapPolicy,
    OdometryNoise,
    SlamConfig,
    SteeringCalibration,
)
from slam.ekf import EkfState, add_landmark, initial_state, predict, update
from slam.errors import SlamError
from slam.log import TIMING_KEYS, SlamLog
from slam.loop import run_slam
from slam.measurement import measurements_from_features
from slam.se2 import interpolate_poses, observe, wrap_angle
from slam.sequence import Sequence
from slam.tentatives import Tentatives
from slam.vehicle import AckermannModel, Odometry, integrate
from slam.visual import NullVisualiser

__all__ = [
    "DEFAULT_CONSTANT_NOISE",
    "TIMING_KEYS",
    "AckermannModel",
    "EkfState",
    "MapPolicy",
    "NullVisualiser",
    "Odometry",
    "OdometryNoise",
    "Sequence",
    "SlamConfig",
    "SlamError",
    "SlamLog",
    "SteeringCalibration",
    "Tentatives",
    "add_landmark",
    "initial_state",
    "integrate",
    "interpolate_poses",
    "measurements_from_features",
    "observe",
    "predict",
    "run_slam",
    "update",
    "wrap_angle",
]
