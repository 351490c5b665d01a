"""`SlamConfig`: every setting of a run, grouped by concern, and its strict conversion from and
to plain dicts (what a TOML configuration file holds).

A run is its configuration: the features (extractor and its parameters), the association
(method, gates, window), the measurement model, the vehicle (odometry noise, steering
calibration, laser and antenna poses), the start, the map policy and the filter. Written beside
a result (`config.toml`), it reproduces the run to the bit.

    [features]      method, [features.extractor] (`features.ExtractorParams`),
                    [features.bailey] (the Bailey detector's noise model and constants)
    [association]   method, gate_prob, new_feature_gate_prob, window_scans, view margins, params
    [measurement]   noise ("auto" | "fit" | "constant"), constant_noise.<method>, fit floors,
                    range_bias.<method>, max_range_m
    [vehicle]       odometry_noise, steering, laser_pose, laser_latency_s, gps_antenna,
                    max_odometry_gap_s, min_travel_m
    [start]         initial_pose_sigma, initial_heading_rad, GPS start fit
    [map_policy]    `slam.tentatives.MapPolicy`
    [closure]       `slam.closure.ClosureConfig` (loop closure; off by default)
    [filter]        first_estimates_jacobians

`SlamConfig.from_dict(d)` refuses unknown keys (with a "did you mean" and, for the keys of the
flat format of earlier versions, where the setting lives now), wrong types and impossible
values, naming the key's path ("vehicle.odometry_noise.speed_sigma_mps: ..."). `to_dict()`
gives the same structure back, leaving out settings that are None (TOML has no null), so a
dumped configuration loads back equal.
"""

from __future__ import annotations

import difflib
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass

from features import ExtractorParams
from features.bailey import BaileyParams
from slam.checks import SETTING_TINY, setting
from slam.closure import ClosureConfig
from slam.errors import SlamError
from slam.measurement import (
    DEFAULT_CONSTANT_NOISE,
    DEFAULT_FIT_FLOOR,
    DEFAULT_RANGE_BIAS,
    MeasurementModel,
    NoiseModel,
)
from slam.motion import IncrementNoise, UnicycleNoise
from slam.sequence import MAX_ANGLE_RAD, MAX_COORDINATE_M
from slam.tentatives import MapPolicy
from slam.vehicle import OdometryNoise, SteeringCalibration

__all__ = [
    "ASSOCIATION_METHODS",
    "FEATURE_METHODS",
    "GPS_START_TRACKS",
    "OWN_COVARIANCE",
    "AssociationConfig",
    "BaileyConfig",
    "FeaturesConfig",
    "FilterConfig",
    "MeasurementConfig",
    "SlamConfig",
    "StartConfig",
    "VehicleConfig",
    "config_from_dict",
    "config_to_dict",
]

# the extractors of `features.extract_features`, and the sequence's own precomputed detections
FEATURE_METHODS = ("paper", "geometric", "kasa", "taubin", "bailey", "detections")
ASSOCIATION_METHODS = ("ihgr", "jcbb", "nn", "ihgr-window")
GPS_START_TRACKS = ("dead-reckoning", "slam")  # StartConfig.gps_track
# Extractors whose circles' covariance ("fit" noise) describes their errors, used under
# measurement noise "auto": the first-order covariance of an orthogonal-distance fit at the
# reported circle (`features.fitting.circle_covariance`). Exact for `geometric`; for the paper's
# Gauss-Newton on eq. (6) the calibration circles' normalised errors under it (floors added,
# range bias removed) have mean squares 0.94 in range and 1.02 in bearing, against 1.79 to 0.33
# in range across beam counts under the constant model (`noise-calibration`, `by-beams` in
# docs/consistency_probes.py). Bailey's diameter-based covariance is not a fit's: constant noise.
OWN_COVARIANCE = ("geometric", "paper")


MAX_LATENCY_S = 1.0  # a laser stamped a second or more off its measurement is a clock fault


def _finite(owner: str, name: str, v) -> None:
    """A finite number >= 0 in the range where the kernels' maths holds (`slam.checks.setting`)."""
    setting(f"{owner}.{name}", v)


def _choice(owner: str, name: str, v, choices) -> None:
    if v not in choices:
        raise SlamError(f"{owner}.{name}: expected one of {list(choices)}, got {v!r}")


