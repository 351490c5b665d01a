"""The GTSAM smoother: the full nonlinear least-squares solution of what an EKF run did.

With the same odometry, the same measurements and the same associations as the filter, the
smoother shows how much of an EKF's error is linearisation and how much is data. This is the
only module of trunkslam that imports `gtsam`.

The graph (`Problem` holds its inputs; `problem_from_log` takes them from a `SlamLog`):
- one `Pose2` per scan, a prior on the first equal to the EKF's start (mean and covariance, the
  covariance raised by `PRIOR_FLOOR` so that a start with zero covariance stays invertible);
- between consecutive scans the odometry increment of the EKF's prediction (the same Ackermann
  integration, `slam.vehicle.integrate`: mean and covariance, floor noise included);
- one bearing-range factor per associated measurement with the EKF's covariance: by default the
  measurements the EKF used (its updates and the measurement that initialised each landmark),
  optionally also the tentative sightings of landmarks that later joined the map;
- with the pass offset carried as a state (`measurement.pass_offset_model = "state"`, a
  non-zero `pass_offset_sd_m`): one "pass landmark" P_q (Point2) per pass of a landmark, tied
  to its landmark L_i by a BetweenFactorPoint2 (P_q - L_i = b_q, b_q ~ N(0, Sigma_b) in the
  world frame, `Problem.pass_cov`), the pass's bearing-range factors on P_q with the white
  covariance. The sightings of a pass z_j = h(L_i + b_q) + w_j then share one offset, exactly:
  this is the model the per-pass inflation (r + n s^2, the "inflation" model) approximates.
  The results are the landmarks L_i; the pass landmarks are counted (`pass_variables`).
- with an offset that drifts as the view turns (a finite `measurement.pass_offset_corr_rad` L,
  `Problem.pass_corr_rad`): one apparent point A_j (Point2) per sighting instead of one per
  pass, the sighting's bearing-range factor on A_j with the white covariance; in each pass, in
  scan order, A_1 - L_i ~ N(0, Sigma_b) and A_{j+1} - phi_j A_j - (1 - phi_j) L_i ~
  N(0, (1 - phi_j^2) Sigma_b + PASS_FLOOR I), phi_j = exp(-|theta_{j+1} - theta_j| / L)
  (`gm_step_factor`), theta the world bearing of the line of sight at the starting poses
  (`view_angles`): the offset b_j = A_j - L_i is first-order Gauss-Markov in the view angle,
  stationary with covariance Sigma_b, the pass's (its first line of sight, so that the process
  is stationary: a Sigma_b turned at each sighting would need steps (Sigma_b(theta_{j+1}) -
  phi^2 Sigma_b(theta_j)) that are not always covariances). L -> inf is the per-pass graph,
  L -> 0 white sightings of r + Sigma_b (tests/slam/test_smoother_pass_drift.py).

**How the laser offset is modelled.** GTSAM's `BearingRangeFactor2D` observes from the pose it
is attached to, and the laser sits ahead of the rear axle (3.78 m on the Victoria Park ute).
Rather than a Python factor per measurement (a callback per factor and iteration), the graph's
variables are the laser's poses L_k = X_k T (X_k the rear-axle pose, T the laser's pose in the
vehicle frame), so every measurement is a native bearing-range factor from the laser itself.
The odometry X_{k-1}^-1 X_k = D becomes L_{k-1}^-1 L_k = T^-1 D T, and the prior on X_0 a prior
on X_0 T; their covariances move by the adjoint of T^-1 (Log(T^-1 M T) = Ad(T^-1) Log(M)). In
GTSAM's Pose2 chart (x, y, theta of the relative pose) this is exact to first order in the
factor's residual; the second-order difference is |l| theta^2 / 2 for a lever arm l and a
heading residual theta (2e-6 m for 3.8 m and 1 mrad), far below any noise here. The results are
returned for the rear-axle poses X_k = L_k T^-1, with covariances in the world frame (x, y,
theta), directly comparable with the EKF's. tests/slam/test_smoother.py checks the graph
against a hand-built one with the factors written on the rear-axle poses.

Solvers (`SmootherOptions.solver`): "batch" (Levenberg-Marquardt from the EKF's path and map),
"isam2" (the online smoother: iSAM2 fed scan by scan, new poses started from the previous
estimate composed with the odometry and new landmarks from their first measurement), with an
optional batch polish after iSAM2. Robust measurement factors (Huber or Cauchy) are an option,
off by default. `solve_graph_file` solves GTSAM's own Victoria Park graph.

chi2 is twice GTSAM's graph error (the sum of squared whitened residuals, of the Gaussian
factors even when robust kernels were used to solve) and dof the number of residuals minus the
number of unknowns: 2 M - 2 L for M measurements and L landmarks (the prior and odometry supply
exactly the poses' 3 N; each pass landmark brings 2 unknowns and its 2 offset residuals).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np

from slam.errors import SlamError
from slam.graph import PoseGraph2D
from slam.log import CONFIRMED, NEW_TENTATIVE, TENTATIVE_HIT, SlamLog
from slam.measurement import line_of_sight_cov, pass_inflation, pass_sizes
from slam.se2 import wrap_angle

__all__ = [
    "MEAS_INIT",
    "MEAS_TENTATIVE",
    "MEAS_UPDATE",
    "GraphResult",
    "Problem",
    "SmootherOptions",
    "SmootherResult",
    "pose_graph_factors",
    "problem_from_log",
    "smooth",
    "solve_graph_file",
    "solve_pose_graph",
]

# Problem.meas_kind: what the EKF did with each measurement.
MEAS_UPDATE = 0  # used in an update of a mapped landmark
MEAS_INIT = 1  # initialised the landmark when it joined the map
MEAS_TENTATIVE = 2  # a sighting while the landmark was still tentative (the EKF ignores it)

# Added to the prior's covariance (m^2, rad^2): a run that starts from the truth with zero
# covariance gets a prior of 1e-6 m and 1e-6 rad, which GTSAM's Gaussian can invert.
PRIOR_FLOOR = 1e-12
# Added to a pass offset's covariance (m^2): an offset with one axis at 0 (e.g. across the
# line of sight only) gets 0.1 mm on it (1e-5 of the variance of a 3 cm sighting). Stiffer
# ties make GTSAM's elimination call the landmark indeterminate (1e-10 m^2 did, on a tree seen
# in one pass along one line of sight: tests/slam/test_smoother_pass_state.py).
PASS_FLOOR = 1e-8
ROBUST_DEFAULT_K = {"huber": 1.345, "cauchy": 2.3849}  # 95% efficiency under Gaussian noise


def _gtsam_errors(solve: Callable) -> Callable:
    """`solve` with GTSAM's exceptions raised as `SlamError` naming the solve and GTSAM's reason.
    Its Python binding raises C++ exceptions as RuntimeError (an indeterminate linear system,
    e.g. a landmark measured at a range of 1e-300 m, which no bearing pins down; a cheirality
    error; a missing key), std::invalid_argument as ValueError and out_of_range as IndexError.
    The project's own errors pass unchanged."""

    @functools.wraps(solve)
    def wrapped(*args, **kwargs):
        try:
            return solve(*args, **kwargs)
        except SlamError:
            raise
        except (RuntimeError, ValueError, IndexError, OverflowError) as exc:
            reason = " ".join(str(exc).strip().split("\n\n")[0].split()) or type(exc).__name__
            if "Indeterminate" in reason:
                reason += (
                    " (a pose or landmark that its factors do not determine: look for a "
                    "measurement at a range near 0 m or a degenerate covariance)"
                )
            raise SlamError(
                f"smoother: GTSAM could not solve the problem ({solve.__name__}): {reason}"
            ) from None

    return wrapped


