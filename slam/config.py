"""`SlamConfig`: every setting of a `slam.run`, with the experiments' values as defaults, and
its strict conversion from and to plain dicts (what a TOML configuration file holds).

`SlamConfig.from_dict(d)` refuses unknown keys and wrong types naming the key's path
("odometry_noise.speed_sigma_mps: ..."), then the dataclasses' own checks refuse impossible
values (negative sigmas, probabilities outside (0, 1)). `to_dict()` gives the same structure
back, leaving out settings that are None (TOML has no null), so a dumped configuration can be
fed back unchanged.
"""

from __future__ import annotations

import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass

from slam.errors import SlamError
from slam.mapping import MapPolicy
from slam.measurement import (
    DEFAULT_CONSTANT_NOISE,
    DEFAULT_FIT_FLOOR,
    DEFAULT_RANGE_BIAS,
    NoiseModel,
)
from slam.vehicle import OdometryNoise, SteeringCalibration

__all__ = ["GPS_START_TRACKS", "OWN_COVARIANCE", "SlamConfig", "config_from_dict", "config_to_dict"]

GPS_START_TRACKS = ("dead-reckoning", "slam")  # SlamConfig.gps_start_track
# Extractors whose circles' covariance ("fit" noise) describes their errors, used under
# measurement_noise "auto": the first-order covariance of an orthogonal-distance fit at the
# reported circle (`features.fitting.circle_covariance`). Exact for `geometric`; for the paper's
# Gauss-Newton on eq. (6) the calibration circles' normalised errors under it (floors added,
# range bias removed) have mean squares 0.94 in range and 1.02 in bearing, against 1.79 to 0.33
# in range across beam counts under the constant model (`noise-calibration`, `by-beams` in
# docs/consistency_probes.py). Bailey's diameter-based covariance is not a fit's: constant noise.
OWN_COVARIANCE = ("geometric", "paper")


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of the run; defaults are the ones the experiments use (the simulated Cycab).

    odometry_noise: sigma of each odometry sample's speed and steering readings.
    steering: the front-wheel angle from the steering reading (`slam.vehicle.SteeringCalibration`,
        offset + gain r + cubic r^3; the identity by default).
    measurement_noise: "auto" (the circles' own covariance when the extractor gives one that
        describes its errors: `geometric` and `paper` features (`OWN_COVARIANCE`; a precomputed
        list whose covariances are all zero carries none), or detections carrying det_cov;
        constant otherwise), "fit" or "constant".
    constant_noise: the constant noise model of each extractor (`slam.measurement.NoiseModel`),
        by method name; methods not given keep their `DEFAULT_CONSTANT_NOISE` entry, methods
        unknown to both use its "other" entry.
    range_sigma_m, range_sigma_per_m, bearing_sigma_rad, cross_range_sigma_m: when set, they
        override that part of the constant model for every method.
    fit_floor_range_m, fit_floor_bearing_rad: added in quadrature to the fit's noise (model
        error the fit cannot see: range quantisation, mixed returns); the defaults are the
        maximum-likelihood floors of the `geometric` fit in the simulated tree park
        (`slam.measurement.DEFAULT_FIT_FLOOR`, calibration seeds 1000-1003).
    range_bias: known mean range error a + b r of each extractor's centres, by method name, as
        (a_m, b_per_m), subtracted from the ranges r of its circles (extracted, or a sequence's
        detections of that method); methods not given keep their `DEFAULT_RANGE_BIAS` entry
        ((0, 0) when it has none).
    laser_pose: (x_m, y_m, theta_rad) of the laser in the vehicle frame, replacing the
        sequence's (a calibrated mounting); None keeps the sequence's.
    gate_prob: chi-square probability of the association gates (passed to `associate`). 0.999
        rather than association's 0.99: in the tree park a 3-sigma odometry heading step
        (one in about a thousand scans) pushed both visible trees out of a 0.99 gate; they were
        re-mapped as new landmarks and the run never recovered (2 of 50 runs, pose errors of
        10-18 cm). Inside the gate the choice is IHGR's likelihood costs, not the gate.
    new_feature_gate_prob: an unassociated measurement starts a tentative feature only when it
        lies outside this (wider) gate of every landmark and tentative feature in view;
        between the two gates it is ignored (status AMBIGUOUS), so a measurement of a mapped
        tree that just failed its gate does not become a duplicate landmark.
    association_params: extra keyword arguments of `association.associate` (for "ihgr-window":
        the `CostModel` densities and the rounding options).
    window_scans: K of the "ihgr-window" association (`association.SlidingWindowAssociator`),
        2..4 intended; see the README for how the default was chosen.
    map_policy: tentative features (`slam.mapping.MapPolicy`).
    initial_pose_sigma: (sigma_x_m, sigma_y_m, sigma_theta_rad) of the start pose when it comes
        from the truth or the origin (0: the map's frame is the start pose).
    gps_start_fit_m: a start from GPS fits the antenna track of the first this many metres of
        driving to the GPS fixes (position and heading, with their uncertainty from the fit);
        see `slam.start`.
    gps_start_track: the track fitted: "dead-reckoning" (the odometry alone; default) or "slam"
        (the path of a first pass of this filter over those metres from a provisional start:
        the landmarks keep its shape over hundreds of metres, where dead reckoning drifts by
        degrees; the pass costs about the run's time over that stretch).
    gps_sigma_m, initial_heading_sigma_rad: floors of the start uncertainty from GPS (the fit's
        own uncertainty is used when it is larger).
    max_odometry_gap_s: a longer stretch without odometry inside the run is an error.
    min_travel_m: a scan is used (associated, updated, mapped) only when the odometry has moved
        the vehicle at least this far since the last scan used; the others are predicted only
        and their measurements logged with status SKIPPED (tentatives are neither seen nor
        missed in them). 0 (default): every scan. A small value (the preset's 1 mm) skips the
        scans of a vehicle standing still: a scan from the same place repeats the last one's
        errors, which a filter that treats scans as independent would count again.
    max_feature_range_m: circles farther away are not used.
    view_margin_m, view_margin_rad: landmarks this far outside the laser's range and field of
        view are still offered to the association.
    """

    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    steering: SteeringCalibration = field(default_factory=SteeringCalibration)
    measurement_noise: str = "auto"
    constant_noise: Mapping[str, NoiseModel] = field(default_factory=dict)
    range_sigma_m: float | None = None
    range_sigma_per_m: float | None = None
    bearing_sigma_rad: float | None = None
    cross_range_sigma_m: float | None = None
    fit_floor_range_m: float = DEFAULT_FIT_FLOOR[0]
    fit_floor_bearing_rad: float = DEFAULT_FIT_FLOOR[1]
    range_bias: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    laser_pose: tuple[float, float, float] | None = None
    gate_prob: float = 0.999
    new_feature_gate_prob: float = 0.9999
    association_params: dict = field(default_factory=dict)
    window_scans: int = 3
    map_policy: MapPolicy = field(default_factory=MapPolicy)
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gps_start_fit_m: float = 50.0
    gps_start_track: str = "dead-reckoning"
    gps_sigma_m: float = 1.0
    initial_heading_sigma_rad: float = math.radians(5.0)
    first_estimates_jacobians: bool = False
    max_odometry_gap_s: float = 1.0
    min_travel_m: float = 0.0
    max_feature_range_m: float = math.inf
    view_margin_m: float = 2.0
    view_margin_rad: float = math.radians(10.0)

    def __post_init__(self) -> None:
        if self.measurement_noise not in ("auto", "fit", "constant"):
            raise SlamError(
                f"SlamConfig.measurement_noise: expected 'auto', 'fit' or 'constant', got "
                f"{self.measurement_noise!r}"
            )
        if self.gps_start_track not in GPS_START_TRACKS:
            raise SlamError(
                f"SlamConfig.gps_start_track: expected one of {list(GPS_START_TRACKS)}, got "
                f"{self.gps_start_track!r}"
            )
        for name in ("gate_prob", "new_feature_gate_prob"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise SlamError(f"SlamConfig.{name}: must be in (0, 1), got {v!r}")
        for name in (
            "range_sigma_m",
            "range_sigma_per_m",
            "bearing_sigma_rad",
            "cross_range_sigma_m",
        ):
            v = getattr(self, name)
            if v is not None and not (0 <= v < math.inf):
                raise SlamError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        for name in (
            "fit_floor_range_m",
            "fit_floor_bearing_rad",
            "gps_start_fit_m",
            "gps_sigma_m",
            "initial_heading_sigma_rad",
            "view_margin_m",
            "view_margin_rad",
            "min_travel_m",
        ):
            v = getattr(self, name)
            if not (0 <= v < math.inf):
                raise SlamError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        if isinstance(self.window_scans, bool) or not 1 <= self.window_scans <= 8:
            raise SlamError(
                f"SlamConfig.window_scans: must be an integer in 1..8, got {self.window_scans!r}"
            )
        if not self.max_odometry_gap_s > 0:
            raise SlamError("SlamConfig.max_odometry_gap_s: must be > 0")
        if not self.max_feature_range_m > 0:
            raise SlamError("SlamConfig.max_feature_range_m: must be > 0 (inf: no limit)")
        if len(self.initial_pose_sigma) != 3 or min(self.initial_pose_sigma) < 0:
            raise SlamError("SlamConfig.initial_pose_sigma: expected three sigmas >= 0")
        if self.laser_pose is not None and (
            len(self.laser_pose) != 3 or not all(math.isfinite(v) for v in self.laser_pose)
        ):
            raise SlamError("SlamConfig.laser_pose: expected three finite numbers (x, y, theta)")
        models = dict(DEFAULT_CONSTANT_NOISE)  # the given methods replace their defaults
        for method, model in dict(self.constant_noise).items():
            m = NoiseModel(*model)
            if not all(0 <= v < math.inf for v in m):
                raise SlamError(f"SlamConfig.constant_noise.{method}: sigmas must be finite, >= 0")
            models[method] = m
        object.__setattr__(self, "constant_noise", types.MappingProxyType(models))
        biases = dict(DEFAULT_RANGE_BIAS)
        for method, v in dict(self.range_bias).items():
            ok = isinstance(v, (tuple, list)) and len(v) == 2
            ok = ok and all(isinstance(x, (int, float)) and math.isfinite(x) for x in v)
            if not ok or abs(v[0]) >= 1.0 or abs(v[1]) >= 0.1:
                raise SlamError(
                    f"SlamConfig.range_bias.{method}: expected (a_m, b_per_m) with |a| < 1 m and "
                    f"|b| < 0.1, got {v!r}"
                )
            biases[method] = (float(v[0]), float(v[1]))
        object.__setattr__(self, "range_bias", types.MappingProxyType(biases))

    def range_bias_for(self, method: str) -> tuple[float, float]:
        """(a_m, b_per_m): the known mean range error a + b r of circles from `method`."""
        return tuple(self.range_bias.get(method, (0.0, 0.0)))

    def __reduce__(self):
        """Pickled as its fields, the read-only `constant_noise` and `range_bias` as plain dicts
        (a mapping proxy does not pickle), so a config can travel to worker processes."""
        state = {f.name: getattr(self, f.name) for f in fields(self)}
        state["constant_noise"] = dict(self.constant_noise)
        state["range_bias"] = dict(self.range_bias)
        return (_slam_config, (state,))

    def noise_for(self, method: str, has_cov: bool | None = None) -> tuple[str, NoiseModel]:
        """("fit" | "constant", NoiseModel) for circles from `method`. has_cov: whether they carry
        their own covariance (default: the methods of `OWN_COVARIANCE`)."""
        kind = self.measurement_noise
        if kind == "auto":
            own = method in OWN_COVARIANCE if has_cov is None else has_cov
            kind = "fit" if own else "constant"
        base = self.constant_noise.get(method, self.constant_noise["other"])
        given = (
            self.range_sigma_m,
            self.range_sigma_per_m,
            self.bearing_sigma_rad,
            self.cross_range_sigma_m,
        )
        model = NoiseModel(*(float(b if g is None else g) for b, g in zip(base, given)))
        if kind == "constant" and (model[0] + model[1] <= 0 or model[2] + model[3] <= 0):
            raise SlamError(f"SlamConfig: the constant noise model {tuple(model)} is zero")
        return kind, model

    def to_dict(self) -> dict:
        """Plain nested dict (None settings left out); `from_dict` reads it back."""
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> SlamConfig:
        """A config from a plain nested dict; unknown keys and wrong types are errors naming
        the key's path. Keys left out keep their defaults."""
        return config_from_dict(cls, data)


def _slam_config(state: dict) -> SlamConfig:
    return SlamConfig(**state)


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


def config_from_dict(cls, data: Mapping, path: str = ""):
    """`cls` (a dataclass) from a plain nested dict, strictly; see the module doc."""
    if not isinstance(data, Mapping):
        raise SlamError(f"{path or cls.__name__}: expected a table of settings, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        where = f"{path}." if path else ""
        raise SlamError(
            f"{where}{unknown[0]}: unknown setting of {cls.__name__} (known: {sorted(names)})"
        )
    kwargs = {k: _convert(hints[k], v, f"{path}.{k}" if path else k) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except SlamError:
        raise
    except (TypeError, ValueError) as exc:  # a nested type's own check
        raise SlamError(f"{path or cls.__name__}: {exc}") from None


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
            raise SlamError(f"{path}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SlamError(f"{path}: expected a whole number, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise SlamError(f"{path}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise SlamError(f"{path}: expected a string, got {value!r}")
        return value
    if tp is dict:  # free-form parameters (checked by whoever takes them)
        if not isinstance(value, Mapping):
            raise SlamError(f"{path}: expected a table, got {value!r}")
        return dict(value)
    if origin is tuple:
        if not isinstance(value, (list, tuple)) or len(value) != len(args):
            raise SlamError(f"{path}: expected a list of {len(args)} numbers, got {value!r}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if origin in (Mapping, dict) and args:
        if not isinstance(value, Mapping):
            raise SlamError(f"{path}: expected a table, got {value!r}")
        return {str(k): _convert(args[1], v, f"{path}.{k}") for k, v in value.items()}
    if isinstance(tp, type) and issubclass(tp, tuple) and hasattr(tp, "_fields"):  # NamedTuple
        if not isinstance(value, Mapping):
            raise SlamError(f"{path}: expected a table with {list(tp._fields)}, got {value!r}")
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
