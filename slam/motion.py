"""The motion models, one per kind of odometry: how a run's odometry moves the filter's pose.

Every odometry model of a run lives here and offers the loop (`slam.loop`) the same two things:

- `integrate(pose, t0_s, t1_s)` -> (pose1 (3,), F (3, 3), Q (3, 3)): the pose at t1_s from the
  pose at t0_s, F = d pose1 / d pose and Q the covariance the odometry's noise adds (world
  frame), heading wrapped to (-pi, pi];
- `distance(t0_s, t1_s)`: the metres driven in between (for `vehicle.min_travel_m`).

`AckermannMotion`: a car's speed and steering samples through its Ackermann model
(`slam.vehicle`: the model, the arc step and its noise).

`UnicycleMotion`: speed v and yaw rate omega samples (a differential-drive robot's, or any
`nav_msgs/Odometry` twist), held between samples and integrated as exact arcs, with noise on
each sample's (v, omega) (`UnicycleNoise`).

`IncrementMotion`: the robot's own integrated odometry poses (a `nav_msgs/Odometry` pose, in its
odometry frame); between two times the filter applies the increment of the odometry poses
interpolated at them, with noise proportional to the distance and the turn (`IncrementNoise`):
the odometry model of laser SLAM (Thrun, Burgard and Fox, Probabilistic Robotics, 5.4), with the
noise on the increment's components.

The Jacobians are analytic, each tested against a numerical one (tests/slam/test_motion.py);
the unicycle's integration loop is a numba kernel with a numpy twin as its test oracle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from slam import se2, vehicle
from slam.config import IncrementNoise, OdometryNoise, UnicycleNoise
from slam.errors import SlamError
from slam.validators import finite, float_array, times
from slam.vehicle import AckermannModel, Odometry

__all__ = [
    "AckermannMotion",
    "IncrementMotion",
    "UnicycleMotion",
    "increment_jacobians",
    "unicycle_step",
]


def _pieces(t: np.ndarray, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """The hold pieces covering [t0, t1]: (dt (k,), index (k,) of the sample holding in each);
    before the first sample the first holds, after the last the last."""
    if not t1 >= t0:
        raise SlamError(f"odometry: t1_s = {t1!r} is before t0_s = {t0!r}")
    a = int(np.searchsorted(t, t0, side="right"))
    b = max(int(np.searchsorted(t, t1, side="left")), a)
    edges = np.concatenate([[t0], t[a:b], [t1]])
    idx = np.maximum(np.arange(a - 1, b), 0)
    dt = np.diff(edges)
    keep = dt > 0
    return dt[keep], idx[keep]


def unicycle_step(pose: np.ndarray, v: float, omega: float, dt: float):
    """One exact arc at constant (v, omega) for dt: (pose1 (3,), F (3, 3), G (3, 2)) with
    F = d pose1 / d pose and G = d pose1 / d (v, omega); the heading not wrapped. The numpy
    twin of the kernel's step, and its test oracle."""
    x, y, th = (float(p) for p in pose)
    d = v * dt
    h = 0.5 * omega * dt
    s, ds = se2.sinc_and_derivative(h)
    c_, s_ = math.cos(th + h), math.sin(th + h)
    pose1 = np.array([x + d * c_ * s, y + d * s_ * s, th + 2.0 * h])
    F = np.array([[1.0, 0.0, -d * s_ * s], [0.0, 1.0, d * c_ * s], [0.0, 0.0, 1.0]])
    J_dh = np.array(
        [[c_ * s, d * (-s_ * s + c_ * ds)], [s_ * s, d * (c_ * s + s_ * ds)], [0.0, 2.0]]
    )
    J_u = np.array([[dt, 0.0], [0.0, 0.5 * dt]])  # (d, h) from (v, omega)
    return pose1, F, J_dh @ J_u