def _pose_key(k: int) -> int:
    return gtsam.symbol("x", k)


def _landmark_key(lid: int) -> int:
    return gtsam.symbol("l", lid)


def _pass_key(q: int) -> int:
    return gtsam.symbol("p", q)


def _apparent_key(i: int) -> int:
    return gtsam.symbol("a", i)


@dataclass(frozen=True, eq=False)
class Problem:
    """The smoother's inputs. N scans, M measurements, L landmarks; world frame; m, rad, s.

    scan_t (N,): scan times. prior_pose (3,), prior_cov (3, 3): the EKF's start (rear axle).
    odo_delta (N, 3), odo_cov (N, 3, 3): row k >= 1 the odometry increment from scan k - 1 to
        k in the frame of pose k - 1, and its covariance in that frame (row 0 unused).
    laser_pose (3,): the laser in the vehicle frame.
    meas_scan (M,), meas_landmark (M,): scan index and landmark id of each measurement;
        meas_z (M, 2) [range, bearing] in the laser frame; meas_R (M, 2, 2) its covariance;
        meas_kind (M,): MEAS_UPDATE, MEAS_INIT or MEAS_TENTATIVE.
    init_pose (N, 3): starting values of the poses (the EKF's path).
    landmark_id (L,), init_landmark (L, 2): the landmarks and their starting values.
    Optional, together (the pass offset as a state, P passes; None: no pass variables):
    meas_pass (M,): the pass (0..P-1) of each measurement; pass_landmark (P,): the landmark
        of each pass (every measurement's landmark is its pass's); pass_cov (P, 2, 2): the
        covariance of each pass's offset in the world frame (m^2). A pass no measurement
        refers to is left out of the graph.
    pass_corr_rad (with the pass fields; None or inf: the offset is constant over a pass): the
        correlation length L in rad of the view angle of an offset that drifts over its pass
        (first-order Gauss-Markov, `measurement.pass_offset_corr_rad`; the module doc).
    """

    scan_t: np.ndarray
    prior_pose: np.ndarray
    prior_cov: np.ndarray
    odo_delta: np.ndarray
    odo_cov: np.ndarray
    laser_pose: np.ndarray
    meas_scan: np.ndarray
    meas_landmark: np.ndarray
    meas_z: np.ndarray
    meas_R: np.ndarray
    meas_kind: np.ndarray
    init_pose: np.ndarray
    landmark_id: np.ndarray
    init_landmark: np.ndarray
    meas_pass: np.ndarray | None = None
    pass_landmark: np.ndarray | None = None
    pass_cov: np.ndarray | None = None
    pass_corr_rad: float | None = None

    def __post_init__(self) -> None:
        n = _shape(self, "scan_t", (None,), np.float64)[0]
        if n < 1:
            raise SlamError("Problem.scan_t: no scans")
        m = _shape(self, "meas_scan", (None,), np.int64)[0]
        n_lm = _shape(self, "landmark_id", (None,), np.int64)[0]
        for name, shape, dtype in (
            ("prior_pose", (3,), np.float64),
            ("prior_cov", (3, 3), np.float64),
            ("odo_delta", (n, 3), np.float64),
            ("odo_cov", (n, 3, 3), np.float64),
            ("laser_pose", (3,), np.float64),
            ("meas_landmark", (m,), np.int64),
            ("meas_z", (m, 2), np.float64),
            ("meas_R", (m, 2, 2), np.float64),
            ("meas_kind", (m,), np.int64),
            ("init_pose", (n, 3), np.float64),
            ("init_landmark", (n_lm, 2), np.float64),
        ):
            _shape(self, name, shape, dtype)
        _check_values(self)
        if np.unique(self.landmark_id).size != n_lm:
            raise SlamError("Problem.landmark_id: an id appears twice")
        if m and not (0 <= self.meas_scan.min() and self.meas_scan.max() < n):
            raise SlamError(f"Problem.meas_scan: scan indices must lie in [0, {n})")
        if m and not np.isin(self.meas_kind, (MEAS_UPDATE, MEAS_INIT, MEAS_TENTATIVE)).all():
            raise SlamError("Problem.meas_kind: expected 0 (update), 1 (init) or 2 (tentative)")
        known = np.isin(self.meas_landmark, self.landmark_id)
        if not known.all():
            i = int(np.flatnonzero(~known)[0])
            raise SlamError(
                f"Problem.meas_landmark[{i}]: landmark {int(self.meas_landmark[i])} is not in "
                "landmark_id"
            )
        seen = np.isin(self.landmark_id, self.meas_landmark)
        if not seen.all():
            lid = int(self.landmark_id[np.flatnonzero(~seen)[0]])
            raise SlamError(f"Problem.landmark_id: landmark {lid} has no measurement")
        _positive_definite("Problem.prior_cov", self.prior_cov[None], semi=True)
        _positive_definite("Problem.odo_cov", self.odo_cov[1:], first=1)
        _positive_definite("Problem.meas_R", self.meas_R)
        if m and not (self.meas_z[:, 0] > 0).all():
            raise SlamError("Problem.meas_z: ranges must be > 0")
        _check_passes(self, m)

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])

    @property
    def n_measurements(self) -> int:
        return int(self.meas_scan.shape[0])

    @property
    def pass_variables(self) -> int:
        """The pass landmarks the graph gets: the passes with a measurement (0: none), or with
        a drifting offset (a finite `pass_corr_rad`) one apparent point per measurement."""
        if self.meas_pass is None:
            return 0
        return self.n_measurements if self.drifts else int(np.unique(self.meas_pass).size)

    @property
    def drifts(self) -> bool:
        """Whether the pass offset drifts (pass fields and a finite `pass_corr_rad`)."""
        c = self.pass_corr_rad
        return self.meas_pass is not None and c is not None and math.isfinite(c)

    def arrays(self) -> dict[str, np.ndarray]:
        """The fields given, as a dict of arrays (what the run-log file stores)."""
        out = {name: getattr(self, name) for name in self.__dataclass_fields__}
        return {name: np.asarray(a) for name, a in out.items() if a is not None}


