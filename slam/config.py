"""`SlamConfig`: every setting of a run, grouped by concern, and its strict conversion from and
to plain dicts (what a TOML configuration file holds).

A run is its configuration: the features (extractor and its parameters), the association
(method, gates, window), the measurement model, the vehicle (odometry noise, steering
calibration, laser and antenna poses), the start, the map policy and the filter. Written beside
a result (`config.toml`), it reproduces the run to the bit.

Every default of a run's settings is set here, once, with its source in one line (`default`:
the paper, the simulator, a sensor model, a named calibration, or a design choice with its
reason); `setting_sources()` lists them (the configuration reference shows that list). The
extractors' parameters keep theirs in `features` (`ExtractorParams`, `BaileyParams`, each field
with its source), since `features` imports nothing of `slam`.

    [features]      method, [features.extractor] (`features.ExtractorParams`),
                    [features.bailey] (the Bailey detector's noise model and constants)
    [association]   method, gate_prob, new_feature_gate_prob, window_scans, view margins, params
    [measurement]   noise ("auto" | "fit" | "constant"), constant_noise.<method>, fit floors,
                    range_bias.<method>, max_range_m, pass_offset_sd_m, pass_gap_s
    [vehicle]       odometry_noise, steering, laser_pose, laser_latency_s, gps_antenna,
                    max_odometry_gap_s, min_travel_m
    [start]         initial_pose_sigma, initial_heading_rad, GPS start fit
    [map_policy]    `MapPolicy`
    [closure]       `ClosureConfig` (loop closure; off by default)
    [filter]        first_estimates_jacobians

`SlamConfig.from_dict(d)` refuses unknown keys (with a "did you mean" and, for the keys of the
flat format of earlier versions, where the setting lives now), wrong types and impossible
values, naming the key's path ("vehicle.odometry_noise.speed_sigma_mps: ..."). `to_dict()`
gives the same structure back, leaving out settings that are None (TOML has no null), so a
dumped configuration loads back equal.
"""

from __future__ import annotations

import difflib
import functools
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass

import numpy as np

from features import ExtractorParams
from features.bailey import BaileyParams
from slam.errors import SlamError
from slam.measurement import MeasurementModel, NoiseModel
from slam.sequence import MAX_ANGLE_RAD, MAX_COORDINATE_M
from slam.validators import SETTING_TINY, nonnegative_fields, setting

