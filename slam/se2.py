"""Planar poses (SE(2)) and range-bearing observations, with their Jacobians.

A pose is [x_m, y_m, theta_rad]: the frame's origin and heading in its parent frame, so a pose
`T_world_vehicle` maps vehicle-frame points into the world. Every pose composed by hand anywhere
in trunkslam comes through here (`compose`, `inverse`, `transform_points`, `to_frame`,
`rotate`), and so does the range-bearing model of a landmark seen by a sensor mounted on the
vehicle (`observe`, `inverse_observe`). Headings are not wrapped unless a function says so;
`wrap_angle` wraps to (-pi, pi].

Single poses use `math.cos`/`math.sin` and write each coordinate out, in the order the inline
code they replaced used, so the project's results did not move by a bit when it came here.
`observe` runs as one numba loop over the points (the SLAM loop calls it four times a scan);
its d/d theta column is the two-term sum written out, which may differ in the last bit from
the BLAS dot product the numpy version used (its twin in tests/slam/test_se2.py). The
Jacobians are checked against numerical derivatives in tests/slam/test_se2.py.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "compose",
    "interpolate_poses",
    "inverse",
    "inverse_observe",
    "observe",
    "observe_kernel",
    "observe_within",
    "observed_points",
    "procrustes_2d",
    "rotate",
    "sensor_numbers",
    "sensor_position",
    "sinc_and_derivative",
    "to_frame",
    "transform_points",
    "wrap_angle",
]


@njit(cache=True, inline="always")
def sinc_and_derivative(h: float) -> tuple[float, float]:
    """sin(h)/h and its derivative (h cos h - sin h)/h^2, by series near 0: the factors of an
    arc step of half-angle h (`slam.vehicle`, `slam.motion`; callable from Python and from
    numba kernels)."""
    if abs(h) < 1e-4:
        h2 = h * h
        return 1.0 - h2 / 6.0 + h2 * h2 / 120.0, -h / 3.0 + h * h2 / 30.0
    return math.sin(h) / h, (h * math.cos(h) - math.sin(h)) / (h * h)


def wrap_angle(a):
    """Angles (rad) wrapped to (-pi, pi]; scalars or arrays. A single float takes Python's
    float arithmetic (`%` is numpy's `mod` for floats, fmod and the same sign fix: the same
    number to the bit, without numpy's per-call cost; the loop wraps a few headings a scan)."""
    if type(a) is float or type(a) is np.float64:
        return np.float64(math.pi - (math.pi - float(a)) % (2.0 * math.pi))
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)


def rotate(theta_rad: float, v_xy) -> np.ndarray:
    """The 2-vector(s) v_xy (2,) or (k, 2) rotated by theta_rad: R(theta) v."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    v = np.asarray(v_xy, dtype=np.float64)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def compose(T_ab, T_bc) -> np.ndarray:
    """T_ac = T_ab * T_bc for single poses (3,): [x_ab + R_ab x_bc, theta_ab + theta_bc].

    E.g. the laser's world pose is compose(T_world_vehicle, T_vehicle_laser). The heading is the
    plain sum (not wrapped).
    """
    x, y, th = float(T_ab[0]), float(T_ab[1]), float(T_ab[2])
    lx, ly, lth = float(T_bc[0]), float(T_bc[1]), float(T_bc[2])
    c, s = math.cos(th), math.sin(th)
    return np.array([x + c * lx - s * ly, y + s * lx + c * ly, th + lth])


def inverse(T_ab) -> np.ndarray:
    """T_ba = T_ab^-1 for a single pose (3,): [-R^T t, -theta]."""
    x, y, th = float(T_ab[0]), float(T_ab[1]), float(T_ab[2])
    c, s = math.cos(th), math.sin(th)
    return np.array([-(c * x + s * y), -(-s * x + c * y), -th])


def transform_points(T_ab, p_b) -> np.ndarray:
    """Points p_b (k, 2) (or (2,)) given in frame b, expressed in frame a: t_ab + R_ab p_b."""
    x, y, th = float(T_ab[0]), float(T_ab[1]), float(T_ab[2])
    c, s = math.cos(th), math.sin(th)
    p = np.asarray(p_b, dtype=np.float64)
    return np.stack([x + (c * p[..., 0] - s * p[..., 1]), y + (s * p[..., 0] + c * p[..., 1])], -1)


def to_frame(T_ab, p_a) -> np.ndarray:
    """Points p_a (k, 2) (or (2,)) given in frame a, expressed in frame b: R_ab^T (p_a - t_ab)."""
    x, y, th = float(T_ab[0]), float(T_ab[1]), float(T_ab[2])
    c, s = math.cos(th), math.sin(th)
    p = np.asarray(p_a, dtype=np.float64)
    dx, dy = p[..., 0] - x, p[..., 1] - y
    return np.stack([dx * c + dy * s, -dx * s + dy * c], axis=-1)


def sensor_position(pose, sensor_pose) -> tuple[np.ndarray, np.ndarray]:
    """World position p_S (2,) of a sensor mounted at `sensor_pose` (vehicle frame) when the
    vehicle is at `pose`, and d p_S / d theta (2,)."""
    px, py, dpx, dpy = sensor_numbers(pose, sensor_pose)
    return np.array([px, py]), np.array([dpx, dpy])


def sensor_numbers(pose, sensor_pose) -> tuple[float, float, float, float]:
    """`sensor_position` as four numbers (p_S x, y; d p_S / d theta x, y), without arrays
    (what `observe_kernel` takes)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    lx, ly = float(sensor_pose[0]), float(sensor_pose[1])
    return pose[0] + c * lx - s * ly, pose[1] + s * lx + c * ly, -s * lx - c * ly, c * lx - s * ly


