"""slam.smoother: the GTSAM smoother of an EKF run (graph, solvers, covariances, errors)."""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest
from support import num_jac

from features.types import Features
from slam import SlamConfig, SlamError, interpolate_poses, run_slam, se2
from slam.config import MeasurementConfig, OdometryNoise, StartConfig, VehicleConfig
from slam.ekf import Filter, initial_state
from slam.measurement import NoiseModel
from slam.smoother import (
    MEAS_INIT,
    MEAS_UPDATE,
    Problem,
    SmootherOptions,
    problem_from_log,
    smooth,
    solve_graph_file,
)
from slam.vehicle import AckermannModel, Odometry, integrate

LASER = np.array([1.55, 0.4, 0.05])  # off the centre line and turned: every term of the offset
CAR = {"model": "ackermann", "wheelbase_m": 1.2, "encoder_offset_m": 0.0}
TREES = np.array(
    [[10.0, 3.0], [14, -4], [20, 6], [26, -2], [5, 8], [0, 10], [-5, 5], [8, -8], [3, -5]]
)


def arc_truth(steer: float, n_scans: int = 60):
    """Scan times and exact rear-axle poses of a drive at 1.5 m/s and constant steer."""
    t = np.arange(n_scans) * 0.2
    odo = Odometry(t, np.full(n_scans, 1.5), np.full(n_scans, steer))
    car = AckermannModel(1.2)
    poses = np.zeros((n_scans, 3))
    poses[0] = [2.0, -1.0, 0.3]
    for k in range(1, n_scans):
        poses[k] = integrate(car, poses[k - 1], odo, t[k - 1], t[k])[0]
    return t, poses, odo


def exact_problem(steer: float, rng, perturb: float) -> tuple[Problem, np.ndarray]:
    """A problem whose odometry and measurements are exact, started `perturb` away."""
    t, truth, _ = arc_truth(steer)
    n = t.size
    delta = np.zeros((n, 3))
    for k in range(1, n):
        delta[k] = se2.compose(se2.inverse(truth[k - 1]), truth[k])
    rows = []
    for k in range(n):
        z, _ = se2.observe(truth[k], TREES, LASER)
        for j in np.flatnonzero((z[:, 0] < 25) & (np.abs(z[:, 1]) < math.pi / 2)):
            rows.append((k, j, z[j]))
    seen = sorted({j for _, j, _ in rows})
    m = len(rows)
    init = truth + perturb * rng.standard_normal(truth.shape) * [1, 1, 0.05]
    return (
        Problem(
            scan_t=t,
            prior_pose=truth[0],
            prior_cov=np.diag([1e-4, 1e-4, 1e-6]),
            odo_delta=delta,
            odo_cov=np.tile(np.diag([1e-4, 1e-4, 1e-5]), (n, 1, 1)),
            laser_pose=LASER,
            meas_scan=np.array([k for k, _, _ in rows]),
            meas_landmark=np.array([j for _, j, _ in rows]),
            meas_z=np.array([z for _, _, z in rows]),
            meas_R=np.tile(np.diag([0.05**2, 0.005**2]), (m, 1, 1)),
            meas_kind=np.zeros(m, np.int64),
            init_pose=init,
            landmark_id=np.array(seen),
            init_landmark=TREES[seen] + perturb * rng.standard_normal((len(seen), 2)),
        ),
        truth,
    )


@pytest.mark.parametrize("steer", [0.0, 0.3], ids=["straight", "circle"])
@pytest.mark.parametrize("solver", ["batch", "isam2"])
def test_noiseless_drive_is_recovered_from_a_bad_start(steer, solver):
    p, truth = exact_problem(steer, np.random.default_rng(3), perturb=0.5)
    r = smooth(p, SmootherOptions(solver=solver))
    err = r.pose - truth
    err[:, 2] = se2.wrap_angle(err[:, 2])
    assert np.abs(err).max() < 1e-6
    np.testing.assert_allclose(r.landmark_xy, TREES[p.landmark_id], atol=1e-6)
    assert r.chi2 < 1e-8
    assert r.dof == 2 * p.n_measurements - 2 * p.landmark_id.size