def _shape(obj, name: str, shape: tuple, dtype) -> tuple[int, ...]:
    """Check and coerce obj.name to `dtype` with `shape` (None: any length); finite floats.
    Only real numbers are taken (integers for the integer fields): booleans, complex numbers,
    dates, strings and objects are refused, not cast."""
    v = getattr(obj, name)
    kinds = "fiu" if dtype is np.float64 else "iuf"
    try:
        given = np.asarray(v)
        if given.dtype.kind not in kinds:
            raise SlamError(
                f"Problem.{name}: expected {'numbers' if kinds == 'fiu' else 'integers'}, got "
                f"dtype {given.dtype}"
            )
        with np.errstate(invalid="ignore", over="ignore"):
            a = given.astype(dtype)
    except (TypeError, ValueError, OverflowError) as e:
        if isinstance(e, SlamError):
            raise
        raise SlamError(f"Problem.{name}: expected numbers, got {type(v).__name__}") from e
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise SlamError(f"Problem.{name}: expected shape {want}, got {a.shape}")
    if dtype is np.float64 and not np.isfinite(a).all():
        raise SlamError(f"Problem.{name}: contains NaN or infinite values")
    if dtype is np.int64 and np.asarray(v).dtype.kind == "f" and not np.array_equal(a, v):
        raise SlamError(f"Problem.{name}: expected integers")
    object.__setattr__(obj, name, a)
    return a.shape


# |landmark id| (gtsam keys hold 56 bits of index); the value limits are the sequence file's
MAX_LANDMARK_ID = 2**53


def _check_values(p: Problem) -> None:
    """Times strictly increasing, every value within the sequence file's limits (beyond them a
    value is a corrupt file: its squares overflow in the solve), integers whole and in range."""
    from slam.sequence import MAX_ANGLE_RAD, MAX_COORDINATE_M, MAX_TIME_S, MAX_VARIANCE
    from slam.validators import times

    times("Problem.scan_t", p.scan_t)
    limits = [("scan_t", p.scan_t, MAX_TIME_S, "s"), ("meas_R", p.meas_R, MAX_VARIANCE, ""),
              ("prior_cov", p.prior_cov, MAX_VARIANCE, ""), ("odo_cov", p.odo_cov, MAX_VARIANCE,
              ""), ("init_landmark", p.init_landmark, MAX_COORDINATE_M, "m"),
              ("meas_z", p.meas_z[:, :1], MAX_COORDINATE_M, "m"),
              ("meas_z", p.meas_z[:, 1:], MAX_ANGLE_RAD, "rad")]  # fmt: skip
    for name in ("prior_pose", "odo_delta", "laser_pose", "init_pose"):
        a = getattr(p, name)
        limits += [(name, a[..., :2], MAX_COORDINATE_M, "m"), (name, a[..., 2:], MAX_ANGLE_RAD,
                   "rad")]  # fmt: skip
    for name in ("meas_landmark", "landmark_id"):
        limits.append((name, getattr(p, name), MAX_LANDMARK_ID, ""))
    for name, a, bound, unit in limits:
        if a.size and np.abs(a).max() > bound:
            raise SlamError(
                f"Problem.{name}: {float(np.abs(a).max()):.6g} is beyond the limit of "
                f"+-{bound:g} {unit}".rstrip()
            )
    if p.landmark_id.size and p.landmark_id.min() < 0:
        raise SlamError("Problem.landmark_id: ids must be >= 0")


PASS_FIELDS = ("meas_pass", "pass_landmark", "pass_cov")


def _check_passes(p: Problem, m: int) -> None:
    """The optional pass fields: all or none, shapes, each measurement's pass of its landmark,
    each offset covariance positive definite and within the sequence file's limit."""
    from slam.sequence import MAX_VARIANCE

    given = [name for name in PASS_FIELDS if getattr(p, name) is not None]
    if not given:
        if p.pass_corr_rad is not None:
            raise SlamError("Problem.pass_corr_rad: given without the pass fields (meas_pass, "
                            "pass_landmark, pass_cov)")  # fmt: skip
        return
    if len(given) < len(PASS_FIELDS):
        missing = ", ".join(name for name in PASS_FIELDS if name not in given)
        raise SlamError(f"Problem: {missing} missing (meas_pass, pass_landmark and pass_cov "
                        "come together)")  # fmt: skip
    n_pass = _shape(p, "pass_landmark", (None,), np.int64)[0]
    _shape(p, "meas_pass", (m,), np.int64)
    _shape(p, "pass_cov", (n_pass, 2, 2), np.float64)
    if m and not (0 <= p.meas_pass.min() and p.meas_pass.max() < n_pass):
        raise SlamError(f"Problem.meas_pass: pass indices must lie in [0, {n_pass})")
    wrong = np.flatnonzero(p.pass_landmark[p.meas_pass] != p.meas_landmark)
    if wrong.size:
        i = int(wrong[0])
        raise SlamError(
            f"Problem.meas_pass[{i}]: pass {int(p.meas_pass[i])} is of landmark "
            f"{int(p.pass_landmark[p.meas_pass[i]])}, the measurement of landmark "
            f"{int(p.meas_landmark[i])}"
        )
    if n_pass and np.abs(p.pass_cov).max() > MAX_VARIANCE:
        raise SlamError(
            f"Problem.pass_cov: {float(np.abs(p.pass_cov).max()):.6g} is beyond the limit of "
            f"+-{MAX_VARIANCE:g}"
        )
    _positive_definite("Problem.pass_cov", p.pass_cov)
    c = p.pass_corr_rad
    if c is not None:
        a = np.asarray(c)
        ok = a.shape == () and a.dtype.kind in "fiu" and not isinstance(c, bool)
        if not ok or not float(a) > 0:
            raise SlamError(f"Problem.pass_corr_rad: expected a length > 0 rad (inf: constant "
                            f"over a pass), got {c!r}")  # fmt: skip
        object.__setattr__(p, "pass_corr_rad", float(a))


def _positive_definite(name: str, covs: np.ndarray, first: int = 0, semi: bool = False) -> None:
    if not covs.shape[0]:
        return
    sym = np.abs(covs - np.swapaxes(covs, -1, -2)).max(axis=(-1, -2))
    scale = np.abs(covs).max(axis=(-1, -2))
    bad = sym > 1e-9 * np.maximum(scale, 1e-300)
    ok = ~bad
    low = np.linalg.eigvalsh(covs[ok]).min(axis=-1)
    ok[ok] = low >= -1e-12 * scale[ok] if semi else low > 0
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        what = "semi-definite" if semi else "definite"
        raise SlamError(f"{name}[{i + first}]: not a symmetric positive {what} covariance")