def observe(pose, landmarks_xy, sensor_pose) -> tuple[np.ndarray, np.ndarray]:
    """Range and bearing of world points from a sensor mounted on the vehicle, with Jacobians.

    pose: (3,) vehicle [x, y, theta] in the world. landmarks_xy: (k, 2) world points.
    sensor_pose: (3,) [lx, ly, lth] of the sensor in the vehicle frame. With p_S the sensor's
    world position, range = |m - p_S| and bearing = atan2((m - p_S)_y, (m - p_S)_x) - theta
    - lth, wrapped to (-pi, pi].
    Returns z (k, 2) [range_m, bearing_rad] and H (k, 2, 5), the Jacobian of each prediction
    with respect to [x, y, theta, m_x, m_y].
    """
    m = np.ascontiguousarray(landmarks_xy, dtype=np.float64).reshape(-1, 2)
    px, py, dpx, dpy = sensor_numbers(pose, sensor_pose)
    return observe_kernel(m, px, py, dpx, dpy, float(pose[2]), float(sensor_pose[2]))


@njit(cache=True)
def _jacobian_row(H, i, dx, dy, q, r, dpx, dpy):
    """Row i of `observe_kernel`'s H: the range and bearing of the point (dx, dy) from the
    sensor (q = dx^2 + dy^2, r = sqrt(q)) against [x, y, theta, m_x, m_y]."""
    rx, ry = dx / r, dy / r  # d range / d m
    bx, by = -dy / q, dx / q  # d bearing / d m
    H[i, 0, 0] = -rx
    H[i, 0, 1] = -ry
    H[i, 0, 2] = -(rx * dpx + ry * dpy)
    H[i, 0, 3] = rx
    H[i, 0, 4] = ry
    H[i, 1, 0] = -bx
    H[i, 1, 1] = -by
    H[i, 1, 2] = -(bx * dpx + by * dpy) - 1.0
    H[i, 1, 3] = bx
    H[i, 1, 4] = by


@njit(cache=True)
def observe_kernel(m, px, py, dpx, dpy, th, sth):
    """`observe` for the sensor at world position (px, py), d p_S / d theta = (dpx, dpy),
    vehicle heading th and sensor yaw sth (`sensor_numbers`), callable from other kernels:
    one pass over the points (the per-call cost of the numpy version, some 20 array
    operations, dominated the run loop's)."""
    k = m.shape[0]
    z = np.empty((k, 2))
    H = np.zeros((k, 2, 5))
    b = np.empty(k)
    for i in range(k):
        dx = m[i, 0] - px
        dy = m[i, 1] - py
        q = dx * dx + dy * dy
        r = math.sqrt(q)
        z[i, 0] = r
        b[i] = math.atan2(dy, dx) - th - sth
        _jacobian_row(H, i, dx, dy, q, r, dpx, dpy)
    wrapped = np.pi - np.mod(np.pi - b, 2.0 * np.pi)  # `wrap_angle`
    for i in range(k):  # not `z[:, 1] = wrapped`: see slam.scan_candidates._put_row
        z[i, 1] = wrapped[i]
    return z, H


