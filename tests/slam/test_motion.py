"""slam.motion: the unicycle and pose-increment models, their Jacobians against numerical ones,
the kernel against its numpy twin, and whole runs on a robot's own odometry."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from experiments.io.sequence_file import load_sequence, save_sequence
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamError, interpolate_poses, run_slam, se2
from slam.config import IncrementNoise, OdometryNoise, UnicycleNoise
from slam.motion import (
    AckermannMotion,
    IncrementMotion,
    UnicycleMotion,
    increment_jacobians,
    unicycle_step,
)
from slam.vehicle import AckermannModel, Odometry

STEP = 1e-6  # central differences: truncation ~ STEP^2, rounding ~ 1e-16 / STEP, both < 1e-9


def _numeric(f, x):
    x = np.asarray(x, float)
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = STEP
        cols.append((f(x + e) - f(x - e)) / (2 * STEP))
    return np.column_stack(cols)


@given(
    th=st.floats(-3.1, 3.1),
    v=st.floats(-3.0, 3.0),
    w=st.sampled_from([0.0, 1e-7, 0.3, -1.2]),
    dt=st.floats(0.01, 0.5),
)
@settings(max_examples=60, deadline=None)
def test_unicycle_step_jacobians_match_numerical_ones(th, v, w, dt):
    pose = np.array([1.0, -2.0, th])
    _, F, G = unicycle_step(pose, v, w, dt)
    F_num = _numeric(lambda p: unicycle_step(p, v, w, dt)[0], pose)
    G_num = _numeric(lambda u: unicycle_step(pose, u[0], u[1], dt)[0], [v, w])
    assert np.allclose(F, F_num, atol=1e-7) and np.allclose(G, G_num, atol=1e-7)


def test_increment_jacobians_match_numerical_ones():
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose, delta = rng.normal(size=3), rng.normal(size=3) * 0.5
        _, F, R = increment_jacobians(pose, delta)
        F_num = _numeric(lambda p, d=delta: increment_jacobians(p, d)[0], pose)
        R_num = _numeric(lambda d, p=pose: increment_jacobians(p, d)[0], delta)
        assert np.allclose(F, F_num, atol=1e-8) and np.allclose(R, R_num, atol=1e-8)


def _samples(n=200, seed=1):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.02, 0.08, n))
    return t, rng.uniform(-0.5, 2.0, n), rng.uniform(-0.8, 0.8, n)


def test_unicycle_kernel_matches_its_numpy_twin():
    """The same operations in the same order but for the 3 x 3 products, which numba and numpy
    may sum in other orders: within 1e-12 (a few ulp of the 1-10 sized terms over 200 steps)."""
    t, v, w = _samples()
    m = UnicycleMotion(t, v, w, UnicycleNoise(speed_sigma_per_speed=0.02))
    for t0, t1 in ((t[3], t[150]), (t[0] - 0.3, t[-1] + 0.2), (t[10] + 0.01, t[10] + 0.02)):
        a = m.integrate(np.array([0.5, 1.0, 2.9]), t0, t1)
        b = m.integrate(np.array([0.5, 1.0, 2.9]), t0, t1, kernel="numpy")
        for x, y in zip(a, b):
            assert np.allclose(x, y, rtol=1e-12, atol=1e-12)


def test_a_unicycle_is_the_car_seen_by_its_yaw_rate():
    """An Ackermann car with its encoder at the axle centre turns at v tan(alpha) / L: the same
    samples as a unicycle's (v, omega) give the same poses and the same F (to rounding)."""
    t, v, a = _samples(seed=3)
    car = AckermannMotion(AckermannModel(1.2), Odometry(t, v, a), OdometryNoise())
    uni = UnicycleMotion(t, v, v * np.tan(a) / 1.2)
    p0 = np.array([3.0, -1.0, 0.4])
    pc, Fc, _ = car.integrate(p0, t[5], t[180])
    pu, Fu, _ = uni.integrate(p0, t[5], t[180])
    assert np.allclose(pc, pu, atol=1e-10) and np.allclose(Fc, Fu, atol=1e-10)
    assert car.distance(t[5], t[180]) == pytest.approx(uni.distance(t[5], t[180]), rel=1e-12)