@dataclass(frozen=True)
class BaileyConfig:
    """The Bailey detector (`features.bailey.extract_bailey`): the noise model its circles carry
    (the Zaragoza SLAM school's for the Victoria Park detections: range sigma 0.05 m + 1% of
    range, bearing sigma 0.5 deg; radius sigma 0.05 m) and its constants (`detector`)."""

    range_sigma_m: float = 0.05
    range_sigma_per_m: float = 0.01
    bearing_sigma_rad: float = math.radians(0.5)
    radius_sigma_m: float = 0.05
    detector: BaileyParams = field(default_factory=BaileyParams)

    def __post_init__(self) -> None:
        for name in ("range_sigma_m", "range_sigma_per_m", "bearing_sigma_rad", "radius_sigma_m"):
            _finite("features.bailey", name, getattr(self, name))


@dataclass(frozen=True)
class FeaturesConfig:
    """Where the circles come from.

    method: an extractor of `features.extract_features` ("paper", "geometric", "kasa", "taubin",
        "bailey") run on the raw scans, or "detections" (the sequence's precomputed detections).
    extractor: the parameters of the fitting extractors (`features.ExtractorParams`).
    bailey: the Bailey detector's noise model and constants (method "bailey").
    file: a features JSON (`trunkslam extract --out`) whose circles are used instead of
        extracting (the command line reads it; `slam.run_slam` takes the features themselves);
        `method` then names the noise model of its circles.
    """

    method: str = "paper"
    extractor: ExtractorParams = field(default_factory=ExtractorParams)
    bailey: BaileyConfig = field(default_factory=BaileyConfig)
    file: str | None = None

    def __post_init__(self) -> None:
        _choice("features", "method", self.method, FEATURE_METHODS)

    def extractor_kwargs(self) -> dict:
        """The keyword arguments of `features.extract_features(scan, self.method, **kwargs)`."""
        if self.method == "bailey":
            b = self.bailey
            return {
                "range_sigma_m": b.range_sigma_m,
                "range_sigma_per_m": b.range_sigma_per_m,
                "bearing_sigma_rad": b.bearing_sigma_rad,
                "radius_sigma_m": b.radius_sigma_m,
                "params": b.detector,
            }
        return {f.name: getattr(self.extractor, f.name) for f in fields(self.extractor)}