@njit(cache=True)
def _unicycle_kernel(pose, dts, vs, ws, sigmas):
    """`UnicycleMotion.integrate`'s loop; sigmas = (sv0, sv1, sw0, sw1, var_xy, var_th)."""
    sv0, sv1, sw0, sw1, var_xy, var_th = sigmas
    x, y, th = pose[0], pose[1], pose[2]
    F = np.eye(3)
    Q = np.zeros((3, 3))
    Fk = np.eye(3)
    G = np.zeros((3, 2))
    for i in range(dts.shape[0]):
        dt, v, w = dts[i], vs[i], ws[i]
        d = v * dt
        h = 0.5 * w * dt
        s, ds = se2.sinc_and_derivative(h)
        c_ = math.cos(th + h)
        s_ = math.sin(th + h)
        Fk[0, 2] = -d * s_ * s
        Fk[1, 2] = d * c_ * s
        G[0, 0] = c_ * s * dt
        G[0, 1] = d * (-s_ * s + c_ * ds) * 0.5 * dt
        G[1, 0] = s_ * s * dt
        G[1, 1] = d * (c_ * s + s_ * ds) * 0.5 * dt
        G[2, 0] = 0.0
        G[2, 1] = dt
        sv = sv0 + sv1 * abs(v)
        sw = sw0 + sw1 * abs(w)
        x = x + d * c_ * s
        y = y + d * s_ * s
        th = th + 2.0 * h
        F = Fk @ F
        Q = Fk @ Q @ Fk.T
        for r in range(3):
            for c in range(3):
                Q[r, c] += G[r, 0] * sv * sv * G[c, 0] + G[r, 1] * sw * sw * G[c, 1]
        Q[0, 0] += var_xy * dt
        Q[1, 1] += var_xy * dt
        Q[2, 2] += var_th * dt
    out = np.empty(3)
    out[0], out[1], out[2] = x, y, th
    return out, F, 0.5 * (Q + Q.T)


@dataclass(frozen=True, eq=False)
class AckermannMotion:
    """A car's motion from its odometry (`slam.vehicle`): the Ackermann model, the speed and
    steering samples, and their noise."""

    model: AckermannModel
    odometry: Odometry
    noise: OdometryNoise

    def integrate(self, pose: np.ndarray, t0_s: float, t1_s: float):
        """(pose1 (3,), F (3, 3), Q (3, 3)) from t0_s to t1_s (`integrate`)."""
        return vehicle.integrate(self.model, pose, self.odometry, t0_s, t1_s, noise=self.noise)

    def distance(self, t0_s: float, t1_s: float) -> float:
        """Distance the rear-axle centre drove from t0_s to t1_s by the odometry (m)."""
        dt, v, a = self.odometry.pieces(t0_s, t1_s)
        k = self.model.encoder_offset_m / self.model.wheelbase_m
        return float(np.sum(np.abs(v / (1.0 - k * np.tan(a))) * dt))


@dataclass(frozen=True, eq=False)
class UnicycleMotion:
    """Speed and yaw-rate samples: t_s (M,) strictly increasing, speed_mps (M,) of the pose's
    origin (the rear-axle centre, or whatever point the robot's odometry reports), yaw_rate_rad_s
    (M,) counter-clockwise; noise: `UnicycleNoise`."""

    t_s: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_rad_s: np.ndarray
    noise: UnicycleNoise = UnicycleNoise()

    def __post_init__(self) -> None:
        t = times("odometry t_s", self.t_s)
        object.__setattr__(self, "t_s", t)
        for name in ("speed_mps", "yaw_rate_rad_s"):
            a = float_array(f"odometry {name}", getattr(self, name), 1)
            if a.shape != t.shape:
                raise SlamError(
                    f"odometry {name}: expected shape {t.shape} like t_s, got {a.shape}"
                )
            finite(f"odometry {name}", a)
            object.__setattr__(self, name, a)

    def integrate(self, pose, t0_s: float, t1_s: float, *, kernel: str = "numba"):
        """(pose1 (3,), F (3, 3), Q (3, 3)) from t0_s to t1_s; kernel "numpy": the step-by-step
        twin (`unicycle_step`), the test oracle."""
        dts, idx = _pieces(self.t_s, float(t0_s), float(t1_s))
        vs, ws = self.speed_mps[idx], self.yaw_rate_rad_s[idx]
        n = self.noise
        sig = (
            n.speed_sigma_mps,
            n.speed_sigma_per_speed,
            n.yaw_rate_sigma_rad_s,
            n.yaw_rate_sigma_per_yaw_rate,
            n.floor_xy_m_per_sqrt_s**2,
            n.floor_theta_rad_per_sqrt_s**2,
        )
        pose = np.asarray(pose, dtype=np.float64)
        if kernel == "numpy":
            p, F, Q = _unicycle_numpy(pose, (dts, vs, ws), sig)
        else:
            p, F, Q = _unicycle_kernel(pose, dts, vs, ws, sig)
        p[2] = float(se2.wrap_angle(p[2]))
        return p, F, Q

    def distance(self, t0_s: float, t1_s: float) -> float:
        """Metres driven from t0_s to t1_s."""
        dts, idx = _pieces(self.t_s, float(t0_s), float(t1_s))
        return float(np.sum(np.abs(self.speed_mps[idx]) * dts))


