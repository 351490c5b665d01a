"""The car-like (Ackermann) vehicle: odometry integration with noise propagation.

Vehicle frame: origin at the centre of the rear axle, x forward, y left (datasets/FORMAT.md).
World frame: the run's fixed frame; a pose is [x_m, y_m, theta_rad] of the vehicle frame.

Model (`"ackermann"` of the sequence format, the Guivant-Nebot model of the Victoria Park ute,
and the rear-axle bicycle model proposed for the Cycab in docs/method.md section 3):
- the speed encoder sits H = `encoder_offset_m` to the left of the centre line on the rear axle;
  the rear-axle-centre speed is v_c = v_e / (1 - (H / L) tan(alpha)),
- the rear-axle centre moves as x' = v_c cos(theta), y' = v_c sin(theta),
  theta' = v_c tan(alpha) / L, with L = `wheelbase_m` and alpha the front steering angle.

Odometry samples are a zero-order hold: sample i's (speed, steer) applies from odo_t[i] to
odo_t[i + 1]. For constant controls the motion is an exact circular arc, integrated in closed
form (no Euler error), so exact odometry reproduces a path built by the same hold exactly:

    dtheta = v_c tan(alpha) dt / L,  h = dtheta / 2,  d = v_c dt,
    x1 = x + d cos(theta + h) sinc(h),  y1 = y + d sin(theta + h) sinc(h),  theta1 = theta + 2 h

with sinc(h) = sin(h) / h (1 at h = 0). Noise: each odometry sample's speed and steering
readings carry independent zero-mean errors of covariance Q_u = diag(sigma_v^2, sigma_alpha^2)
(`slam.config.OdometryNoise`; the sigmas may grow with the speed and the lateral acceleration of the
sample); they enter the pose through the analytic Jacobian G = d pose1 / d(v_e, alpha), and the
pose's own uncertainty through F = d pose1 / d pose.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

from slam.config import OdometryNoise
from slam.errors import SlamError
from slam.se2 import sinc_and_derivative, wrap_angle
from slam.validators import finite, float_array, times

__all__ = [
    "AckermannModel",
    "Odometry",
    "arc_step",
    "arc_step_jacobians",
    "integrate",
    "wrap_angle",
]


@dataclass(frozen=True)
class AckermannModel:
    """A front-steered car whose pose is that of the centre of its rear axle.

    wheelbase_m: L, rear axle to front axle, > 0.
    encoder_offset_m: H, lateral position of the speed encoder on the rear axle, to the left of
        the centre line (0: the speed is already the rear-axle-centre speed, the Cycab case).
    """

    wheelbase_m: float
    encoder_offset_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("wheelbase_m", "encoder_offset_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise SlamError(f"AckermannModel.{name}: must be a number, got {v!r}")
            if not math.isfinite(v):
                raise SlamError(f"AckermannModel.{name}: must be finite, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.wheelbase_m <= 0:
            raise SlamError(f"AckermannModel.wheelbase_m: must be > 0, got {self.wheelbase_m!r}")

    @classmethod
    def from_vehicle(cls, vehicle) -> AckermannModel:
        """From a sequence's `vehicle`: a `slam.sequence.Vehicle`, or its dict ({"model":
        "ackermann", "wheelbase_m": ..., "encoder_offset_m": ...})."""
        if vehicle is None:
            raise SlamError("vehicle: the sequence has no vehicle model (needed for odometry)")
        if isinstance(vehicle, Mapping):
            model = vehicle.get("model")
        elif hasattr(vehicle, "wheelbase_m"):
            model = vehicle.model
            vehicle = {
                "wheelbase_m": vehicle.wheelbase_m,
                "encoder_offset_m": vehicle.encoder_offset_m,
            }
        else:
            raise SlamError(f"vehicle: expected a Vehicle or a dict, got {type(vehicle).__name__}")
        if model != "ackermann":
            raise SlamError(f"vehicle.model: only 'ackermann' is known, got {model!r}")
        if "wheelbase_m" not in vehicle:
            raise SlamError("vehicle.wheelbase_m: missing")
        geometry = (vehicle["wheelbase_m"], vehicle.get("encoder_offset_m", 0.0))
        return cls(*geometry)

    def axle_speed(self, v_enc_mps: float, steer_rad: float) -> float:
        """v_c = v_e / (1 - (H / L) tan(alpha)): encoder speed to rear-axle-centre speed."""
        return v_enc_mps / (1.0 - self.encoder_offset_m / self.wheelbase_m * math.tan(steer_rad))

    def axle_speed_jacobian(self, v_enc_mps: float, steer_rad: float) -> tuple[float, float]:
        """(d v_c / d v_e, d v_c / d alpha)."""
        k = self.encoder_offset_m / self.wheelbase_m
        den = 1.0 - k * math.tan(steer_rad)
        sec2 = 1.0 / math.cos(steer_rad) ** 2
        return 1.0 / den, v_enc_mps * k * sec2 / (den * den)


def arc_step(
    pose: np.ndarray, v_axle_mps: float, steer_rad: float, dt_s: float, wheelbase_m: float
) -> np.ndarray:
    """Exact motion of the rear-axle centre for constant (v_c, alpha) over dt_s; (3,) pose."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    d = v_axle_mps * dt_s
    h = 0.5 * d * math.tan(steer_rad) / wheelbase_m
    s, _ = sinc_and_derivative(h)
    return np.array([x + d * math.cos(th + h) * s, y + d * math.sin(th + h) * s, th + 2.0 * h])


