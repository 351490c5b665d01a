"""slam.ekf: observation model and Jacobians, prediction, Joseph update, landmark initialisation,
and the filter's consistency with known association."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2
from support import num_jac

from slam.config import OdometryNoise
from slam.ekf import EkfState, add_landmark, initial_state, observe_jacobian_full, predict, update
from slam.measurement import polar_cov_from_xy
from slam.se2 import inverse_observe, observe
from slam.vehicle import AckermannModel, Odometry, integrate, wrap_angle

LASER = np.array([1.55, 0.2, 0.05])


def test_polar_covariance_matches_numerical_jacobian():
    c = np.array([[3.0, -4.0]])
    C = np.array([[[0.01, 0.002], [0.002, 0.02]]])
    z, R = polar_cov_from_xy(c, C)
    J = num_jac(lambda p: np.array([np.hypot(*p), math.atan2(p[1], p[0])]), c[0])
    np.testing.assert_allclose(z[0], [5.0, math.atan2(-4, 3)])
    np.testing.assert_allclose(R[0], J @ C[0] @ J.T, atol=1e-12)


def wrapped(z):
    z = np.array(z, float)
    z[..., 1] = wrap_angle(z[..., 1])
    return z


def random_state(rng, n=5, laser=LASER) -> EkfState:
    s = initial_state(np.array([1.0, -2.0, 0.3]), np.diag([0.04, 0.09, 0.003]))
    for i in range(n):
        z = np.array([rng.uniform(3, 20), rng.uniform(-1.4, 1.4)])
        s = add_landmark(s, z, np.diag([0.02**2, 0.003**2]), laser, 10 + i)
    return s


def test_add_landmark_has_the_linearised_cross_covariances():
    rng = np.random.default_rng(0)
    s = random_state(rng, 3)
    z = np.array([8.0, 0.3])
    R = np.diag([0.05**2, 0.01**2])
    s2 = add_landmark(s, z, R, LASER, 99)
    # oracle: the augmented state y = [x, g(x, z)] has Jacobian [[I, 0], [Gx Sel, Gz]]
    _, Gx, Gz = inverse_observe(s.pose, z, LASER)
    d = s.dim
    J = np.zeros((d + 2, d + 2))
    J[:d, :d] = np.eye(d)
    J[d:, :3] = Gx
    J[d:, d:] = Gz
    big = np.zeros((d + 2, d + 2))
    big[:d, :d] = s.P
    big[d:, d:] = R
    np.testing.assert_allclose(s2.P, J @ big @ J.T, atol=1e-14)
    assert s2.landmark_ids.tolist() == [10, 11, 12, 99]
    with pytest.raises(ValueError, match="already in the state"):
        add_landmark(s2, z, R, LASER, 99)


def test_predict_touches_only_the_vehicle_rows_and_columns():
    rng = np.random.default_rng(1)
    s = random_state(rng, 4)
    F = np.array([[1, 0, -0.3], [0, 1, 0.5], [0, 0, 1.0]])
    Q = np.diag([1e-3, 2e-3, 1e-4])
    s2 = predict(s, np.array([1.5, -1.7, 0.35]), F, Q)
    np.testing.assert_array_equal(s2.P[3:, 3:], s.P[3:, 3:])
    np.testing.assert_array_equal(s2.x[3:], s.x[3:])
    np.testing.assert_allclose(s2.P[:3, :3], F @ s.P[:3, :3] @ F.T + Q)
    np.testing.assert_allclose(s2.P[:3, 3:], F @ s.P[:3, 3:])
    np.testing.assert_allclose(s2.P[3:, :3], s2.P[:3, 3:].T)
    assert not s.P.flags.writeable and np.array_equal(s.x[:3], [1.0, -2.0, 0.3])  # unchanged


def test_update_equals_the_dense_joseph_form():
    rng = np.random.default_rng(2)
    s = random_state(rng, 6)
    idx = np.array([4, 0, 2])
    z = observe(s.pose, s.landmarks_xy[idx], LASER)[0] + rng.normal(size=(3, 2)) * [0.05, 0.01]
    R = np.array([np.diag([0.03**2, 0.004**2])] * 3)
    s2, res = update(s, idx, z, R, LASER)
    zh, H = observe_jacobian_full(s, idx, LASER)
    H = H.reshape(6, -1)
    Rb = np.zeros((6, 6))
    for j in range(3):
        Rb[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = R[j]
    S = H @ s.P @ H.T + Rb
    K = np.linalg.solve(S, H @ s.P).T
    nu = wrapped(z - zh).reshape(-1)
    A = np.eye(s.dim) - K @ H
    np.testing.assert_allclose(s2.P, A @ s.P @ A.T + K @ Rb @ K.T, atol=1e-13)
    np.testing.assert_allclose(s2.x[3:], s.x[3:] + (K @ nu)[3:], atol=1e-13)
    np.testing.assert_allclose(res.S, S, atol=1e-13)
    assert res.nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)))
    with pytest.raises(ValueError, match="twice"):
        update(s, np.array([1, 1]), z[:2], R[:2], LASER)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 6), st.floats(1e-4, 1.0))
def test_covariance_stays_symmetric_psd(seed, k, scale):
    rng = np.random.default_rng(seed)
    s = random_state(rng, 6)
    for _ in range(5):
        F = np.eye(3) + rng.normal(size=(3, 3)) * 0.1
        s = predict(s, s.pose + rng.normal(size=3) * 0.1, F, np.diag([1e-3, 1e-3, 1e-4]) * scale)
        idx = rng.choice(s.n_landmarks, size=min(k, s.n_landmarks), replace=False)
        z = observe(s.pose, s.landmarks_xy[idx], LASER)[0] + rng.normal(size=(idx.size, 2)) * 0.01
        R = np.array([np.diag([scale * 1e-4 + 1e-8, scale * 1e-6 + 1e-10])] * idx.size)
        s, _ = update(s, idx, z, R, LASER)
        np.testing.assert_array_equal(s.P, s.P.T)
        assert np.linalg.eigvalsh(s.P).min() > -1e-12 * np.abs(s.P).max()


def test_state_validation():
    with pytest.raises(ValueError, match="EkfState.x"):
        EkfState(np.zeros(4), np.zeros((4, 4)), np.zeros(0))
    with pytest.raises(ValueError, match="EkfState.P"):
        EkfState(np.zeros(5), np.zeros((3, 3)), np.zeros(1))
    with pytest.raises(ValueError, match="landmark_ids"):
        EkfState(np.zeros(5), np.zeros((5, 5)), np.zeros(2))


# ---- consistency with known association ---------------------------------------------------------


def _known_association_run(seed: int, n_scans: int = 100):
    """A Cycab-like car on a circle among 12 point landmarks; ideal range-bearing measurements
    (Gaussian, the filter's R), associations known. Returns NEES per scan (1..n-1)."""
    rng = np.random.default_rng(seed)
    car = AckermannModel(1.2)
    noise = OdometryNoise(0.1, math.radians(2.0), 0.0, 0.0)
    dt, every = 0.05, 4
    t = np.arange((n_scans - 1) * every + 1) * dt
    v_true, a_true = 1.2, 0.12
    # truth by exact arcs, readings with noise
    truth = np.zeros((t.size, 3))
    for i in range(1, t.size):
        truth[i] = integrate(
            car, truth[i - 1], Odometry(t[:2], np.full(2, v_true), np.full(2, a_true)), 0.0, dt
        )[0]
    odo = Odometry(
        t,
        v_true + 0.1 * rng.standard_normal(t.size),
        a_true + math.radians(2.0) * rng.standard_normal(t.size),
    )
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    R_turn = 1.2 / math.tan(a_true)
    rad = np.where(np.arange(12) % 2, R_turn - 4.0, R_turn + 4.0)
    lm = np.stack([rad * np.sin(ang), R_turn - rad * np.cos(ang)], axis=1)
    sr, sb = 0.02, 0.002
    R = np.diag([sr**2, sb**2])
    s = initial_state(truth[0].copy())
    nees = []
    for k in range(n_scans):
        i = k * every
        if k:
            p1, F, Q = integrate(car, s.pose, odo, t[i - every], t[i], noise)
            s = predict(s, p1, F, Q)
        zt, _ = observe(truth[i], lm, LASER)
        seen = np.flatnonzero((zt[:, 0] < 15.0) & (np.abs(zt[:, 1]) < np.pi / 2))
        z = zt[seen] + rng.standard_normal((seen.size, 2)) * [sr, sb]
        known = np.isin(seen, s.landmark_ids)
        if known.any():
            pos = np.array([s.index_of(j) for j in seen[known]])
            s, _ = update(s, pos, z[known], np.array([R] * pos.size), LASER)
        for j, zj in zip(seen[~known], z[~known]):
            s = add_landmark(s, zj, R, LASER, int(j))
        if k:
            e = s.pose - truth[i]
            e[2] = wrap_angle(e[2])
            nees.append(float(e @ np.linalg.solve(s.pose_cov, e)))
    return np.array(nees)


@pytest.mark.slow
def test_nees_with_known_association_lies_inside_its_bounds():
    """50 seeded Monte Carlo runs of 100 scans: the average pose NEES lies inside its 95%
    chi-square bounds at >= 90% of the scans (95% expected for a consistent filter), and its
    overall mean is within 10% of the 3 degrees of freedom."""
    runs = 50
    nees = np.array([_known_association_run(seed) for seed in range(runs)])
    avg = nees.mean(axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    inside = np.mean((avg >= lo) & (avg <= hi))
    assert inside >= 0.9, f"only {inside:.2f} of scans inside [{lo:.2f}, {hi:.2f}]"
    assert 2.7 <= avg.mean() <= 3.3


def test_symmetric_rank_downdate_in_place_equals_the_plain_difference():
    """Joseph's P - W W^T: BLAS on one triangle plus the mirror, in place, equals the numpy
    difference and is symmetric to the last bit; a non-contiguous P takes the numpy route."""
    from slam.ekf import _subtract_gram

    rng = np.random.default_rng(3)
    for d in (1, 5, 70, 300):
        M = rng.standard_normal((d, d))
        P = M @ M.T
        W = rng.standard_normal((d, 6))
        expected = P - W @ W.T
        got = P.copy()
        ref = got
        _subtract_gram(got, W)
        assert got is ref
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-10)
        np.testing.assert_array_equal(got, got.T)
        strided = np.asfortranarray(P)
        _subtract_gram(strided, W)
        np.testing.assert_allclose(strided, expected, rtol=1e-12, atol=1e-10)


def test_update_equals_the_expanded_joseph_form_it_replaced():
    """The rank-q downdate P - W W^T (W = P H^T L^-T) gives the estimate of the expanded Joseph
    form P + K A^T + A K^T (A = K S / 2 - P H^T, K from np.linalg.solve) up to rounding."""
    rng = np.random.default_rng(5)
    s = random_state(rng, 40)
    for _ in range(20):
        idx = rng.choice(s.n_landmarks, size=int(rng.integers(1, 8)), replace=False)
        z = observe(s.pose, s.landmarks_xy[idx], LASER)[0] + rng.normal(size=(idx.size, 2)) * 0.02
        R = np.array([np.diag([0.03**2, 0.004**2])] * idx.size)
        s2, res = update(s, idx, z, R, LASER)
        zh, H = observe_jacobian_full(s, idx, LASER)
        H = H.reshape(2 * idx.size, -1)
        S = H @ s.P @ H.T + np.kron(np.eye(idx.size), R[0])
        PHt = s.P @ H.T
        K = np.linalg.solve(S, PHt.T).T
        A = 0.5 * (K @ S) - PHt
        P_old = s.P + K @ A.T + A @ K.T
        x_old = s.x + K @ wrapped(z - zh).reshape(-1)
        np.testing.assert_allclose(s2.P, P_old, rtol=0, atol=1e-12 * np.abs(P_old).max())
        np.testing.assert_allclose(s2.x[3:], x_old[3:], rtol=0, atol=1e-11)
        assert res.logdet == pytest.approx(np.linalg.slogdet(S)[1], rel=1e-12)
        s = s2


def test_filter_reads_blocks_from_the_lower_triangle_while_the_upper_lags():
    """After an update only P's lower triangle is current; `cov`, `pose_cov`, `landmark_covs`
    and the next steps read from it, and `P` is mirrored when read: the same numbers as the
    immutable path (which mirrors every time)."""
    from slam.ekf import Filter, landmark_columns

    rng = np.random.default_rng(8)
    s = random_state(rng, 8)
    f = Filter(s)
    for step in range(6):
        F = np.eye(3) + rng.normal(size=(3, 3)) * 0.05
        pose1, Q = s.pose + rng.normal(size=3) * 0.1, np.diag([1e-3, 1e-3, 1e-4])
        s = predict(s, pose1, F, Q)
        f.predict(pose1, F, Q)
        idx = rng.choice(s.n_landmarks, size=3, replace=False)
        z = observe(s.pose, s.landmarks_xy[idx], LASER)[0] + rng.normal(size=(3, 2)) * 0.01
        R = np.array([np.diag([1e-4, 1e-6])] * 3)
        s, _ = update(s, idx, z, R, LASER)
        f.update(idx, z, R, LASER)
        if step == 2:
            zn = np.array([7.0, 0.2])
            s = add_landmark(s, zn, R[0], LASER, 99)
            f.add_landmark(zn, R[0], LASER, 99)
        assert not f._mirrored
        cols = landmark_columns([0, 2, 5])
        np.testing.assert_array_equal(f.cov(cols), s.P[cols[:, :, None], cols[:, None, :]])
        sub = np.array([0, 1, 2, 9, 10, 5, 6])
        np.testing.assert_array_equal(f.cov(sub), s.P[np.ix_(sub, sub)])
        np.testing.assert_array_equal(f.pose_cov, s.pose_cov)
        np.testing.assert_array_equal(f.landmark_covs, s.landmark_covs)
        rows = np.array([4, 0, 9, 10, 2])
        np.testing.assert_array_equal(f.rows(rows), s.P[rows])
        np.testing.assert_array_equal(s.rows(rows), s.P[rows])
        assert not f._mirrored  # `rows` read the lower triangle, P was not mirrored for it
    np.testing.assert_array_equal(f.x, s.x)
    np.testing.assert_array_equal(f.P, s.P)  # mirrored on reading
    assert f._mirrored
    np.testing.assert_array_equal(f.rows(rows), s.P[rows])  # mirrored: P's own rows
    np.testing.assert_array_equal(f.P, f.P.T)
    assert f.cov(np.zeros((0, 5), np.int64)).shape == (0, 5, 5)


def test_removing_a_landmark_keeps_the_marginal_of_the_rest():
    from slam.ekf import Filter
    from slam.errors import SlamError

    rng = np.random.default_rng(3)
    d = 3 + 2 * 3
    A = rng.standard_normal((d, d))
    x = rng.standard_normal(d)
    st0 = EkfState(x, A @ A.T + d * np.eye(d), np.array([4, 7, 9]))
    f = Filter(st0)
    f.remove_landmarks([7])
    keep = np.r_[0, 1, 2, 3, 4, 7, 8]
    np.testing.assert_array_equal(f.x, x[keep])
    np.testing.assert_array_equal(f.P, st0.P[np.ix_(keep, keep)])
    np.testing.assert_array_equal(f.landmark_ids, [4, 9])
    assert f.P.flags.c_contiguous and f.first_xy.shape == (2, 2)
    with pytest.raises(SlamError, match=r"landmark ids \[7\] are not in the state"):
        f.remove_landmarks([7])
