"""The run log `run_log.npz` that `trunkslam slam` writes beside its results: what the GTSAM
smoother needs to re-solve the run after the fact (`trunkslam smooth RUN_DIR`).

Format (datasets/FORMAT.md, "Run log"): one compressed `.npz` with `format` =
"trunkslam.run_log/1", the strings `features` and `association`, and the arrays of
`slam.smoother.Problem` (N scans, M measurements, L landmarks):

    scan_t (N,) s; prior_pose (3,), prior_cov (3, 3): the EKF's start (rear axle, world);
    odo_delta (N, 3), odo_cov (N, 3, 3): odometry increment k-1 -> k in the frame of pose
        k-1 and its covariance (row 0 zeros); laser_pose (3,): laser in the vehicle frame;
    meas_scan, meas_landmark, meas_kind (M,) int; meas_z (M, 2) [range m, bearing rad];
        meas_R (M, 2, 2); kind 0 = used in an EKF update, 1 = initialised its landmark,
        2 = a tentative sighting of a landmark that later joined the map (unused by the EKF);
    init_pose (N, 3): the EKF's path; landmark_id (L,), init_landmark (L, 2): its map.
    Optional: landmark_existence (L,) each landmark's existence (map policy "existence");
    departed_landmark, departed_scan, departed_reason (D,) int, departed_existence (D,) float
    (map policy "existence", or a run that prunes): the landmarks that left the map, after
    which scan, why (`DEPARTURE_REASONS`) and their existence then (NaN for "pruned").
    Optional, together (`measurement.pass_offset_model = "state"`, P passes): meas_pass (M,)
    int, the pass of each measurement; pass_landmark (P,) int, each pass's landmark;
    pass_cov (P, 2, 2), each pass's offset covariance in the world frame (m^2).
    pass_corr_rad (optional, with them): the drift's correlation length (rad) when finite.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.npz import Var, check_method_name, read_npz
from experiments.io.writers import write_atomic
from slam import SlamError, SlamLog
from slam.smoother import MEAS_TENTATIVE, Problem, problem_from_log

__all__ = [
    "DEPARTURE_REASONS",
    "RUN_LOG_FORMAT",
    "RUN_LOG_NAME",
    "SCHEMA",
    "read_existence",
    "read_run_log",
    "write_run_log",
]

RUN_LOG_FORMAT = "trunkslam.run_log/1"
RUN_LOG_NAME = "run_log.npz"
# The format's schema: each variable's kind and dimensions (N scans, M measurements, L
# landmarks), checked before any value is read; the values are `slam.smoother.Problem`'s.
SCHEMA: dict[str, Var] = {
    "format": Var("str", required=True),
    "features": Var("str"),
    "association": Var("str"),
    "scan_t": Var("float", ("N",), required=True),
    "prior_pose": Var("float", (3,), required=True),
    "prior_cov": Var("float", (3, 3), required=True),
    "odo_delta": Var("float", ("N", 3), required=True),
    "odo_cov": Var("float", ("N", 3, 3), required=True),
    "laser_pose": Var("float", (3,), required=True),
    "meas_scan": Var("int", ("M",), required=True),
    "meas_landmark": Var("int", ("M",), required=True),
    "meas_z": Var("float", ("M", 2), required=True),
    "meas_R": Var("float", ("M", 2, 2), required=True),
    "meas_kind": Var("int", ("M",), required=True),
    "init_pose": Var("float", ("N", 3), required=True),
    "landmark_id": Var("int", ("L",), required=True),
    "init_landmark": Var("float", ("L", 2), required=True),
}
SCHEMA |= {
    "landmark_existence": Var("float", ("L",)),
    "departed_landmark": Var("int", ("D",)),
    "departed_scan": Var("int", ("D",)),
    "departed_reason": Var("int", ("D",)),
    "departed_existence": Var("float", ("D",)),
    "meas_pass": Var("int", ("M",)),
    "pass_landmark": Var("int", ("P",)),
    "pass_cov": Var("float", ("P", 2, 2)),
    "pass_corr_rad": Var("float", ()),
}
# departed_reason codes: SlamLog.departures' reasons
DEPARTURE_REASONS = ("existence", "pruned")
_NAMES = ("features", "association")  # the run's methods, for the smoother's summary


def write_run_log(path: Path | str, log: SlamLog) -> Path:
    """Write the smoother's inputs of `log` (every candidate measurement, kinds 0-2)."""
    p = problem_from_log(log, measurements="all")
    arrays = {
        "format": np.array(RUN_LOG_FORMAT),
        "features": np.array(log.features_method),
        "association": np.array(log.association_method),
        **p.arrays(),
        **_existence_arrays(log),
    }
    return write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays))


def _existence_arrays(log: SlamLog) -> dict:
    """The optional existence variables (module doc) of a run with departures or existence."""
    out = {}
    if log.landmark_existence is not None:
        out["landmark_existence"] = np.asarray(log.landmark_existence, np.float64)
    dep = log.departures or []
    if dep or log.landmark_existence is not None:
        out["departed_landmark"] = np.array([d[0] for d in dep], np.int64)
        out["departed_scan"] = np.array([d[1] for d in dep], np.int64)
        out["departed_reason"] = np.array([DEPARTURE_REASONS.index(d[2]) for d in dep], np.int64)
        out["departed_existence"] = np.array([d[3] for d in dep], np.float64)
    return out


def read_run_log(path: Path | str, measurements: str = "ekf") -> tuple[Problem, dict]:
    """(Problem, {"features": ..., "association": ...}) from a run log, or a `DataError`
    naming the file and what is wrong. measurements: "ekf" (kinds 0 and 1, what the filter
    used) or "all" (also kind 2). The file is checked against `SCHEMA` (`experiments.io.npz`)
    before any value is read, then its values by `Problem`."""
    if measurements not in ("ekf", "all"):
        raise DataError(f"measurements: expected 'ekf' or 'all', got {measurements!r}")
    path = Path(path)
    if path.is_dir():
        path = path / RUN_LOG_NAME
    if not path.is_file() and not path.is_symlink():
        raise DataError(
            f"{path}: no run log (written by `trunkslam slam` since trunkslam 0.1; re-run it)"
        )
    data = read_npz(path, SCHEMA, "run log", signature=("format", RUN_LOG_FORMAT))
    names = {}
    for k in _NAMES:
        if k in data:
            names[k] = check_method_name(path, k, str(data[k]))
    arrays = {k: data[k] for k in Problem.__dataclass_fields__ if k in data}
    if np.any(np.diff(arrays["meas_scan"]) < 0):
        raise DataError(f"{path}: meas_scan: must be sorted by scan, as trunkslam slam writes it")
    if measurements == "ekf":
        keep = arrays["meas_kind"] != MEAS_TENTATIVE
        for k in ("meas_scan", "meas_landmark", "meas_z", "meas_R", "meas_kind", "meas_pass"):
            if k in arrays:
                arrays[k] = arrays[k][keep]
    try:
        return Problem(**arrays), names
    except SlamError as exc:
        raise DataError(f"{path}: {exc}") from None


def read_existence(path: Path | str) -> dict[str, np.ndarray]:
    """The existence variables of a run log (module doc; {} for a run without them), checked
    against `SCHEMA` like `read_run_log`."""
    path = Path(path)
    if path.is_dir():
        path = path / RUN_LOG_NAME
    data = read_npz(path, SCHEMA, "run log", signature=("format", RUN_LOG_FORMAT))
    keys = ("landmark_id", "landmark_existence", *(k for k in SCHEMA if k.startswith("departed")))
    return {k: data[k] for k in keys if k in data} if "departed_landmark" in data else {}