@dataclass(frozen=True)
class AssociationConfig:
    """Which measurement belongs to which landmark.

    method: "ihgr" (LP relaxation and rounding, one scan), "jcbb", "nn", or "ihgr-window" (the
        K-scan `association.SlidingWindowAssociator`, K = window_scans, in place of tentatives).
    gate_prob: chi-square probability of the association gates. 0.999 rather than
        association's 0.99: in the tree park a 3-sigma odometry heading step (one in about a
        thousand scans) pushed both visible trees out of a 0.99 gate; they were re-mapped as new
        landmarks and the run never recovered (2 of 50 runs, pose errors of 10-18 cm). Inside
        the gate the choice is IHGR's likelihood costs, not the gate.
    new_feature_gate_prob: an unassociated measurement starts a new landmark only when it lies
        outside this (wider) gate of every landmark and tentative in view; between the two gates
        it is ignored (status AMBIGUOUS): a measurement of a mapped tree that just failed its
        gate does not become a duplicate.
    window_scans: K of "ihgr-window", 2..4 intended (docs/experiments/association.md).
    view_margin_m, view_margin_rad: landmarks this far outside the laser's range and field of
        view are still offered to the association.
    params: extra keyword arguments of the associator (`association.associate`; for
        "ihgr-window" the `CostModel` densities and the rounding options).
    """

    method: str = "ihgr"
    gate_prob: float = 0.999
    new_feature_gate_prob: float = 0.9999
    window_scans: int = 3
    view_margin_m: float = 2.0
    view_margin_rad: float = math.radians(10.0)
    params: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        _choice("association", "method", self.method, ASSOCIATION_METHODS)
        for name in ("gate_prob", "new_feature_gate_prob"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise SlamError(f"association.{name}: must be in (0, 1), got {v!r}")
        if isinstance(self.window_scans, bool) or not 1 <= self.window_scans <= 8:
            raise SlamError(
                f"association.window_scans: must be an integer in 1..8, got {self.window_scans!r}"
            )
        for name in ("view_margin_m", "view_margin_rad"):
            _finite("association", name, getattr(self, name))
        from association.api import check_params
        from association.errors import AssociationError

        try:  # checked here, not at the first scan: a wrong parameter is named with its file
            check_params("ihgr" if self.method == "ihgr-window" else self.method, self.params)
        except AssociationError as exc:
            raise SlamError(f"association.params: {exc}") from None

    @property
    def windowed(self) -> bool:
        """Whether the K-scan window replaces the tentatives."""
        return self.method == "ihgr-window"

    @property
    def gate_new(self) -> float:
        """chi2 (2 dof) of the gate outside which a measurement may start a landmark."""
        return -2.0 * math.log1p(-max(self.new_feature_gate_prob, self.gate_prob))


@dataclass(frozen=True)
class MeasurementConfig:
    """How a circle becomes a range-bearing measurement of its centre, and with what noise.

    noise: "auto" (the circles' own covariance when the extractor gives one that describes its
        errors: `geometric` and `paper` (`OWN_COVARIANCE`; a precomputed list whose covariances
        are all zero carries none), or detections carrying det_cov; constant otherwise), "fit"
        or "constant".
    constant_noise: the constant model of each extractor (`slam.measurement.NoiseModel`), by
        method name; methods not given keep their `DEFAULT_CONSTANT_NOISE` entry, methods
        unknown to both use its "other" entry.
    fit_floor_range_m, fit_floor_bearing_rad: added in quadrature to a fit's covariance (model
        error the fit cannot see: range quantisation, mixed returns); the defaults are the
        maximum-likelihood floors of the `geometric` fit in the simulated tree park
        (`slam.measurement.DEFAULT_FIT_FLOOR`, calibration seeds 1000-1003).
    range_bias: known mean range error a + b r of each extractor's centres, by method name, as
        (a_m, b_per_m), subtracted from its ranges; methods not given keep their
        `DEFAULT_RANGE_BIAS` entry ((0, 0) when it has none).
    max_range_m: circles farther away are not used (the laser's own maximum applies too).
    """

    noise: str = "auto"
    constant_noise: Mapping[str, NoiseModel] = field(default_factory=dict)
    fit_floor_range_m: float = DEFAULT_FIT_FLOOR[0]
    fit_floor_bearing_rad: float = DEFAULT_FIT_FLOOR[1]
    range_bias: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    max_range_m: float = math.inf

    def __post_init__(self) -> None:
        _choice("measurement", "noise", self.noise, ("auto", "fit", "constant"))
        for name in ("fit_floor_range_m", "fit_floor_bearing_rad"):
            _finite("measurement", name, getattr(self, name))
        if not self.max_range_m > 0:
            raise SlamError("measurement.max_range_m: must be > 0 (inf: no limit)")
        if self.max_range_m < SETTING_TINY:
            raise SlamError(
                f"measurement.max_range_m: must be at least {SETTING_TINY:g} (inf: no limit), "
                f"got {self.max_range_m!r}"
            )
        models = dict(DEFAULT_CONSTANT_NOISE)  # the given methods replace their defaults
        for method, model in dict(self.constant_noise).items():
            m = NoiseModel(*model)
            for name, v in m._asdict().items():  # each sigma finite, >= 0, in range
                setting(f"measurement.constant_noise.{method}.{name}", v)
            models[method] = m
        object.__setattr__(self, "constant_noise", types.MappingProxyType(models))
        biases = dict(DEFAULT_RANGE_BIAS)
        for method, v in dict(self.range_bias).items():
            ok = isinstance(v, (tuple, list)) and len(v) == 2
            ok = ok and all(isinstance(x, (int, float)) and math.isfinite(x) for x in v)
            ok = ok and not any(x != 0 and abs(x) < SETTING_TINY for x in v)  # no subnormals
            if not ok or abs(v[0]) >= 1.0 or abs(v[1]) >= 0.1:
                raise SlamError(
                    f"measurement.range_bias.{method}: expected (a_m, b_per_m) with |a| < 1 m "
                    f"and |b| < 0.1 (each 0 or at least {SETTING_TINY:g} in size), got {v!r}"
                )
            biases[method] = (float(v[0]), float(v[1]))
        object.__setattr__(self, "range_bias", types.MappingProxyType(biases))

    def model_for(self, method: str, has_cov: bool | None = None) -> MeasurementModel:
        """The measurement model of circles from `method`. has_cov: whether they carry their own
        covariance (default: the methods of `OWN_COVARIANCE`)."""
        kind = self.noise
        if kind == "auto":
            own = method in OWN_COVARIANCE if has_cov is None else has_cov
            kind = "fit" if own else "constant"
        key = method if method in self.constant_noise else "other"
        constant = self.constant_noise[key]
        if kind == "constant" and (
            constant[0] + constant[1] <= 0 or constant[2] + constant[3] <= 0
        ):
            raise SlamError(
                f"measurement: the constant noise model {tuple(constant)} is zero "
                f"(measurement.constant_noise.{key}: range_sigma_m + range_sigma_per_m and "
                "bearing_sigma_rad + cross_range_sigma_m must each be > 0)"
            )
        return MeasurementModel(
            kind=kind,
            constant=constant,
            floor=(self.fit_floor_range_m, self.fit_floor_bearing_rad),
            range_bias=tuple(self.range_bias.get(method, (0.0, 0.0))),
        )

    def __reduce__(self):
        """Pickled as its fields, the read-only mappings as plain dicts (a mapping proxy does
        not pickle), so a config can travel to worker processes."""
        state = {f.name: getattr(self, f.name) for f in fields(self)}
        state["constant_noise"] = dict(self.constant_noise)
        state["range_bias"] = dict(self.range_bias)
        return (_build, (MeasurementConfig, state))


def _build(cls, state: dict):
    return cls(**state)


@dataclass(frozen=True)
class VehicleConfig:
    """The car: its odometry and where its sensors sit (vehicle frame: rear-axle centre, x
    forward, y left).

    odometry_noise: sigma of each odometry sample's speed and steering readings, for an
        "ackermann" car (`slam.vehicle.OdometryNoise`, with its pose floor for slip).
    unicycle_noise: the same for a "unicycle" vehicle's speed and yaw-rate samples
        (`slam.motion.UnicycleNoise`).
    increment_noise: the noise of a "pose-increment" vehicle's odometry increments, per metre
        and per radian (`slam.motion.IncrementNoise`). The sequence's vehicle says which of the
        three its odometry is.
    steering: the front-wheel angle from the steering reading (`slam.vehicle.SteeringCalibration`,
        offset + gain r + cubic r^3; the identity by default).
    laser_pose: (x_m, y_m, theta_rad) of the laser, replacing the sequence's (a calibrated
        mounting); None keeps the sequence's.
    laser_latency_s: how long after it was measured a scan is stamped: scan k is placed at the
        pose of its stamp minus this (`SlamLog.scan_t` holds those times; the sequence's own
        stamps stay the scans', e.g. for choosing the GPS fixes within 25 ms of a scan). 0
        (default): at its stamp. Derived for the ute by the calibration's J on scans 1-2000
        (`experiments.paper.vp_calibration.latency_profile`), a sensor property, never a
        GPS error; a magnitude of a second or more is an error.
    gps_antenna: (x_m, y_m) of the GPS antenna, replacing the sequence's; None keeps the
        sequence's (the laser's position when it has none).
    max_odometry_gap_s: a longer stretch without odometry inside the run is an error.
    min_travel_m: a scan is used (associated, updated, mapped) only when the odometry has moved
        the vehicle at least this far since the last scan used; the others are predicted only
        (status SKIPPED). 0 (default): every scan. A small value (the ute's 1 mm) skips the scans
        of a vehicle standing still: a scan from the same place repeats the last one's errors.
    calibrated_for: (wheelbase_m, encoder_offset_m) of the car whose odometry these settings
        describe (the simulated Cycab's by default); a run on a sequence whose vehicle differs
        is warned (`slam.checks.check_fit`). None: no claim.
    """

    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    unicycle_noise: UnicycleNoise = field(default_factory=UnicycleNoise)
    increment_noise: IncrementNoise = field(default_factory=IncrementNoise)
    steering: SteeringCalibration = field(default_factory=SteeringCalibration)
    laser_pose: tuple[float, float, float] | None = None
    laser_latency_s: float = 0.0
    gps_antenna: tuple[float, float] | None = None
    max_odometry_gap_s: float = 1.0
    min_travel_m: float = 0.0
    calibrated_for: tuple[float, float] | None = (1.2, 0.0)

    def __post_init__(self) -> None:
        for name, n in (("laser_pose", 3), ("gps_antenna", 2), ("calibrated_for", 2)):
            v = getattr(self, name)
            if v is not None and (len(v) != n or not all(math.isfinite(x) for x in v)):
                raise SlamError(f"vehicle.{name}: expected {n} finite numbers, got {v!r}")
            for i, x in enumerate(v or ()):  # x, y m (the file's coordinates); theta rad
                limit = MAX_ANGLE_RAD if name == "laser_pose" and i == 2 else MAX_COORDINATE_M
                setting(f"vehicle.{name}[{i}]", x, signed=True, limit=limit)
        if not self.max_odometry_gap_s > 0:
            raise SlamError("vehicle.max_odometry_gap_s: must be > 0")
        if self.max_odometry_gap_s < SETTING_TINY:
            raise SlamError(
                f"vehicle.max_odometry_gap_s: must be at least {SETTING_TINY:g} s, "
                f"got {self.max_odometry_gap_s!r}"
            )
        _finite("vehicle", "min_travel_m", self.min_travel_m)
        v = self.laser_latency_s
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or not abs(v) < MAX_LATENCY_S
            or (v != 0 and abs(v) < SETTING_TINY)
        ):
            raise SlamError(
                f"vehicle.laser_latency_s: must be 0 or a number of magnitude in "
                f"[{SETTING_TINY:g}, {MAX_LATENCY_S:g}) s, got {v!r}"
            )