def problem_from_log(log: SlamLog, measurements: str = "ekf") -> Problem:
    """The smoother's inputs from what an EKF run did.

    measurements: "ekf" (the measurements the filter used: its updates and each landmark's
        initialising measurement) or "all" (also the tentative sightings of the landmarks that
        joined the map, which the filter never uses).
    Measurements of landmarks that left the map (`MapPolicy` pruning) are left out. With a
    pass offset in the run's configuration (`measurement.pass_offset_sd_m`), each measurement
    of a pass of n sightings of its landmark (all its sightings in the log, tentative ones
    included, with the filter's gap rule) gets the batch pass variance r + n s^2 per axis
    (`slam.measurement.pass_inflation`): the covariance the smoother and an exported graph
    use. With `measurement.pass_offset_model = "state"` instead, the measurements keep their
    white covariance and the problem gets the passes (`pass_offsets`): a variable per pass.
    """
    if measurements not in ("ekf", "all"):
        raise SlamError(f"measurements: expected 'ekf' or 'all', got {measurements!r}")
    st = log.meas_status
    kind = np.full(st.shape, -1, np.int64)
    kind[st >= 0] = MEAS_UPDATE
    kind[st == CONFIRMED] = MEAS_INIT
    if measurements == "all":
        tentative = ((st == NEW_TENTATIVE) | (st == TENTATIVE_HIT)) & np.isin(
            log.meas_track, log.landmark_id
        )
        kind[tentative] = MEAS_TENTATIVE
    # a landmark the map policy pruned is not in the final map: its measurements stay out
    use = (kind >= 0) & np.isin(log.meas_track, log.landmark_id)
    passes = pass_offsets(log, use)
    return Problem(
        scan_t=log.scan_t,
        prior_pose=log.start_pose,
        prior_cov=log.start_cov,
        odo_delta=log.odo_delta,
        odo_cov=log.odo_cov,
        laser_pose=log.laser_pose,
        meas_scan=log.meas_scan[use],
        meas_landmark=log.meas_track[use],
        meas_z=log.meas_z[use],
        meas_R=log.meas_R[use] if passes else _pass_R(log, use),
        meas_kind=kind[use],
        init_pose=log.pose,
        landmark_id=log.landmark_id,
        init_landmark=log.landmark_xy,
        **passes,
    )


def _pass_settings(log: SlamLog) -> tuple[tuple[float, float], float, str]:
    """The run's pass offset: (range, across) sd in m, the gap in s, the model."""
    cfg = log.config.get("measurement", {}) if isinstance(log.config, dict) else {}
    sd = tuple(float(v) for v in cfg.get("pass_offset_sd_m", (0.0, 0.0)))
    gap = float(cfg.get("pass_gap_s", 2.0))
    return (sd[0], sd[1]), gap, str(cfg.get("pass_offset_model", "inflation"))


def _pass_R(log: SlamLog, use: np.ndarray) -> np.ndarray:
    """The covariances of measurements `use` of `log`, with the run's pass offset (batch)."""
    sd, gap, _ = _pass_settings(log)
    if sd == (0.0, 0.0):
        return log.meas_R[use]
    st = log.meas_status
    sighting = (st >= 0) | (st == CONFIRMED) | (st == NEW_TENTATIVE) | (st == TENTATIVE_HIT)
    sighting &= np.isin(log.meas_track, log.landmark_id)
    rows = np.flatnonzero(sighting)
    t = log.scan_t[log.meas_scan[rows]]
    _, size = pass_sizes(t, log.meas_track[rows], gap)
    n = np.zeros(st.shape, np.int64)
    n[rows] = size
    return pass_inflation(log.meas_z[use], log.meas_R[use], n[use], sd, batch=True)


def pass_offsets(log: SlamLog, use: np.ndarray) -> dict[str, np.ndarray]:
    """`Problem`'s pass fields for measurements `use` (K,) bool of `log` when the run carries
    the pass offset as a state (`measurement.pass_offset_model = "state"`, a non-zero
    `pass_offset_sd_m`); {} otherwise.

    The passes are the filter's (`pass_numbers`: the gap rule over each landmark's updates,
    under the id it had then), except that the filter also ends a pass at a loop closure's
    merge or re-registration (`slam.pass_state`), which the graph does not. Each pass's offset
    covariance in the world frame is Sigma_b = Rot(beta) diag(s_r^2, s_a^2) Rot(beta)^T
    (+ `PASS_FLOOR`), beta the bearing in the world of the line of sight from the laser at the
    pass's first sighting (the EKF's pose) to the landmark's estimate (the EKF's map)."""
    sd, gap, model = _pass_settings(log)
    if model != "state" or sd == (0.0, 0.0):
        return {}
    rows = np.flatnonzero(use)
    scan = log.meas_scan[rows]
    t = log.scan_t[scan]
    track = log.meas_track if log.meas_track_unmerged is None else log.meas_track_unmerged
    number = pass_numbers(t, track[rows], log.meas_status[rows] >= 0, gap)
    order = np.lexsort((t, number))
    first = order[np.r_[True, number[order][1:] != number[order][:-1]]]  # by pass number
    lid = log.meas_track[rows][first]
    x = log.pose[scan[first]]
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    lx, ly = log.laser_pose[0], log.laser_pose[1]
    laser_xy = np.stack([x[:, 0] + c * lx - s * ly, x[:, 1] + s * lx + c * ly], axis=1)
    row_of = {int(v): j for j, v in enumerate(log.landmark_id.tolist())}
    d = log.landmark_xy[[row_of[int(v)] for v in lid]] - laser_xy
    corr = log.config.get("measurement", {}).get("pass_offset_corr_rad", math.inf)
    return {
        "meas_pass": number,
        "pass_landmark": lid,
        "pass_cov": pass_offset_cov(np.arctan2(d[:, 1], d[:, 0]), sd),
        **({"pass_corr_rad": float(corr)} if math.isfinite(float(corr)) else {}),
    }


def pass_numbers(t_s, landmark, update, gap_s: float) -> np.ndarray:
    """The pass (0..P-1) of each sighting at times t_s (m,) of landmarks `landmark` (m,):
    the sightings with `update` (m,) True are the filter's updates, grouped as the filter
    counts its passes (the gap rule over a landmark's updates, `slam.measurement.pass_sizes`,
    `slam.history.RunHistory.pass_index`); another sighting (the one that initialised its
    landmark, a tentative one) joins the pass of its landmark's nearest update in time when
    that is at most `gap_s` away, else the gap rule groups such sightings among themselves."""
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    lm = np.asarray(landmark, dtype=np.int64).reshape(-1)
    update = np.asarray(update, dtype=bool).reshape(-1)
    out = np.full(t.size, -1, np.int64)
    if not t.size:
        return out
    up, other = np.flatnonzero(update), np.flatnonzero(~update)
    out[up] = pass_sizes(t[up], lm[up], gap_s)[0]
    # one sorted key per sighting: landmarks apart by more than the time span and the gap
    _, rank = np.unique(lm, return_inverse=True)
    span = float(t.max() - t.min()) + 2.0 * gap_s + 1.0
    key = rank * span + (t - t.min())
    o = np.argsort(key[up], kind="stable")
    ukey = key[up][o]
    if up.size and other.size:
        i = np.searchsorted(ukey, key[other])
        lo, hi = np.clip(i - 1, 0, up.size - 1), np.clip(i, 0, up.size - 1)
        d_lo, d_hi = np.abs(ukey[lo] - key[other]), np.abs(ukey[hi] - key[other])
        near = np.where(d_lo <= d_hi, lo, hi)
        joined = np.minimum(d_lo, d_hi) <= gap_s
        out[other[joined]] = out[up[o[near[joined]]]]
    orphan = np.flatnonzero(out < 0)
    if orphan.size:
        out[orphan] = out.max() + 1 + pass_sizes(t[orphan], lm[orphan], gap_s)[0]
    return out


