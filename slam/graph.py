"""A 2D pose-landmark graph as plain arrays: what a graph file holds (g2o/TORO, read and
written by `experiments.io.g2o`) and what `slam.smoother.solve_pose_graph` solves.

Conventions are GTSAM's `readG2o` (2D): a pose is (x, y, theta) in the world frame, m and rad;
an odometry factor measures pose `odo_to` in the frame of pose `odo_from` with the information
matrix `odo_info` over (x, y, theta); a bearing-range factor measures a landmark from a pose,
bearing (rad, in the pose's frame) and range (m), with independent Gaussian noise of standard
deviations `br_sigma` (bearing rad, range m): GTSAM's BR line carries no correlation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slam import se2
from slam.errors import SlamError

__all__ = ["PoseGraph2D", "graph_of_problem"]


@dataclass(frozen=True, eq=False)
class PoseGraph2D:
    """N poses, L landmarks, E odometry factors, M bearing-range factors.

    pose_id (N,) int, pose (N, 3): the poses' ids and starting values (x m, y m, theta rad).
    landmark_id (L,) int, landmark_xy (L, 2): the landmarks' ids and starting values (m).
    odo_from, odo_to (E,) int: pose ids; odo_delta (E, 3): pose odo_to in the frame of pose
        odo_from; odo_info (E, 3, 3): its information matrix (symmetric positive definite).
    br_pose, br_landmark (M,) int: pose and landmark ids; br_bearing (M,) rad, br_range (M,)
        m; br_sigma (M, 2): standard deviations of bearing (rad) and range (m), > 0.
    """

    pose_id: np.ndarray
    pose: np.ndarray
    landmark_id: np.ndarray
    landmark_xy: np.ndarray
    odo_from: np.ndarray
    odo_to: np.ndarray
    odo_delta: np.ndarray
    odo_info: np.ndarray
    br_pose: np.ndarray
    br_landmark: np.ndarray
    br_bearing: np.ndarray
    br_range: np.ndarray
    br_sigma: np.ndarray

    def __post_init__(self) -> None:
        n = self._take("pose_id", np.int64, 1)
        self._take("pose", np.float64, 2, (n, 3))
        n_lm = self._take("landmark_id", np.int64, 1)
        self._take("landmark_xy", np.float64, 2, (n_lm, 2))
        e = self._take("odo_from", np.int64, 1)
        for name, shape in (("odo_to", (e,)), ("odo_delta", (e, 3)), ("odo_info", (e, 3, 3))):
            self._take(name, np.int64 if name == "odo_to" else np.float64, len(shape), shape)
        m = self._take("br_pose", np.int64, 1)
        for name, shape in (("br_bearing", (m,)), ("br_range", (m,)), ("br_sigma", (m, 2))):
            self._take(name, np.float64, len(shape), shape)
        self._take("br_landmark", np.int64, 1, (m,))
        self._check_ids()
        if m and not (self.br_sigma > 0).all():
            raise SlamError("PoseGraph2D.br_sigma: standard deviations must be > 0")
        if m and not (self.br_range > 0).all():
            raise SlamError("PoseGraph2D.br_range: ranges must be > 0")
        if e:
            info = self.odo_info
            sym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2))
            bad = sym > 1e-9 * np.abs(info).max(axis=(1, 2))
            bad[~bad] = np.linalg.eigvalsh(info[~bad]).min(axis=1) <= 0
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise SlamError(
                    f"PoseGraph2D.odo_info[{i}]: not a symmetric positive definite information "
                    "matrix"
                )

    def _take(self, name: str, dtype, ndim: int, shape: tuple | None = None) -> int:
        v = np.asarray(getattr(self, name))
        if v.size == 0:
            v = v.reshape(shape if shape is not None else (0,) * ndim)
        if v.dtype.kind not in ("iu" if dtype is np.int64 else "fiu"):
            raise SlamError(f"PoseGraph2D.{name}: expected numbers, got dtype {v.dtype}")
        a = v.astype(dtype)
        if a.ndim != ndim or (shape is not None and a.shape != shape):
            raise SlamError(f"PoseGraph2D.{name}: expected shape {shape}, got {a.shape}")
        if dtype is np.float64 and not np.isfinite(a).all():
            raise SlamError(f"PoseGraph2D.{name}: contains NaN or infinite values")
        object.__setattr__(self, name, a)
        return int(a.shape[0])

    def _check_ids(self) -> None:
        for name in ("pose_id", "landmark_id"):
            ids = getattr(self, name)
            if np.unique(ids).size != ids.size:
                raise SlamError(f"PoseGraph2D.{name}: an id appears twice")
            if ids.size and ids.min() < 0:
                raise SlamError(f"PoseGraph2D.{name}: ids must be >= 0")
        for name, known, what in (
            ("odo_from", self.pose_id, "pose"),
            ("odo_to", self.pose_id, "pose"),
            ("br_pose", self.pose_id, "pose"),
            ("br_landmark", self.landmark_id, "landmark"),
        ):
            ids = getattr(self, name)
            missing = ~np.isin(ids, known)
            if missing.any():
                i = int(np.flatnonzero(missing)[0])
                raise SlamError(f"PoseGraph2D.{name}[{i}]: {what} {int(ids[i])} has no value")

    @property
    def n_factors(self) -> int:
        return int(self.odo_from.size + self.br_pose.size)


def _adjoint(T: np.ndarray) -> np.ndarray:
    """(3, 3) the adjoint of the SE(2) pose T (x, y, theta) in GTSAM's (x, y, theta) tangent
    order: [[R, (y, -x)^T], [0, 1]] (gtsam.Pose2.AdjointMap)."""
    c, s = math.cos(T[2]), math.sin(T[2])
    return np.array([[c, -s, T[1]], [s, c, -T[0]], [0.0, 0.0, 1.0]])


def _rotation3(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def graph_of_problem(p) -> tuple[PoseGraph2D, int]:
    """The pose-landmark graph of a `slam.smoother.Problem` as `slam.smoother.smooth` builds
    it, on the laser's poses L_k = X_k T (see that module's doc): pose k is scan k's laser pose
    (starting value: the EKF's), odometry k-1 -> k is T^-1 D_k T with the information of its
    covariance moved by the adjoint of T^-1, each measurement a bearing-range factor with the
    standard deviations of its covariance's diagonal, landmark ids as run (closures merged).
    The prior on the start is not part of it (a g2o file has none; the solver's gauge fix
    takes its place). Returns (graph, measurements whose covariance has a correlation the
    bearing-range factor leaves out). A problem with pass variables (the pass offset as a
    state) is refused: a g2o file has no factor between two landmarks."""
    if getattr(p, "meas_pass", None) is not None:
        raise SlamError(
            "the run carries its pass offset as a state (measurement.pass_offset_model = "
            '"state"): its graph has a variable per pass tied to its landmark, which a graph of '
            "range-bearing factors cannot hold; solve it with `trunkslam smooth RUN_DIR`, or "
            'export a run with pass_offset_model "inflation"'
        )
    T = np.asarray(p.laser_pose, dtype=np.float64)
    T_inv = se2.inverse(T)
    ad_inv = _adjoint(T_inv)
    n = int(p.scan_t.shape[0])
    pose = np.array([se2.compose(x, T) for x in p.init_pose]).reshape(-1, 3)
    pose[:, 2] = se2.wrap_angle(pose[:, 2])
    delta = np.array([se2.compose(se2.compose(T_inv, d), T) for d in p.odo_delta[1:]])
    delta = delta.reshape(-1, 3)
    delta[:, 2] = se2.wrap_angle(delta[:, 2])
    info = np.empty((n - 1, 3, 3))
    for k in range(1, n):
        A = _rotation3(-p.odo_delta[k, 2])  # the covariance in the frame of the increment
        cov = ad_inv @ (A @ p.odo_cov[k] @ A.T) @ ad_inv.T
        inv = np.linalg.inv(0.5 * (cov + cov.T))
        info[k - 1] = 0.5 * (inv + inv.T)
    R = np.asarray(p.meas_R, dtype=np.float64).reshape(-1, 2, 2)
    corr = np.abs(R[:, 0, 1]) > 1e-12 * np.sqrt(R[:, 0, 0] * R[:, 1, 1])
    g = PoseGraph2D(
        pose_id=np.arange(n),
        pose=pose,
        landmark_id=p.landmark_id,
        landmark_xy=p.init_landmark,
        odo_from=np.arange(n - 1),
        odo_to=np.arange(1, n),
        odo_delta=delta,
        odo_info=info,
        br_pose=p.meas_scan,
        br_landmark=p.meas_landmark,
        br_bearing=p.meas_z[:, 1],
        br_range=p.meas_z[:, 0],
        br_sigma=np.sqrt(np.stack([R[:, 1, 1], R[:, 0, 0]], axis=1)),
    )
    return g, int(corr.sum())