def arc_step_jacobians(
    model: AckermannModel, pose: np.ndarray, v_enc_mps: float, steer_rad: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One zero-order-hold step from encoder readings: (pose1 (3,), F (3, 3), G (3, 2)).

    F = d pose1 / d pose, G = d pose1 / d (v_e, alpha); heading not wrapped (continuous).
    """
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    L = model.wheelbase_m
    v = model.axle_speed(v_enc_mps, steer_rad)
    dv_dve, dv_da = model.axle_speed_jacobian(v_enc_mps, steer_rad)
    t = math.tan(steer_rad)
    sec2 = 1.0 + t * t
    d = v * dt_s
    h = 0.5 * d * t / L
    s, ds = sinc_and_derivative(h)
    c_, s_ = math.cos(th + h), math.sin(th + h)
    pose1 = np.array([x + d * c_ * s, y + d * s_ * s, th + 2.0 * h])
    F = np.array([[1.0, 0.0, -d * s_ * s], [0.0, 1.0, d * c_ * s], [0.0, 0.0, 1.0]])
    # pose1 as a function of (d, h)
    J_dh = np.array(
        [[c_ * s, d * (-s_ * s + c_ * ds)], [s_ * s, d * (c_ * s + s_ * ds)], [0.0, 2.0]]
    )
    # (d, h) as a function of (v_c, alpha): d = v dt, h = v dt tan(alpha) / (2 L)
    J_va = np.array([[dt_s, 0.0], [0.5 * dt_s * t / L, 0.5 * v * dt_s * sec2 / L]])
    # (v_c, alpha) as a function of (v_e, alpha)
    J_u = np.array([[dv_dve, dv_da], [0.0, 1.0]])
    return pose1, F, J_dh @ J_va @ J_u


@dataclass(frozen=True, eq=False)
class Odometry:
    """Odometry samples (zero-order hold).

    t_s: (M,) strictly increasing sample times, s. speed_mps: (M,) encoder speed, m/s.
    steer_rad: (M,) front steering angle, rad, positive = turning left.
    """

    t_s: np.ndarray
    speed_mps: np.ndarray
    steer_rad: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_s", times("Odometry.t_s", self.t_s))
        m = self.t_s.shape[0]
        if m == 0:
            raise SlamError("Odometry.t_s: no odometry samples")
        for name in ("speed_mps", "steer_rad"):
            a = float_array(f"Odometry.{name}", getattr(self, name), 1)
            if a.shape != (m,):
                raise SlamError(f"Odometry.{name}: expected shape ({m},) like t_s, got {a.shape}")
            finite(f"Odometry.{name}", a)
            object.__setattr__(self, name, a)

    def pieces(self, t0_s: float, t1_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The hold pieces covering [t0_s, t1_s]: (dt (k,), speed (k,), steer (k,)).

        Before the first sample the first sample's values hold, after the last the last's.
        """
        if not t1_s >= t0_s:
            raise SlamError(f"Odometry.pieces: t1_s = {t1_s!r} is before t0_s = {t0_s!r}")
        return _pieces(self.t_s, self.speed_mps, self.steer_rad, float(t0_s), float(t1_s))


@njit(cache=True)
def _pieces(t, speed, steer, t0_s, t1_s):
    """`Odometry.pieces` in one pass (it runs twice a scan; its dozen array operations cost
    more than the integration): the pieces' edges are t0_s, the samples strictly inside
    (t0_s, t1_s) and t1_s; piece i holds the sample before its start (sample 0 before the first
    sample); pieces of zero length are left out."""
    a = np.searchsorted(t, t0_s, side="right")  # first sample after t0
    b = max(np.searchsorted(t, t1_s, side="left"), a)  # first sample at or after t1
    n = b - a + 1
    dt, v, alpha = np.empty(n), np.empty(n), np.empty(n)
    k = 0
    for i in range(n):
        lo = t0_s if i == 0 else t[a + i - 1]
        hi = t1_s if i == n - 1 else t[a + i]
        if hi - lo > 0:
            held = max(a - 1 + i, 0)
            dt[k], v[k], alpha[k] = hi - lo, speed[held], steer[held]
            k += 1
    return dt[:k], v[:k], alpha[:k]


def integrate(
    model: AckermannModel,
    pose: np.ndarray,
    odometry: Odometry,
    t0_s: float,
    t1_s: float,
    noise: OdometryNoise | None = None,
    *,
    kernel: str = "numba",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate the odometry from t0_s to t1_s: (pose1 (3,), F (3, 3), Q (3, 3)).

    F = d pose1 / d pose over the whole interval (the product of the steps' Jacobians) and Q
    the covariance the readings' noise adds, propagated step by step:
    Q <- F_k Q F_k^T + G_k Q_u G_k^T + Q_floor dt_k. The heading of pose1 is wrapped to
    (-pi, pi]. kernel: "numba" (the loop as a numba kernel) or "numpy" (step by step with
    `arc_step_jacobians`, its plain twin and test oracle).
    """
    if kernel not in ("numba", "numpy"):
        raise SlamError(f"kernel: expected 'numba' or 'numpy', got {kernel!r}")
    noise = noise or OdometryNoise(0.0, 0.0, 0.0, 0.0)
    dts, vs, alphas = odometry.pieces(float(t0_s), float(t1_s))
    pose = np.asarray(pose, dtype=np.float64)
    if kernel == "numpy":
        p, F, Q = _integrate_numpy(model, pose, (dts, vs, alphas), noise)
    else:
        p, F, Q = _integrate_kernel(
            pose,
            dts,
            vs,
            alphas,
            model.wheelbase_m,
            model.encoder_offset_m,
            noise.speed_sigma_mps,
            noise.steer_sigma_rad,
            noise.speed_sigma_per_speed,
            noise.steer_sigma_per_lateral_mps2,
            noise.floor_xy_m_per_sqrt_s**2,
            noise.floor_theta_rad_per_sqrt_s**2,
        )
    p[2] = float(wrap_angle(p[2]))
    return p, F, Q


def _integrate_numpy(model, pose, pieces, noise):
    dts, vs, alphas = pieces
    p = pose.copy()
    F = np.eye(3)
    Q = np.zeros((3, 3))
    for dt, v, a in zip(dts, vs, alphas):
        Q_u = noise.Q_u(float(v), model.axle_speed(float(v), float(a)), float(a), model.wheelbase_m)
        p, Fk, Gk = arc_step_jacobians(model, p, float(v), float(a), float(dt))
        F = Fk @ F
        Q = Fk @ Q @ Fk.T + Gk @ Q_u @ Gk.T + noise.Q_floor * dt
    return p, F, 0.5 * (Q + Q.T)


@njit(cache=True)
def _integrate_kernel(pose, dts, vs, alphas, L, H, sv0, sa0, sv1, sa1, var_xy, var_th):
    x, y, th = pose[0], pose[1], pose[2]
    F = np.eye(3)
    Q = np.zeros((3, 3))
    Fk = np.eye(3)
    G = np.zeros((3, 2))
    k = H / L
    for i in range(dts.shape[0]):
        dt, ve, a = dts[i], vs[i], alphas[i]
        t = math.tan(a)
        den = 1.0 - k * t
        v = ve / den
        dv_dve = 1.0 / den
        dv_da = ve * k * (1.0 + t * t) / (den * den)
        d = v * dt
        h = 0.5 * d * t / L
        sv = sv0 + sv1 * abs(ve)
        sa = sa0 + sa1 * v * v * abs(t) / L
        var_v = sv * sv
        var_a = sa * sa
        s, ds = sinc_and_derivative(h)
        c_ = math.cos(th + h)
        s_ = math.sin(th + h)
        Fk[0, 2] = -d * s_ * s
        Fk[1, 2] = d * c_ * s
        # d pose1 / d(d, h), then (d, h) / (v_c, alpha), then (v_c, alpha) / (v_e, alpha)
        j00, j01 = c_ * s, d * (-s_ * s + c_ * ds)
        j10, j11 = s_ * s, d * (c_ * s + s_ * ds)
        j20, j21 = 0.0, 2.0
        m00, m01 = dt, 0.0
        m10, m11 = 0.5 * dt * t / L, 0.5 * v * dt * (1.0 + t * t) / L
        # J_va @ J_u with J_u = [[dv_dve, dv_da], [0, 1]]
        n00, n01 = m00 * dv_dve, m00 * dv_da + m01
        n10, n11 = m10 * dv_dve, m10 * dv_da + m11
        G[0, 0] = j00 * n00 + j01 * n10
        G[0, 1] = j00 * n01 + j01 * n11
        G[1, 0] = j10 * n00 + j11 * n10
        G[1, 1] = j10 * n01 + j11 * n11
        G[2, 0] = j20 * n00 + j21 * n10
        G[2, 1] = j20 * n01 + j21 * n11
        x = x + d * c_ * s
        y = y + d * s_ * s
        th = th + 2.0 * h
        F = Fk @ F
        Q = Fk @ Q @ Fk.T
        for r in range(3):
            for c in range(3):
                Q[r, c] += G[r, 0] * var_v * G[c, 0] + G[r, 1] * var_a * G[c, 1]
        Q[0, 0] += var_xy * dt
        Q[1, 1] += var_xy * dt
        Q[2, 2] += var_th * dt
    out = np.empty(3)
    out[0], out[1], out[2] = x, y, th
    return out, F, 0.5 * (Q + Q.T)