def pass_offset_cov(beta_rad, sd) -> np.ndarray:
    """(P, 2, 2) world-frame covariances of pass offsets with standard deviations sd = (range,
    across) in m along and across lines of sight at world bearings beta_rad (P,):
    Rot(beta) diag(s_r^2, s_a^2) Rot(beta)^T + `PASS_FLOOR` I."""
    return line_of_sight_cov(beta_rad, (float(sd[0]), float(sd[1]))) + PASS_FLOOR * np.eye(2)


@dataclass(frozen=True)
class SmootherOptions:
    """How to solve.

    solver: "batch" (Levenberg-Marquardt from the problem's starting values) or "isam2" (fed
        scan by scan, `isam2_every` scans per update). polish: after iSAM2, a batch
        Levenberg-Marquardt from its estimate. robust: None, "huber" or "cauchy" on the
        measurement factors, with threshold `robust_k` (whitened units; None: 1.345 for Huber,
        2.3849 for Cauchy). max_iterations, relative_error_tol: the Levenberg-Marquardt stops
        (GTSAM's defaults but 100 iterations). relinearize_threshold, relinearize_skip: iSAM2's
        (GTSAM's defaults). partial_relinearization_check: iSAM2 looks for variables to
        relinearise only in the part of the tree an update touches (GTSAM's option, off by
        default there; on the Victoria Park run 40 s instead of 64 s for the same chi-square).
        marginals: compute the poses' and landmarks' marginal covariances.
    """

    solver: str = "batch"
    polish: bool = False
    robust: str | None = None
    robust_k: float | None = None
    max_iterations: int = 100
    relative_error_tol: float = 1e-5
    isam2_every: int = 1
    relinearize_threshold: float = 0.1
    relinearize_skip: int = 10
    partial_relinearization_check: bool = True
    marginals: bool = True

    def __post_init__(self) -> None:
        if self.solver not in ("batch", "isam2"):
            raise SlamError(
                f"SmootherOptions.solver: expected 'batch' or 'isam2', got {self.solver!r}"
            )
        if self.robust not in (None, "huber", "cauchy"):
            raise SlamError(
                f"SmootherOptions.robust: expected None, 'huber' or 'cauchy', got {self.robust!r}"
            )
        for name in ("polish", "marginals", "partial_relinearization_check"):
            if not isinstance(getattr(self, name), bool):
                raise SlamError(f"SmootherOptions.{name}: expected true or false")
        for name in ("max_iterations", "isam2_every", "relinearize_skip"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 1 <= v < 2**31:
                raise SlamError(f"SmootherOptions.{name}: expected an integer >= 1, got {v!r}")
        for name in ("relative_error_tol", "relinearize_threshold", "robust_k"):
            v = getattr(self, name)
            if v is None and name == "robust_k":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < math.inf:
                raise SlamError(f"SmootherOptions.{name}: expected a number > 0, got {v!r}")

    def kernel_k(self) -> float:
        return ROBUST_DEFAULT_K[self.robust] if self.robust_k is None else float(self.robust_k)


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """The smoothed run. N scans, L landmarks; world frame; m, rad.

    pose (N, 3), pose_cov (N, 3, 3): the rear-axle poses and their marginal covariances in
        (x, y, theta) (NaN when marginals were not asked for).
    landmark_id (L,), landmark_xy (L, 2), landmark_cov (L, 2, 2): the map.
    chi2, dof: final chi-square (Gaussian factors) and degrees of freedom; initial_chi2 at the
        starting values (batch) or of the iSAM2 estimate before a polish.
    iterations: Levenberg-Marquardt iterations (batch or polish) or iSAM2 updates.
    seconds: building the graph and solving; seconds_marginals: the covariances.
    pass_variables: the pass landmarks in the graph (the pass offset as a state; 0: none).
    """

    pose: np.ndarray
    pose_cov: np.ndarray
    landmark_id: np.ndarray
    landmark_xy: np.ndarray
    landmark_cov: np.ndarray
    chi2: float
    dof: int
    initial_chi2: float
    iterations: int
    seconds: float
    seconds_marginals: float
    solver: str
    robust: str | None
    pass_variables: int = 0

    @property
    def chi2_per_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan


# ---- the graph ----------------------------------------------------------------------------------


class _Graph:
    """The factors of a `Problem` on the laser poses, grouped by the scan that brings them."""

    def __init__(self, p: Problem, robust: str | None, robust_k: float) -> None:
        self.p = p
        self.T = gtsam.Pose2(*p.laser_pose)
        self.T_inv = self.T.inverse()
        self.ad_inv = self.T_inv.AdjointMap()
        n = p.n_scans
        self.by_scan: list[list] = [[] for _ in range(n)]
        self.gaussian = gtsam.NonlinearFactorGraph()  # for chi2 when robust kernels are used
        self.robust = robust is not None
        # prior on L_0 = X_0 T
        x0 = p.prior_pose
        B = _frame_rotation(-x0[2])
        cov0 = self.ad_inv @ B @ (p.prior_cov + PRIOR_FLOOR * np.eye(3)) @ B.T @ self.ad_inv.T
        self._add(0, gtsam.PriorFactorPose2(_pose_key(0), self.laser_of(x0), _gauss(cov0)), None)
        for k in range(1, n):
            d = p.odo_delta[k]
            A = _frame_rotation(-d[2])
            cov = self.ad_inv @ (A @ p.odo_cov[k] @ A.T) @ self.ad_inv.T
            meas = self.T_inv.compose(gtsam.Pose2(*d)).compose(self.T)
            f = gtsam.BetweenFactorPose2(_pose_key(k - 1), _pose_key(k), meas, _gauss(cov))
            self._add(k, f, None)
        self.passes = self._pass_factors(p)
        swap = np.array([[0.0, 1.0], [1.0, 0.0]])  # (range, bearing) -> (bearing, range)
        for i, (k, z, R) in enumerate(zip(p.meas_scan, p.meas_z, p.meas_R)):
            keys = (_pose_key(int(k)), self.point_key(i))
            noise = _gauss(swap @ R @ swap)
            model = noise
            if robust is not None:
                est = (
                    gtsam.noiseModel.mEstimator.Huber
                    if robust == "huber"
                    else gtsam.noiseModel.mEstimator.Cauchy
                ).Create(robust_k)
                model = gtsam.noiseModel.Robust.Create(est, noise)
            bearing = gtsam.Rot2(float(z[1]))
            f = gtsam.BearingRangeFactor2D(*keys, bearing, float(z[0]), model)
            g = gtsam.BearingRangeFactor2D(*keys, bearing, float(z[0]), noise)
            self._add(int(k), f, g)

    def _pass_factors(self, p: Problem) -> np.ndarray:
        """The pass landmarks' factors P_q - L_i = b_q ~ N(0, pass_cov[q]), each with the scan
        of its pass's first measurement. Returns the passes in the graph (those measured)."""
        if p.meas_pass is None:
            return np.zeros(0, np.int64)
        if p.drifts:
            return self._drift_factors(p)
        first = np.full(p.pass_landmark.size, p.n_scans, np.int64)
        np.minimum.at(first, p.meas_pass, p.meas_scan)
        used = np.flatnonzero(first < p.n_scans)
        for q in used.tolist():
            keys = (_landmark_key(int(p.pass_landmark[q])), _pass_key(q))
            f = gtsam.BetweenFactorPoint2(*keys, np.zeros(2), _gauss(p.pass_cov[q]))
            self._add(int(first[q]), f, None)
        return used

    def _drift_factors(self, p: Problem) -> np.ndarray:
        """The apparent points A_j of a drifting pass offset (module doc), each pass's in scan
        order: A_1 - L_i ~ N(0, Sigma_b) at the pass's first scan, then the Gauss-Markov step
        A_{j+1} - phi A_j - (1 - phi) L_i ~ N(0, (1 - phi^2) Sigma_b), phi = exp(-|dtheta| / L)
        at the scan of j + 1. Returns the measurements (one variable each)."""
        theta = view_angles(p)
        order = np.lexsort((np.arange(p.n_measurements), p.meas_scan, p.meas_pass))
        q = p.meas_pass[order]
        new = np.r_[True, q[1:] != q[:-1]]
        for i in order[new].tolist():
            keys = (_landmark_key(int(p.meas_landmark[i])), _apparent_key(i))
            f = gtsam.BetweenFactorPoint2(*keys, np.zeros(2), _gauss(p.pass_cov[p.meas_pass[i]]))
            self._add(int(p.meas_scan[i]), f, None)
        for a, b in zip(order[:-1][~new[1:]].tolist(), order[1:][~new[1:]].tolist()):
            phi = math.exp(-abs(float(wrap_angle(theta[b] - theta[a]))) / p.pass_corr_rad)
            cov = (1.0 - phi * phi) * p.pass_cov[p.meas_pass[b]] + PASS_FLOOR * np.eye(2)
            keys = (_apparent_key(a), _apparent_key(b), _landmark_key(int(p.meas_landmark[b])))
            self._add(int(p.meas_scan[b]), gm_step_factor(keys, phi, cov), None)
        return np.arange(p.n_measurements)

    def pass_points(self) -> list[tuple[int, int]]:
        """(key, landmark id) of each pass landmark or apparent point in the graph."""
        p = self.p
        if p.drifts:
            return [(_apparent_key(i), int(v)) for i, v in enumerate(p.meas_landmark.tolist())]
        return [(_pass_key(q), int(p.pass_landmark[q])) for q in self.passes.tolist()]

    def point_key(self, i: int) -> int:
        """The point measurement i observes: its apparent point (a drifting pass offset), its
        pass landmark (a constant one), else its landmark."""
        if self.p.meas_pass is None:
            return _landmark_key(int(self.p.meas_landmark[i]))
        if self.p.drifts:
            return _apparent_key(i)
        return _pass_key(int(self.p.meas_pass[i]))

    def _add(self, k: int, factor, gaussian) -> None:
        self.by_scan[k].append(factor)
        self.gaussian.add(factor if gaussian is None else gaussian)

    def laser_of(self, pose) -> gtsam.Pose2:
        return gtsam.Pose2(*pose).compose(self.T)

    def all(self) -> gtsam.NonlinearFactorGraph:
        g = gtsam.NonlinearFactorGraph()
        for fs in self.by_scan:
            for f in fs:
                g.add(f)
        return g

    def chi2(self, values: gtsam.Values) -> float:
        return 2.0 * self.gaussian.error(values)


def view_angles(p: Problem) -> np.ndarray:
    """(M,) the world bearing (rad) of each measurement's line of sight at the problem's
    starting poses: the pose's heading, the laser's yaw and the measured bearing."""
    return p.init_pose[p.meas_scan, 2] + p.laser_pose[2] + p.meas_z[:, 1]


def gm_step_factor(keys, phi: float, cov: np.ndarray):
    """The Gauss-Markov step of a drifting pass offset on keys (A_j, A_{j+1}, L_i), all Point2:
    error A_{j+1} - phi A_j - (1 - phi) L_i with covariance `cov` (world frame, m^2). Linear in
    vector-space variables, so a native linear factor states it exactly: GTSAM's
    LinearContainerFactor of the whitened JacobianFactor (blocks W (-phi I, I, -(1 - phi) I),
    W the square-root information of `cov`) about the origin, which relinearises at a point x
    with the right-hand side moved by the blocks times x. (A gtsam.CustomFactor, a Python
    callback per factor, made one Levenberg-Marquardt iteration of scans 1-2000 take minutes.)"""
    W = _gauss(cov).R()
    blocks = (-phi * W, W, -(1.0 - phi) * W)
    unit = gtsam.noiseModel.Unit.Create(2)
    # GTSAM's ternary constructor (key, block) x 3, b, model: positional only in the binding
    terms = [x for kb in zip(keys, blocks) for x in kb]
    lin = gtsam.JacobianFactor(*terms, np.zeros(2), unit)
    origin = gtsam.Values()
    for k in keys:
        origin.insert(k, np.zeros(2))
    return gtsam.LinearContainerFactor(lin, origin)


def _gauss(cov: np.ndarray):
    return gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T))


