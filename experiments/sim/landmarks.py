"""Point-landmark worlds for association and filter studies: no laser, landmark centres only.

- `simulate_landmark_scans`: a random field of point landmarks (trunk centres), some not in the
  map yet; a vehicle driving a short path; an EKF-like estimate of the pose (a common error drawn
  from the pose covariance plus a small odometry drift per scan) and of the mapped landmarks
  (independent errors); range-bearing measurements with noise, missed detections and Poisson
  clutter. The state is [x, y, heading, landmarks...], P is block diagonal and the true errors
  are drawn from it, so the predictions are consistent. (Experiment `association`.)
- `vp_scale_scans`: association inputs at Victoria Park scale with a dense covariance
  (`trunkslam bench association`).
- `avenue`: a straight drive past hundreds of trees, as a `slam.Sequence` and the circle centres
  each scan would give (`trunkslam bench slam`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from features.types import Features
from slam import Sequence, se2
from slam.se2 import wrap_angle

__all__ = [
    "LandmarkScan",
    "LandmarkSimConfig",
    "avenue",
    "hard_core_points",
    "predict_map",
    "simulate_landmark_scans",
    "vp_scale_scans",
]


# The ranges of `LandmarkSimConfig`'s fields (others: >= 0), and the landmarks a scenario may
# hold: beyond them the simulation is a unit error or would not fit in memory.
_SIM_RANGES = {
    "unmapped_fraction": (0.0, 1.0),
    "p_detect": (0.0, 1.0),
    "max_range_m": (1e-3, 1e4),
    "n_scans": (1, 10_000),
    "sigma_heading_rad": (0.0, math.pi),
    "sigma_bearing_rad": (0.0, math.pi),
    "drift_heading_rad": (0.0, math.pi),
    "clutter_per_scan": (0.0, 10_000.0),
}
MAX_SIM_LANDMARKS = 1_000_000


@dataclass(frozen=True)
class LandmarkSimConfig:
    """One simulated scenario (a short sequence of scans over a landmark field).

    density_per_100m2: landmarks per 100 m^2 (trunks).
    clutter_per_scan: mean number of false returns per scan (Poisson, uniform in range-bearing).
    sigma_xy_m, sigma_heading_rad: std of the vehicle pose estimate (common to the sequence).
    sigma_landmark_m: std of each mapped landmark's estimate.
    unmapped_fraction: landmarks not in the map (their measurements should be -1).
    p_detect: probability of detecting a landmark in range.
    sigma_range_m, sigma_bearing_rad: measurement noise.
    max_range_m: detection range (360 deg field of view, so bearings wrap at +-pi).
    n_scans: scans per sequence; step_m: distance driven between scans.
    min_separation_m: no two landmarks closer than this (trunks do not overlap).
    drift_xy_m, drift_heading_rad: odometry error std added to the pose error per scan.
    """

    density_per_100m2: float = 1.0
    clutter_per_scan: float = 3.0
    sigma_xy_m: float = 0.3
    sigma_heading_rad: float = math.radians(1.0)
    sigma_landmark_m: float = 0.1
    unmapped_fraction: float = 0.1
    p_detect: float = 0.9
    sigma_range_m: float = 0.1
    sigma_bearing_rad: float = math.radians(0.5)
    max_range_m: float = 20.0
    n_scans: int = 6
    step_m: float = 1.0
    drift_xy_m: float = 0.02
    drift_heading_rad: float = math.radians(0.2)
    min_separation_m: float = 1.5

    def __post_init__(self) -> None:
        from experiments.errors import ConfigError

        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            whole = f.name == "n_scans"
            ok = isinstance(v, int) if whole else isinstance(v, (int, float))
            if isinstance(v, bool) or not ok or not abs(v) < 1e300 or not math.isfinite(v):
                kind = "a whole number" if whole else "a finite number"
                raise ConfigError(f"LandmarkSimConfig.{f.name}: must be {kind}, got {v!r}")
            low, high = _SIM_RANGES.get(f.name, (0.0, math.inf))
            if not low <= v <= high:
                raise ConfigError(
                    f"LandmarkSimConfig.{f.name}: must be in [{low:g}, {high:g}], got {v!r}"
                )
        half = self.max_range_m + 5.0 + self.n_scans * self.step_m
        expected = self.density_per_100m2 * (2 * half) ** 2 / 100.0
        if expected > MAX_SIM_LANDMARKS:
            raise ConfigError(
                f"LandmarkSimConfig.density_per_100m2: {self.density_per_100m2:g} over the "
                f"{2 * half:.0f} m square the scans cover is {expected:.3g} landmarks, more than "
                f"the limit of {MAX_SIM_LANDMARKS}"
            )

    @property
    def R(self) -> np.ndarray:
        return np.diag([self.sigma_range_m**2, self.sigma_bearing_rad**2])

    @property
    def Q_drift(self) -> np.ndarray:
        return np.diag([self.drift_xy_m**2, self.drift_xy_m**2, self.drift_heading_rad**2])


@dataclass(frozen=True, eq=False)
class LandmarkScan:
    """One simulated scan: the inputs of `associate` and the truth.

    z (m, 2), R (2, 2), z_hat (n, 2), H (n, 2, d), P (d, d): as for `associate`.
    truth: (m,) the correct answer, index into z_hat or -1 (clutter or unmapped landmark).
    pose_est: (3,) estimated sensor pose [x_m, y_m, heading_rad]; pose_cov_rel: (3, 3) its
        uncertainty relative to the other scans of a short window (odometry drift).
    feature_ids: (n,) the landmark behind each map feature (stable across scans).
    truth_landmark: (m,) the landmark behind each measurement, -1 for clutter.
    """

    z: np.ndarray
    R: np.ndarray
    z_hat: np.ndarray
    H: np.ndarray
    P: np.ndarray
    truth: np.ndarray
    pose_est: np.ndarray
    pose_cov_rel: np.ndarray
    feature_ids: np.ndarray
    truth_landmark: np.ndarray

    @property
    def inputs(self) -> dict[str, np.ndarray]:
        """The inputs of `association.associate` (z, R, z_hat, H, P), by name."""
        return {"z": self.z, "R": self.R, "z_hat": self.z_hat, "H": self.H, "P": self.P}

    def feed(self, window) -> np.ndarray:
        """Give this scan to a K-scan `association.SlidingWindowAssociator` (with the estimated
        sensor pose, its relative covariance and the feature ids); returns its decision."""
        return window.step(
            self.z,
            self.R,
            self.z_hat,
            self.H,
            self.P,
            sensor_pose=self.pose_est,
            sensor_pose_cov=self.pose_cov_rel,
            feature_ids=self.feature_ids,
        )


def predict_map(pose: np.ndarray, P_pose: np.ndarray, lm: np.ndarray, sigma_lm_m: float):
    """z_hat (n, 2), H (n, 2, 3 + 2n), P for state [pose, lm...] with block-diagonal P
    (the sensor at the pose's origin; `slam.se2.observe` gives the range-bearing model)."""
    n = lm.shape[0]
    d = 3 + 2 * n
    z_hat, H5 = se2.observe(pose, lm, np.zeros(3))
    H = np.zeros((n, 2, d))
    H[:, :, :3] = H5[:, :, :3]
    j = np.arange(n)
    H[j, :, 3 + 2 * j] = H5[:, :, 3]
    H[j, :, 4 + 2 * j] = H5[:, :, 4]
    P = np.zeros((d, d))
    P[:3, :3] = P_pose
    P[3:, 3:] = np.eye(2 * n) * sigma_lm_m**2
    return z_hat, H, P


def hard_core_points(rng: np.random.Generator, n: int, half: float, d_min: float) -> np.ndarray:
    """Up to n uniform points in [-half, half]^2, no two closer than d_min (sequential
    inhibition; candidates that land too close are dropped, so dense fields come out slightly
    thinner than asked)."""
    cand = rng.uniform(-half, half, (n, 2))
    if d_min <= 0 or n < 2:
        return cand
    cell = {}
    keep = []
    for k, p in enumerate(cand):
        cx, cy = int(math.floor(p[0] / d_min)), int(math.floor(p[1] / d_min))
        ok = True
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for q in cell.get((cx + dx, cy + dy), ()):
                    if (cand[q, 0] - p[0]) ** 2 + (cand[q, 1] - p[1]) ** 2 < d_min * d_min:
                        ok = False
        if ok:
            cell.setdefault((cx, cy), []).append(k)
            keep.append(k)
    return cand[keep]


def simulate_landmark_scans(
    cfg: LandmarkSimConfig, rng: np.random.Generator, n_landmarks: int | None = None
) -> list[LandmarkScan]:
    """A sequence of `cfg.n_scans` scans; see the module docstring."""
    path_len = cfg.step_m * cfg.n_scans
    half = cfg.max_range_m + 5.0 + path_len
    area = (2 * half) ** 2
    n_lm = rng.poisson(cfg.density_per_100m2 * area / 100.0) if n_landmarks is None else n_landmarks
    lm = hard_core_points(rng, n_lm, half, cfg.min_separation_m)
    n_lm = lm.shape[0]
    mapped = rng.random(n_lm) >= cfg.unmapped_fraction
    lm_est = lm + rng.normal(0.0, cfg.sigma_landmark_m, lm.shape)
    P_pose0 = np.diag([cfg.sigma_xy_m**2, cfg.sigma_xy_m**2, cfg.sigma_heading_rad**2])
    err = rng.multivariate_normal(np.zeros(3), P_pose0)
    pose = np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
    R = cfg.R
    scans = []
    for t in range(cfg.n_scans):
        if t:
            pose = se2.compose(pose, (cfg.step_m, 0.0, rng.normal(0.0, 0.05)))
            err = err + rng.multivariate_normal(np.zeros(3), cfg.Q_drift)
        est = pose + err
        est[2] = math.remainder(est[2], 2 * math.pi)
        P_pose = P_pose0 + t * cfg.Q_drift
        near = mapped & (np.hypot(*(lm_est - est[:2]).T) <= cfg.max_range_m + 5.0)
        idx = np.flatnonzero(near)  # map features offered to the association
        z_hat, H, P = predict_map(est, P_pose, lm_est[idx], cfg.sigma_landmark_m)
        feat_of_lm = np.full(n_lm, -1, np.int64)
        feat_of_lm[idx] = np.arange(idx.size)
        # measurements of the true landmarks from the true pose
        dx, dy = lm[:, 0] - pose[0], lm[:, 1] - pose[1]
        rng_true = np.hypot(dx, dy)
        seen = np.flatnonzero((rng_true <= cfg.max_range_m) & (rng.random(n_lm) < cfg.p_detect))
        z_lm = np.column_stack([rng_true[seen], np.arctan2(dy[seen], dx[seen]) - pose[2]])
        z_lm = z_lm + rng.multivariate_normal(np.zeros(2), R, seen.size).reshape(-1, 2)
        n_cl = rng.poisson(cfg.clutter_per_scan)
        z_cl = np.column_stack(
            [rng.uniform(0.5, cfg.max_range_m, n_cl), rng.uniform(-np.pi, np.pi, n_cl)]
        )
        z = np.vstack([z_lm, z_cl])
        z[:, 0] = np.abs(z[:, 0])
        z[:, 1] = wrap_angle(z[:, 1])
        truth = np.concatenate([feat_of_lm[seen], np.full(n_cl, -1, np.int64)])
        truth_lm = np.concatenate([seen, np.full(n_cl, -1, np.int64)])
        perm = rng.permutation(z.shape[0])
        scans.append(
            LandmarkScan(
                z=z[perm],
                R=R,
                z_hat=z_hat,
                H=H,
                P=P,
                truth=truth[perm],
                pose_est=est,
                pose_cov_rel=2 * cfg.Q_drift,
                feature_ids=idx,
                truth_landmark=truth_lm[perm],
            )
        )
    return scans


# ---- benchmark worlds ----

# the association benchmark scene (vp_scale_scans)
N_LANDMARKS = 200
N_UNMAPPED = 20
HALF_M = 80.0
MAX_RANGE_M = 20.0


def vp_scale_scans(n_scans: int, seed: int = 0) -> list[dict]:
    """Scans of the association benchmark: dicts with z, R, z_hat, H, P, pose (the estimated
    sensor pose). 200 mapped trunks and 20 not yet in the map (at least 1.5 m apart) over a
    160 m x 160 m park, so that about 10 are within the 20 m detection range; a 403-dimensional
    state [pose, 200 landmarks] with a dense covariance (landmark errors correlated with the
    pose, as after SLAM); every feature offered each scan; 2 clutter returns per scan; P_D 0.9;
    the vehicle drives 1 m between scans."""
    rng = np.random.default_rng(seed)
    lm_all = hard_core_points(rng, (N_LANDMARKS + N_UNMAPPED) * 3, HALF_M, 1.5)
    lm_all = lm_all[: N_LANDMARKS + N_UNMAPPED]
    lm = lm_all[:N_LANDMARKS]  # the mapped ones
    n = lm.shape[0]
    d = 3 + 2 * n
    R = np.diag([0.1**2, math.radians(0.5) ** 2])
    sig_pose = np.array([0.3, 0.3, math.radians(1.0)])
    out = []
    pose = np.array([-60.0, -60.0, math.pi / 4])
    for _ in range(n_scans):
        pose = se2.compose(pose, (1.0, 0.0, rng.normal(0, 0.03)))
        if np.abs(pose[:2]).max() > HALF_M - 20:  # stay inside the park: turn around
            pose[2] += math.pi
        # dense P: independent landmark errors + a common part correlated with the pose error
        U = np.zeros((d, 3))
        U[:3] = np.diag(sig_pose)
        U[3:] = np.tile(np.diag(sig_pose[:2] * 0.8), (n, 1)) @ np.eye(2, 3)
        D = np.full(d, 0.1**2)
        D[:3] = 1e-6
        P = U @ U.T + np.diag(D)
        err = U @ rng.normal(size=3) + np.sqrt(D) * rng.normal(size=d)
        est = pose + err[:3]
        z_hat, H, _ = predict_map(est, np.zeros((3, 3)), lm + err[3:].reshape(n, 2), 0.0)
        dx, dy = lm_all[:, 0] - pose[0], lm_all[:, 1] - pose[1]
        r = np.hypot(dx, dy)
        seen = np.flatnonzero((r <= MAX_RANGE_M) & (rng.random(r.size) < 0.9))
        z = np.column_stack([r[seen], np.arctan2(dy[seen], dx[seen]) - pose[2]])
        z = z + rng.multivariate_normal(np.zeros(2), R, seen.size).reshape(-1, 2)
        zc = np.column_stack([rng.uniform(1, MAX_RANGE_M, 2), rng.uniform(-np.pi, np.pi, 2)])
        z = np.vstack([z, zc])
        z[:, 1] = np.pi - np.mod(np.pi - z[:, 1], 2 * np.pi)
        out.append({"z": z, "R": R, "z_hat": z_hat, "H": H, "P": P, "pose": est})
    return out


def avenue(
    n_trees: int,
    rng: np.random.Generator,
    spacing_m: float = 4.0,
    half_width_m: float = 6.0,
    speed_mps: float = 10.0,
    view_m: float = 20.0,
):
    """(Sequence, list of Features): a straight drive past n_trees trees.

    Trees every `spacing_m` on both sides of a straight road (`half_width_m` off its centre,
    +-1 m), the car at `speed_mps` with 5 Hz scans and 20 Hz odometry (the Cycab noise); every
    tree within `view_m` ahead is measured as a circle centre with the `paper` noise model. The
    scans themselves are empty (all no return): only the features matter.
    """
    length = spacing_m * n_trees / 2 + view_m
    dt, every = 0.05, 4
    n_scans = int(length / (speed_mps * dt * every)) + 1
    t = np.arange((n_scans - 1) * every + 1) * dt
    x = speed_mps * t
    truth = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    side = np.where(np.arange(n_trees) % 2, 1.0, -1.0)
    trees = np.column_stack(
        [
            view_m * 0.5 + spacing_m * (np.arange(n_trees) // 2),
            side * half_width_m + rng.uniform(-1, 1, n_trees),
        ]
    )
    laser = np.array([1.55, 0.0, 0.0])
    feats = []
    for k in range(n_scans):
        px = x[k * every] + laser[0]
        d = trees - np.array([px, 0.0])
        r = np.hypot(d[:, 0], d[:, 1])
        b = np.arctan2(d[:, 1], d[:, 0])
        seen = (r < view_m) & (np.abs(b) < math.pi / 2)
        rr = r[seen] + (0.011 + 0.001 * r[seen]) * rng.standard_normal(seen.sum())
        bb = b[seen] + np.sqrt(0.00022**2 + (0.0067 / r[seen]) ** 2) * rng.standard_normal(
            seen.sum()
        )
        n = int(seen.sum())
        f = Features.empty(float(t[k * every]), "paper")
        feats.append(
            dataclasses.replace(
                f,
                circle_params=np.column_stack([rr * np.cos(bb), rr * np.sin(bb), np.full(n, 0.3)]),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    speed = speed_mps + 0.1 * rng.standard_normal(t.size)
    steer = math.radians(2.0) * rng.standard_normal(t.size)
    seq = Sequence(
        scan_t=t[::every],
        scan_ranges=np.full((n_scans, 361), np.nan),
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        scan_max_range=80.0,
        laser_pose=laser,
        odo_t=t,
        odo_speed=speed,
        odo_steer=steer,
        vehicle={"model": "ackermann", "wheelbase_m": 1.2, "encoder_offset_m": 0.0},
        truth_t=t,
        truth_pose=truth,
        name=f"avenue of {n_trees} trees",
    )
    return seq, feats
