"""slam.smoother with a pass offset that drifts with the view angle (`pass_corr_rad`, the
"state" model with a finite correlation length): an apparent point per sighting, chained by
Gauss-Markov steps, against the batch Gaussian posterior of the same model; its limits (L -> inf:
the per-pass graph; L -> 0: white sightings of variance r + Sigma_b); the step's Jacobians."""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest

from slam import SlamError, se2
from slam.config import MeasurementConfig
from slam.smoother import PASS_FLOOR, SmootherOptions, gm_step_factor, problem_from_log, smooth
from tests.slam.test_smoother_pass_state import (
    R_WHITE,
    TREE,
    S,
    one_tree,
    pass_poses,
    range_bearing,
)


def arc(n: int, turn_rad: float, dist_m: float = 8.0) -> np.ndarray:
    """n poses on a circle of `dist_m` about TREE, facing it at a laser bearing of ~0, the
    view turning by `turn_rad` over the pass (uneven steps)."""
    a = -0.3 + np.cumsum(np.r_[0.0, np.linspace(0.5, 1.5, n - 1)])
    a = a / a[-1] * turn_rad if n > 1 else a
    xy = TREE + dist_m * np.stack([np.cos(a), np.sin(a)], 1)
    return np.hstack([xy, (a + math.pi)[:, None]])


def drifting(n: int, L: float, rng, turn: float = 0.8):
    """One tree seen in one pass of n sightings, with the offset of `one_tree` (constant) as
    data, the model's L given."""
    p = one_tree([arc(n, turn)], [np.array([0.03, -0.02])], rng)
    return dataclasses.replace(p, pass_corr_rad=L)


def solve(p, **kw):
    return smooth(p, SmootherOptions(relative_error_tol=1e-12, **kw))


def gm_cov(p) -> np.ndarray:
    """(2n, 2n) the apparent offsets' covariance in scan order by the recursion the graph
    states: Var_1 = Sigma_b, Var_{j+1} = phi^2 Var_j + (1 - phi^2) Sigma_b + floor I,
    Cov(b_k, b_j) = phi_{j..k} Var_j, with phi = exp(-|dtheta| / L), theta the line of sight's
    world bearing (pose heading + laser yaw + measured bearing)."""
    n, Sb = p.n_measurements, p.pass_cov[0]
    theta = p.init_pose[:, 2] + p.laser_pose[2] + p.meas_z[:, 1]
    phi = np.exp(-np.abs(np.diff(theta)) / p.pass_corr_rad)
    var = [Sb]
    for f in phi:
        var.append(f * f * var[-1] + (1 - f * f) * Sb + PASS_FLOOR * np.eye(2))
    C = np.zeros((2 * n, 2 * n))
    for j in range(n):
        for k in range(j, n):
            c = np.prod(phi[j:k]) * var[j]
            C[2 * k : 2 * k + 2, 2 * j : 2 * j + 2] = c
            C[2 * j : 2 * j + 2, 2 * k : 2 * k + 2] = c.T
    return C