__all__ = [
    "ASSOCIATION_METHODS",
    "DEFAULT_CONSTANT_NOISE",
    "DEFAULT_FIT_FLOOR",
    "DEFAULT_RANGE_BIAS",
    "FEATURE_METHODS",
    "GPS_START_TRACKS",
    "OWN_COVARIANCE",
    "AssociationConfig",
    "BaileyConfig",
    "ClosureConfig",
    "FeaturesConfig",
    "FilterConfig",
    "IncrementNoise",
    "MapPolicy",
    "MeasurementConfig",
    "OdometryNoise",
    "SlamConfig",
    "StartConfig",
    "SteeringCalibration",
    "UnicycleNoise",
    "VehicleConfig",
    "config_from_dict",
    "config_to_dict",
    "default",
    "setting_sources",
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


MAX_PASS_OFFSET_M = 10.0  # a trunk's centre offset shared by a pass: above a trunk's size
MAX_PASS_GAP_S = 1e6  # s, longer than any run: one pass per landmark
MAX_PASS_CORR_RAD = 1e6  # rad: a finite correlation length beyond this is inf in all but name
MAX_LATENCY_S = 1.0  # a laser stamped a second or more off its measurement is a clock fault


def default(value, source: str, *, factory: bool = False):
    """A setting's default and where it comes from, in one line: "paper: ...", "simulator: ...",
    "sensor model: ...", "calibration: ..." (a named calibration run) or "design: ..." (a choice
    of this program's, reason given). `factory`: `value` makes the default (a dataclass)."""
    meta = {"source": source}
    if factory:
        return field(default_factory=value, metadata=meta)
    return field(default=value, metadata=meta)


def setting_sources(obj=None, path: str = "") -> list[tuple[str, object, str]]:
    """(dotted path, default, source) of every setting of `obj` (default `SlamConfig()`, the
    built-in settings as they take effect), nested sections expanded: the configuration
    reference (docs/configuration.md) shows this list."""
    obj = SlamConfig() if obj is None else obj
    out = []
    for f in fields(obj):
        where = f"{path}.{f.name}" if path else f.name
        value = getattr(obj, f.name)
        if is_dataclass(value):
            out += setting_sources(value, where)
        else:
            out.append((where, _plain(value), f.metadata.get("source", "")))
    return out


def _finite(owner: str, name: str, v) -> None:
    """A finite number >= 0 in the range where the kernels' maths holds
    (`slam.validators.setting`)."""
    setting(f"{owner}.{name}", v)


def _choice(owner: str, name: str, v, choices) -> None:
    if v not in choices:
        raise SlamError(f"{owner}.{name}: expected one of {list(choices)}, got {v!r}")


# ---- the defaults' tables and the sections' parts (odometry, steering, map policy, closure) ----

# The built-in measurement model is neutral: it assumes no site's calibration. The simulated
# tree park's calibrated values (`trunkslam reproduce noise-calibration`: the constant models of
# the paper, geometric and Bailey circles, their range biases and the geometric fit's floors) are
# the `cycab` preset's (experiments/presets/cycab.toml; docs/experiments/consistency.md).
#
# The "constant" measurement noise model of each extractor: configured constants, not a fit:
#   sigma_range = range_sigma_m + range_sigma_per_m * range,
#   sigma_bearing^2 = bearing_sigma_rad^2 + (cross_range_sigma_m / range)^2.
# Built in: one model for every extractor ("other"), the published model of a tree detector on
# a SICK laser, the Zaragoza SLAM school's for the Victoria Park detections: 0.05 m + 1% of the
# range and 0.5 deg (BAILEY_DETECTOR.md section 4; the Bailey detector's own, `BaileyConfig`).
DEFAULT_CONSTANT_NOISE: dict[str, NoiseModel] = {
    "other": NoiseModel(0.05, 0.01, math.radians(0.5), 0.0)
}

# Mean range error of each extractor's centres as a function of range, bias(r) = a + b r
# (a in m, b in m per m of range), subtracted from its ranges. Built in: none (no correction; a
# bias is a property of one sensor and extractor, measured by a calibration such as the
# simulated tree park's in the `cycab` preset). A bias that every tree shares is not noise: a
# filter that treats scans as independent averages it into the pose with ever-growing
# confidence (NEES above its bounds), so a calibrated sensor should give its own.
DEFAULT_RANGE_BIAS: dict[str, tuple[float, float]] = {}

# Floors (range m, bearing rad) added in quadrature to a fit's own covariance ("fit" noise).
# Built in: none, the circle fit's own first-order covariance (`features.fitting.
# circle_covariance`) as the sensor model gives it. The simulated tree park's maximum-likelihood
# floors of the geometric fit (6.3 mm, 0.093 mrad: range quantisation and mixed returns, which
# the fit's independent-Gaussian model cannot see) are the `cycab` preset's.
DEFAULT_FIT_FLOOR: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class OdometryNoise:
    """Independent errors of each odometry sample's readings (zero-order hold values).

    speed_sigma_mps: standard deviation of the encoder speed reading, m/s.
    steer_sigma_rad: standard deviation of the steering angle reading, rad.
    The defaults are those of the simulated Cycab (`experiments.sim.trajectory.CycabParams`):
    a car's odometry noise has no neutral value, so a run on these built-in values says so
    (`experiments.pipeline.slam`); a car's own calibration (a preset) replaces them.
    floor_xy_m_per_sqrt_s, floor_theta_rad_per_sqrt_s: a small white process noise on the pose
        itself (variance per second). It keeps the covariance from being singular when the car
        is at or near rest: the linearised model then puts no noise on y and theta, while the
        neglected second-order terms (speed error x steering error, heading error x distance
        actually driven) do move the car; without it the first scans' NEES reached 2000 in
        some runs of the tree park. While driving it is negligible (1 mm and 0.1 mrad per
        square-root second against about 2 cm and 8 mrad per second of odometry noise).
    speed_sigma_per_speed: the speed sigma grows by this much per m/s of the encoder's reading
        (a scale error, wheel slip): sigma_v = speed_sigma_mps + speed_sigma_per_speed |v_e|.
    steer_sigma_per_lateral_mps2: the steering sigma grows by this much (rad) per m/s^2 of the
        sample's lateral acceleration a = v_c^2 |tan(alpha)| / L (the tyres' slip angles grow
        with the cornering force): sigma_alpha = steer_sigma_rad + this * a.
    Both 0 by default (constant noise, as the simulated Cycab's readings); the Victoria Park
    preset's values are fitted (experiments/paper/victoria_park/calibration.py).
    """

    speed_sigma_mps: float = default(
        0.1, "simulator: the simulated Cycab's, no neutral value exists (a run says so)"
    )
    steer_sigma_rad: float = default(
        math.radians(2.0), "simulator: the simulated Cycab's 2 deg, no neutral value exists"
    )
    floor_xy_m_per_sqrt_s: float = default(
        0.001, "design: keeps the covariance regular at rest (tree park NEES, see doc)"
    )
    floor_theta_rad_per_sqrt_s: float = default(
        0.0001, "design: keeps the covariance regular at rest (tree park NEES, see doc)"
    )
    speed_sigma_per_speed: float = default(0.0, "design: 0, no scale error modelled")
    steer_sigma_per_lateral_mps2: float = default(0.0, "design: 0, no tyre slip modelled")

    def __post_init__(self) -> None:
        nonnegative_fields("vehicle.odometry_noise", self)

    def Q_u(self, v_enc_mps: float, v_axle_mps: float, steer_rad: float, L: float) -> np.ndarray:
        """(2, 2) covariance of one sample's (v_e, alpha) readings."""
        sv = self.speed_sigma_mps + self.speed_sigma_per_speed * abs(v_enc_mps)
        lateral = v_axle_mps * v_axle_mps * abs(math.tan(steer_rad)) / L
        sa = self.steer_sigma_rad + self.steer_sigma_per_lateral_mps2 * lateral
        return np.diag([sv * sv, sa * sa])

    @property
    def Q_floor(self) -> np.ndarray:
        """(3, 3) pose noise per second (world frame)."""
        a, b = self.floor_xy_m_per_sqrt_s**2, self.floor_theta_rad_per_sqrt_s**2
        return np.diag([a, a, b])


@dataclass(frozen=True)
class SteeringCalibration:
    """The front-wheel angle from the steering reading r:

        alpha = offset_rad + gain r + cubic_per_rad2 r^3

    A steering sensor reads the wheel angle through a linkage, and a bicycle model's single
    wheel stands for two that turn by different angles, so the angle that sets the turn rate
    v tan(alpha) / L need not be the reading itself. The identity by default (the simulated
    Cycab's readings are the model's angle); the Victoria Park preset's gain and cubic term are
    fitted (experiments/paper/victoria_park/calibration.py). The odometry noise (`OdometryNoise`)
    applies to the calibrated angle.
    """

    offset_rad: float = default(0.0, "design: identity, no correction of the reading")
    gain: float = default(1.0, "design: identity, no correction of the reading")
    cubic_per_rad2: float = default(0.0, "design: identity, no correction of the reading")

    def __post_init__(self) -> None:
        for name in ("offset_rad", "gain", "cubic_per_rad2"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise SlamError(f"SteeringCalibration.{name}: must be a finite number, got {v!r}")
        if not self.gain > 0:
            raise SlamError(f"SteeringCalibration.gain: must be > 0, got {self.gain!r}")
        for name in ("offset_rad", "gain", "cubic_per_rad2"):  # the range where the maths holds
            setting(f"SteeringCalibration.{name}", getattr(self, name), signed=True)

    @property
    def is_identity(self) -> bool:
        return self.offset_rad == 0.0 and self.gain == 1.0 and self.cubic_per_rad2 == 0.0

    def apply(self, steer_rad: np.ndarray) -> np.ndarray:
        """The calibrated angles of readings `steer_rad` (the same array when the identity)."""
        if self.is_identity:
            return steer_rad
        r = np.asarray(steer_rad, dtype=np.float64)
        return self.offset_rad + self.gain * r + self.cubic_per_rad2 * r**3


@dataclass(frozen=True)
class UnicycleNoise:
    """Independent errors of each (speed, yaw rate) sample (zero-order hold values).

    speed_sigma_mps (+ speed_sigma_per_speed per m/s of the reading) and yaw_rate_sigma_rad_s
    (+ yaw_rate_sigma_per_yaw_rate per rad/s of the reading): the sigmas of one sample. The
    defaults are the simulated Cycab's odometry seen as a unicycle's: its speed sigma 0.1 m/s,
    and its 2 degree steering sigma at its 1.2 m/s cruise speed on its 1.2 m wheelbase,
    v sigma_alpha / L = 2 degrees per second (`experiments.sim.trajectory.CycabParams`); a
    robot's own figures replace them.
    floor_xy_m_per_sqrt_s, floor_theta_rad_per_sqrt_s: a small white pose noise per second,
    which keeps the covariance non-singular at rest (as `OdometryNoise`'s).
    """

    speed_sigma_mps: float = default(
        0.1, "simulator: the simulated Cycab's speed noise as a unicycle's"
    )
    yaw_rate_sigma_rad_s: float = default(
        math.radians(2.0), "simulator: the Cycab's 2 deg steering noise at 1.2 m/s on 1.2 m"
    )
    speed_sigma_per_speed: float = default(0.0, "design: 0, no scale error modelled")
    yaw_rate_sigma_per_yaw_rate: float = default(0.0, "design: 0, no scale error modelled")
    floor_xy_m_per_sqrt_s: float = default(0.001, "design: as OdometryNoise's floor")
    floor_theta_rad_per_sqrt_s: float = default(0.0001, "design: as OdometryNoise's floor")

    def __post_init__(self) -> None:
        nonnegative_fields("vehicle.unicycle_noise", self)


@dataclass(frozen=True)
class IncrementNoise:
    """The noise of an odometry increment (dx, dy, dtheta in the frame of its start) of length
    d metres and turn dtheta: sigma_x = sigma_y = xy_sigma_per_m d, sigma_theta =
    theta_sigma_per_rad |dtheta| + theta_sigma_per_m d, plus the floors per second. The
    defaults are the simulated Cycab's odometry over its 1.2 m/s cruise: a speed error of 0.1 m/s
    per 50 ms sample, independent from sample to sample, adds 0.1 x 0.05 x sqrt(20) = 0.022 m per
    second of driving, 0.019 m per metre; its 2 degree steering error adds, through
    v tan(alpha) / L, 2 x 0.05 x sqrt(20) = 0.45 degree per second, 0.0065 rad per metre.
    Turning on the spot has no such derivation: theta_sigma_per_rad 0.05 (3 degrees per radian)
    is a caution to replace with a robot's own figures.
    """

    xy_sigma_per_m: float = default(
        0.019, "simulator: the Cycab's speed noise over its 1.2 m/s cruise (see doc)"
    )
    theta_sigma_per_rad: float = default(
        0.05, "design: a caution, 3 deg per radian turned on the spot"
    )
    theta_sigma_per_m: float = default(
        0.0065, "simulator: the Cycab's steering noise over its 1.2 m/s cruise (see doc)"
    )
    floor_xy_m_per_sqrt_s: float = default(0.001, "design: as OdometryNoise's floor")
    floor_theta_rad_per_sqrt_s: float = default(0.0001, "design: as OdometryNoise's floor")

    def __post_init__(self) -> None:
        nonnegative_fields("vehicle.increment_noise", self)


@dataclass(frozen=True)
class MapPolicy:
    """When tentative features join the map or are dropped.

    confirm_scans: a tentative feature joins the map when it has been associated in this many
        scans (its first sighting included): the paper's 3.
    drop_after_missed: a tentative feature is dropped when it has gone this many consecutive
        scans without being associated (1: "not seen again" in the next scan drops it).
    prune_after_expected, prune_hit_ratio, prune_range_m: a landmark of the map is removed from
        the state (marginalised out) once it has been expected in at least
        `prune_after_expected` scans since it joined the map and was associated in fewer than
        `prune_hit_ratio` of them. Expected: its predicted position lies inside the laser's
        field of view (no margins) and within `prune_range_m` and the usable range. 0 (the
        default): never; the map keeps whatever joined it.
    policy: "confirm" (the above) or "existence": every landmark and tentative carries the
        probability that it is a real trunk, updated every scan from the scan's beams and the
        association (`slam.existence`, `slam.existence_map`); a tentative joins the map when
        it reaches `existence_join_prob`, any landmark leaves it below
        `existence_remove_prob` (confirm_scans no longer decides; tentatives are still dropped
        after drop_after_missed scans unseen, and the pruner still runs when asked for).
    existence_pd_max, existence_min_beams, existence_see_through_q: the sensor model's
        detection probability, the returns a trunk needs to be seen, the chance that a beam
        passes a real trunk's place (`slam.existence.ExistenceConfig`).
    existence_pd_range_m, existence_pd_range_scale_m: Pd's range fall-off, pd_max / (1 +
        exp((d - pd_range_m) / pd_range_scale_m)) at range d (persistent clutter's repeat_prob
        falls alike; `slam.existence`, "Range fall-off"); inf: Pd does not fall with range.
    existence_false_per_scan: the extractor's false circles per scan (the clutter density is
        that spread over the view's range and field of view).
    existence_birth_prob: the existence of a new tentative: of the circles seen where nothing
        was mapped, the share that are trunks.
    existence_clutter: "uniform" (a re-sighting is weighed against the clutter density) or
        "persistent" (against a non-tree object at the landmark's place, reported again with
        probability `existence_repeat_prob` in a scan whose beams reach it, its fitted centre
        spread by `existence_shape_sd_m` per axis; `slam.existence`, "Persistent clutter").
    existence_keep_tentatives: with the existence policy, a tentative is no longer dropped
        after drop_after_missed scans unseen: it stays through its misses, each costing its
        existence (1 - Pd) where the sensor model says it was detectable (nothing where Pd is
        0), and leaves only when its existence falls below `existence_remove_prob`, so a trunk
        the extractor reports in, say, 60% of the scans that reach it accumulates its sightings
        (`slam.existence`, "Intermittent detection"). False: the paper's drop at a miss.
        A tentative that leaves the laser's reach is charged no miss; it stays a tentative
        until `existence_unreached_scans` bounds it.
        The window associator ("ihgr-window") keeps no tentatives: it has no effect there.
    existence_unreached_scans: with kept tentatives, a tentative the sensor model gave Pd 0
        (outside the view or the reach, or with fewer than `existence_min_beams` free beams)
        and that was not detected, in this many consecutive scans, is dropped: it could not
        have been confirmed in them, mostly because the car has left it behind (0: never, the
        set of kept tentatives is unbounded).
    existence_fuse_tentatives: with the existence policy, a tentative's position is its
        sightings fused (`slam.tentatives.fuse`: the inverse-covariance-weighted mean, its
        covariance shrinking) instead of its latest sighting, before its beams are counted
        (and for association). False: the latest sighting, as the paper's tentatives.
    existence_see_through_k: the see-through tolerance (`slam.existence`, "See-through
        tolerance"): a beam passing a landmark's or tentative's place is evidence against it
        only beyond its predicted position's k-sigma region plus the trunk's radius, and none
        when a beam returned inside that region; 0: no tolerance. sqrt(chi2_2(0.95)) = 2.448 is
        the 95% region.
    existence_see_through_footprint: a beam counts as passing beyond a landmark or tentative
        only when its footprint, this many beam steps either side of its ray (+ k sd_bearing
        with the tolerance), lies inside the trunk's angular half-width asin(radius / range)
        (`slam.existence`, "Beam footprint"); 0: none. 0.5 is half the beam step, the ray's
        own angular uncertainty (a design choice: the data state no beam divergence): at 35 m
        and a 0.5 deg step no beam counts against a trunk of
        radius 0.15 m.
    existence_see_through_q_by_range, existence_see_through_q_bin_m: the see-through rate per
        range bin [i bin, (i + 1) bin) (the last bin's beyond the table), each in (0, 1], in
        place of existence_see_through_q (`slam.existence`, "See-through rate by range"; (),
        the default: one q at every range). Derived per bin on a run's own established
        landmarks (`existence_rates.derive_see_through_by_range`). At most 100 rates: a
        design bound on the table's length, not a measured one.
    existence_repeat_prob_by_range, existence_repeat_prob_bin_m: with persistent clutter, the
        non-tree object's re-report rate per range bin [i bin, (i + 1) bin) (the last bin's
        beyond the table), each in (0, 1), in place of existence_repeat_prob scaled by Pd's
        range fall-off (`slam.existence`, "Repeat rate by range"; (), the default: that
        scaled single rate). A detection then weighs Pd(d) against the rate at its range, so
        a far sighting, where the extractor's false circles are common, is weaker evidence.
        Derived per bin from a run's own never-mapped tracks
        (`existence_rates.derive_repeat_by_range`). At most 100 rates (a design bound).
        Accepted and ignored with existence_clutter "uniform" (as existence_repeat_prob is)
        and with policy "confirm" (as every existence_ setting is).
    existence_birth_prob_by_range, existence_birth_prob_bin_m: a new tentative's existence per
        range bin of the circle that starts it [i bin, (i + 1) bin) (the last bin's beyond the
        table), each in (0, 1) (1 would keep the landmark forever: no evidence lowers an
        existence of 1), in place of existence_birth_prob (`slam.existence_map`; (), the
        default: one birth at every range). Of the circles seen where nothing was mapped, the
        share that are new trunks at that range: far away, where the extractor's false
        circles are common, a new track starts less probable. Derived per bin as the share of
        a run's tracks started there that joined (`existence_rates.derive_birth_by_range`).
        At most 100 rates (a design bound). Accepted and ignored with policy "confirm" (as
        every existence_ setting is).
    """

    confirm_scans: int = default(3, "paper: a tentative feature joins the map after 3 scans")
    drop_after_missed: int = default(1, "paper: a tentative feature not seen again is dropped")
    prune_after_expected: int = default(
        0, "design: 0, no pruning (the map keeps whatever joined it)"
    )
    prune_hit_ratio: float = default(0.0, "design: 0, no pruning")
    prune_range_m: float = default(math.inf, "design: inf, no range limit on pruning")
    policy: str = default(
        "confirm", "paper: 'confirm', a tentative joins after confirm_scans sightings"
    )
    existence_pd_max: float = default(
        0.9, "design: placeholder; derived from a run's detection rates (split-half)"
    )
    existence_min_beams: int = default(3, "sensor model: a circle is fitted to at least 3 returns")
    existence_false_per_scan: float = default(
        1.0, "design: placeholder; derived as the rate of circles that never join (split-half)"
    )
    existence_birth_prob: float = default(
        0.2, "design: placeholder; derived as the share of new circles that join (split-half)"
    )
    existence_see_through_q: float = default(
        0.1, "design: 1 in 10 beams passes a real trunk's place (position error, grazing)"
    )
    existence_clutter: str = default(
        "uniform", "design: 'uniform', every false circle a fresh draw over the view (as before)"
    )
    existence_repeat_prob: float = default(
        0.5, "design: placeholder; derived as how often a circle never mapped is seen again"
    )
    existence_shape_sd_m: float = default(
        0.0, "design: placeholder; derived from the spread of a never-mapped track's sightings"
    )
    existence_keep_tentatives: bool = default(
        False, "paper: False, a tentative not seen again is dropped (drop_after_missed)"
    )
    existence_pd_range_m: float = default(
        math.inf, "design: inf, Pd does not fall with range (as before); derived (split-half)"
    )
    existence_pd_range_scale_m: float = default(
        5.0, "design: placeholder, used only with a finite pd_range_m; derived (split-half)"
    )
    existence_unreached_scans: int = default(
        0, "design: 0, a kept tentative out of reach stays to the end of the run (as before)"
    )
    existence_fuse_tentatives: bool = default(
        False, "paper: False, a tentative is placed by its latest sighting"
    )
    existence_see_through_k: float = default(
        0.0, "design: 0, no tolerance (as before); 2.448 = sqrt(chi2_2(0.95)), the 95% region"
    )
    existence_see_through_footprint: float = default(
        0.0,
        "design: 0, none (as before); design: 0.5, half the beam step (the data state no beam "
        "divergence)",
    )
    existence_see_through_q_by_range: tuple[float, ...] = default(
        (),
        "design: (), one see-through rate at every range (as before); derived per bin; at "
        "most 100 rates, a design bound on the table's length",
    )
    existence_see_through_q_bin_m: float = default(
        10.0, "design: 10 m bins, as the notebook's detection-rate tables read Pd by range"
    )
    existence_repeat_prob_by_range: tuple[float, ...] = default(
        (),
        "design: (), one repeat rate scaled by Pd's fall-off (as before); derived per bin; at "
        "most 100 rates, a design bound on the table's length",
    )
    existence_repeat_prob_bin_m: float = default(
        10.0, "design: 10 m bins, as the see-through rate's by range"
    )
    existence_birth_prob_by_range: tuple[float, ...] = default(
        (),
        "design: (), one birth probability at every range (as before); derived per bin; at "
        "most 100 rates, a design bound on the table's length",
    )
    existence_birth_prob_bin_m: float = default(
        10.0, "design: 10 m bins, as the see-through rate's by range"
    )
    existence_join_prob: float = default(0.99, "design: 99% probable that it is a real trunk")
    existence_remove_prob: float = default(0.01, "design: below 1% probable that it is real")

    def __post_init__(self) -> None:
        self._check_existence()
        for name in ("confirm_scans", "drop_after_missed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise SlamError(f"MapPolicy.{name}: must be an integer >= 1, got {v!r}")
        v = self.prune_after_expected
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise SlamError(f"MapPolicy.prune_after_expected: must be an integer >= 0, got {v!r}")
        r = self.prune_hit_ratio
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not 0.0 <= r <= 1.0:
            raise SlamError(f"MapPolicy.prune_hit_ratio: must be in [0, 1], got {r!r}")
        m = self.prune_range_m
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not m > 0 or m != m:
            raise SlamError(f"MapPolicy.prune_range_m: must be > 0 (inf: no limit), got {m!r}")

    @property
    def prunes(self) -> bool:
        """Whether landmarks can leave the map."""
        return self.prune_after_expected > 0 and self.prune_hit_ratio > 0.0

    @property
    def by_existence(self) -> bool:
        """Whether landmarks join and leave the map by their existence (`slam.existence`)."""
        return self.policy == "existence"

    def _check_by_range(self, name: str, noun: str, top: str) -> None:
        """existence_{name}_by_range: at most 100 of `noun` in (0, 1] (top "]") or (0, 1) (top
        ")"), kept as a tuple; existence_{name}_bin_m: finite and > 0."""
        table, v = f"existence_{name}_by_range", getattr(self, f"existence_{name}_by_range")
        ok = isinstance(v, (tuple, list)) and len(v) <= 100
        if not ok or not all(
            isinstance(p, (int, float))
            and not isinstance(p, bool)
            and 0.0 < p
            and (p <= 1.0 if top == "]" else p < 1.0)
            for p in v
        ):
            raise SlamError(
                f"map_policy.{table}: expected a list of at most 100 {noun} in (0, 1{top} (100: "
                f"a design bound on the table's length), got {_shown(v)}"
            )
        object.__setattr__(self, table, tuple(float(p) for p in v))
        v = getattr(self, f"existence_{name}_bin_m")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v < math.inf:
            raise SlamError(f"map_policy.existence_{name}_bin_m: must be finite and > 0, got {v!r}")

    def _check_existence(self) -> None:
        if self.policy not in ("confirm", "existence"):
            raise SlamError(
                f"map_policy.policy: must be 'confirm' or 'existence', got {self.policy!r}"
            )
        for name in ("existence_pd_max", "existence_see_through_q", "existence_birth_prob"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v <= 1.0:
                raise SlamError(f"map_policy.{name}: must be in (0, 1], got {v!r}")
        for name in ("existence_join_prob", "existence_remove_prob"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
                raise SlamError(f"map_policy.{name}: must be in [0, 1], got {v!r}")
        if not self.existence_remove_prob < self.existence_join_prob:
            raise SlamError(
                "map_policy.existence_remove_prob: must be below existence_join_prob "
                f"({self.existence_join_prob!r}), got {self.existence_remove_prob!r}"
            )
        if self.existence_clutter not in ("uniform", "persistent"):
            raise SlamError(
                "map_policy.existence_clutter: must be 'uniform' or 'persistent', got "
                f"{self.existence_clutter!r}"
            )
        v = self.existence_repeat_prob
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v < 1.0:
            raise SlamError(f"map_policy.existence_repeat_prob: must be in (0, 1), got {v!r}")
        v = self.existence_shape_sd_m
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v < math.inf:
            raise SlamError(f"map_policy.existence_shape_sd_m: must be finite and >= 0, got {v!r}")
        if not isinstance(self.existence_keep_tentatives, bool):
            raise SlamError(
                "map_policy.existence_keep_tentatives: must be true or false, got "
                f"{self.existence_keep_tentatives!r}"
            )
        v = self.existence_pd_range_m
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise SlamError(
                f"map_policy.existence_pd_range_m: must be > 0 (inf: no fall-off), got {v!r}"
            )
        v = self.existence_pd_range_scale_m
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v < math.inf:
            raise SlamError(
                f"map_policy.existence_pd_range_scale_m: must be finite and > 0, got {v!r}"
            )
        if not isinstance(self.existence_fuse_tentatives, bool):
            raise SlamError(
                "map_policy.existence_fuse_tentatives: must be true or false, got "
                f"{self.existence_fuse_tentatives!r}"
            )
        v = self.existence_see_through_k
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v < math.inf:
            raise SlamError(
                f"map_policy.existence_see_through_k: must be finite and >= 0, got {v!r}"
            )
        v = self.existence_see_through_footprint
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v < math.inf:
            raise SlamError(
                f"map_policy.existence_see_through_footprint: must be finite and >= 0, got {v!r}"
            )
        self._check_by_range("see_through_q", "rates", "]")
        self._check_by_range("repeat_prob", "rates", ")")
        # a birth of 1 would keep its landmark forever: update_existence never lowers r = 1
        self._check_by_range("birth_prob", "probabilities", ")")
        v = self.existence_unreached_scans
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise SlamError(
                f"map_policy.existence_unreached_scans: must be an integer >= 0, got {v!r}"
            )
        v = self.existence_min_beams
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise SlamError(f"map_policy.existence_min_beams: must be an integer >= 1, got {v!r}")
        v = self.existence_false_per_scan
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v < math.inf:
            raise SlamError(
                f"map_policy.existence_false_per_scan: must be finite and > 0, got {v!r}"
            )


# The smallest match_m: the match bins landmark pairs by length in steps of match_m, so a
# subnormal one makes the bins' count overflow; 1 mm is far below any trunk's measured spread.
MIN_MATCH_M = 1e-3


@dataclass(frozen=True)
class ClosureConfig:
    """The `[closure]` section (see the module doc for what each setting does).

    Where the defaults come from (each field's `source`; one, tree_sd_m, from Victoria Park, the
    others from the simulator): recent_s 30 and old_s 60 s: a
    landmark seen in the last 30 s is part of the local map, one unseen for a minute has been
    left behind (at 1-3 m/s, 60-180 m away), and one in view unseen for 30 s while new
    landmarks join the map within max_offset_m of it is passed by (module doc, step 1);
    min_pairs 6 with margin 3 and match_m 0.5 m were set by hand in the simulated park
    (experiment `loop-closure`, drives 0-11): at 1.0 m, random hypotheses in a stand of trees
    3 m apart explained 5-6 landmarks, at 0.5 m 3-4, and landmarks of one local map agree to
    a few centimetres; min_sep_m 3 m: the trees' spacing
    there; max_offset_m 15 m and max_rotation_deg 15 deg: larger than any drift of the
    simulated returns (0-8 m); jc_prob 0.999 as the association gates. every_scans 5: a match
    a second at 5 Hz. re_register: check a match the filter's covariance refuses against dead
    reckoning and one rigid motion instead (module doc, step 3); off, such a match is
    refused. tree_sd_m 0.04 m: a trunk's measured centre moves along the line of sight with
    the side it is seen from, which the filter's white measurement noise averages away; the
    rigid-fit test adds it to each landmark (per axis). The figure is what
    `experiments.eval.trunk_offsets.view_offset` measures on Victoria Park scans 1-2000, the
    calibration scans (a test checks it; 0.05 m with the preset before its laser latency, 0.04 m
    with it); in the simulator, whose trunks are circles, 0.05 m changed no figure of the
    standard filter's park and orchard runs (100 drives each) against none, and 0.04 m moves
    only their mean landmark and duplicate counts, a little.
    The others are a first version, checked in the simulator only.
    """

    enabled: bool = default(
        False, "design: off unless asked for (a run without closure is the paper's filter)"
    )
    every_scans: int = default(
        5, "simulator: hand-set in the simulated park, a match a second at 5 Hz"
    )
    recent_s: float = default(
        30.0, "simulator: hand-set in the simulated park (experiment loop-closure, drives 0-11)"
    )
    old_s: float = default(
        60.0, "simulator: hand-set in the simulated park (experiment loop-closure, drives 0-11)"
    )
    min_pairs: int = default(
        6, "simulator: hand-set in the simulated park (experiment loop-closure, drives 0-11)"
    )
    margin: int = default(
        3, "simulator: hand-set in the simulated park (experiment loop-closure, drives 0-11)"
    )
    match_m: float = default(
        0.5, "simulator: hand-set in the simulated park (experiment loop-closure, drives 0-11)"
    )
    min_sep_m: float = default(3.0, "simulator: the simulated park's tree spacing, 3 m")
    max_offset_m: float = default(15.0, "simulator: above the simulated returns' drift (0-8 m)")
    max_rotation_deg: float = default(15.0, "simulator: above the simulated returns' drift")
    jc_prob: float = default(
        0.999, "design: as the association gates (AssociationConfig.gate_prob)"
    )
    re_register: bool = default(
        True, "design: check a refused match against dead reckoning (module doc, step 3)"
    )
    tree_sd_m: float = default(
        0.04, "calibration: Victoria Park scans 1-2000 (experiments.eval.trunk_offsets.view_offset)"
    )

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.type == "bool":
                if not isinstance(v, bool):
                    raise SlamError(f"closure.{f.name}: must be true or false, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise SlamError(f"closure.{f.name}: must be a finite number, got {v!r}")
            if f.type == "int" and (v != int(v) or v < 1):
                raise SlamError(f"closure.{f.name}: must be a whole number >= 1, got {v!r}")
            if f.name == "tree_sd_m":
                if v < 0:
                    raise SlamError(f"closure.{f.name}: must be >= 0, got {v!r}")
            elif v <= 0:
                raise SlamError(f"closure.{f.name}: must be > 0, got {v!r}")
        if not 0.0 < self.jc_prob < 1.0:
            raise SlamError(f"closure.jc_prob: must be in (0, 1), got {self.jc_prob!r}")
        if self.match_m < MIN_MATCH_M:  # pairs are binned by length in steps of match_m
            raise SlamError(
                f"closure.match_m: must be >= {MIN_MATCH_M} m (MIN_MATCH_M), got {self.match_m!r}"
            )
        if self.old_s < self.recent_s:  # an old landmark must not be a recent one too
            raise SlamError(
                f"closure.old_s: must be >= recent_s ({self.recent_s!r}), got {self.old_s!r}"
            )
        if self.min_pairs < 3:
            raise SlamError(f"closure.min_pairs: must be >= 3, got {self.min_pairs!r}")


@dataclass(frozen=True)
class BaileyConfig:
    """The Bailey detector (`features.bailey.extract_bailey`): the noise model its circles carry
    (the Zaragoza SLAM school's for the Victoria Park detections: range sigma 0.05 m + 1% of
    range, bearing sigma 0.5 deg; radius sigma 0.05 m) and its constants (`detector`)."""

    range_sigma_m: float = default(
        0.05, "sensor model: the Zaragoza school's Victoria Park detections, 0.05 m"
    )
    range_sigma_per_m: float = default(
        0.01, "sensor model: the Zaragoza school's Victoria Park detections, 1% of range"
    )
    bearing_sigma_rad: float = default(
        math.radians(0.5), "sensor model: the Zaragoza school's Victoria Park detections, 0.5 deg"
    )
    radius_sigma_m: float = default(
        0.05, "sensor model: the Zaragoza school's Victoria Park detections, 0.05 m"
    )
    detector: BaileyParams = default(
        BaileyParams,
        "paper: Bailey's detector constants (features.bailey.BaileyParams)",
        factory=True,
    )

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

    method: str = default("paper", "paper: the paper's extractor")
    extractor: ExtractorParams = default(
        ExtractorParams,
        "paper: the paper's parameters (features.ExtractorParams, each field's own)",
        factory=True,
    )
    bailey: BaileyConfig = default(
        BaileyConfig, "sensor model: the Zaragoza school's Victoria Park detections", factory=True
    )
    file: str | None = default(None, "design: none, extract from the scans")

    def __post_init__(self) -> None:
        _choice("features", "method", self.method, FEATURE_METHODS)

    def extractor_args(self) -> tuple:
        """(params, options) of `features.extract_features(scan, self.method, params,
        **options)`: the `ExtractorParams` itself (the Bailey detector's `BaileyParams` and its
        noise model's sigmas for "bailey"), so a setting keeps its form to the kernel."""
        if self.method == "bailey":
            b = self.bailey
            sigmas = ("range_sigma_m", "range_sigma_per_m", "bearing_sigma_rad", "radius_sigma_m")
            return b.detector, {name: getattr(b, name) for name in sigmas}
        return self.extractor, {}

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
    joint_check: after the association, test the scan's pairings with mapped landmarks
        jointly (their stacked innovation and its full covariance, the pose's correlations
        included) against chi2_2k(gate_prob), and while the test fails drop the pairing whose
        removal lowers the joint distance most (`association.joint`, Neira and Tardos 2001); a
        dropped measurement is ignored (status AMBIGUOUS: it lies in a landmark's gate, where
        an unassigned measurement is ignored). Off: the associator's pairings as they are.
    """

    method: str = default("ihgr", "paper: IHGR, the paper's associator")
    gate_prob: float = default(
        0.999, "simulator: 0.999, where 0.99 lost the tree park in 2 of 50 runs (see doc)"
    )
    new_feature_gate_prob: float = default(
        0.9999, "design: a wider gate than gate_prob for new landmarks (see doc)"
    )
    window_scans: int = default(3, "design: K = 3, 2..4 intended (docs/experiments/association.md)")
    view_margin_m: float = default(
        2.0, "design: landmarks 2 m beyond the laser's range are still offered"
    )
    view_margin_rad: float = default(
        math.radians(10.0), "design: landmarks 10 deg beyond the field of view are still offered"
    )
    params: dict = default(dict, "design: none, the associator's own defaults", factory=True)
    joint_check: bool = default(
        False, "design: off, the associator's pairings as they are (measured: docs/notebook.md)"
    )

    def __post_init__(self) -> None:
        _choice("association", "method", self.method, ASSOCIATION_METHODS)
        if not isinstance(self.joint_check, bool):
            raise SlamError(
                f"association.joint_check: must be true or false, got {self.joint_check!r}"
            )
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
        unknown to both use its "other" entry (built in: "other" only, for every method).
    fit_floor_range_m, fit_floor_bearing_rad: added in quadrature to a fit's covariance (model
        error the fit cannot see: range quantisation, mixed returns); 0 by default (the fit's own
        covariance); the `cycab` preset holds the simulated tree park's.
    range_bias: known mean range error a + b r of each extractor's centres, by method name, as
        (a_m, b_per_m), subtracted from its ranges; methods not given keep their
        `DEFAULT_RANGE_BIAS` entry ((0, 0) when it has none; none is built in).
    max_range_m: circles farther away are not used (the laser's own maximum applies too).
    pass_offset_sd_m: (range, across) standard deviations in metres of an offset of a trunk's
        centre shared by the sightings of one pass (along and across the line of sight), on top
        of the white noise above: the filter and the smoother weigh a pass of n sightings as
        at most 1 / (r/n + s^2) per axis (`slam.measurement.pass_variance`). (0, 0): white
        errors, nothing is computed.
    pass_gap_s: a landmark's pass ends after this long without a sighting of it.
    pass_offset_model: how the filter carries the pass offset when one is set: "inflation"
        (each sighting's covariance grown by `slam.measurement.pass_inflation`) or "state" (the
        offset as a state of the filter while its pass lasts, a variable per pass in the
        smoother).
    pass_offset_corr_rad: with the "state" model, the correlation length in rad of view angle
        of an offset that drifts over its pass (first-order Gauss-Markov; the smoother's
        apparent point per sighting, `slam.smoother`); inf: constant over a pass.
    """

    noise: str = default(
        "auto",
        "design: the circles' own covariance where it describes their errors (OWN_COVARIANCE)",
    )
    constant_noise: Mapping[str, NoiseModel] = default(
        dict,
        "sensor model: one model for all, the Zaragoza school's 0.05 m + 1%, 0.5 deg",
        factory=True,
    )
    fit_floor_range_m: float = default(
        DEFAULT_FIT_FLOOR[0], "sensor model: 0, the circle fit's own covariance, no floor"
    )
    fit_floor_bearing_rad: float = default(
        DEFAULT_FIT_FLOOR[1], "sensor model: 0, the circle fit's own covariance, no floor"
    )
    range_bias: Mapping[str, tuple[float, float]] = default(
        dict, "design: none, no range correction (a calibration's to give)", factory=True
    )
    max_range_m: float = default(
        math.inf, "sensor model: inf, the laser's own maximum range applies"
    )
    pass_offset_sd_m: tuple[float, float] = default(
        (0.0, 0.0), "design: (0, 0), white measurement errors (today's model)"
    )
    pass_gap_s: float = default(
        2.0, "design: 2 s, the pass of experiments/eval/trunk_offsets.view_offset"
    )
    pass_offset_model: str = default(
        "inflation", "design: the per-sighting inflation of slam.measurement.pass_inflation"
    )
    pass_offset_corr_rad: float = default(
        math.inf,
        "design: inf, an offset constant over a pass (today's model); the drift's L is derived "
        "on scans 1-2000 by experiments.eval.pass_drift (victoria-park-pass-offset)",
    )

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
        self._check_pass_model()
        models = dict(DEFAULT_CONSTANT_NOISE)  # the given methods replace their defaults
        for method, model in dict(self.constant_noise).items():
            m = NoiseModel(*model)
            for name, v in m._asdict().items():  # each sigma finite, >= 0, in range
                setting(f"measurement.constant_noise.{method}.{name}", v)
            models[method] = m
        models["other"] = models.pop("other")  # last, after the methods it does not name
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

    def _check_pass_model(self) -> None:
        v = self.pass_offset_sd_m
        if not isinstance(v, (tuple, list)) or len(v) != 2 or any(isinstance(x, bool) for x in v):
            raise SlamError(
                f"measurement.pass_offset_sd_m: expected (range, across) in metres, got {v!r}"
            )
        for i, x in enumerate(v):
            setting(f"measurement.pass_offset_sd_m[{i}]", x, limit=MAX_PASS_OFFSET_M)
        object.__setattr__(self, "pass_offset_sd_m", (float(v[0]), float(v[1])))
        _choice("measurement", "pass_offset_model", self.pass_offset_model, ("inflation", "state"))
        g = self.pass_gap_s
        setting("measurement.pass_gap_s", g, limit=MAX_PASS_GAP_S)
        if not g > 0:
            raise SlamError(f"measurement.pass_gap_s: must be > 0 s, got {g!r}")
        c = self.pass_offset_corr_rad
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not c > 0:
            raise SlamError(
                "measurement.pass_offset_corr_rad: must be a number > 0 rad (inf: constant over "
                f"a pass), got {c!r}"
            )
        if math.isfinite(c):
            setting("measurement.pass_offset_corr_rad", c, limit=MAX_PASS_CORR_RAD)
            if self.pass_offset_model != "state":
                raise SlamError(
                    "measurement.pass_offset_corr_rad: a drift length is used only with "
                    f"measurement.pass_offset_model = 'state', got {self.pass_offset_model!r} "
                    "(inf: no drift)"
                )

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
        "ackermann" car (`OdometryNoise`, with its pose floor for slip).
    unicycle_noise: the same for a "unicycle" vehicle's speed and yaw-rate samples
        (`UnicycleNoise`).
    increment_noise: the noise of a "pose-increment" vehicle's odometry increments, per metre
        and per radian (`IncrementNoise`). The sequence's vehicle says which of the
        three its odometry is.
    steering: the front-wheel angle from the steering reading (`SteeringCalibration`,
        offset + gain r + cubic r^3; the identity by default).
    laser_pose: (x_m, y_m, theta_rad) of the laser, replacing the sequence's (a calibrated
        mounting); None keeps the sequence's.
    laser_latency_s: how long after it was measured a scan is stamped: scan k is placed at the
        pose of its stamp minus this (`SlamLog.scan_t` holds those times; the sequence's own
        stamps stay the scans', e.g. for choosing the GPS fixes within 25 ms of a scan). 0
        (default): at its stamp. Derived for the ute by the calibration's J on scans 1-2000
        (`experiments.paper.victoria_park.calibration.latency_profile`), a sensor property, never a
        GPS error; a magnitude of a second or more is an error.
    gps_antenna: (x_m, y_m) of the GPS antenna, replacing the sequence's; None keeps the
        sequence's (the laser's position when it has none).
    max_odometry_gap_s: a longer stretch without odometry inside the run is an error.
    min_travel_m: a scan is used (associated, updated, mapped) only when the odometry has moved
        the vehicle at least this far since the last scan used; the others are predicted only
        (status SKIPPED). 0 (default): every scan. A small value (the ute's 1 mm) skips the scans
        of a vehicle standing still: a scan from the same place repeats the last one's errors.
    calibrated_for: (wheelbase_m, encoder_offset_m) of the car whose odometry these settings
        describe; a run on a sequence whose vehicle differs is warned
        (`slam.checks.check_fit`). None (the default): no claim.
    """

    odometry_noise: OdometryNoise = default(
        OdometryNoise, "simulator: the simulated Cycab's (OdometryNoise)", factory=True
    )
    unicycle_noise: UnicycleNoise = default(
        UnicycleNoise,
        "simulator: the simulated Cycab's as a unicycle's (UnicycleNoise)",
        factory=True,
    )
    increment_noise: IncrementNoise = default(
        IncrementNoise,
        "simulator: the simulated Cycab's as increments (IncrementNoise)",
        factory=True,
    )
    steering: SteeringCalibration = default(
        SteeringCalibration, "design: identity, no correction (SteeringCalibration)", factory=True
    )
    laser_pose: tuple[float, float, float] | None = default(
        None, "sensor model: none, the sequence's own laser pose"
    )
    laser_latency_s: float = default(0.0, "sensor model: 0, scans stamped when measured")
    gps_antenna: tuple[float, float] | None = default(
        None, "sensor model: none, the sequence's own antenna position"
    )
    max_odometry_gap_s: float = default(1.0, "design: a second without odometry is a data fault")
    min_travel_m: float = default(0.0, "design: 0, every scan is used")
    calibrated_for: tuple[float, float] | None = default(
        None, "design: none, the built-in settings claim no car (the cycab preset: 1.2, 0)"
    )

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

    initial_pose_sigma: tuple[float, float, float] = default(
        (0.0, 0.0, 0.0), "design: 0, the map's frame is the start pose"
    )
    initial_heading_rad: float | None = default(None, "design: none, from the GPS fit or 0")
    gps_fit_m: float = default(50.0, "design: 50 m of driving for the GPS start fit")
    gps_track: str = default("dead-reckoning", "design: dead reckoning, no first pass")
    gps_sigma_m: float = default(1.0, "design: 1 m floor of a GPS start's position")
    heading_sigma_rad: float = default(
        math.radians(5.0), "design: 5 deg floor of a GPS start's heading"
    )

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

    first_estimates_jacobians: bool = default(
        False, "paper: off, the paper's EKF (Huang et al. 2008 when on)"
    )


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
            want = _type_hints(SlamConfig)[f.name]
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
    hints = _type_hints(cls)
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


@functools.cache
def _type_hints(cls) -> Mapping:
    """`typing.get_type_hints(cls)`, resolved once per class, read only: resolving the
    postponed annotations was over half the time of reading a sweep or configuration file."""
    return types.MappingProxyType(typing.get_type_hints(cls))


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
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:  # any length
        if not isinstance(value, (list, tuple)):
            raise SlamError(f"{path}: expected a list of numbers, got {_shown(value)}")
        return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
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