def point_features(truth_poses, scan_t, rng, sigma=(0.05, 0.005), outlier=None) -> list:
    """Circles at the true trees (laser frame) plus noise; outlier: (scan, dx, dy) moves the
    first circle of that scan."""
    out = []
    for k, p in enumerate(truth_poses):
        z, _ = se2.observe(p, TREES, LASER)
        z = z + rng.standard_normal(z.shape) * sigma
        keep = (np.abs(z[:, 1]) < math.pi / 2) & (z[:, 0] < 30)
        xy = np.stack([z[keep, 0] * np.cos(z[keep, 1]), z[keep, 0] * np.sin(z[keep, 1])], 1)
        if outlier is not None and k == outlier[0]:
            xy[0] += outlier[1:]
        n = len(xy)
        f = Features.empty(float(scan_t[k]), "paper")
        out.append(
            dataclasses.replace(
                f,
                circle_params=np.column_stack([xy, np.full(n, 0.3)]),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    return out


def simulated_run(seed: int = 1, outlier=None, n_scans: int = 60, steer: float = 0.3):
    """A noisy EKF run (noisy odometry and measurements) with its truth."""
    from slam import Sequence

    rng = np.random.default_rng(seed)
    t = np.arange((n_scans - 1) * 4 + 1) * 0.05
    odo = Odometry(t, np.full(t.size, 1.5), np.full(t.size, steer))
    car = AckermannModel(1.2)
    truth = np.zeros((t.size, 3))
    truth[0] = [2.0, -1.0, 0.3]
    for i in range(1, t.size):
        truth[i] = integrate(car, truth[i - 1], odo, t[i - 1], t[i])[0]
    noise = OdometryNoise(0.05, math.radians(1.0))
    seq = Sequence(
        scan_t=t[::4],
        scan_ranges=np.full((n_scans, 361), np.nan),
        scan_angle_min=-math.pi / 2,
        scan_angle_increment=math.pi / 360,
        laser_pose=LASER,
        scan_max_range=80.0,
        odo_t=t,
        odo_speed=odo.speed_mps + noise.speed_sigma_mps * rng.standard_normal(t.size),
        odo_steer=odo.steer_rad + noise.steer_sigma_rad * rng.standard_normal(t.size),
        vehicle=CAR,
        truth_t=t,
        truth_pose=truth,
    )
    scan_truth = interpolate_poses(seq.scan_t, t, truth)
    feats = point_features(scan_truth, seq.scan_t, rng, outlier=outlier)
    cfg = SlamConfig(
        measurement=MeasurementConfig(constant_noise={"paper": NoiseModel(0.05, 0.0, 0.005, 0.0)}),
        vehicle=VehicleConfig(odometry_noise=noise),
        start=StartConfig(initial_pose_sigma=(0.01, 0.01, 0.001)),
    )
    return run_slam(seq, features=feats, config=cfg), scan_truth


def hand_built(p: Problem):
    """The same factors written on the rear-axle poses X_k: the prior and the odometry as
    GTSAM's own factors, each bearing-range measurement from the laser at X_k T as a Python
    factor with the analytic Jacobian of `slam.se2.observe`."""
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    X = lambda k: gtsam.symbol("x", k)  # noqa: E731
    L = lambda i: gtsam.symbol("l", i)  # noqa: E731

    def rot(th):
        c, s = math.cos(th), math.sin(th)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])

    B = rot(-p.prior_pose[2])
    g.add(
        gtsam.PriorFactorPose2(
            X(0),
            gtsam.Pose2(*p.prior_pose),
            gtsam.noiseModel.Gaussian.Covariance(B @ (p.prior_cov + 1e-12 * np.eye(3)) @ B.T),
        )
    )
    for k in range(1, p.n_scans):
        A = rot(-p.odo_delta[k, 2])
        g.add(
            gtsam.BetweenFactorPose2(
                X(k - 1),
                X(k),
                gtsam.Pose2(*p.odo_delta[k]),
                gtsam.noiseModel.Gaussian.Covariance(A @ p.odo_cov[k] @ A.T),
            )
        )
    for k, lid, z, R in zip(p.meas_scan, p.meas_landmark, p.meas_z, p.meas_R):

        def error(this, values, H, z=z):
            x = values.atPose2(this.keys()[0])
            m = values.atPoint2(this.keys()[1])
            pose = np.array([x.x(), x.y(), x.theta()])
            zh, J = se2.observe(pose, m[None], p.laser_pose)
            e = np.array([se2.wrap_angle(zh[0, 1] - z[1]), zh[0, 0] - z[0]])
            if H is not None:  # world-frame derivatives -> GTSAM's tangent (X' = X Pose2(xi))
                J = J[0][[1, 0]]
                H[0] = J[:, :3] @ rot(pose[2])
                H[1] = J[:, 3:]
            return e

        sw = np.array([[0, 1.0], [1.0, 0]])
        noise = gtsam.noiseModel.Gaussian.Covariance(sw @ R @ sw)
        g.add(gtsam.CustomFactor(noise, [X(int(k)), L(int(lid))], error))
    for k in range(p.n_scans):
        v.insert(X(k), gtsam.Pose2(*p.init_pose[k]))
    for lid, xy in zip(p.landmark_id, p.init_landmark):
        v.insert(L(int(lid)), xy)
    r = gtsam.LevenbergMarquardtOptimizer(g, v, gtsam.LevenbergMarquardtParams()).optimize()
    pose = np.array(
        [[q.x(), q.y(), q.theta()] for q in (r.atPose2(X(k)) for k in range(p.n_scans))]
    )
    lm = np.array([r.atPoint2(L(int(i))) for i in p.landmark_id])
    return pose, lm, 2 * g.error(r)