def _frame_rotation(theta: float) -> np.ndarray:
    """(3, 3) blockdiag(R(theta), 1)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _lm_params(o: SmootherOptions) -> gtsam.LevenbergMarquardtParams:
    prm = gtsam.LevenbergMarquardtParams()
    prm.setMaxIterations(int(o.max_iterations))
    prm.setRelativeErrorTol(float(o.relative_error_tol))
    return prm


@_gtsam_errors
def smooth(
    problem: Problem,
    options: SmootherOptions | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> SmootherResult:
    """Solve the smoothing problem; see the module doc for the graph and the solvers.

    progress: callback(stage, done, total): "isam2" after each update (done = scans fed), then
    "optimise" (0 of 1, then 1 of 1) around a batch or polishing solve and "covariances"
    around the marginals."""
    report = progress or (lambda stage, done, total: None)
    if not isinstance(problem, Problem):
        raise SlamError(f"problem: expected a slam.smoother.Problem, got {type(problem).__name__}")
    o = options or SmootherOptions()
    if not isinstance(o, SmootherOptions):
        raise SlamError(f"options: expected SmootherOptions, got {type(o).__name__}")
    t0 = time.perf_counter()
    g = _Graph(problem, o.robust, o.kernel_k() if o.robust else 0.0)
    if o.solver == "batch":
        values = gtsam.Values()
        for k in range(problem.n_scans):
            values.insert(_pose_key(k), g.laser_of(problem.init_pose[k]))
        start = {}
        for lid, xy in zip(problem.landmark_id, problem.init_landmark):
            start[int(lid)] = np.asarray(xy, dtype=np.float64)
            values.insert(_landmark_key(int(lid)), start[int(lid)])
        for key, lid in g.pass_points():  # a pass landmark or apparent point: at its landmark
            values.insert(key, start[lid])
        initial = g.chi2(values)
        report("optimise", 0, 1)
        opt = gtsam.LevenbergMarquardtOptimizer(g.all(), values, _lm_params(o))
        values = opt.optimize()
        iterations = int(opt.iterations())
        report("optimise", 1, 1)
    else:
        values, iterations = _isam2(g, o, report)
        initial = g.chi2(values)
        if o.polish:
            report("optimise", 0, 1)
            opt = gtsam.LevenbergMarquardtOptimizer(g.all(), values, _lm_params(o))
            values = opt.optimize()
            iterations = int(opt.iterations())
            report("optimise", 1, 1)
    seconds = time.perf_counter() - t0
    t1 = time.perf_counter()
    if o.marginals:
        report("covariances", 0, 1)
    pose, pose_cov, lm_xy, lm_cov = _read(g, values, o.marginals)
    if o.marginals:
        report("covariances", 1, 1)
    return SmootherResult(
        pose=pose,
        pose_cov=pose_cov,
        landmark_id=problem.landmark_id.copy(),
        landmark_xy=lm_xy,
        landmark_cov=lm_cov,
        chi2=g.chi2(values),
        dof=2 * problem.n_measurements - 2 * int(problem.landmark_id.size),
        initial_chi2=initial,
        iterations=iterations,
        seconds=seconds,
        seconds_marginals=time.perf_counter() - t1,
        solver=o.solver + ("+polish" if o.solver == "isam2" and o.polish else ""),
        robust=o.robust,
        pass_variables=int(g.passes.size),
    )


def _isam2(g: _Graph, o: SmootherOptions, report) -> tuple[gtsam.Values, int]:
    """iSAM2 fed scan by scan (`isam2_every` scans per update): a new pose starts at the
    previous estimate composed with the odometry, a new landmark at its first measurement."""
    prm = gtsam.ISAM2Params()
    prm.setRelinearizeThreshold(float(o.relinearize_threshold))
    prm.relinearizeSkip = int(o.relinearize_skip)
    prm.enablePartialRelinearizationCheck = bool(o.partial_relinearization_check)
    isam = gtsam.ISAM2(prm)
    p = g.p
    known: set[int] = set()
    prev = g.laser_of(p.prior_pose)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    updates = 0
    order = np.argsort(p.meas_scan, kind="stable")
    meas_at = np.split(order, np.searchsorted(p.meas_scan[order], np.arange(1, p.n_scans)))
    for k in range(p.n_scans):
        if k > 0:  # L_k = L_{k-1} (T^-1 D_k T)
            prev = prev.compose(g.T_inv.compose(gtsam.Pose2(*p.odo_delta[k])).compose(g.T))
        values.insert(_pose_key(k), prev)
        for f in g.by_scan[k]:
            graph.add(f)
        for i in meas_at[k]:  # a new landmark or pass landmark starts at the measured point
            r, b = p.meas_z[i]
            for key in {_landmark_key(int(p.meas_landmark[i])), g.point_key(i)}:
                if key not in known:
                    known.add(key)
                    values.insert(
                        key, prev.transformFrom(np.array([r * math.cos(b), r * math.sin(b)]))
                    )
        if (k + 1) % o.isam2_every == 0 or k == p.n_scans - 1:
            isam.update(graph, values)
            updates += 1
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            prev = isam.calculateEstimatePose2(_pose_key(k))
            report("isam2", k + 1, p.n_scans)
    return isam.calculateEstimate(), updates


def _read(g: _Graph, values: gtsam.Values, marginals: bool):
    """Rear-axle poses, world-frame covariances, and the map from a solution on laser poses."""
    p = g.p
    n, n_lm = p.n_scans, p.landmark_id.size
    pose = np.empty((n, 3))
    pose_cov = np.full((n, 3, 3), np.nan)
    lm_xy = np.empty((n_lm, 2))
    lm_cov = np.full((n_lm, 2, 2), np.nan)
    for k in range(n):
        x = values.atPose2(_pose_key(k)).compose(g.T_inv)
        pose[k] = (x.x(), x.y(), x.theta())
    for j, lid in enumerate(p.landmark_id):
        lm_xy[j] = values.atPoint2(_landmark_key(int(lid)))
    if marginals:
        m = gtsam.Marginals(g.all(), values)
        ad = g.T.AdjointMap()
        for k in range(n):
            J = _frame_rotation(pose[k, 2]) @ ad  # laser tangent -> rear-axle tangent -> world
            C = J @ m.marginalCovariance(_pose_key(k)) @ J.T
            pose_cov[k] = 0.5 * (C + C.T)
        for j, lid in enumerate(p.landmark_id):
            lm_cov[j] = m.marginalCovariance(_landmark_key(int(lid)))
    return pose, pose_cov, lm_xy, lm_cov


# ---- GTSAM's own Victoria Park graph ------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GraphResult:
    """A solve of a graph file in GTSAM's 2D dataset format.

    n_factors, n_values: what `gtsam.load2D` read (the gauge prior not counted); n_poses,
    n_landmarks. chi2, dof: final chi-square and residuals minus unknowns (the 3 gauge
    freedoms fixed by the prior); initial_chi2: at the file's values. seconds: the solve
    (reading the file not included); iterations: LM iterations of the last stage.
    pose (n_poses, 3), pose_id; landmark_xy (n_landmarks, 2), landmark_id: the solution.
    """

    method: str
    n_factors: int
    n_values: int
    n_poses: int
    n_landmarks: int
    chi2: float
    dof: int
    initial_chi2: float
    seconds: float
    iterations: int
    pose_id: np.ndarray
    pose: np.ndarray
    landmark_id: np.ndarray
    landmark_xy: np.ndarray

    @property
    def chi2_per_dof(self) -> float:
        return self.chi2 / self.dof


GRAPH_METHODS = ("isam2-chunks", "isam2", "batch")


@_gtsam_errors
def solve_graph_file(
    path: str | Path, method: str = "isam2-chunks", chunk_poses: int = 25, polish: bool = True
) -> GraphResult:
    """Solve a 2D pose-landmark graph file (e.g. GTSAM's `victoria_park.txt`).

    method: "batch" (Levenberg-Marquardt from the file's dead-reckoned values), "isam2"
    (iSAM2 one pose at a time) or "isam2-chunks" (iSAM2 fed `chunk_poses` poses per update;
    each new pose starts at the previous estimate composed with its odometry and each new
    landmark at its first bearing-range measurement). polish: a batch Levenberg-Marquardt after
    iSAM2. The first pose gets a prior (sigma 1e-6) that fixes the gauge and adds no error.
    """
    _check_method(method, chunk_poses)
    path = Path(path)
    if not path.is_file():
        raise SlamError(f"{path}: no such graph file")
    graph, values = gtsam.load2D(str(path))
    if not values.size() or not graph.size():
        raise SlamError(f"{path}: no poses or no factors read (not a GTSAM 2D graph file?)")
    return _solve_loaded(graph, values, method, chunk_poses, polish=polish)


def _check_method(method: str, chunk_poses: int) -> None:
    if method not in GRAPH_METHODS:
        raise SlamError(f"method: expected one of {list(GRAPH_METHODS)}, got {method!r}")
    if isinstance(chunk_poses, bool) or not isinstance(chunk_poses, int) or chunk_poses < 1:
        raise SlamError(f"chunk_poses: expected an integer >= 1, got {chunk_poses!r}")


@_gtsam_errors
def solve_pose_graph(
    pg: PoseGraph2D,
    method: str = "batch",
    chunk_poses: int = 25,
    polish: bool = True,
    fixed: int | None = None,
) -> GraphResult:
    """Solve a `slam.graph.PoseGraph2D` (e.g. a g2o file read by `experiments.io.g2o`) as
    `solve_graph_file` solves a file: the same factors GTSAM's `readG2o` makes of it (keys: pose
    id i, landmark id l as L(l)), and a prior (sigma 1e-6) on pose `fixed` (None: the pose of
    lowest id) at its starting value to fix the gauge. The result's landmark_id are the graph's
    ids, not GTSAM keys."""
    if not isinstance(pg, PoseGraph2D):
        raise SlamError(f"graph: expected a slam.graph.PoseGraph2D, got {type(pg).__name__}")
    _check_method(method, chunk_poses)
    if fixed is not None and fixed not in set(pg.pose_id.tolist()):
        raise SlamError(f"fixed: pose {fixed} is not in the graph")
    graph, values = pose_graph_factors(pg)
    if not graph.size():
        raise SlamError("graph: no factors")
    r = _solve_loaded(graph, values, method, chunk_poses, polish=polish, fixed=fixed)
    lid = np.array([gtsam.Symbol(int(k)).index() for k in r.landmark_id], np.int64)
    return dataclasses.replace(r, landmark_id=lid)


def pose_graph_factors(pg: PoseGraph2D) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """The GTSAM graph and starting values of `pg`: BetweenFactorPose2 with the information
    matrices and BearingRangeFactor2D with diagonal sigmas, in the order readG2o makes them of
    a file with the odometry lines first; poses keyed by their id, landmarks by L(id)."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for i, p in zip(pg.pose_id, pg.pose):
        values.insert(int(i), gtsam.Pose2(*p))
    for i, xy in zip(pg.landmark_id, pg.landmark_xy):
        values.insert(_landmark_key(int(i)), np.asarray(xy, dtype=np.float64))
    for i, j, d, info in zip(pg.odo_from, pg.odo_to, pg.odo_delta, pg.odo_info):
        noise = gtsam.noiseModel.Gaussian.Information(0.5 * (info + info.T), True)
        graph.add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*d), noise))
    for i, j, b, r, sig in zip(pg.br_pose, pg.br_landmark, pg.br_bearing, pg.br_range, pg.br_sigma):
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sig, dtype=np.float64))
        graph.add(
            gtsam.BearingRangeFactor2D(
                int(i), _landmark_key(int(j)), gtsam.Rot2(float(b)), float(r), noise
            )
        )
    return graph, values