def test_increments_rebuild_the_odometrys_path_in_any_frame():
    """Composing the increments from another start gives the odometry path moved rigidly there,
    and the noise is the stated one: 1 m straight is 0.019 m across and along, 0.0065 rad."""
    t, v, w = _samples(seed=4)
    uni = UnicycleMotion(t, v, w)
    poses = [np.zeros(3)]
    for k in range(1, t.size):
        poses.append(uni.integrate(poses[-1], t[k - 1], t[k])[0])
    inc = IncrementMotion(t, np.array(poses))
    start = np.array([10.0, 5.0, 1.0])
    p = start.copy()
    for k in range(1, t.size):
        p = inc.integrate(p, t[k - 1], t[k])[0]
    assert np.allclose(p, se2.compose(start, poses[-1]), atol=1e-9)
    straight = IncrementMotion(np.array([0.0, 1.0]), np.array([[0, 0, 0], [1.0, 0, 0]]))
    _, F, Q = straight.integrate(np.zeros(3), 0.0, 1.0)
    n = IncrementNoise()
    floor = np.array([n.floor_xy_m_per_sqrt_s] * 2 + [n.floor_theta_rad_per_sqrt_s]) ** 2
    expected = np.array([0.019, 0.019, 0.0065]) ** 2 + floor
    assert np.allclose(np.diag(Q), expected, rtol=1e-12)
    assert F[1, 2] == pytest.approx(1.0)  # a heading error swings the 1 m increment sideways


def test_bad_odometry_is_named():
    with pytest.raises(SlamError, match="odometry yaw_rate_rad_s: expected shape"):
        UnicycleMotion(np.arange(3.0), np.zeros(3), np.zeros(2))
    with pytest.raises(SlamError, match="odometry pose"):
        IncrementMotion(np.arange(3.0), np.zeros((3, 2)))
    with pytest.raises(SlamError, match=r"vehicle\.unicycle_noise\.yaw_rate_sigma_rad_s"):
        UnicycleNoise(yaw_rate_sigma_rad_s=-1.0)


def _as_robot(seq, kind: str):
    """The simulated Cycab's drive as a robot's own odometry: its (v, omega), or the poses
    its odometry integrates to (in the odometry's own frame)."""
    L = seq.vehicle.wheelbase_m
    omega = seq.odo_speed * np.tan(seq.odo_steer) / L
    if kind == "unicycle":
        extra = {"odo_yaw_rate": omega}
    else:
        uni = UnicycleMotion(seq.odo_t, seq.odo_speed, omega)
        poses = [np.zeros(3)]
        for k in range(1, seq.odo_t.size):
            poses.append(uni.integrate(poses[-1], seq.odo_t[k - 1], seq.odo_t[k])[0])
        extra = {"odo_pose": np.array(poses), "odo_speed": None}
    return dataclasses.replace(seq, vehicle={"model": kind}, odo_steer=None, **extra)


@pytest.mark.parametrize("kind", ["unicycle", "pose-increment"])
def test_a_run_on_a_robots_own_odometry(kind, tmp_path):
    """The tree park driven by the Cycab, its odometry given as a unicycle's or as integrated
    poses: the filter follows the truth as closely as on the car's own model (its errors within
    1.5 times the car's, a few centimetres), and the sequence file keeps the new fields."""
    seq = simulate_cycab_run(np.random.default_rng(6), "tree_park", CycabParams(n_scans=120))
    robot = _as_robot(seq, kind)
    path = tmp_path / "robot.npz"
    save_sequence(robot, path)
    back = load_sequence(path)
    assert back.vehicle.model == kind
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)

    def error(s):
        lg = run_slam(s, features="paper")
        return float(np.mean(np.hypot(*(lg.pose[1:, :2] - truth[1:, :2]).T)))

    car, own = error(seq), error(back)
    assert own < max(1.5 * car, 0.05), (car, own)


def test_a_vehicle_whose_odometry_is_not_its_kind_is_refused():
    seq = simulate_cycab_run(np.random.default_rng(6), "tree_park", CycabParams(n_scans=5))
    with pytest.raises(SlamError, match="'unicycle' vehicle's odometry is odo_t, odo_speed"):
        dataclasses.replace(seq, vehicle={"model": "unicycle"})
    with pytest.raises(SlamError, match=r"odo_yaw_rate: must be within \+-20 rad/s"):
        dataclasses.replace(
            seq,
            vehicle={"model": "unicycle"},
            odo_steer=None,
            odo_yaw_rate=np.full(seq.odo_t.size, 90.0),
        )
    assert math.isfinite(seq.odo_speed[0])


def test_the_smoother_takes_a_robots_own_increments():
    """The run log holds the increments of whatever model predicted (here a unicycle's), and
    the GTSAM smoother re-solves the run from them: its path stays by the filter's, and its
    chi-square per degree of freedom is that of a consistent problem (0.5-2)."""
    from slam.smoother import problem_from_log, smooth

    seq = simulate_cycab_run(np.random.default_rng(6), "tree_park", CycabParams(n_scans=80))
    lg = run_slam(_as_robot(seq, "unicycle"), features="paper")
    sm = smooth(problem_from_log(lg))
    assert np.max(np.hypot(*(sm.pose[:, :2] - lg.pose[:, :2]).T)) < 0.05
    assert 0.5 < sm.chi2_per_dof < 2.0