def _unicycle_numpy(pose, pieces, sig):
    sv0, sv1, sw0, sw1, var_xy, var_th = sig
    p, F, Q = pose.copy(), np.eye(3), np.zeros((3, 3))
    for dt, v, w in zip(*pieces):
        p, Fk, G = unicycle_step(p, v, w, dt)
        sv, sw = sv0 + sv1 * abs(v), sw0 + sw1 * abs(w)
        Q = Fk @ Q @ Fk.T + G @ np.diag([sv * sv, sw * sw]) @ G.T
        Q += np.diag([var_xy, var_xy, var_th]) * dt
        F = Fk @ F
    return p, F, 0.5 * (Q + Q.T)


@dataclass(frozen=True, eq=False)
class IncrementMotion:
    """The robot's integrated odometry: t_s (M,) strictly increasing, pose (M, 3) [x, y, theta]
    in the odometry's own frame (its origin and drift do not matter: only increments are used);
    noise: `IncrementNoise`. Between samples the odometry pose is interpolated (position
    linearly, heading along the shorter turn); before the first and after the last it holds."""

    t_s: np.ndarray
    pose: np.ndarray
    noise: IncrementNoise = IncrementNoise()

    def __post_init__(self) -> None:
        t = times("odometry t_s", self.t_s)
        p = float_array("odometry pose", self.pose, 2, width=3)
        if p.shape[0] != t.shape[0]:
            raise SlamError(f"odometry pose: expected {t.shape[0]} rows like t_s, got {p.shape[0]}")
        finite("odometry pose", p)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "pose", p)
        # the heading unwrapped once (not at every query): interpolation along the shorter turn
        object.__setattr__(self, "_heading", np.unwrap(p[:, 2]))

    def _at(self, t: float) -> np.ndarray:
        """The odometry pose interpolated at t (held before the first sample, after the last)."""
        t_s, p = self.t_s, self.pose
        th = float(np.interp(t, t_s, self._heading))
        return np.array([np.interp(t, t_s, p[:, 0]), np.interp(t, t_s, p[:, 1]), th])

    def increment(self, t0_s: float, t1_s: float) -> np.ndarray:
        """(dx, dy, dtheta) from t0_s to t1_s in the frame of the odometry pose at t0_s."""
        delta = se2.compose(se2.inverse(self._at(t0_s)), self._at(t1_s))
        delta[2] = float(se2.wrap_angle(delta[2]))
        return delta

    def integrate(self, pose, t0_s: float, t1_s: float):
        """(pose1 (3,), F (3, 3), Q (3, 3)): `pose` composed with the increment; Q the
        increment's noise (`IncrementNoise`) in the world frame, plus the floors."""
        if not t1_s >= t0_s:
            raise SlamError(f"odometry: t1_s = {t1_s!r} is before t0_s = {t0_s!r}")
        pose = np.asarray(pose, dtype=np.float64)
        delta = self.increment(t0_s, t1_s)
        pose1, F, R = increment_jacobians(pose, delta)
        n = self.noise
        d = float(np.hypot(delta[0], delta[1]))
        s_xy = n.xy_sigma_per_m * d
        s_th = n.theta_sigma_per_rad * abs(delta[2]) + n.theta_sigma_per_m * d
        dt = float(t1_s - t0_s)
        Q = R @ np.diag([s_xy**2, s_xy**2, s_th**2]) @ R.T
        Q += np.diag([n.floor_xy_m_per_sqrt_s**2] * 2 + [n.floor_theta_rad_per_sqrt_s**2]) * dt
        pose1[2] = float(se2.wrap_angle(pose1[2]))
        return pose1, F, 0.5 * (Q + Q.T)

    def distance(self, t0_s: float, t1_s: float) -> float:
        """Metres driven from t0_s to t1_s: the length of the odometry's path between them."""
        inside = (self.t_s > t0_s) & (self.t_s < t1_s)
        pts = np.vstack([self._at(t0_s)[:2], self.pose[inside, :2], self._at(t1_s)[:2]])
        return float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))


def increment_jacobians(pose: np.ndarray, delta: np.ndarray):
    """pose (+) delta and its Jacobians: (pose1, d pose1 / d pose, d pose1 / d delta)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = delta[0], delta[1]
    pose1 = np.array([pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy, pose[2] + delta[2]])
    F = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pose1, F, R