@njit(cache=True)
def observe_within(m, px, py, dpx, dpy, th, sth, r_max):
    """`observe_kernel` for the points within r_max of the sensor, the same bits; a point
    farther (or at a NaN range) gets its range only, bearing 0 and H 0, which a view test
    that also asks range <= r_max reads as out of view (`slam.scan_candidates`): the bearing
    and Jacobian of the hundreds of landmarks out of range cost most of a scan's pass."""
    k = m.shape[0]
    z = np.empty((k, 2))
    H = np.zeros((k, 2, 5))
    for i in range(k):
        dx = m[i, 0] - px
        dy = m[i, 1] - py
        q = dx * dx + dy * dy
        r = math.sqrt(q)
        z[i, 0] = r
        if not r <= r_max:
            z[i, 1] = 0.0
            continue
        b = math.atan2(dy, dx) - th - sth
        z[i, 1] = np.pi - np.mod(np.pi - b, 2.0 * np.pi)  # `wrap_angle`
        _jacobian_row(H, i, dx, dy, q, r, dpx, dpy)
    return z, H


def inverse_observe(pose, z, sensor_pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The world point seen at z (2,) [range, bearing]: m (2,), Gx = dm/dpose (2, 3) and
    Gz = dm/dz (2, 2) (the inverse of `observe` for one measurement)."""
    pL, dpL = sensor_position(pose, sensor_pose)
    r, b = float(z[0]), float(z[1])
    phi = pose[2] + sensor_pose[2] + b
    c, s = math.cos(phi), math.sin(phi)
    m = pL + r * np.array([c, s])
    Gx = np.array([[1.0, 0.0, dpL[0] - r * s], [0.0, 1.0, dpL[1] + r * c]])
    Gz = np.array([[c, -r * s], [s, r * c]])
    return m, Gx, Gz


def observed_points(poses, z, sensor_pose) -> np.ndarray:
    """(k, 2) world points seen at z (k, 2) [range, bearing] by a sensor mounted at
    `sensor_pose` on a vehicle at poses (k, 3), one pose per observation (`inverse_observe`'s
    point, for many at once)."""
    P = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    z = np.asarray(z, dtype=np.float64).reshape(-1, 2)
    sp = np.asarray(sensor_pose, dtype=np.float64)
    c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
    sensor = P[:, :2] + np.stack([c * sp[0] - s * sp[1], s * sp[0] + c * sp[1]], axis=1)
    phi = P[:, 2] + sp[2] + z[:, 1]
    return sensor + z[:, :1] * np.stack([np.cos(phi), np.sin(phi)], axis=1)


def interpolate_poses(t_query, t_s, poses) -> np.ndarray:
    """Poses (T, 3) sampled at t_s, linearly interpolated at t_query (heading unwrapped first,
    result wrapped). Queries outside [t_s[0], t_s[-1]] take the end values."""
    t_s = np.asarray(t_s, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    tq = np.atleast_1d(np.asarray(t_query, dtype=np.float64))
    th = np.unwrap(poses[:, 2])
    return np.stack(
        [
            np.interp(tq, t_s, poses[:, 0]),
            np.interp(tq, t_s, poses[:, 1]),
            wrap_angle(np.interp(tq, t_s, th)),
        ],
        axis=1,
    )


def procrustes_2d(A: np.ndarray, B: np.ndarray) -> tuple[float, np.ndarray]:
    """The rotation theta and translation t (2,) minimising sum |B_i - (R(theta) A_i + t)|^2."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    H = (A - ca).T @ (B - cb)
    theta = math.atan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
    return theta, cb - rotate(theta, ca)
