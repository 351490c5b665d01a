"""A Cycab-like car driven through a scene: true path, noisy odometry, DGPS, laser scans.

The paper's second experiment drives the Cycab (INRIA/Robosoft, a small electric car-like
vehicle) with a SICK LMS200 and a DGPS "with up to 2 cm accuracy" as ground truth. Its
geometry is not published; `CycabParams` holds our choices (docs/method.md section 3: a
rear-axle bicycle model, wheelbase about 1.2 m, unverified; speed from the mean of the rear-wheel
encoders, so the encoder offset H is 0).

How a run is made (`simulate_cycab_run`):
1. Controls: at every odometry sample (20 Hz) a pure-pursuit controller steers toward the point
   `lookahead_m` ahead on the scene's route (its `scan_positions`, a closed polyline), with a
   steering limit and rate limit; the speed ramps up to `speed_mps` over `accel_time_s`.
2. Truth: the controls are held constant between samples (zero-order hold) and the rear-axle
   centre is moved along the exact arc (`slam.vehicle.arc_step`), so the filter's motion model is
   exact and only the readings' noise separates odometry from truth.
3. Odometry: each sample's encoder speed and steering angle plus independent Gaussian noise
   (`speed_sigma_mps`, `steer_sigma_rad`).
4. Scans: every `scan_every`-th odometry sample (5 Hz), a simulated LMS200 scan from the true
   pose with the laser at `laser_pose`, and the per-beam truth labels.
5. DGPS: the true antenna position (at the laser) at `dgps_rate_hz` on its own clock
   (`dgps_offset_s`), plus N(0, dgps_sigma_m^2) per axis: the paper's reference, stored as
   gps_t/gps_xy. The exact truth is stored as truth_t/truth_pose at every odometry sample time
   (which includes every scan time).
Randomness: one `numpy.random.Generator`, split into independent streams for the odometry
noise, the scans and the DGPS noise.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from experiments.errors import ConfigError
from experiments.sim.scene import Scene, load_scene
from experiments.sim.simulate import laser_world_pose, sensor_preset, simulate_scan
from slam import Sequence
from slam.vehicle import arc_step

__all__ = [
    "MAX_SCANS",
    "MONTE_CARLO_PATH",
    "CycabParams",
    "Drive",
    "drive",
    "offset_route",
    "route_polyline",
    "simulate_cycab_run",
]

# How the true path varies between the runs of a Monte Carlo study (`CycabParams` fields). The
# extractors' errors are largely fixed by the geometry (which beams hit a trunk: Bailey's bearing
# is the mid-point of the first and last beam, identical in every run that passes the same
# place), so runs along one path share them and are not independent samples. The variation makes
# each trunk's place on the beam grid differ between runs: a sideways shift whose sd is one beam
# spacing (0.5 deg) at the 95th percentile of the trunk ranges in the calibration runs (22.4 m,
# Bailey's circles on seeds 1000-1003: 0.195 m, rounded to 0.2 m), and a start uniform over one
# scan spacing along the route (1.2 m/s at 5 Hz: 0.24 m), so no scan position is favoured.
MONTE_CARLO_PATH = {"route_offset_sigma_m": 0.2, "start_along_m": 0.24}
# Limits of a simulated drive (`trunkslam simulate-drive --scans`, a sweep's cycab.n_scans):
# 100,000 scans are 5.6 hours of driving at 5 Hz and about 0.7 GB of scans and labels.
MAX_SCANS = 100_000
MAX_SCAN_EVERY = 100  # odometry samples per scan (at 20 Hz: a scan every 5 s)


@dataclass(frozen=True)
class CycabParams:
    """The car, its sensors and the drive (metres, radians, seconds).

    wheelbase_m: L (docs/method.md section 3: about 1.2 m, unverified). encoder_offset_m: H, 0 for a
    mean of both rear wheels. laser_pose: the LMS200 at the front bumper, in the vehicle frame.
    speed_mps: cruising speed; accel_time_s: linear ramp from rest at the start.
    lookahead_m, max_steer_rad, max_steer_rate_rad_s: the pure-pursuit driver.
    odo_rate_hz: odometry sample rate; scan_every: a scan every this many samples (5 Hz);
    n_scans: scans in the run.
    speed_sigma_mps, steer_sigma_rad: noise of each odometry sample's readings.
    dgps_rate_hz, dgps_offset_s, dgps_sigma_m: the DGPS reference (2 cm, the paper's figure).
    sensor: preset name; range_sigma_m, mixed_prob: its noise and mixed-return probability;
        quantisation_m: its range quantisation (None: the preset's, 1 cm for the LMS200).
    route_offset_sigma_m, start_along_m: how the true path varies between runs (0, 0: every run
        drives the same path). Each run's driver follows the route shifted sideways by an offset
        drawn from N(0, route_offset_sigma_m^2), from a start moved along it by a distance drawn
        uniformly from [0, start_along_m). A Monte Carlo study needs this: an extractor's error
        is largely fixed by the geometry (which beams hit the trunk), so runs that drive one
        path repeat the same errors and are not independent (see `experiments.paper.slam`).
    """

    wheelbase_m: float = 1.2
    encoder_offset_m: float = 0.0
    laser_pose: tuple[float, float, float] = (1.55, 0.0, 0.0)
    speed_mps: float = 1.2
    accel_time_s: float = 1.0
    lookahead_m: float = 3.0
    max_steer_rad: float = 0.4
    max_steer_rate_rad_s: float = 0.6
    odo_rate_hz: float = 20.0
    scan_every: int = 4
    n_scans: int = 240
    speed_sigma_mps: float = 0.1
    steer_sigma_rad: float = math.radians(2.0)
    dgps_rate_hz: float = 10.0
    dgps_offset_s: float = 0.03
    dgps_sigma_m: float = 0.02
    sensor: str = "lms200"
    range_sigma_m: float = 0.01
    mixed_prob: float = 0.1
    quantisation_m: float | None = None
    route_offset_sigma_m: float = 0.0
    start_along_m: float = 0.0

    def __post_init__(self) -> None:
        floats = [f.name for f in fields(self) if f.type in ("float", "float | None")]
        for name in floats:
            v = getattr(self, name)
            if v is None and name == "quantisation_m":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) < 1e300:
                raise ConfigError(f"CycabParams.{name}: must be a finite number, got {v!r}")
        for name in (
            "wheelbase_m",
            "speed_mps",
            "lookahead_m",
            "max_steer_rad",
            "max_steer_rate_rad_s",
            "odo_rate_hz",
            "dgps_rate_hz",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"CycabParams.{name}: must be > 0, got {getattr(self, name)!r}")
        for name in (
            "accel_time_s",
            "speed_sigma_mps",
            "steer_sigma_rad",
            "dgps_sigma_m",
            "dgps_offset_s",
            "range_sigma_m",
            "mixed_prob",
            "route_offset_sigma_m",
            "start_along_m",
        ):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"CycabParams.{name}: must be >= 0, got {getattr(self, name)!r}")
        whole = {"scan_every": MAX_SCAN_EVERY, "n_scans": MAX_SCANS}
        for name, limit in whole.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= limit:
                raise ConfigError(
                    f"CycabParams.{name}: must be a whole number in 1..{limit}, got {v!r}"
                    + (" (experiments.sim.trajectory.MAX_SCANS)" if name == "n_scans" else "")
                )
        pose = self.laser_pose
        if (
            not isinstance(pose, (tuple, list))
            or len(pose) != 3
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in pose
            )
        ):
            raise ConfigError(f"CycabParams.laser_pose: expected 3 finite numbers, got {pose!r}")
        if self.quantisation_m is not None and not self.quantisation_m >= 0:
            raise ConfigError(
                f"CycabParams.quantisation_m: must be >= 0, got {self.quantisation_m!r}"
            )
        if not isinstance(self.sensor, str):
            raise ConfigError(f"CycabParams.sensor: expected a sensor name, got {self.sensor!r}")
        try:  # the sensor the run will simulate, with this car's noise: checked now
            self.sensor_model()
        except ConfigError as exc:
            raise ConfigError(f"CycabParams.sensor: {exc}") from None

    def sensor_model(self):
        """The simulated laser: the `sensor` preset with this car's range noise, mixed-return
        probability and quantisation."""
        quant = {} if self.quantisation_m is None else {"quantisation_m": self.quantisation_m}
        return sensor_preset(
            self.sensor, range_sigma_m=self.range_sigma_m, mixed_prob=self.mixed_prob, **quant
        )

    @property
    def vehicle(self) -> dict:
        return {
            "model": "ackermann",
            "wheelbase_m": self.wheelbase_m,
            "encoder_offset_m": self.encoder_offset_m,
        }

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class Drive:
    """The true drive at the odometry samples (M of them).

    t_s: (M,) sample times. pose: (M, 3) true rear-axle pose at t_s (world). speed_enc_mps: (M,)
    true encoder speed held from t_s[i] to t_s[i + 1]. steer_rad: (M,) true steering angle.
    """

    t_s: np.ndarray
    pose: np.ndarray
    speed_enc_mps: np.ndarray
    steer_rad: np.ndarray


def route_polyline(waypoints: np.ndarray, spacing_m: float = 0.1) -> np.ndarray:
    """The closed route through the waypoints' (x, y), resampled every ~spacing_m: (K, 2)."""
    w = np.asarray(waypoints, dtype=np.float64)[:, :2]
    if w.shape[0] < 2:
        raise ConfigError("route_polyline.waypoints: need at least 2 waypoints")
    loop = np.vstack([w, w[:1]])
    out = []
    for a, b in itertools.pairwise(loop):
        n = max(math.ceil(np.hypot(*(b - a)) / spacing_m), 1)
        out.append(a + (b - a) * (np.arange(n) / n)[:, None])
    return np.vstack(out)


def offset_route(route: np.ndarray, offset_m: float) -> np.ndarray:
    """The closed polyline (K, 2) shifted by offset_m along its left normals (each point's normal
    from the chord between its neighbours)."""
    if offset_m == 0.0:
        return route
    chord = np.roll(route, -1, axis=0) - np.roll(route, 1, axis=0)
    normal = np.column_stack([-chord[:, 1], chord[:, 0]]) / np.hypot(*chord.T)[:, None]
    return route + offset_m * normal


def drive(
    scene: Scene, p: CycabParams, n_samples: int, offset_m: float = 0.0, start_along_m: float = 0.0
) -> Drive:
    """Pure pursuit around the scene's route, n_samples odometry samples. offset_m: the route is
    shifted that far to its left (negative: right); start_along_m: the drive starts that far
    along the (shifted) route, heading along it. Both 0: from the first waypoint's pose."""
    if scene.scan_positions.shape[0] < 2:
        raise ConfigError(f"drive.scene: scene {scene.name!r} has no route (scan_positions)")
    route = offset_route(route_polyline(scene.scan_positions), offset_m)
    K = route.shape[0]
    step = np.hypot(*np.diff(np.vstack([route, route[:1]]), axis=0).T)
    ahead = max(round(p.lookahead_m / float(np.mean(step))), 1)
    dt = 1.0 / p.odo_rate_hz
    L = p.wheelbase_m
    pose = np.array(scene.scan_positions[0], dtype=np.float64)
    near = 0
    if offset_m != 0.0 or start_along_m != 0.0:
        s = np.concatenate([[0.0], np.cumsum(step)])
        along = start_along_m % s[-1]  # the route is a loop
        j = min(int(np.searchsorted(s, along, side="right")) - 1, K - 1)
        a, b = route[j], route[(j + 1) % K]
        u = (along - s[j]) / step[j]
        pose = np.array([*(a + u * (b - a)), math.atan2(b[1] - a[1], b[0] - a[0])])
        near = j
    poses = np.empty((n_samples, 3))
    v_enc = np.empty(n_samples)
    steer = np.empty(n_samples)
    alpha = 0.0
    for i in range(n_samples):
        poses[i] = pose
        t = i * dt
        v = p.speed_mps * (min(t / p.accel_time_s, 1.0) if p.accel_time_s > 0 else 1.0)
        # nearest route point, searched forward from the last one (the route is a loop)
        window = (near + np.arange(0, 60)) % K
        near = int(window[np.argmin(np.hypot(*(route[window] - pose[:2]).T))])
        target = route[(near + ahead) % K]
        eta = math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2]
        eta = math.atan2(math.sin(eta), math.cos(eta))
        ld = max(float(np.hypot(*(target - pose[:2]))), 1e-6)
        want = math.atan(2.0 * L * math.sin(eta) / ld)
        want = float(np.clip(want, -p.max_steer_rad, p.max_steer_rad))
        da = p.max_steer_rate_rad_s * dt
        alpha = float(np.clip(want, alpha - da, alpha + da))
        steer[i] = alpha
        # the encoder H to the left turns at v_c (1 - H tan(alpha) / L)
        v_enc[i] = v * (1.0 - p.encoder_offset_m / L * math.tan(alpha))
        pose = arc_step(pose, v, alpha, dt, L)
    return Drive(np.arange(n_samples) * dt, poses, v_enc, steer)


def _pose_at(d: Drive, p: CycabParams, t: np.ndarray) -> np.ndarray:
    """True poses (T, 3) at times t (within the drive), by exact arcs from the last sample."""
    i = np.clip(np.searchsorted(d.t_s, t, side="right") - 1, 0, d.t_s.size - 1)
    out = np.empty((t.size, 3))
    L = p.wheelbase_m
    for j, (ij, tj) in enumerate(zip(i, t)):
        v = d.speed_enc_mps[ij] / (1.0 - p.encoder_offset_m / L * math.tan(d.steer_rad[ij]))
        out[j] = arc_step(d.pose[ij], v, d.steer_rad[ij], tj - d.t_s[ij], L)
    return out


def simulate_cycab_run(
    rng: np.random.Generator, scene: Scene | str = "tree_park", params: CycabParams | None = None
) -> Sequence:
    """One simulated Cycab run through `scene` as a `Sequence` (see the module docstring)."""
    if not isinstance(rng, np.random.Generator):
        raise ConfigError(
            f"simulate_cycab_run.rng: expected a numpy.random.Generator, got {type(rng).__name__}"
        )
    p = params or CycabParams()
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    rng_odo, rng_scan, rng_gps = rng.spawn(3)
    n_samples = (p.n_scans - 1) * p.scan_every + 1
    offset = along = 0.0
    if p.route_offset_sigma_m > 0 or p.start_along_m > 0:
        rng_path = rng.spawn(1)[0]  # a fourth stream: the first three are as without it
        offset = p.route_offset_sigma_m * float(rng_path.standard_normal())
        along = p.start_along_m * float(rng_path.random())
    d = drive(sc, p, n_samples, offset, along)
    # odometry readings
    speed = d.speed_enc_mps + p.speed_sigma_mps * rng_odo.standard_normal(n_samples)
    steer = d.steer_rad + p.steer_sigma_rad * rng_odo.standard_normal(n_samples)
    steer = np.clip(steer, -math.pi / 2, math.pi / 2)
    # scans
    sensor = p.sensor_model()
    scan_idx = np.arange(p.n_scans) * p.scan_every
    ranges = np.empty((p.n_scans, sensor.n_beams))
    labels = np.empty((p.n_scans, sensor.n_beams), dtype=np.int64)
    for k, i in enumerate(scan_idx):
        ranges[k], labels[k] = simulate_scan(
            sc, d.pose[i], sensor, rng_scan, laser_pose=p.laser_pose
        )
    # DGPS at its own rate and clock
    t_end = float(d.t_s[-1])
    gps_t = np.arange(p.dgps_offset_s, t_end, 1.0 / p.dgps_rate_hz)
    gps = {}  # a drive shorter than the first fix (one scan) has no GPS
    if gps_t.size:
        true_pose = _pose_at(d, p, gps_t)
        antenna = np.array([laser_world_pose(q, p.laser_pose)[:2] for q in true_pose])
        gps_xy = antenna + p.dgps_sigma_m * rng_gps.standard_normal(antenna.shape)
        gps = {"gps_t": gps_t, "gps_xy": gps_xy, "gps_pose": np.array(p.laser_pose)}
    return Sequence(
        scan_t=d.t_s[scan_idx],
        scan_ranges=ranges,
        scan_angle_min=sensor.angle_min_rad,
        scan_angle_increment=sensor.angle_increment_rad,
        laser_pose=np.array(p.laser_pose, dtype=np.float64),
        scan_max_range=sensor.max_range_m,
        odo_t=d.t_s,
        odo_speed=speed,
        odo_steer=steer,
        vehicle=p.vehicle,
        **gps,
        truth_t=d.t_s,
        truth_pose=d.pose,
        truth_landmarks=sc.truth_landmarks,
        scan_labels=labels,
        name=f"simulated Cycab run: scene {sc.name}, {p.n_scans} scans, sensor {sensor.name}",
    )