def _solve_loaded(graph, values, method: str, chunk_poses: int, *, polish: bool, fixed=None):
    """`solve_graph_file`'s solve of a loaded graph and its starting values."""
    n_factors, n_values = int(graph.size()), int(values.size())
    poses = sorted(k for k in values.keys() if _is_pose(values, k))
    landmarks = sorted(k for k in values.keys() if not _is_pose(values, k))
    if not poses:
        raise SlamError("graph: no poses")
    gauge = poses[0] if fixed is None else int(fixed)
    dims = sum(graph.at(i).dim() for i in range(n_factors))
    dof = dims - 3 * len(poses) - 2 * len(landmarks) + 3
    initial_chi2 = 2.0 * graph.error(values)
    prior = gtsam.PriorFactorPose2(
        gauge, values.atPose2(gauge), gtsam.noiseModel.Isotropic.Sigma(3, 1e-6)
    )
    full = gtsam.NonlinearFactorGraph(graph)
    full.add(prior)
    t0 = time.perf_counter()
    iterations = 0
    if method == "batch":
        opt = gtsam.LevenbergMarquardtOptimizer(full, values, gtsam.LevenbergMarquardtParams())
        result = opt.optimize()
        iterations = int(opt.iterations())
    else:
        result = _isam2_graph(graph, values, poses, prior, 1 if method == "isam2" else chunk_poses)
        if polish:
            opt = gtsam.LevenbergMarquardtOptimizer(full, result, gtsam.LevenbergMarquardtParams())
            result = opt.optimize()
            iterations = int(opt.iterations())
    seconds = time.perf_counter() - t0
    name = method + (f"({chunk_poses})" if method == "isam2-chunks" else "")
    return GraphResult(
        method=name + ("+polish" if polish and method != "batch" else ""),
        n_factors=n_factors,
        n_values=n_values,
        n_poses=len(poses),
        n_landmarks=len(landmarks),
        chi2=2.0 * graph.error(result),
        dof=dof,
        initial_chi2=initial_chi2,
        seconds=seconds,
        iterations=iterations,
        pose_id=np.array(poses, np.int64),
        pose=np.array([_xyt(result.atPose2(k)) for k in poses]).reshape(-1, 3),
        landmark_id=np.array(landmarks, np.int64),
        landmark_xy=np.array([result.atPoint2(k) for k in landmarks]).reshape(-1, 2),
    )