# The start's sigmas: a prior far wider than the measurements' noise loses their information to
# rounding (the innovation covariance is then not positive definite in double precision: seen
# from 1e7 m and 2e6 rad, with centimetre measurements); no heading is less known than +-pi.
START_XY_SIGMA_LIMIT = 1e4  # m
START_HEADING_SIGMA_LIMIT = math.pi  # rad


@dataclass(frozen=True)
class StartConfig:
    """The filter's prior at the first scan (`slam.start`): the truth when the sequence has it,
    else a fit of the antenna track to the GPS fixes of the first `gps_fit_m` metres, else the
    origin.

    initial_pose_sigma: (sigma_x_m, sigma_y_m, sigma_theta_rad) of a start from the truth or the
        origin (0: the map's frame is the start pose).
    initial_heading_rad: the start heading, overriding the GPS fit's (needed for a GPS start
        without motion) or the origin's 0; None: not given.
    gps_fit_m: metres of driving whose fixes the start is fitted to.
    gps_track: the track fitted: "dead-reckoning" (the odometry alone) or "slam" (the path of a
        first pass of this filter over those metres from a provisional start: the landmarks
        keep its shape over hundreds of metres, where dead reckoning drifts by degrees).
    gps_sigma_m, heading_sigma_rad: floors of the start uncertainty from GPS (the fit's own is
        used when it is larger).
    """

    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    initial_heading_rad: float | None = None
    gps_fit_m: float = 50.0
    gps_track: str = "dead-reckoning"
    gps_sigma_m: float = 1.0
    heading_sigma_rad: float = math.radians(5.0)

    def __post_init__(self) -> None:
        if len(self.initial_pose_sigma) != 3 or not all(
            0 <= v < math.inf for v in self.initial_pose_sigma
        ):
            raise SlamError("start.initial_pose_sigma: expected three finite sigmas >= 0")
        for i, v in enumerate(self.initial_pose_sigma):
            limit = START_HEADING_SIGMA_LIMIT if i == 2 else START_XY_SIGMA_LIMIT
            setting(f"start.initial_pose_sigma[{i}]", v, limit=limit)
        h = self.initial_heading_rad
        if h is not None and (isinstance(h, bool) or not math.isfinite(h)):
            raise SlamError(f"start.initial_heading_rad: must be a finite number, got {h!r}")
        if h is not None:
            setting("start.initial_heading_rad", h, signed=True, limit=MAX_ANGLE_RAD)
        _choice("start", "gps_track", self.gps_track, GPS_START_TRACKS)
        _finite("start", "gps_fit_m", self.gps_fit_m)
        setting("start.gps_sigma_m", self.gps_sigma_m, limit=START_XY_SIGMA_LIMIT)
        setting("start.heading_sigma_rad", self.heading_sigma_rad, limit=START_HEADING_SIGMA_LIMIT)


