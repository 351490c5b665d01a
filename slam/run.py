"""`slam.run`: EKF-SLAM over one sequence, scan by scan.

Per scan k (times `scan_t[k]`):
1. predict: integrate the odometry from the previous scan (zero-order hold, `slam.vehicle`);
2. features: circles of the scan (a method name for `features.extract_features`, a callable
   (k, scan) -> Features, or a list of precomputed Features), turned into range-bearing
   measurements of their centres in the laser frame, with noise from the fit covariance
   (`"fit"`, the default for `geometric`) or a configured constant (`"constant"`, the default
   for `paper` and `bailey`; per-method values in `DEFAULT_CONSTANT_NOISE`);
3. associate: the landmarks and tentative features that can be in view are offered to
   `association.associate` (IHGR by default, JCBB or NN), on the sub-state [pose, those
   landmarks] (the Jacobians are zero elsewhere, so this is exact and keeps the cost down);
4. update: all associated map measurements at once (Joseph form, `slam.ekf.update`);
5. map management (`slam.mapping`): associated tentatives count a sighting and join the map
   after three scans (initialised from the current measurement with cross covariances);
   unassociated measurements that gate with no landmark or tentative start new tentatives;
   tentatives not associated are dropped.

The start pose is the truth at the first scan when the sequence has truth, else the first GPS
fix (antenna offset removed; heading from `initial_heading_rad` or the first GPS motion of at
least 2 m), else the origin. Everything the run did is returned as a `SlamLog`.

`slam` knows nothing of `experiments`: the sequence is any object with the fields of
`experiments.sequence.Sequence` (and its `scan(k)` method), and the optional visualiser any
object with the methods of `NullVisualiser` (which does nothing).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from slam.ekf import (
    EkfState,
    add_landmark,
    initial_state,
    observe,
    polar_cov_from_xy,
    predict,
    update,
)
from slam.mapping import MapPolicy, Tentatives, sighting
from slam.vehicle import AckermannModel, Odometry, OdometryNoise, integrate, wrap_angle

__all__ = [
    "DEFAULT_CONSTANT_NOISE",
    "TIMING_KEYS",
    "NullVisualiser",
    "SlamConfig",
    "SlamLog",
    "interpolate_poses",
    "measurements_from_features",
    "run",
]

log = logging.getLogger(__name__)

# The "constant" measurement noise model of each extractor: configured constants, not a fit:
#   sigma_range = range_sigma_m + range_sigma_per_m * range,
#   sigma_bearing^2 = bearing_sigma_rad^2 + (cross_range_sigma_m / range)^2.
# Values: maximum-likelihood fits of this model to the range and bearing errors of the centres
# of the circles found on trunks in the simulated tree park (LMS200, 1 cm range noise, 1 cm
# quantisation; `experiments.exp_slam.calibrate_measurement_noise`, seeds 1000-1003, apart from
# the experiment's), rounded up to two digits. Fitted (a, b, c, t): paper (0.0107, 0.00095,
# 0.00021, 0.0066), geometric (0.0069, 0.0013, 0.00030, 0.0060), bailey (0.0091, 0.0015,
# 0.0018, 0.0028). The fitted extractors' centres are off by under 1 cm across the beam (the
# bearing error falls as 1/range); the Bailey detector's bearing is quantised by the beams
# (about 0.1 deg whatever the range). The paper's fit also has a mean range error of -4 mm
# (Kasa's bias toward the sensor), which a zero-mean model cannot represent.
# (range_sigma_m, range_sigma_per_m, bearing_sigma_rad, cross_range_sigma_m):
DEFAULT_CONSTANT_NOISE: dict[str, tuple[float, float, float, float]] = {
    "paper": (0.011, 0.001, 0.00022, 0.0067),
    "geometric": (0.007, 0.0014, 0.00031, 0.0061),
    "bailey": (0.0092, 0.0015, 0.0019, 0.0028),
    "other": (0.05, 0.01, math.radians(0.5), 0.0),
}
TIMING_KEYS = ("predict", "features", "associate", "update", "manage", "total")

# Status of each measurement in SlamLog.meas_status (>= 0: the landmark id it updated).
NEW_TENTATIVE = -1
TENTATIVE_HIT = -2
CONFIRMED = -3
AMBIGUOUS = -4
OUT_OF_RANGE = -5


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of the run; defaults are the ones the experiments use.

    odometry_noise: sigma of each odometry sample's speed and steering readings.
    measurement_noise: "auto" (fit covariance for `geometric` features, constant otherwise),
        "fit" or "constant".
    range_sigma_m, range_sigma_per_m, bearing_sigma_rad, cross_range_sigma_m: the constant
        noise model (see `DEFAULT_CONSTANT_NOISE`); None = the feature method's default.
    fit_floor_range_m, fit_floor_bearing_rad: added in quadrature to the fit's noise (model
        error the fit cannot see; 0 in simulation where trunks are true circles).
    gate_prob: chi-square probability of the association gates (passed to `associate`). 0.999
        rather than association's 0.99: in the tree park a 3-sigma odometry heading step
        (one in about a thousand scans) pushed both visible trees out of a 0.99 gate; they were
        re-mapped as new landmarks and the run never recovered (2 of 50 runs, pose errors of
        10-18 cm). Inside the gate the choice is IHGR's likelihood costs, not the gate.
    new_feature_gate_prob: an unassociated measurement starts a tentative feature only when it
        lies outside this (wider) gate of every landmark and tentative feature in view;
        between the two gates it is ignored (status AMBIGUOUS), so a measurement of a mapped
        tree that just failed its gate does not become a duplicate landmark.
    association_params: extra keyword arguments of `association.associate`.
    map_policy: tentative features (`slam.mapping.MapPolicy`).
    initial_pose_sigma: (sigma_x_m, sigma_y_m, sigma_theta_rad) of the start pose when it comes
        from the truth (0: the map's frame is the start pose).
    gps_sigma_m, initial_heading_sigma_rad: start uncertainty when the start is a GPS fix.
    max_odometry_gap_s: a longer stretch without odometry inside the run is an error.
    max_feature_range_m: circles farther away are not used.
    view_margin_m, view_margin_rad: landmarks this far outside the laser's range and field of
        view are still offered to the association.
    """

    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    measurement_noise: str = "auto"
    range_sigma_m: float | None = None
    range_sigma_per_m: float | None = None
    bearing_sigma_rad: float | None = None
    cross_range_sigma_m: float | None = None
    fit_floor_range_m: float = 0.0
    fit_floor_bearing_rad: float = 0.0
    gate_prob: float = 0.999
    new_feature_gate_prob: float = 0.9999
    association_params: dict = field(default_factory=dict)
    map_policy: MapPolicy = field(default_factory=MapPolicy)
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gps_sigma_m: float = 1.0
    initial_heading_sigma_rad: float = math.radians(5.0)
    max_odometry_gap_s: float = 1.0
    max_feature_range_m: float = math.inf
    view_margin_m: float = 2.0
    view_margin_rad: float = math.radians(10.0)

    def __post_init__(self) -> None:
        if self.measurement_noise not in ("auto", "fit", "constant"):
            raise ValueError(
                f"SlamConfig.measurement_noise: expected 'auto', 'fit' or 'constant', got "
                f"{self.measurement_noise!r}"
            )
        for name in ("gate_prob", "new_feature_gate_prob"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise ValueError(f"SlamConfig.{name}: must be in (0, 1), got {v!r}")
        for name in (
            "range_sigma_m",
            "range_sigma_per_m",
            "bearing_sigma_rad",
            "cross_range_sigma_m",
        ):
            v = getattr(self, name)
            if v is not None and not (0 <= v < math.inf):
                raise ValueError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        for name in (
            "fit_floor_range_m",
            "fit_floor_bearing_rad",
            "gps_sigma_m",
            "initial_heading_sigma_rad",
            "view_margin_m",
            "view_margin_rad",
        ):
            v = getattr(self, name)
            if not (0 <= v < math.inf):
                raise ValueError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        if not self.max_odometry_gap_s > 0:
            raise ValueError("SlamConfig.max_odometry_gap_s: must be > 0")
        if len(self.initial_pose_sigma) != 3 or min(self.initial_pose_sigma) < 0:
            raise ValueError("SlamConfig.initial_pose_sigma: expected three sigmas >= 0")

    def noise_for(self, method: str) -> tuple[str, tuple[float, float, float, float]]:
        """("fit" | "constant", (range_sigma_m, range_sigma_per_m, bearing_sigma_rad,
        cross_range_sigma_m)) for a feature method."""
        kind = self.measurement_noise
        if kind == "auto":
            kind = "fit" if method == "geometric" else "constant"
        base = DEFAULT_CONSTANT_NOISE.get(method, DEFAULT_CONSTANT_NOISE["other"])
        given = (
            self.range_sigma_m,
            self.range_sigma_per_m,
            self.bearing_sigma_rad,
            self.cross_range_sigma_m,
        )
        model = tuple(float(b if g is None else g) for b, g in zip(base, given))
        if kind == "constant" and (model[0] + model[1] <= 0 or model[2] + model[3] <= 0):
            raise ValueError(f"SlamConfig: the constant noise model {model} is zero")
        return kind, model  # type: ignore[return-value]

    def to_dict(self) -> dict:
        return asdict(self)


class NullVisualiser:
    """The visualiser interface; does nothing (kiss-icp's StubVisualizer).

    Poses are world [x, y, theta]; `pose` of log_scan/log_features is the laser's world pose.
    """

    def set_scan(self, k: int) -> None: ...
    def log_scan(self, scan, pose=None, path: str = "world/scan") -> None: ...
    def log_features(self, scan, features, pose=None, path: str = "world/features") -> None: ...
    def log_vehicle(self, pose, cov) -> None: ...
    def log_landmarks(self, xy, cov, ids) -> None: ...
    def log_tentatives(self, xy) -> None: ...
    def log_associations(self, from_xy, to_xy) -> None: ...
    def log_truth(self, pose) -> None: ...


@dataclass(frozen=True, eq=False)
class SlamLog:
    """Everything one run did. N scans; world frame; m, rad, s.

    scan_t: (N,) scan times. pose, pose_cov: (N, 3), (N, 3, 3) the estimate of the rear-axle
        centre after the scan's update. pred_pose, pred_pose_cov: the same after the prediction,
        before the update (pred == pose for scans without an update).
    landmark_xy (n, 2), landmark_cov (n, 2, 2), landmark_id (n,), landmark_first_scan (n,),
        landmark_n_obs (n,): the final map (first_scan: the scan it joined the map; n_obs: the
        scans it was associated in, its tentative sightings included).
    obs_*: one row per measurement used in an update: obs_scan, obs_feature (circle index in the
        scan's features), obs_landmark (id), obs_z (range, bearing), obs_innov (z - z_hat),
        obs_innov_cov (2, 2) its block of the joint innovation covariance.
    meas_*: one row per circle extracted: meas_scan, meas_feature, meas_z (K, 2), meas_R
        (K, 2, 2), meas_status (landmark id >= 0 when used in an update; -1 new tentative,
        -2 tentative seen again, -3 tentative confirmed into the map, -4 ambiguous (gated but not
        assigned, ignored), -5 beyond max_feature_range_m).
    scan_nis (N,), scan_nis_dof (N,): NIS of each scan's batch update and its degrees of
        freedom (NaN, 0 without an update).
    n_features, n_associated, n_tentative, n_map: (N,) per scan.
    timing_s: {"predict", "features", "associate", "update", "manage", "total"} -> (N,) s.
    final_x, final_P: the final state. landmark ids index `final_x` via landmark_id order.
    start: "truth", "gps" or "origin". features_method, association_method: names used.
    config: the resolved configuration (plain types).
    """

    scan_t: np.ndarray
    pose: np.ndarray
    pose_cov: np.ndarray
    pred_pose: np.ndarray
    pred_pose_cov: np.ndarray
    landmark_xy: np.ndarray
    landmark_cov: np.ndarray
    landmark_id: np.ndarray
    landmark_first_scan: np.ndarray
    landmark_n_obs: np.ndarray
    obs_scan: np.ndarray
    obs_feature: np.ndarray
    obs_landmark: np.ndarray
    obs_z: np.ndarray
    obs_innov: np.ndarray
    obs_innov_cov: np.ndarray
    meas_scan: np.ndarray
    meas_feature: np.ndarray
    meas_z: np.ndarray
    meas_R: np.ndarray
    meas_status: np.ndarray
    scan_nis: np.ndarray
    scan_nis_dof: np.ndarray
    n_features: np.ndarray
    n_associated: np.ndarray
    n_tentative: np.ndarray
    n_map: np.ndarray
    timing_s: dict
    final_x: np.ndarray
    final_P: np.ndarray
    start: str
    features_method: str
    association_method: str
    config: dict

    @property
    def n_scans(self) -> int:
        return int(self.scan_t.shape[0])


def interpolate_poses(t_query, t_s, poses) -> np.ndarray:
    """Poses (T, 3) sampled at t_s, linearly interpolated at t_query (heading unwrapped first).

    Queries outside [t_s[0], t_s[-1]] take the end values.
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    tq = np.atleast_1d(np.asarray(t_query, dtype=np.float64))
    th = np.unwrap(poses[:, 2])
    out = np.stack(
        [
            np.interp(tq, t_s, poses[:, 0]),
            np.interp(tq, t_s, poses[:, 1]),
            wrap_angle(np.interp(tq, t_s, th)),
        ],
        axis=1,
    )
    return out


def measurements_from_features(
    features,
    noise: tuple[str, tuple[float, float, float, float]],
    floor: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Range-bearing measurements (C, 2) of the circle centres and their covariances (C, 2, 2).

    noise: ("fit", _) uses the centre's fit covariance, plus `floor` (range, bearing) sigmas in
    quadrature; ("constant", (s_r, s_r_per_m, s_b, s_t)) uses
    diag((s_r + s_r_per_m r)^2, s_b^2 + (s_t / r)^2).
    """
    c = np.asarray(features.circle_params, dtype=np.float64).reshape(-1, 3)
    kind, (s_r, s_rm, s_b, s_t) = noise
    if kind == "fit":
        z, R = polar_cov_from_xy(c[:, :2], np.asarray(features.circle_cov)[:, :2, :2])
        R = R + np.diag([floor[0] ** 2, floor[1] ** 2])
    else:
        z, _ = polar_cov_from_xy(c[:, :2], np.zeros((c.shape[0], 2, 2)))
        R = np.zeros((c.shape[0], 2, 2))
        R[:, 0, 0] = (s_r + s_rm * z[:, 0]) ** 2
        with np.errstate(divide="ignore"):
            R[:, 1, 1] = s_b**2 + (s_t / z[:, 0]) ** 2
    return z, R


def _check_sequence(seq, n_features: int | None, cfg: SlamConfig) -> None:
    scan_t = getattr(seq, "scan_t", None)
    if scan_t is None or np.asarray(scan_t).ndim != 1 or np.asarray(scan_t).shape[0] == 0:
        raise ValueError("sequence.scan_t: no scans (empty sequence)")
    scan_t = np.asarray(scan_t, dtype=np.float64)
    if not np.all(np.isfinite(scan_t)):
        raise ValueError("sequence.scan_t: scan times must be finite")
    bad = np.flatnonzero(np.diff(scan_t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"sequence.scan_t: scan times must be strictly increasing; scan_t[{i + 1}] = "
            f"{scan_t[i + 1]!r} follows scan_t[{i}] = {scan_t[i]!r}"
        )
    ranges = getattr(seq, "scan_ranges", None)
    if ranges is None or np.asarray(ranges).ndim != 2 or np.asarray(ranges).shape[1] == 0:
        raise ValueError("sequence.scan_ranges: empty scans (expected shape (N, B), B >= 1)")
    if np.asarray(ranges).shape[0] != scan_t.shape[0]:
        raise ValueError(
            f"sequence.scan_ranges: {np.asarray(ranges).shape[0]} scans but "
            f"{scan_t.shape[0]} scan times"
        )
    if getattr(seq, "odo_t", None) is None or len(seq.odo_t) == 0:
        raise ValueError(
            "sequence: missing odometry (odo_t, odo_speed, odo_steer); EKF-SLAM needs it"
        )
    if getattr(seq, "vehicle", None) is None:
        raise ValueError("sequence.vehicle: missing vehicle model (needed to use the odometry)")
    odo_t = np.asarray(seq.odo_t, dtype=np.float64)
    if odo_t.ndim != 1 or np.any(np.diff(odo_t) <= 0):
        raise ValueError("sequence.odo_t: odometry times must be strictly increasing")
    veh = seq.vehicle
    k = float(veh.get("encoder_offset_m", 0.0)) / float(veh["wheelbase_m"])
    den = 1.0 - k * np.tan(np.asarray(seq.odo_steer, dtype=np.float64))
    if np.any(den <= 0):  # v_c = v_e / (1 - (H/L) tan(alpha)) would be infinite or negative
        i = int(np.flatnonzero(den <= 0)[0])
        raise ValueError(
            f"sequence.vehicle: encoder_offset_m / wheelbase_m = {k:.3g} with odo_steer[{i}] = "
            f"{float(seq.odo_steer[i]):.3g} rad makes the encoder-to-axle speed correction "
            "infinite or negative; check the vehicle parameters and the steering units"
        )
    # The longest stretch of the run [scan_t[0], scan_t[-1]] on stale (held) odometry.
    lead = max(0.0, float(odo_t[0] - scan_t[0]))
    tail = max(0.0, float(scan_t[-1] - odo_t[-1]))
    clipped = np.clip(odo_t, scan_t[0], scan_t[-1])
    steps = np.diff(clipped)
    inner = float(steps.max()) if steps.size else 0.0
    if max(lead, tail, inner) > cfg.max_odometry_gap_s:
        if lead > cfg.max_odometry_gap_s:
            where = f"odometry starts at {odo_t[0]:.3f} s, {lead:.3f} s after the first scan"
        elif tail > cfg.max_odometry_gap_s:
            where = f"odometry ends at {odo_t[-1]:.3f} s, {tail:.3f} s before the last scan"
        else:
            i = int(np.argmax(steps))
            where = f"no odometry from {clipped[i]:.3f} s to {clipped[i + 1]:.3f} s"
        raise ValueError(
            f"sequence.odo_t: missing odometry: {where} (max_odometry_gap_s = "
            f"{cfg.max_odometry_gap_s} s)"
        )
    if n_features is not None and n_features != scan_t.shape[0]:
        raise ValueError(
            f"features: {n_features} precomputed feature sets for {scan_t.shape[0]} scans"
        )


def _start(
    seq, cfg: SlamConfig, initial_heading_rad: float | None
) -> tuple[np.ndarray, np.ndarray, str]:
    t0 = float(seq.scan_t[0])
    truth_t = getattr(seq, "truth_t", None)
    if truth_t is not None and len(truth_t) and not truth_t[0] <= t0 <= truth_t[-1]:
        log.warning(
            "the truth (%.3f .. %.3f s) does not cover the first scan (%.3f s); "
            "not starting from it",
            truth_t[0],
            truth_t[-1],
            t0,
        )
        truth_t = None
    if truth_t is not None and len(truth_t):
        pose = interpolate_poses(t0, seq.truth_t, seq.truth_pose)[0]
        if initial_heading_rad is not None:
            log.warning("initial_heading_rad ignored: the run starts from the truth")
        return pose, np.diag(np.square(cfg.initial_pose_sigma)), "truth"
    if getattr(seq, "gps_t", None) is not None and len(seq.gps_t):
        xy = np.asarray(seq.gps_xy, dtype=np.float64)
        if initial_heading_rad is not None:
            th = float(initial_heading_rad)
        else:
            far = np.flatnonzero(np.hypot(*(xy - xy[0]).T) >= 2.0)
            if far.size == 0:
                raise ValueError(
                    "initial_heading_rad: the GPS never moves 2 m from its first fix, so the "
                    "start heading is unknown; give --initial-heading"
                )
            d = xy[far[0]] - xy[0]
            th = math.atan2(d[1], d[0])
        ant = seq.gps_pose if getattr(seq, "gps_pose", None) is not None else seq.laser_pose
        c, s = math.cos(th), math.sin(th)
        p = xy[0] - np.array([c * ant[0] - s * ant[1], s * ant[0] + c * ant[1]])
        if abs(float(seq.gps_t[0]) - t0) > 1.0:
            log.warning(
                "first GPS fix at %.3f s is %.3f s from the first scan",
                float(seq.gps_t[0]),
                float(seq.gps_t[0]) - t0,
            )
        cov = np.diag([cfg.gps_sigma_m**2, cfg.gps_sigma_m**2, cfg.initial_heading_sigma_rad**2])
        return np.array([p[0], p[1], th]), cov, "gps"
    th = 0.0 if initial_heading_rad is None else float(initial_heading_rad)
    return np.array([0.0, 0.0, th]), np.diag(np.square(cfg.initial_pose_sigma)), "origin"


def _resolve_association(association) -> tuple[Callable, str]:
    if callable(association):
        return association, getattr(association, "__name__", "custom")
    if not isinstance(association, str):
        raise ValueError(f"association: expected a method name or a callable, got {association!r}")
    import association as assoc_pkg

    fn = getattr(assoc_pkg, "associate", None)
    methods = getattr(assoc_pkg, "METHODS", None)
    if fn is None or methods is None:  # the package's __init__ does not re-export them
        from association.api import METHODS as methods
        from association.api import associate as fn
    if association not in methods:
        raise ValueError(f"association: unknown method {association!r}; known: {list(methods)}")
    method = association

    def call(z, R, z_hat, H, P, gate_prob=0.99, **params):
        return fn(z, R, z_hat, H, P, method=method, gate_prob=gate_prob, **params)

    return call, method


def _resolve_features(features, seq, feature_params: dict):
    """(callable (k, scan) -> Features, method name, number of precomputed sets or None)."""
    if isinstance(features, str):
        from features import extract_features

        method = features
        return (lambda k, scan: extract_features(scan, method, **feature_params)), method, None
    if callable(features):
        return (lambda k, scan: features(k, scan)), getattr(features, "method", "custom"), None
    feats = list(features)
    method = feats[0].method if feats and hasattr(feats[0], "method") else "custom"
    return (lambda k, scan: feats[k]), method, len(feats)


def _scan_fov(seq) -> tuple[float, float]:
    a0 = float(seq.scan_angle_min)
    a1 = a0 + float(seq.scan_angle_increment) * (np.asarray(seq.scan_ranges).shape[1] - 1)
    return a0, a1


def run(
    sequence,
    features="paper",
    association="ihgr",
    config: SlamConfig | None = None,
    *,
    feature_params: dict | None = None,
    visualiser=None,
    initial_heading_rad: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SlamLog:
    """EKF-SLAM over `sequence`; returns the `SlamLog`.

    features: a `features.extract_features` method name ("paper", "geometric", "bailey"), a
        callable (k, scan) -> Features, or a list of N precomputed Features (laser frame).
    association: "ihgr", "jcbb", "nn", or a callable with the signature of
        `association.associate` minus `method` (z, R, z_hat, H, P, gate_prob=..., **params).
    feature_params: keyword arguments for `extract_features` (method name only).
    visualiser: an object with the methods of `NullVisualiser` (default: nothing is logged).
    initial_heading_rad: overrides the start heading (needed for GPS starts without motion).
    progress: callback(done, total) after each scan.
    Raises ValueError for a sequence that cannot be run (no scans, unsorted times, missing
    odometry or vehicle, a mismatched list of features).
    """
    cfg = config or SlamConfig()
    feat_fn, method, n_pre = _resolve_features(features, sequence, dict(feature_params or {}))
    _check_sequence(sequence, n_pre, cfg)
    assoc_fn, assoc_name = _resolve_association(association)
    vis = visualiser or NullVisualiser()
    model = AckermannModel.from_vehicle(sequence.vehicle)
    odo = Odometry(sequence.odo_t, sequence.odo_speed, sequence.odo_steer)
    laser = np.asarray(sequence.laser_pose, dtype=np.float64)
    noise = cfg.noise_for(method)
    floor = (cfg.fit_floor_range_m, cfg.fit_floor_bearing_rad)
    fov0, fov1 = _scan_fov(sequence)
    max_range = min(float(getattr(sequence, "scan_max_range", math.inf)), cfg.max_feature_range_m)
    gate_new = -2.0 * math.log1p(-max(cfg.new_feature_gate_prob, cfg.gate_prob))  # chi2, 2 dof
    has_truth = getattr(sequence, "truth_t", None) is not None

    pose0, cov0, start = _start(sequence, cfg, initial_heading_rad)
    state = initial_state(pose0, cov0)
    tent = Tentatives.empty()
    next_id = 0
    n_obs: dict[int, int] = {}
    first_scan: dict[int, int] = {}

    scan_t = np.asarray(sequence.scan_t, dtype=np.float64)
    N = scan_t.shape[0]
    pose_log = np.empty((N, 3))
    cov_log = np.empty((N, 3, 3))
    pred_log = np.empty((N, 3))
    pred_cov_log = np.empty((N, 3, 3))
    nis = np.full(N, np.nan)
    nis_dof = np.zeros(N, np.int64)
    counts = {
        k: np.zeros(N, np.int64) for k in ("n_features", "n_associated", "n_tentative", "n_map")
    }
    timing = {k: np.zeros(N) for k in TIMING_KEYS}
    obs: dict[str, list] = {k: [] for k in ("scan", "feature", "landmark", "z", "innov", "S")}
    meas: dict[str, list] = {k: [] for k in ("scan", "feature", "z", "R", "status")}

    for k in range(N):
        t_start = time.perf_counter()
        # 1. predict
        if k > 0:
            p1, F, Q = integrate(
                model, state.pose, odo, scan_t[k - 1], scan_t[k], cfg.odometry_noise
            )
            state = predict(state, p1, F, Q)
        pred_log[k] = state.pose
        pred_cov_log[k] = state.pose_cov
        t1 = time.perf_counter()
        # 2. features
        scan = sequence.scan(k)
        f = feat_fn(k, scan)
        z, R = measurements_from_features(f, noise, floor)
        t2 = time.perf_counter()
        m = z.shape[0]
        status = np.full(m, NEW_TENTATIVE, np.int64)
        usable = (z[:, 0] <= max_range) & np.all(np.isfinite(z), axis=1)
        status[~usable] = OUT_OF_RANGE
        # 3. associate with the landmarks and tentatives that can be in view
        pose = state.pose
        lm_idx = np.arange(state.n_landmarks)
        z_lm, H_lm = observe(pose, state.landmarks_xy, laser)
        vis_lm = _in_view(z_lm, max_range, fov0, fov1, cfg)
        z_t, H_t = observe(pose, tent.xy, laser)
        vis_t = _in_view(z_t, max_range, fov0, fov1, cfg)
        lm_idx = lm_idx[vis_lm]
        t_idx = np.flatnonzero(vis_t)
        n_l, n_t = lm_idx.size, t_idx.size
        assign = np.full(m, -1, np.int64)
        ambiguous = np.zeros(m, bool)
        use = np.flatnonzero(usable)
        if use.size and (n_l + n_t):
            zh = np.concatenate([z_lm[vis_lm], z_t[vis_t]])
            d_sub = 3 + 2 * (n_l + n_t)
            Hv = np.concatenate([H_lm[vis_lm], H_t[vis_t]])  # (n, 2, 5)
            H = np.zeros((n_l + n_t, 2, d_sub))
            H[:, :, :3] = Hv[:, :, :3]
            for j in range(n_l + n_t):
                H[j, :, 3 + 2 * j : 5 + 2 * j] = Hv[j, :, 3:5]
            cols = np.concatenate(
                [[0, 1, 2], np.stack([3 + 2 * lm_idx, 4 + 2 * lm_idx], 1).reshape(-1)]
            ).astype(np.int64)
            P_sub = np.zeros((d_sub, d_sub))
            nc = cols.size
            P_sub[:nc, :nc] = state.P[np.ix_(cols, cols)]
            for j, ti in enumerate(t_idx):
                a = nc + 2 * j
                P_sub[a : a + 2, a : a + 2] = tent.cov[ti]
            a_use = assoc_fn(
                z[use], R[use], zh, H, P_sub, gate_prob=cfg.gate_prob, **cfg.association_params
            )
            assign[use] = np.asarray(a_use, dtype=np.int64)
            ambiguous[use] = (assign[use] < 0) & _gated_any(z[use], R[use], zh, H, P_sub, gate_new)
        t3 = time.perf_counter()
        # 4. update with the map measurements
        to_map = np.flatnonzero(assign >= 0)
        to_map = to_map[assign[to_map] < n_l]
        if to_map.size:
            pos = lm_idx[assign[to_map]]
            state, res = update(state, pos, z[to_map], R[to_map], laser)
            nis[k] = res.nis
            nis_dof[k] = 2 * to_map.size
            for j, i in enumerate(to_map):
                lid = int(state.landmark_ids[pos[j]])
                status[i] = lid
                n_obs[lid] = n_obs.get(lid, 0) + 1
                obs["scan"].append(k)
                obs["feature"].append(int(i))
                obs["landmark"].append(lid)
                obs["z"].append(z[i])
                obs["innov"].append(res.innovation[j])
                obs["S"].append(res.S[2 * j : 2 * j + 2, 2 * j : 2 * j + 2])
        t4 = time.perf_counter()
        # 5. map management
        matched: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        matched_meas: dict[int, int] = {}
        new: list[tuple[np.ndarray, np.ndarray, int]] = []
        new_meas: list[int] = []
        for i in np.flatnonzero(assign >= n_l):
            ti = int(t_idx[assign[i] - n_l])
            matched[ti] = sighting(state.pose, state.pose_cov, z[i], R[i], laser)
            matched_meas[ti] = int(i)
            status[i] = TENTATIVE_HIT
        for i in np.flatnonzero((assign < 0) & usable):
            if ambiguous[i]:
                status[i] = AMBIGUOUS
                continue
            mxy, C = sighting(state.pose, state.pose_cov, z[i], R[i], laser)
            new.append((mxy, C, next_id))
            new_meas.append(int(i))
            first_scan[next_id] = k
            next_id += 1
        if cfg.map_policy.confirm_scans == 1:  # every sighting joins the map at once
            for (_, _, lid), i in zip(new, new_meas):
                state = add_landmark(state, z[i], R[i], laser, lid)
                status[i] = CONFIRMED
                n_obs[lid] = 1
            new = []
        tent_before = tent
        tent, confirm = tent.step(matched, new, k, cfg.map_policy)
        for ti in confirm:
            i = matched_meas[ti]
            lid = int(tent_before.ids[ti])
            state = add_landmark(state, z[i], R[i], laser, lid)
            status[i] = CONFIRMED
            n_obs[lid] = int(tent_before.hits[ti]) + 1
            first_scan[lid] = k
        t5 = time.perf_counter()

        pose_log[k] = state.pose
        cov_log[k] = state.pose_cov
        counts["n_features"][k] = m
        counts["n_associated"][k] = to_map.size
        counts["n_tentative"][k] = len(tent)
        counts["n_map"][k] = state.n_landmarks
        for i in range(m):
            meas["scan"].append(k)
            meas["feature"].append(i)
            meas["z"].append(z[i])
            meas["R"].append(R[i])
            meas["status"].append(int(status[i]))
        timing["predict"][k] = t1 - t_start
        timing["features"][k] = t2 - t1
        timing["associate"][k] = t3 - t2
        timing["update"][k] = t4 - t3
        timing["manage"][k] = t5 - t4
        timing["total"][k] = t5 - t_start

        _visualise(vis, k, sequence, scan, f, state, tent, laser, z, status, has_truth)
        if progress is not None:
            progress(k + 1, N)

    ids = state.landmark_ids
    return SlamLog(
        scan_t=scan_t,
        pose=pose_log,
        pose_cov=cov_log,
        pred_pose=pred_log,
        pred_pose_cov=pred_cov_log,
        landmark_xy=state.landmarks_xy.copy(),
        landmark_cov=state.landmark_covs,
        landmark_id=ids.copy(),
        landmark_first_scan=np.array([first_scan.get(int(i), -1) for i in ids], np.int64),
        landmark_n_obs=np.array([n_obs.get(int(i), 0) for i in ids], np.int64),
        obs_scan=np.array(obs["scan"], np.int64),
        obs_feature=np.array(obs["feature"], np.int64),
        obs_landmark=np.array(obs["landmark"], np.int64),
        obs_z=np.array(obs["z"]).reshape(-1, 2),
        obs_innov=np.array(obs["innov"]).reshape(-1, 2),
        obs_innov_cov=np.array(obs["S"]).reshape(-1, 2, 2),
        meas_scan=np.array(meas["scan"], np.int64),
        meas_feature=np.array(meas["feature"], np.int64),
        meas_z=np.array(meas["z"]).reshape(-1, 2),
        meas_R=np.array(meas["R"]).reshape(-1, 2, 2),
        meas_status=np.array(meas["status"], np.int64),
        scan_nis=nis,
        scan_nis_dof=nis_dof,
        **counts,
        timing_s=timing,
        final_x=state.x.copy(),
        final_P=state.P.copy(),
        start=start,
        features_method=method,
        association_method=assoc_name,
        config=cfg.to_dict(),
    )


def _in_view(
    z_hat: np.ndarray, max_range: float, fov0: float, fov1: float, cfg: SlamConfig
) -> np.ndarray:
    """(n,) bool: predictions within range and field of view, plus margins."""
    if z_hat.shape[0] == 0:
        return np.zeros(0, bool)
    b = z_hat[:, 1]
    in_fov = (b >= fov0 - cfg.view_margin_rad) & (b <= fov1 + cfg.view_margin_rad)
    if fov1 - fov0 + 2 * cfg.view_margin_rad >= 2 * math.pi:
        in_fov[:] = True
    return in_fov & (z_hat[:, 0] <= max_range + cfg.view_margin_m)


def _gated_any(z, R, z_hat, H, P, gate: float) -> np.ndarray:
    """(m,) bool: measurement i passes the individual gate with at least one prediction."""
    HPH = np.einsum("nad,de,nbe->nab", H, P, H)  # (n, 2, 2)
    nu = z[:, None, :] - z_hat[None, :, :]
    nu[..., 1] = wrap_angle(nu[..., 1])
    S = HPH[None, :, :, :] + R[:, None, :, :]
    d2 = np.einsum("mna,mna->mn", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return np.any(d2 <= gate, axis=1)


def _visualise(
    vis, k, seq, scan, f, state: EkfState, tent: Tentatives, laser, z, status, has_truth
) -> None:
    if isinstance(vis, NullVisualiser) and type(vis) is NullVisualiser:
        return
    vis.set_scan(k)
    pose = state.pose
    c, s = math.cos(pose[2]), math.sin(pose[2])
    lpose = np.array(
        [
            pose[0] + c * laser[0] - s * laser[1],
            pose[1] + s * laser[0] + c * laser[1],
            pose[2] + laser[2],
        ]
    )
    vis.log_scan(scan, lpose)
    vis.log_features(scan, f, lpose)
    vis.log_vehicle(pose, state.pose_cov)
    vis.log_landmarks(state.landmarks_xy, state.landmark_covs, state.landmark_ids)
    vis.log_tentatives(tent.xy)
    used = np.flatnonzero(status >= 0)
    if used.size:
        ang = lpose[2] + z[used, 1]
        frm = lpose[:2] + z[used, 0:1] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        to = np.array([state.landmarks_xy[state.index_of(int(i))] for i in status[used]])
        vis.log_associations(frm, to)
    else:
        vis.log_associations(np.zeros((0, 2)), np.zeros((0, 2)))
    if has_truth:
        vis.log_truth(interpolate_poses(seq.scan_t[k], seq.truth_t, seq.truth_pose)[0])