def _is_pose(values: gtsam.Values, key: int) -> bool:
    try:
        values.atPose2(key)
    except RuntimeError:
        return False
    return True


def _xyt(p: gtsam.Pose2) -> tuple[float, float, float]:
    return p.x(), p.y(), p.theta()


def _isam2_graph(graph, values, poses, prior, chunk: int) -> gtsam.Values:
    """iSAM2 over a pose-landmark graph, `chunk` poses per update, in pose order."""
    rank = {k: i for i, k in enumerate(poses)}
    buckets: list[list] = [[] for _ in poses]
    odometry: dict[int, tuple[int, gtsam.Pose2]] = {}
    for i in range(graph.size()):
        f = graph.at(i)
        keys = f.keys()
        buckets[max(rank[k] for k in keys if k in rank)].append(f)
        if isinstance(f, gtsam.BetweenFactorPose2) and all(k in rank for k in keys):
            odometry[keys[1]] = (keys[0], f.measured())
    buckets[rank[prior.keys()[0]]].append(prior)
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    current = {poses[0]: values.atPose2(poses[0])}
    known = set()
    for start in range(0, len(poses), chunk):
        new_graph, new_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for j in range(start, min(start + chunk, len(poses))):
            key = poses[j]
            if j > 0:
                if key not in odometry:
                    raise SlamError(f"graph: pose {key} has no odometry from an earlier pose")
                a, d = odometry[key]
                current[key] = current[a].compose(d)
            new_values.insert(key, current[key])
            known.add(key)
            for f in buckets[j]:
                new_graph.add(f)
                for k in f.keys():
                    if k in known:
                        continue
                    known.add(k)
                    br = f.measured()
                    b, r = br.bearing().theta(), br.range()
                    pose = current[f.keys()[0]]
                    new_values.insert(
                        k, pose.transformFrom(np.array([r * math.cos(b), r * math.sin(b)]))
                    )
        isam.update(new_graph, new_values)
        last = poses[min(start + chunk, len(poses)) - 1]
        current[last] = isam.calculateEstimatePose2(last)
    return isam.calculateEstimate()