@dataclass(frozen=True)
class FilterConfig:
    """The EKF itself.

    first_estimates_jacobians: each landmark's Jacobian at its first estimate and the motion
        Jacobian from the prior poses (Huang, Mourikis and Roumeliotis 2008), so that the filter
        does not grow confident in the global heading, which nothing observes.
    """

    first_estimates_jacobians: bool = False


@dataclass(frozen=True)
class SlamConfig:
    """Every setting of a run, by concern; the defaults are trunkslam's built-in ones
    (`trunkslam slam` without --config). See the module doc for the sections."""

    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    measurement: MeasurementConfig = field(default_factory=MeasurementConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    start: StartConfig = field(default_factory=StartConfig)
    map_policy: MapPolicy = field(default_factory=MapPolicy)
    filter: FilterConfig = field(default_factory=FilterConfig)
    closure: ClosureConfig = field(default_factory=ClosureConfig)

    def __post_init__(self) -> None:
        for f in fields(self):
            want = typing.get_type_hints(SlamConfig)[f.name]
            if not isinstance(getattr(self, f.name), want):
                raise SlamError(
                    f"SlamConfig.{f.name}: expected a {want.__name__}, got "
                    f"{type(getattr(self, f.name)).__name__}"
                )

    def with_(self, **sections) -> SlamConfig:
        """A copy with settings replaced by dotted path: `with_(**{"association.method": "nn",
        "features.extractor.short_trunks": True})`, or a whole section by its name."""
        data = self.to_dict()
        for path, value in sections.items():
            *head, last = path.split(".")
            node = data
            for k in head:
                node = node.setdefault(k, {})
            node[last] = _plain(value)
        return SlamConfig.from_dict(data)

    def to_dict(self) -> dict:
        """Plain nested dict (None settings left out); `from_dict` reads it back."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> SlamConfig:
        """A config from a plain nested dict; unknown keys and wrong types are errors naming
        the key's path. Keys left out keep their defaults."""
        return config_from_dict(cls, data)


# The flat keys of the format before the sections: where each lives now (for the error message).
MOVED = {
    "odometry_noise": "vehicle.odometry_noise",
    "steering": "vehicle.steering",
    "laser_pose": "vehicle.laser_pose",
    "max_odometry_gap_s": "vehicle.max_odometry_gap_s",
    "min_travel_m": "vehicle.min_travel_m",
    "measurement_noise": "measurement.noise",
    "constant_noise": "measurement.constant_noise",
    "fit_floor_range_m": "measurement.fit_floor_range_m",
    "fit_floor_bearing_rad": "measurement.fit_floor_bearing_rad",
    "range_bias": "measurement.range_bias",
    "max_feature_range_m": "measurement.max_range_m",
    "gate_prob": "association.gate_prob",
    "new_feature_gate_prob": "association.new_feature_gate_prob",
    "window_scans": "association.window_scans",
    "association_params": "association.params",
    "view_margin_m": "association.view_margin_m",
    "view_margin_rad": "association.view_margin_rad",
    "initial_pose_sigma": "start.initial_pose_sigma",
    "gps_start_fit_m": "start.gps_fit_m",
    "gps_start_track": "start.gps_track",
    "gps_sigma_m": "start.gps_sigma_m",
    "initial_heading_sigma_rad": "start.heading_sigma_rad",
    "first_estimates_jacobians": "filter.first_estimates_jacobians",
}
# Settings that were removed, and why (for the error message).
RETIRED = {
    "short_trunk_radius_m": "removed: a short trunk's radius prior is now the extractor's radius "
    "limits, uniform on [r_min_m, r_max_m] (no site's trunk sizes)",
    "short_trunk_radius_sigma_m": "removed: a short trunk's radius prior is now the extractor's "
    "radius limits, uniform on [r_min_m, r_max_m] (no site's trunk sizes)",
}
SWEEP_KEYS = {"study", "trials", "grid", "points", "base", "executor"}


def config_to_dict(obj) -> dict:
    """A dataclass (or NamedTuple) as a plain nested dict, None values left out."""
    out = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if v is None:
            continue
        out[f.name] = _plain(v)
    return out


def _plain(v):
    if is_dataclass(v):
        return config_to_dict(v)
    if isinstance(v, tuple) and hasattr(v, "_asdict"):
        return {k: _plain(x) for k, x in v._asdict().items()}
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def _unknown_key(cls, key: str, names: set, path: str) -> SlamError:
    where = f"{path}.{key}" if path else key
    close = difflib.get_close_matches(key, sorted(names), n=1, cutoff=0.6)
    if cls is SlamConfig and key in MOVED:
        hint = f"; this setting is now {MOVED[key]} (configurations have sections)"
    elif key in RETIRED:
        hint = f"; {RETIRED[key]}"
    else:
        hint = f"; did you mean {close[0]!r}?" if close else ""
    return SlamError(
        f"{where}: unknown setting of {cls.__name__}{hint} (known: {', '.join(sorted(names))})"
    )


def config_from_dict(cls, data: Mapping, path: str = ""):
    """`cls` (a dataclass) from a plain nested dict, strictly; see the module doc."""
    if not isinstance(data, Mapping):
        raise SlamError(f"{path or cls.__name__}: expected a table of settings, got {_shown(data)}")
    if cls is SlamConfig and SWEEP_KEYS & set(data):
        raise SlamError(
            f"{', '.join(sorted(SWEEP_KEYS & set(data)))}: this is a sweep specification (a "
            "study over a grid of settings), not a SLAM configuration; run it with "
            "`trunkslam sweep FILE`"
        )
    hints = typing.get_type_hints(cls)
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise _unknown_key(cls, unknown[0], names, path)
    kwargs = {k: _convert(hints[k], v, f"{path}.{k}" if path else k) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except SlamError:
        raise
    except (TypeError, ValueError) as exc:  # a nested type's own check (features: FeaturesError)
        raise SlamError(f"{path or cls.__name__}: {exc}") from None


_MAX_INT = 2**63 - 1  # TOML's integers are 64-bit


def _shown(v) -> str:
    """A value as an error message shows it (long ones cut)."""
    text = repr(v)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _convert(tp, value, path: str):
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _convert(inner, value, path)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SlamError(f"{path}: expected a number, got {_shown(value)}")
        if isinstance(value, int) and abs(value) > _MAX_INT:
            raise SlamError(f"{path}: expected a number, got one too large ({_shown(value)})")
        if math.isnan(value):
            raise SlamError(f"{path}: expected a number, got nan")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SlamError(f"{path}: expected a whole number, got {_shown(value)}")
        if abs(value) > _MAX_INT:
            raise SlamError(f"{path}: a whole number beyond 64 bits ({_shown(value)})")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise SlamError(f"{path}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise SlamError(f"{path}: expected a string, got {_shown(value)}")
        return value
    if tp is dict:  # free-form parameters (checked by the section that takes them)
        if not isinstance(value, Mapping):
            raise SlamError(f"{path}: expected a table, got {_shown(value)}")
        return dict(value)
    if origin is tuple:
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            raise SlamError(f"{path}: expected a list of {len(args)} numbers, got {_shown(value)}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if origin in (Mapping, dict) and args:
        if not isinstance(value, Mapping):
            raise SlamError(f"{path}: expected a table, got {_shown(value)}")
        return {str(k): _convert(args[1], v, f"{path}.{k}") for k, v in value.items()}
    if isinstance(tp, type) and issubclass(tp, tuple) and hasattr(tp, "_fields"):  # NamedTuple
        if not isinstance(value, Mapping):
            raise SlamError(
                f"{path}: expected a table with {list(tp._fields)}, got {_shown(value)}"
            )
        missing = [k for k in tp._fields if k not in value]
        unknown = sorted(set(value) - set(tp._fields))
        if missing or unknown:
            raise SlamError(
                f"{path}: needs exactly {list(tp._fields)} (missing {missing}, unknown {unknown})"
            )
        return tp(*(_convert(float, value[k], f"{path}.{k}") for k in tp._fields))
    if is_dataclass(tp):
        return config_from_dict(tp, value, path)
    raise SlamError(f"{path}: cannot read a setting of type {tp!r}")  # pragma: no cover