def batch_posterior(p, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The landmark's estimate and covariance of z_j = h_j(m + b_j) + w_j, b ~ N(0, gm_cov),
    poses fixed, by Gauss-Newton on (m, b) in numpy; then the closed form of its marginal,
    (sum_jk H_j^T [S^-1]_jk H_k)^-1 with S = Hb C Hb^T + blockdiag(R) at the solution."""
    n = p.n_measurements
    C = gm_cov(p)
    sensor = np.array([se2.compose(x, p.laser_pose) for x in p.init_pose])
    x = np.r_[at, np.zeros(2 * n)]
    wr = np.linalg.cholesky(np.linalg.inv(R_WHITE)).T
    wb = np.linalg.cholesky(np.linalg.inv(C)).T
    for _ in range(40):
        rows, jac, Hs = [], [], []
        for j in range(n):
            e, H = range_bearing(x[:2] + x[2 + 2 * j : 4 + 2 * j], sensor[j], p.meas_z[j])
            J = np.zeros((2, x.size))
            J[:, :2] = J[:, 2 + 2 * j : 4 + 2 * j] = H
            rows.append(wr @ e)
            jac.append(wr @ J)
            Hs.append(H)
        jac.append(np.hstack([np.zeros((2 * n, 2)), wb]))
        rows.append(wb @ x[2:])
        A, r = np.vstack(jac), np.concatenate(rows)
        step = np.linalg.solve(A.T @ A, -A.T @ r)
        x = x + step
        if np.abs(step).max() < 1e-13:
            break
    cov = np.linalg.inv(A.T @ A)[:2, :2]
    Hb = np.zeros((2 * n, 2 * n))
    for j, H in enumerate(Hs):
        Hb[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = H
    Sm = Hb @ C @ Hb.T + np.kron(np.eye(n), R_WHITE)
    Hs_ = np.vstack(Hs)
    closed = np.linalg.inv(Hs_.T @ np.linalg.solve(Sm, Hs_))
    np.testing.assert_allclose(cov, closed, rtol=1e-8)  # the two forms of one posterior
    return x[:2], cov


def close(a, b, rel: float) -> None:
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * np.abs(b).max())


@pytest.mark.parametrize("L", [0.05, 0.3, 2.0])
def test_one_pass_is_the_batch_posterior_of_the_gauss_markov_offset(L):
    """n = 15 sightings of one pass, view turning 0.8 rad: the landmark's estimate and
    marginal equal the batch Gaussian posterior with the GM covariance matrix, to 1e-6 (poses
    known to 1e-6: the prior floor and the odometry, as in test_smoother_pass_state)."""
    rng = np.random.default_rng(2)
    p = drifting(15, L, rng)
    got = solve(p)
    m, cov = batch_posterior(p, got.landmark_xy[0])
    np.testing.assert_allclose(got.landmark_xy[0], m, rtol=0, atol=1e-6)
    close(got.landmark_cov[0], cov, 1e-6)
    assert got.pass_variables == 15 and got.dof == 2 * 15 - 2


def test_the_marginal_lies_between_the_constant_and_the_white_offset():
    """A shorter L forgets the offset sooner: the landmark's variance falls monotonically from
    the constant offset's (L = inf) towards white sightings of r + Sigma_b."""
    rng = np.random.default_rng(4)
    p = drifting(20, 1.0, rng)
    tr = [np.trace(solve(dataclasses.replace(p, pass_corr_rad=L)).landmark_cov[0])
          for L in (None, 10.0, 1.0, 0.1, 0.01)]  # fmt: skip
    assert all(a > b for a, b in zip(tr, tr[1:]))


def test_a_long_correlation_is_the_per_pass_graph():
    """L = 1e7 rad (phi = 1 - 1e-7 per step): the same estimate and marginal as one pass
    landmark (L = inf), to the chain's floor: each step adds PASS_FLOOR (1e-8 m^2), 14 of them
    1.4e-7 m^2 against a marginal of ~3e-3 m^2 (rel 1e-4)."""
    rng = np.random.default_rng(5)
    p = drifting(15, None, rng)
    const, long = solve(p), solve(dataclasses.replace(p, pass_corr_rad=1e7))
    np.testing.assert_allclose(long.landmark_xy, const.landmark_xy, rtol=0, atol=1e-5)
    close(long.landmark_cov[0], const.landmark_cov[0], 1e-4)
    assert const.pass_variables == 1 and long.pass_variables == 15


def test_a_short_correlation_is_white_with_the_offset_added():
    """L = 1e-9 rad (phi = 0): each sighting independent with r + H Sigma_b H^T (H the range-
    bearing Jacobian at the tree), the white graph with that covariance: equal to 1e-4 (H at
    the tree, not at each apparent point: a 3 cm offset at 8 m moves H by ~0.4%, applied to
    Sigma_b's share of the variance)."""
    rng = np.random.default_rng(6)
    p = drifting(15, 1e-9, rng)
    sensor = np.array([se2.compose(x, p.laser_pose) for x in p.init_pose])
    R = []
    for j in range(p.n_measurements):
        d = TREE - sensor[j, :2]
        r2 = d @ d
        H = np.array([d / math.sqrt(r2), [-d[1] / r2, d[0] / r2]])
        R.append(p.meas_R[j] + H @ (p.pass_cov[0] + PASS_FLOOR * np.eye(2)) @ H.T)
    white = dataclasses.replace(
        p, meas_R=np.array(R), meas_pass=None, pass_landmark=None, pass_cov=None,
        pass_corr_rad=None)  # fmt: skip
    got, want = solve(p), solve(white)
    np.testing.assert_allclose(got.landmark_xy, want.landmark_xy, rtol=0, atol=1e-4)
    close(got.landmark_cov[0], want.landmark_cov[0], 1e-2)
    assert np.trace(got.landmark_cov[0]) < 0.5 * np.trace(
        solve(drifting(15, None, rng)).landmark_cov[0]
    )


def test_two_passes_and_isam2_solve_the_same_graph():
    """Two passes of one tree (a chain each), batch and iSAM2 (+ polish) agree to 1e-6 m."""
    rng = np.random.default_rng(8)
    p = one_tree([pass_poses(10, (0.0, 0.0), 0.2), pass_poses(8, (2.0, -6.0), 0.9)],
                 [np.array([0.04, 0.0]), np.array([-0.03, 0.02])], rng)  # fmt: skip
    p = dataclasses.replace(p, pass_corr_rad=0.2)
    a = solve(p)
    b = solve(p, solver="isam2", polish=True)
    np.testing.assert_allclose(b.landmark_xy, a.landmark_xy, rtol=0, atol=1e-6)
    assert a.pass_variables == 18


def test_the_step_factors_jacobians_against_numerical_derivatives():
    """gm_step_factor linearised at a point: its whitened residual is W (A_{j+1} - phi A_j -
    (1 - phi) L) (W the square-root information) and its Jacobian (-phi W, W, -(1 - phi) W)
    equals central differences of that residual over the linearisation point (h = 1e-6 m; the
    error is linear: exact to rounding, 1e-6 of the entries' size ~30)."""
    phi = 0.37
    cov = np.array([[2e-3, 4e-4], [4e-4, 1e-3]])
    keys = [gtsam.symbol("a", 0), gtsam.symbol("a", 1), gtsam.symbol("l", 0)]
    f = gm_step_factor(keys, phi, cov)
    pts = [np.array([1.0, 2.0]), np.array([1.3, 1.7]), np.array([0.9, 2.2])]

    def residual(points):
        values = gtsam.Values()
        for k, v in zip(keys, points):
            values.insert(k, v)
        A, b = f.linearize(values).jacobian()
        return A, -b

    A, r = residual(pts)
    e = pts[1] - phi * pts[0] - (1 - phi) * pts[2]
    assert r @ r == pytest.approx(e @ np.linalg.solve(cov, e), rel=1e-12)
    want = np.hstack([-phi * np.eye(2), np.eye(2), -(1 - phi) * np.eye(2)])
    np.testing.assert_allclose(A.T @ A, want.T @ np.linalg.solve(cov, want), rtol=1e-10)
    num = np.zeros((2, 6))
    for n in range(3):
        for c in range(2):
            for sign in (1, -1):
                x = [v.copy() for v in pts]
                x[n][c] += sign * 1e-6
                num[:, 2 * n + c] += sign * residual(x)[1] / 2e-6
    np.testing.assert_allclose(A, num, rtol=0, atol=1e-6 * np.abs(A).max())
    assert f.error(_values(keys, pts)) == pytest.approx(0.5 * r @ r)


def _values(keys, pts):
    values = gtsam.Values()
    for k, v in zip(keys, pts):
        values.insert(k, v)
    return values


def test_a_bad_correlation_is_refused_naming_it():
    rng = np.random.default_rng(9)
    p = drifting(5, 1.0, rng)
    for bad in (0.0, -1.0, math.nan, True, "1"):
        with pytest.raises(SlamError, match="pass_corr_rad"):
            dataclasses.replace(p, pass_corr_rad=bad)
    white = dataclasses.replace(p, meas_pass=None, pass_landmark=None, pass_cov=None,
                                pass_corr_rad=None)  # fmt: skip
    with pytest.raises(SlamError, match="pass_corr_rad: given without the pass fields"):
        dataclasses.replace(white, pass_corr_rad=1.0)
    for bad in (0.0, -0.5, math.nan, True, "inf"):
        with pytest.raises(SlamError, match="measurement.pass_offset_corr_rad"):
            MeasurementConfig(pass_offset_corr_rad=bad)
    assert MeasurementConfig().pass_offset_corr_rad == math.inf
    with pytest.raises(SlamError, match="used only with measurement.pass_offset_model = 'state'"):
        MeasurementConfig(pass_offset_corr_rad=0.3)  # the inflation model has no drift
    assert (
        MeasurementConfig(pass_offset_corr_rad=0.3, pass_offset_model="state").pass_offset_corr_rad
        == 0.3
    )


def test_a_run_with_a_finite_correlation_gives_the_problem_its_length():
    """problem_from_log reads `measurement.pass_offset_corr_rad` of a "state" run: finite, the
    Problem drifts with that L; inf (the default), the per-pass problem as before."""
    from tests.slam.test_pass_offset import _run
    from tests.slam.test_smoother_pass_state import _state

    log = _state(_run(S, 2.0))
    const = problem_from_log(log)
    assert const.pass_corr_rad is None and not const.drifts
    m = {**log.config["measurement"], "pass_offset_corr_rad": 0.25}
    p = problem_from_log(dataclasses.replace(log, config={**log.config, "measurement": m}))
    assert p.pass_corr_rad == 0.25 and p.drifts
    assert p.pass_variables == p.n_measurements
    np.testing.assert_array_equal(p.meas_pass, const.meas_pass)


def test_the_run_log_carries_the_correlation_length(tmp_path):
    """A drifting run's log read back (`trunkslam smooth`'s input) has the same L and solves
    as the in-memory problem; a constant run's log has none."""
    from experiments.io.run_log import read_run_log, write_run_log
    from tests.slam.test_pass_offset import _run
    from tests.slam.test_smoother_pass_state import _state

    log = _state(_run((0.03, 0.05), 0.5))
    m = {**log.config["measurement"], "pass_offset_corr_rad": 0.4}
    drift = dataclasses.replace(log, config={**log.config, "measurement": m})
    back, _ = read_run_log(write_run_log(tmp_path / "drift.npz", drift), "all")
    mem = problem_from_log(drift, "all")
    assert back.pass_corr_rad == 0.4 and back.pass_variables == mem.pass_variables
    np.testing.assert_allclose(smooth(back).landmark_xy, smooth(mem).landmark_xy, atol=1e-9)
    const, _ = read_run_log(write_run_log(tmp_path / "const.npz", log), "ekf")
    assert const.pass_corr_rad is None and const.pass_variables < mem.pass_variables
