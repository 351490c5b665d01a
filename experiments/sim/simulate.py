"""SICK-like laser sensor model and scan / sequence simulation over a `Scene`.

Measurement model, per beam, in this order (all randomness from the `rng` passed in):
  1. truth: exact ray cast from the laser's world pose (`raycast`), only objects taller than the
     sensor's `mount_height_m` (flat ground);
  2. mixed returns (optional, `mixed_prob` > 0): see `SensorModel`;
  3. range noise: + N(0, range_sigma_m^2), independent per beam (default sigma 0.01 m);
  4. quantisation: rounded to the nearest multiple of `quantisation_m` (0.01 m, SICK's 1 cm);
  5. no return: nothing hit, or a reading at or beyond `max_range_m` (or <= 0), is NaN with
     label NO_RETURN_LABEL (-1). So `labels == -1` exactly where `ranges_m` is NaN.

Frames: `pose_xytheta` is the vehicle (rear-axle centre) in the world; `laser_pose` is the laser
in the vehicle frame; beam angles are in the laser frame, 0 = laser x-axis, CCW positive, exactly
`angle_min_rad + k * angle_increment_rad` as `features.Scan.angles_rad` computes them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from experiments.errors import ConfigError
from experiments.sim.raycast import raycast
from experiments.sim.scene import MIXED_LABEL, NO_RETURN_LABEL, Scene, load_scene
from features.types import Scan
from slam import Sequence, se2

__all__ = [
    "SensorModel",
    "sensor_preset",
    "SENSOR_PRESETS",
    "laser_world_pose",
    "simulate_scan",
    "simulate_sequence",
    "simulate_to_sequence",
]

_TWO_PI = 2.0 * math.pi


def _whole(x: float, tol: float = 1e-6) -> int | None:
    n = round(x)
    return int(n) if abs(x - n) <= tol else None


@dataclass(frozen=True)
class SensorModel:
    """A 2D scanning laser (SICK PLS200 / LMS200 style).

    name: label for the run's description.
    fov_rad: field of view of one sensor, (0, 2 pi); must be a whole number of increments.
        A single sensor has round(fov / increment) + 1 beams from -fov/2 to +fov/2 in the laser
        frame (180 deg at 0.5 deg: 361 beams, -90 .. +90 deg).
    angle_increment_rad: angle between beams (0.5 deg).
    max_range_m: readings at or beyond this are no return (PLS200 50 m, LMS200 80 m).
    range_sigma_m: standard deviation of the additive Gaussian range noise; default 0.01 m, a
        typical figure for SICK scanners at these ranges (the paper gives none).
    quantisation_m: readings are rounded to multiples of this (0.01 m); 0 = no rounding.
    mixed_prob: probability that a depth jump produces a mixed return (default 0 = never).
        Model: for two neighbouring beams that both hit something within max range and whose
        true ranges differ by more than `mixed_min_jump_m`, with probability `mixed_prob` the
        footprint of one of them (either, equally likely) straddles the edge and it returns
        r_near + u (r_far - r_near), u ~ U(0, 1): a point in mid-air between the two surfaces,
        labelled MIXED_LABEL (-2). Noise and quantisation are then added as for any beam. In a
        back-to-back scan the last and first beams are neighbours too.
    mixed_min_jump_m: the depth difference that counts as a jump for mixed returns.
    back_to_back: two sensors back to back for 360 deg (the paper's pair of PLS200s), idealised
        as co-located at the laser pose, the second rotated by pi. They are laid out as ONE scan
        of round(2 pi / increment) beams (720 at 0.5 deg) from angle_min = -pi, beam k at
        -pi + k * increment, ending one increment short of +pi. Beams in [-fov/2, +fov/2] belong
        to the front sensor, the rest to the rear one; the two beams both would measure (at
        +-90 deg for 180 deg sensors) appear once. Requires fov_rad >= pi and 2 pi a whole
        number of increments.
    mount_height_m: height of the scan plane above flat ground; objects no taller are unseen
        (the paper's laser is at about 1.2 m and sees over the low balusters).
    """

    name: str = "custom"
    fov_rad: float = math.pi
    angle_increment_rad: float = math.radians(0.5)
    max_range_m: float = 50.0
    range_sigma_m: float = 0.01
    quantisation_m: float = 0.01
    mixed_prob: float = 0.0
    mixed_min_jump_m: float = 0.5
    back_to_back: bool = False
    mount_height_m: float = 1.2

    def __post_init__(self) -> None:
        def num(field_name: str) -> float:
            v = getattr(self, field_name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ConfigError(f"SensorModel.{field_name}: must be a number, got {v!r}")
            if math.isnan(v):
                raise ConfigError(f"SensorModel.{field_name}: must not be NaN")
            object.__setattr__(self, field_name, float(v))
            return float(v)

        inc = num("angle_increment_rad")
        if not (0 < inc < math.pi):
            raise ConfigError(f"SensorModel.angle_increment_rad: must be in (0, pi), got {inc!r}")
        fov = num("fov_rad")
        if not (0 < fov < _TWO_PI):
            raise ConfigError(
                f"SensorModel.fov_rad: must be in (0, 2 pi) (back_to_back gives 360 deg), "
                f"got {fov!r}"
            )
        if _whole(fov / inc) is None:
            raise ConfigError(
                f"SensorModel.fov_rad: must be a whole number of increments, got {fov!r} / {inc!r}"
            )
        if not num("max_range_m") > 0:
            raise ConfigError(
                f"SensorModel.max_range_m: must be > 0 (inf allowed), got {self.max_range_m!r}"
            )
        sig = num("range_sigma_m")
        if not (0 <= sig < math.inf):
            raise ConfigError(f"SensorModel.range_sigma_m: must be finite and >= 0, got {sig!r}")
        q = num("quantisation_m")
        if not (0 <= q < math.inf):
            raise ConfigError(f"SensorModel.quantisation_m: must be finite and >= 0, got {q!r}")
        p = num("mixed_prob")
        if not (0 <= p <= 1):
            raise ConfigError(f"SensorModel.mixed_prob: must be in [0, 1], got {p!r}")
        j = num("mixed_min_jump_m")
        if not (0 < j < math.inf):
            raise ConfigError(f"SensorModel.mixed_min_jump_m: must be finite and > 0, got {j!r}")
        h = num("mount_height_m")
        if not (0 <= h < math.inf):
            raise ConfigError(f"SensorModel.mount_height_m: must be finite and >= 0, got {h!r}")
        if not isinstance(self.back_to_back, (bool, np.bool_)):
            raise ConfigError(
                f"SensorModel.back_to_back: must be True or False, got {self.back_to_back!r}"
            )
        object.__setattr__(self, "back_to_back", bool(self.back_to_back))
        if self.back_to_back:
            if fov < math.pi - 1e-9:
                raise ConfigError(
                    f"SensorModel.fov_rad: back_to_back needs sensors of >= 180 deg, got {fov!r}"
                )
            if _whole(_TWO_PI / inc) is None:
                raise ConfigError(
                    f"SensorModel.angle_increment_rad: back_to_back needs 2 pi to be a whole "
                    f"number of increments, got {inc!r}"
                )
        if not isinstance(self.name, str):
            raise ConfigError(f"SensorModel.name: must be a string, got {self.name!r}")

    @property
    def n_beams(self) -> int:
        """Beams per scan: 361 for 180 deg at 0.5 deg, 720 back to back."""
        if self.back_to_back:
            return int(round(_TWO_PI / self.angle_increment_rad))
        return int(round(self.fov_rad / self.angle_increment_rad)) + 1

    @property
    def angle_min_rad(self) -> float:
        """Bearing of beam 0 in the laser frame: -fov/2, or -pi back to back."""
        return -math.pi if self.back_to_back else -0.5 * self.fov_rad

    @property
    def angles_rad(self) -> np.ndarray:
        """(B,) beam bearings in the laser frame, angle_min + k * increment."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.n_beams)

    @property
    def effective_sigma_m(self) -> float:
        """The range noise an extractor should assume, m: the Gaussian noise and the uniform
        quantisation error combined, sqrt(sigma^2 + q^2 / 12)."""
        return math.sqrt(self.range_sigma_m**2 + self.quantisation_m**2 / 12.0)

    def scan(self, ranges_m: np.ndarray, stamp_s: float = 0.0) -> Scan:
        """Wrap simulated ranges as a `features.Scan` with this sensor's angles and max range."""
        return Scan(
            ranges_m, self.angle_min_rad, self.angle_increment_rad, stamp_s, self.max_range_m
        )


SENSOR_PRESETS: dict[str, dict[str, Any]] = {
    # The paper's sensor: 180 deg, 0.5 deg, 50 m (two of them back to back for 360 deg).
    "pls200": dict(
        name="pls200", fov_rad=math.pi, angle_increment_rad=math.radians(0.5), max_range_m=50.0
    ),
    # The Cycab's SICK LMS200 (and Victoria Park's): 180 deg, 0.5 deg, 80 m.
    "lms200": dict(
        name="lms200", fov_rad=math.pi, angle_increment_rad=math.radians(0.5), max_range_m=80.0
    ),
}


def sensor_preset(name: str, **overrides: Any) -> SensorModel:
    """A preset sensor ("pls200", "lms200"), with any `SensorModel` field overridden."""
    key = str(name).lower()
    if key not in SENSOR_PRESETS:
        raise ConfigError(
            f"sensor_preset.name: unknown sensor {name!r}; known: {sorted(SENSOR_PRESETS)}"
        )
    fields = {f.name for f in dataclasses.fields(SensorModel)}
    bad = sorted(set(overrides) - fields)
    if bad:
        raise ConfigError(
            f"sensor_preset: unknown SensorModel field(s) {bad}; fields: {sorted(fields)}"
        )
    return SensorModel(**{**SENSOR_PRESETS[key], **overrides})


def _pose3(v: Any, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ConfigError(f"{what}: expected 3 finite numbers [x, y, theta], got {v!r}")
    return a


def laser_world_pose(pose_xytheta: Any, laser_pose: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """(3,) the laser's world pose T_world_vehicle * T_vehicle_laser, [x, y, theta]."""
    return se2.compose(_pose3(pose_xytheta, "pose_xytheta"), _pose3(laser_pose, "laser_pose"))


def simulate_scan(
    scene: Scene,
    pose_xytheta: Any,
    sensor: SensorModel,
    rng: np.random.Generator,
    laser_pose: Any = (0.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """One simulated scan from vehicle pose `pose_xytheta` (world) with the laser at `laser_pose`
    (vehicle frame).

    Returns ranges_m (B,) float64, m, NaN = no return, and labels (B,) int64 (scene label of the
    object each beam hit, -1 no return, -2 mixed return); B = sensor.n_beams, beam k at bearing
    sensor.angle_min_rad + k * sensor.angle_increment_rad in the laser frame.
    """
    if not isinstance(rng, np.random.Generator):
        raise ConfigError(
            f"simulate_scan.rng: expected a numpy.random.Generator, got {type(rng).__name__}"
        )
    lx, ly, lth = laser_world_pose(pose_xytheta, laser_pose)
    true_m, labels = raycast(
        scene, (lx, ly), lth + sensor.angles_rad, plane_height_m=sensor.mount_height_m
    )
    n = true_m.shape[0]
    noise = rng.standard_normal(n)  # always drawn first, so noise does not depend on mixed_prob
    r = true_m.copy()
    if sensor.mixed_prob > 0:
        _mixed_returns(r, labels, true_m, sensor, rng)
    if sensor.range_sigma_m > 0:
        r += sensor.range_sigma_m * noise
    if sensor.quantisation_m > 0:
        r = np.round(r / sensor.quantisation_m) * sensor.quantisation_m
    with np.errstate(invalid="ignore"):
        none = ~np.isfinite(r) | (r <= 0) | (r >= sensor.max_range_m)
    r[none] = np.nan
    labels[none] = NO_RETURN_LABEL
    return r, labels


def _mixed_returns(
    r: np.ndarray,
    labels: np.ndarray,
    true_m: np.ndarray,
    sensor: SensorModel,
    rng: np.random.Generator,
) -> None:
    """In place: replace one beam of some depth jumps by a range between the two surfaces."""
    n = true_m.shape[0]
    i = np.arange(n) if sensor.back_to_back else np.arange(n - 1)
    k = (i + 1) % n
    ok = np.isfinite(true_m) & (true_m < sensor.max_range_m)
    event = rng.random(i.shape[0]) < sensor.mixed_prob
    first = rng.random(i.shape[0]) < 0.5
    frac = rng.random(i.shape[0])
    with np.errstate(invalid="ignore"):
        jump = ok[i] & ok[k] & (np.abs(true_m[i] - true_m[k]) > sensor.mixed_min_jump_m)
    sel = jump & event
    ri, rk = true_m[i[sel]], true_m[k[sel]]
    near, far = np.minimum(ri, rk), np.maximum(ri, rk)
    target = np.where(first[sel], i[sel], k[sel])
    r[target] = near + frac[sel] * (far - near)
    labels[target] = MIXED_LABEL


def simulate_sequence(
    scene: Scene,
    poses: Any,
    sensor: SensorModel,
    rng: np.random.Generator,
    times_s: Any = None,
    laser_pose: Any = (0.0, 0.0, 0.0),
) -> Sequence:
    """One simulated scan at each vehicle pose, as a `Sequence` with its truth.

    poses: (T, 3) [x, y, theta] of the vehicle (rear-axle centre), world frame.
    times_s: (T,) strictly increasing scan times, s; default 0, 1, 2, ... (one scan a second).
    Fills scan_* (scan_max_range = sensor.max_range_m), laser_pose, truth_t (= scan times),
    truth_pose (= poses), truth_landmarks (= scene.truth_landmarks), scan_labels and name.
    """
    P = np.array(poses, dtype=np.float64)
    if P.ndim == 1 and P.shape == (3,):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] == 0 or not np.all(np.isfinite(P)):
        raise ConfigError(
            f"simulate_sequence.poses: expected a finite (T, 3) array, got shape {P.shape}"
        )
    T = P.shape[0]
    if times_s is None:
        t = np.arange(T, dtype=np.float64)
    else:
        t = np.array(times_s, dtype=np.float64)
        if t.shape != (T,) or not np.all(np.isfinite(t)):
            raise ConfigError(
                f"simulate_sequence.times_s: expected {T} finite times, got shape {t.shape}"
            )
        if T > 1 and not np.all(np.diff(t) > 0):
            raise ConfigError("simulate_sequence.times_s: must be strictly increasing")
    lp = _pose3(laser_pose, "simulate_sequence.laser_pose")
    ranges = np.empty((T, sensor.n_beams))
    labels = np.empty((T, sensor.n_beams), dtype=np.int64)
    for j in range(T):
        ranges[j], labels[j] = simulate_scan(scene, P[j], sensor, rng, laser_pose=lp)
    two = " back-to-back" if sensor.back_to_back else ""
    return Sequence(
        scan_t=t,
        scan_ranges=ranges,
        scan_angle_min=sensor.angle_min_rad,
        scan_angle_increment=sensor.angle_increment_rad,
        laser_pose=lp,
        scan_max_range=sensor.max_range_m,
        truth_t=t.copy(),
        truth_pose=P,
        truth_landmarks=scene.truth_landmarks,
        scan_labels=labels,
        name=f"simulated: scene {scene.name or '<unnamed>'}, sensor {sensor.name}{two}",
    )


def simulate_to_sequence(
    scene_name_or_path: str | Path | Scene,
    poses: Any = None,
    sensor_name: str = "pls200",
    back_to_back: bool = False,
    noise_m: float | None = None,
    seed: int = 0,
) -> Sequence:
    """Load a scene, simulate scans at `poses` and return the `Sequence` (for `trunkslam simulate`).

    poses: (3,) or (T, 3) vehicle poses [x, y, theta]; None = the scene's scan positions.
    sensor_name: a `sensor_preset` name. noise_m: range noise sigma (None = the preset's 0.01 m).
    seed: seeds `numpy.random.default_rng`. The laser sits at the vehicle origin.
    """
    scene = (
        scene_name_or_path
        if isinstance(scene_name_or_path, Scene)
        else load_scene(scene_name_or_path)
    )
    if poses is None:
        if scene.scan_positions.shape[0] == 0:
            raise ConfigError(
                f"simulate_to_sequence.poses: scene {scene.name!r} has no scan positions, "
                "so poses must be given"
            )
        poses = scene.scan_positions
    extra = {} if noise_m is None else {"range_sigma_m": noise_m}
    sensor = sensor_preset(sensor_name, back_to_back=back_to_back, **extra)
    return simulate_sequence(scene, poses, sensor, np.random.default_rng(seed))