def test_smoother_equals_a_hand_built_graph_on_the_rear_axle_poses():
    log, _ = simulated_run()
    p = problem_from_log(log)
    assert (p.meas_kind == MEAS_INIT).sum() == p.landmark_id.size  # each landmark's first
    assert p.meas_kind.tolist().count(MEAS_UPDATE) == log.obs_scan.size
    r = smooth(p)
    pose, lm, chi2 = hand_built(p)
    # the laser-pose parametrisation differs from this one at second order in the residuals
    np.testing.assert_allclose(r.pose[:, :2], pose[:, :2], atol=2e-6)
    np.testing.assert_allclose(se2.wrap_angle(r.pose[:, 2] - pose[:, 2]), 0, atol=2e-7)
    np.testing.assert_allclose(r.landmark_xy, lm, atol=2e-6)
    assert r.chi2 == pytest.approx(chi2, rel=1e-4)


def test_solvers_reach_the_same_optimum_and_beat_the_ekf():
    log, truth = simulated_run(seed=2)
    p = problem_from_log(log)
    batch = smooth(p)
    isam = smooth(p, SmootherOptions(solver="isam2", isam2_every=3))
    polish = smooth(p, SmootherOptions(solver="isam2", polish=True))
    assert polish.solver == "isam2+polish"
    np.testing.assert_allclose(polish.pose, batch.pose, atol=1e-6)
    np.testing.assert_allclose(isam.pose, batch.pose, atol=1e-3)
    assert batch.chi2 <= isam.chi2 + 1e-9 and batch.chi2 < batch.initial_chi2
    e_s = np.hypot(*(batch.pose[:, :2] - truth[:, :2]).T).mean()
    e_f = np.hypot(*(log.pose[:, :2] - truth[:, :2]).T).mean()
    assert e_s < e_f
    # the last pose's marginal is the filter's covariance (same information, different order)
    np.testing.assert_allclose(batch.pose_cov[-1], log.pose_cov[-1], rtol=0.05, atol=1e-7)
    assert np.all(np.linalg.eigvalsh(batch.landmark_cov) > 0)


