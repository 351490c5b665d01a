"""slam.vehicle: the Ackermann model, its analytic Jacobians, odometry integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slam.config import OdometryNoise, SteeringCalibration
from slam.vehicle import (
    AckermannModel,
    Odometry,
    arc_step,
    arc_step_jacobians,
    integrate,
    wrap_angle,
)

VP = AckermannModel(2.83, 0.76)  # Victoria Park ute
CYCAB = AckermannModel(1.2, 0.0)


def numerical_jacobians(model, pose, v, a, dt, eps=1e-6):
    F = np.zeros((3, 3))
    G = np.zeros((3, 2))
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        F[:, i] = (
            arc_step_jacobians(model, pose + d, v, a, dt)[0]
            - arc_step_jacobians(model, pose - d, v, a, dt)[0]
        ) / (2 * eps)
    for i, (dv, da) in enumerate(((eps, 0.0), (0.0, eps))):
        G[:, i] = (
            arc_step_jacobians(model, pose, v + dv, a + da, dt)[0]
            - arc_step_jacobians(model, pose, v - dv, a - da, dt)[0]
        ) / (2 * eps)
    return F, G


@pytest.mark.parametrize("model", [VP, CYCAB], ids=["vp", "cycab"])
@pytest.mark.parametrize(
    "v, a, dt",
    [
        (3.0, 0.3, 0.2),
        (1.2, -0.4, 0.05),
        (2.0, 0.0, 0.1),
        (1.0, 1e-6, 0.05),
        (-0.5, 0.2, 0.1),
        (0.0, 0.3, 0.05),
    ],
)
def test_step_jacobians_match_numerical_derivatives(model, v, a, dt):
    pose = np.array([1.0, -2.0, 0.7])
    _, F, G = arc_step_jacobians(model, pose, v, a, dt)
    Fn, Gn = numerical_jacobians(model, pose, v, a, dt)
    np.testing.assert_allclose(F, Fn, atol=1e-8)
    np.testing.assert_allclose(G, Gn, atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-3, 3),
    st.floats(-3, 3),
    st.floats(-math.pi, math.pi),
    st.floats(-2, 8),
    st.floats(-0.6, 0.6),
    st.floats(0.001, 0.5),
)
def test_step_jacobians_property(x, y, th, v, a, dt):
    pose = np.array([x, y, th])
    _, F, G = arc_step_jacobians(VP, pose, v, a, dt)
    Fn, Gn = numerical_jacobians(VP, pose, v, a, dt)
    np.testing.assert_allclose(F, Fn, atol=1e-6)
    np.testing.assert_allclose(G, Gn, atol=1e-6)


def test_encoder_correction_matches_the_dataset_formula():
    # v_c = v_e / (1 - (H / L) tan(alpha)); the left wheel turns slower in a left turn
    a = 0.3
    assert VP.axle_speed(2.0, a) == pytest.approx(2.0 / (1 - 0.76 / 2.83 * math.tan(a)), rel=1e-15)
    assert VP.axle_speed(2.0, a) > 2.0 > VP.axle_speed(2.0, -a)
    assert CYCAB.axle_speed(2.0, a) == 2.0


def test_arc_step_is_an_exact_circle():
    # constant steer: the rear axle centre runs on a circle of radius L / tan(alpha)
    L, a, v = 1.2, 0.35, 1.5
    R = L / math.tan(a)
    p = arc_step(np.array([0.0, 0.0, 0.0]), v, a, 2.0, L)
    phi = v * 2.0 / R
    np.testing.assert_allclose(p, [R * math.sin(phi), R * (1 - math.cos(phi)), phi], atol=1e-12)


def odometry(t, v, a):
    return Odometry(np.asarray(t, float), np.full(len(t), v, float), np.full(len(t), a, float))


def test_straight_drive_with_exact_odometry_reproduces_the_truth():
    odo = odometry(np.arange(0, 10.01, 0.05), 1.7, 0.0)
    pose0 = np.array([3.0, -1.0, 0.4])
    for t1 in (0.013, 2.5, 7.777, 10.0):
        p, _, Q = integrate(CYCAB, pose0, odo, 0.0, t1)
        truth = pose0 + 1.7 * t1 * np.array([math.cos(0.4), math.sin(0.4), 0.0])
        np.testing.assert_allclose(p, truth, atol=1e-12)
        assert np.all(Q == 0)  # no noise model given


def test_circle_with_exact_odometry_reproduces_the_truth_and_encoder_offset():
    # the Victoria Park ute: encoder H left of the centre line, speed read at the wheel
    a, v_c = 0.25, 2.0
    v_e = v_c * (1 - VP.encoder_offset_m / VP.wheelbase_m * math.tan(a))
    odo = odometry(np.arange(0, 20.01, 0.025), v_e, a)
    R = VP.wheelbase_m / math.tan(a)
    for t1 in (1.0, 5.4321, 20.0):
        p, _, _ = integrate(VP, np.zeros(3), odo, 0.0, t1)
        phi = v_c * t1 / R
        truth = [R * math.sin(phi), R * (1 - math.cos(phi)), float(wrap_angle(phi))]
        np.testing.assert_allclose(p, truth, atol=1e-9)


def test_pieces_hold_samples_and_split_at_sample_times():
    odo = Odometry(np.array([1.0, 2.0, 3.0]), np.array([10.0, 20.0, 30.0]), np.zeros(3))
    dt, v, _ = odo.pieces(1.5, 2.5)
    np.testing.assert_allclose(dt, [0.5, 0.5])
    np.testing.assert_allclose(v, [10.0, 20.0])
    dt, v, _ = odo.pieces(0.0, 1.5)  # before the first sample: the first sample holds
    np.testing.assert_allclose(dt, [1.0, 0.5])
    np.testing.assert_allclose(v, [10.0, 10.0])
    dt, v, _ = odo.pieces(2.5, 4.0)  # after the last: the last holds
    np.testing.assert_allclose(dt, [0.5, 1.0])
    np.testing.assert_allclose(v, [20.0, 30.0])
    dt, _, _ = odo.pieces(2.0, 2.0)
    assert dt.size == 0


def test_kernel_matches_numpy_twin_and_noise_propagation():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.05, 300))
    odo = Odometry(t, rng.uniform(-0.5, 4, 300), rng.uniform(-0.5, 0.5, 300))
    noise = OdometryNoise(0.2, 0.03, 0.001, 0.0002)
    for t0, t1 in ((t[3], t[40]), (t[10] + 0.003, t[200] - 0.001), (0.0, t[5])):
        a = integrate(VP, np.array([1.0, 2.0, 3.0]), odo, t0, t1, noise)
        b = integrate(VP, np.array([1.0, 2.0, 3.0]), odo, t0, t1, noise, kernel="numpy")
        for x, y in zip(a, b):
            np.testing.assert_allclose(x, y, atol=1e-12)
        Q = a[2]
        np.testing.assert_allclose(Q, Q.T, atol=0)
        assert np.linalg.eigvalsh(Q).min() > 0


def test_motion_dependent_noise_kernel_matches_twin_and_monte_carlo():
    """The speed sigma grows with |v_e|, the steering sigma with the lateral acceleration
    v_c^2 |tan(alpha)| / L: the kernel equals its numpy twin, a straight drive's along-track
    variance is the hand-computed sum, and a turn's Q matches the spread of noisy readings
    drawn with the same per-sample sigmas."""
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.01, 0.05, 300))
    odo = Odometry(t, rng.uniform(-0.5, 4, 300), rng.uniform(-0.5, 0.5, 300))
    noise = OdometryNoise(0.2, 0.03, 0.001, 0.0002, 0.05, 0.04)
    a = integrate(VP, np.array([1.0, 2.0, 3.0]), odo, t[10] + 0.003, t[200], noise)
    b = integrate(VP, np.array([1.0, 2.0, 3.0]), odo, t[10] + 0.003, t[200], noise, kernel="numpy")
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, atol=1e-12)
    plain = integrate(
        VP,
        np.array([1.0, 2.0, 3.0]),
        odo,
        t[10] + 0.003,
        t[200],
        OdometryNoise(0.2, 0.03, 0.001, 0.0002),
    )[2]
    assert np.all(np.diag(a[2]) > np.diag(plain))
    # straight at 2 m/s for 1 s in 20 steps: var_x = 20 (dt (0.1 + 0.05 * 2))^2, no floor
    straight = OdometryNoise(0.1, 0.0, 0.0, 0.0, speed_sigma_per_speed=0.05)
    _, _, Q = integrate(
        CYCAB, np.zeros(3), odometry(np.arange(0, 1.0, 0.05), 2.0, 0.0), 0, 1, straight
    )
    assert Q[0, 0] == pytest.approx(20 * (0.05 * 0.2) ** 2, rel=1e-12)
    # a turn: alpha = 0.2 at 1.5 m/s on the Cycab (L = 1.2): lateral acceleration 0.38 m/s^2
    v, alpha, dt = 1.5, 0.2, 0.05
    tt = np.arange(0, 1.0, dt)
    turn = OdometryNoise(0.05, math.radians(0.5), 0.0, 0.0, 0.1, 0.1)
    _, _, Q = integrate(CYCAB, np.zeros(3), odometry(tt, v, alpha), 0.0, 1.0, turn)
    sv = 0.05 + 0.1 * v
    sa = math.radians(0.5) + 0.1 * v * v * math.tan(alpha) / CYCAB.wheelbase_m
    ends = []
    for _ in range(4000):
        noisy = Odometry(
            tt, v + sv * rng.standard_normal(tt.size), alpha + sa * rng.standard_normal(tt.size)
        )
        ends.append(integrate(CYCAB, np.zeros(3), noisy, 0.0, 1.0)[0])
    C = np.cov(np.array(ends).T)
    np.testing.assert_allclose(np.diag(C), np.diag(Q), rtol=0.08)


def test_integrated_jacobian_matches_numerical():
    rng = np.random.default_rng(5)
    t = np.arange(0, 2, 0.05)
    odo = Odometry(t, rng.uniform(0.5, 3, t.size), rng.uniform(-0.4, 0.4, t.size))
    pose = np.array([0.5, 0.2, -2.0])
    _, F, _ = integrate(VP, pose, odo, 0.01, 1.73)
    eps = 1e-6
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        num = (
            integrate(VP, pose + d, odo, 0.01, 1.73)[0]
            - integrate(VP, pose - d, odo, 0.01, 1.73)[0]
        ) / (2 * eps)
        np.testing.assert_allclose(F[:, i], num, atol=1e-7)


def test_odometry_noise_covariance_matches_monte_carlo():
    # The propagated Q against the spread of poses integrated from noisy readings.
    rng = np.random.default_rng(11)
    t = np.arange(0, 1.0, 0.05)
    v, a = 1.5, 0.2
    noise = OdometryNoise(0.1, math.radians(2.0), 0.0, 0.0)
    _, _, Q = integrate(CYCAB, np.zeros(3), odometry(t, v, a), 0.0, 1.0, noise)
    ends = []
    for _ in range(4000):
        odo = Odometry(
            t,
            v + 0.1 * rng.standard_normal(t.size),
            a + math.radians(2.0) * rng.standard_normal(t.size),
        )
        ends.append(integrate(CYCAB, np.zeros(3), odo, 0.0, 1.0)[0])
    C = np.cov(np.array(ends).T)
    # sampling error of a variance with 4000 samples is about 2.2%; linearisation adds little
    np.testing.assert_allclose(np.diag(C), np.diag(Q), rtol=0.08)


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="wheelbase_m"):
        AckermannModel(0.0)
    with pytest.raises(ValueError, match="no vehicle model"):
        AckermannModel.from_vehicle(None)
    with pytest.raises(ValueError, match="only 'ackermann'"):
        AckermannModel.from_vehicle({"model": "diff"})
    with pytest.raises(ValueError, match="strictly increasing"):
        Odometry(np.array([0.0, 1.0, 1.0]), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="no odometry samples"):
        Odometry(np.zeros(0), np.zeros(0), np.zeros(0))
    with pytest.raises(ValueError, match="like t_s"):
        Odometry(np.arange(3.0), np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="before t0_s"):
        odometry([0.0, 1.0], 1.0, 0.0).pieces(1.0, 0.5)
    with pytest.raises(ValueError, match="speed_sigma_mps"):
        OdometryNoise(-1.0)
    with pytest.raises(ValueError, match="speed_sigma_per_speed"):
        OdometryNoise(speed_sigma_per_speed=-0.1)
    with pytest.raises(ValueError, match="steer_sigma_per_lateral_mps2"):
        OdometryNoise(steer_sigma_per_lateral_mps2=math.nan)
    with pytest.raises(ValueError, match="SteeringCalibration.gain: must be > 0"):
        SteeringCalibration(gain=0.0)
    with pytest.raises(ValueError, match="SteeringCalibration.cubic_per_rad2: must be a finite"):
        SteeringCalibration(cubic_per_rad2=math.inf)
    with pytest.raises(ValueError, match="SteeringCalibration.offset_rad: must be a finite"):
        SteeringCalibration(offset_rad="0.1")


def test_steering_calibration_maps_readings():
    """alpha = offset + gain r + cubic r^3, by hand; the identity returns its input unchanged."""
    r = np.array([-0.5, 0.0, 0.2])
    cal = SteeringCalibration(offset_rad=0.01, gain=1.1, cubic_per_rad2=0.2)
    np.testing.assert_allclose(cal.apply(r), [0.01 - 0.55 - 0.025, 0.01, 0.01 + 0.22 + 0.0016])
    assert not cal.is_identity
    ident = SteeringCalibration()
    assert ident.is_identity and ident.apply(r) is r
