"""EKF-SLAM with car-like odometry: vehicle model, filter steps, map management, the run loop.

    from slam import run, SlamConfig
    log = run(sequence, features="paper", association="ihgr")

`slam` imports `features` and `association` only (never `experiments`).
"""

from slam.ekf import EkfState, add_landmark, initial_state, observe, predict, update
from slam.mapping import MapPolicy, Tentatives
from slam.run import (
    DEFAULT_CONSTANT_NOISE,
    NullVisualiser,
    SlamConfig,
    SlamLog,
    interpolate_poses,
    measurements_from_features,
    run,
)
from slam.vehicle import AckermannModel, Odometry, OdometryNoise, integrate, wrap_angle

__all__ = [
    "DEFAULT_CONSTANT_NOISE",
    "AckermannModel",
    "EkfState",
    "MapPolicy",
    "NullVisualiser",
    "Odometry",
    "OdometryNoise",
    "SlamConfig",
    "SlamLog",
    "Tentatives",
    "add_landmark",
    "initial_state",
    "integrate",
    "interpolate_poses",
    "measurements_from_features",
    "observe",
    "predict",
    "run",
    "update",
    "wrap_angle",
]