def test_bearing_range_factor_from_the_mounting_pose_against_numerical_derivatives():
    """The factor on the laser pose L = X T, seen as a function of the rear-axle pose X and
    the landmark: its error is `se2.observe` minus z, and its Jacobian chained through the
    adjoint of T equals numerical derivatives in X's tangent space."""
    T = gtsam.Pose2(*LASER)
    x = gtsam.Pose2(3.0, -2.0, 0.7)
    m = np.array([12.0, 4.0])
    z = np.array([9.0, 0.2])
    noise = gtsam.noiseModel.Unit.Create(2)
    f = gtsam.BearingRangeFactor2D(1, 2, gtsam.Rot2(z[1]), z[0], noise)

    def err(xi, mm):
        v = gtsam.Values()
        v.insert(1, x.compose(gtsam.Pose2(*xi)).compose(T))
        v.insert(2, mm)
        return f.unwhitenedError(v)

    zh, _ = se2.observe(np.array([x.x(), x.y(), x.theta()]), m[None], LASER)
    np.testing.assert_allclose(
        err(np.zeros(3), m), [se2.wrap_angle(zh[0, 1] - z[1]), zh[0, 0] - z[0]], atol=1e-12
    )
    v = gtsam.Values()
    v.insert(1, x.compose(T))
    v.insert(2, m)
    lin = f.linearize(v)
    A, _ = lin.jacobian()  # whitened = unwhitened with a unit model; columns [L (3), m (2)]
    H_L, H_m = A[:, :3], A[:, 3:]
    H_x = H_L @ T.inverse().AdjointMap()  # L' = X Exp(xi) T = L Exp(Ad(T^-1) xi)
    np.testing.assert_allclose(H_x, num_jac(lambda xi: err(xi, m), np.zeros(3)), atol=1e-6)
    np.testing.assert_allclose(H_m, num_jac(lambda mm: err(np.zeros(3), mm), m), atol=1e-6)


def test_ekf_and_smoother_agree_on_a_linear_gaussian_step():
    """Prior, one landmark initialised at scan 0, one prediction, one update with zero
    innovation: the EKF linearises at the optimum, so its mean and covariance are the
    smoother's to numerical precision."""
    pose0, P0 = np.array([1.0, 2.0, 0.4]), np.diag([0.04, 0.09, 0.01])
    R = np.array([[0.01, 0.001], [0.001, 0.0004]])
    tree = np.array([9.0, 6.0])
    f = Filter(initial_state(pose0, P0))
    z0 = se2.observe(pose0, tree[None], LASER)[0][0]
    f.add_landmark(z0, R, LASER, landmark_id=7)
    delta = np.array([1.2, 0.1, 0.15])
    Qb = np.diag([0.01, 0.004, 0.002])
    p1 = se2.compose(pose0, delta)
    c, s = math.cos(pose0[2]), math.sin(pose0[2])
    Rw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    F = np.array([[1, 0, -(p1[1] - pose0[1])], [0, 1, p1[0] - pose0[0]], [0, 0, 1.0]])
    f.predict(p1, F, Rw @ Qb @ Rw.T)
    z1 = se2.observe(p1, tree[None], LASER)[0][0]
    res = f.update(np.array([0]), z1[None], R[None], LASER)
    assert np.abs(res.innovation).max() < 1e-12
    p = Problem(
        scan_t=np.array([0.0, 1.0]),
        prior_pose=pose0,
        prior_cov=P0,
        odo_delta=np.array([np.zeros(3), delta]),
        odo_cov=np.array([np.zeros((3, 3)), Qb]),
        laser_pose=LASER,
        meas_scan=np.array([0, 1]),
        meas_landmark=np.array([7, 7]),
        meas_z=np.array([z0, z1]),
        meas_R=np.array([R, R]),
        meas_kind=np.array([MEAS_INIT, MEAS_UPDATE]),
        init_pose=np.array([pose0, p1]),
        landmark_id=np.array([7]),
        init_landmark=tree[None],
    )
    r = smooth(p)
    np.testing.assert_allclose(r.pose[1], f.pose, atol=1e-9)
    np.testing.assert_allclose(r.landmark_xy[0], f.landmarks_xy[0], atol=1e-9)
    np.testing.assert_allclose(r.pose_cov[1], f.P[:3, :3], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(r.landmark_cov[0], f.P[3:, 3:], rtol=1e-6, atol=1e-12)
    assert r.chi2 < 1e-12 and r.dof == 2


def test_robust_kernels_resist_a_false_pairing():
    log, _ = simulated_run(seed=4)
    p = problem_from_log(log)
    clean = smooth(p, SmootherOptions(marginals=False)).pose
    # a false pairing: one measurement moved by 3 m in range (a wrong tree)
    i = int(np.flatnonzero(p.meas_kind == MEAS_UPDATE)[40])
    z = p.meas_z.copy()
    z[i, 0] += 3.0
    bad = dataclasses.replace(p, meas_z=z)
    err = {}
    for robust in (None, "huber", "cauchy"):
        r = smooth(bad, SmootherOptions(robust=robust, marginals=False))
        err[robust] = np.hypot(*(r.pose[:, :2] - clean[:, :2]).T).max()  # moved by the outlier
        assert r.robust == robust
    assert err["huber"] < 0.25 * err[None] and err["cauchy"] < 0.25 * err[None]
    with pytest.raises(SlamError, match="robust"):
        SmootherOptions(robust="tukey")


def test_all_measurements_adds_the_tentative_sightings():
    log, _ = simulated_run(seed=5)
    ekf, everything = problem_from_log(log), problem_from_log(log, measurements="all")
    assert everything.n_measurements == ekf.n_measurements + 2 * ekf.landmark_id.size
    assert smooth(everything).dof == smooth(ekf).dof + 4 * ekf.landmark_id.size
    with pytest.raises(SlamError, match="measurements"):
        problem_from_log(log, measurements="some")


def test_bad_problems_name_the_field():
    p, _ = exact_problem(0.0, np.random.default_rng(0), 0.0)
    cases = {
        "meas_z": dict(meas_z=p.meas_z[:-1]),
        "meas_landmark": dict(meas_landmark=p.meas_landmark + 100),
        "meas_R": dict(meas_R=-p.meas_R),
        "odo_cov\\[1\\]": dict(odo_cov=np.zeros_like(p.odo_cov)),
        "init_pose": dict(init_pose=np.full_like(p.init_pose, np.nan)),
        "meas_scan": dict(meas_scan=p.meas_scan + 1000),
        "meas_kind": dict(meas_kind=p.meas_kind + 5),
        "landmark_id": dict(
            landmark_id=np.append(p.landmark_id, 99),
            init_landmark=np.vstack([p.init_landmark, [0, 0]]),
        ),
    }
    for name, change in cases.items():
        with pytest.raises(SlamError, match=name):
            dataclasses.replace(p, **change)
    with pytest.raises(SlamError, match="problem"):
        smooth("not a problem")
    with pytest.raises(SlamError, match="solver"):
        SmootherOptions(solver="gauss-newton")
    with pytest.raises(SlamError, match="isam2_every"):
        SmootherOptions(isam2_every=0)


@pytest.mark.slow
@pytest.mark.data
def test_gtsam_victoria_park_graph_reaches_the_optimum(vp_dir):
    path = vp_dir / "gtsam" / "victoria_park.txt"
    r = solve_graph_file(path)
    # GTSAM's own unit test (testDataset.cpp) counts
    assert (r.n_factors, r.n_values) == (10608, 7120)
    assert (r.n_poses, r.n_landmarks) == (6969, 151)
    assert r.chi2_per_dof <= 1.0
    assert r.initial_chi2 / r.dof > 1000
    with pytest.raises(SlamError, match="no such graph file"):
        solve_graph_file(path.with_name("nope.txt"))


def test_progress_reports_each_stage():
    p, _ = exact_problem(0.3, np.random.default_rng(5), perturb=0.1)
    calls = []
    opts = SmootherOptions(solver="isam2", polish=True, isam2_every=10)
    smooth(p, opts, progress=lambda *a: calls.append(a))
    isam = [c for c in calls if c[0] == "isam2"]
    n = p.n_scans
    assert [c[1] for c in isam] == [*range(10, n + 1, 10), *([n] if n % 10 else [])]
    assert {c[2] for c in isam} == {n}
    assert calls[len(isam) :] == [
        ("optimise", 0, 1),
        ("optimise", 1, 1),
        ("covariances", 0, 1),
        ("covariances", 1, 1),
    ]
    calls.clear()
    smooth(p, SmootherOptions(marginals=False), progress=lambda *a: calls.append(a))
    assert calls == [("optimise", 0, 1), ("optimise", 1, 1)]
