"""slam.smoother with the pass offset as a state (`measurement.pass_offset_model = "state"`): a
pass landmark per pass, tied to its landmark by the offset's covariance, against an independent
solve of the same model (z_j = h(m + b_q) + w_j, b_q ~ N(0, Sigma_b), one b per pass)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from slam import SlamError, se2
from slam.history import RunHistory
from slam.measurement import pass_sizes
from slam.smoother import (
    PASS_FLOOR,
    Problem,
    SmootherOptions,
    pass_numbers,
    pass_offset_cov,
    problem_from_log,
    smooth,
)

LASER = np.array([1.0, 0.3, 0.05])
TREE = np.array([12.0, 5.0])
R_WHITE = np.diag([0.03**2, 0.003**2])  # (range m, bearing rad) of one sighting
S = (0.05, 0.04)  # the pass offset's sd (range, across), m


def pass_poses(n: int, start, heading: float) -> np.ndarray:
    """n rear-axle poses 0.3 m apart from `start` along `heading`."""
    k = np.arange(n)[:, None]
    step = 0.3 * np.array([math.cos(heading), math.sin(heading)])
    return np.hstack([np.asarray(start) + k * step, np.full((n, 1), heading)])


def one_tree(passes, offsets, rng, noise: float = 1.0, sd=S, white: bool = False) -> Problem:
    """One tree seen in passes (list of pose arrays), pass q's sightings all displaced by
    offsets[q] (world, m) plus white noise (`noise` x R_WHITE's sigmas); poses known (tight
    prior and odometry). white: no pass fields (the white model)."""
    pose = np.vstack(passes)
    n = pose.shape[0]
    delta = np.zeros((n, 3))
    for k in range(1, n):
        delta[k] = se2.compose(se2.inverse(pose[k - 1]), pose[k])
    q = np.concatenate([np.full(len(p), i) for i, p in enumerate(passes)])
    z = np.array([se2.observe(x, TREE + offsets[i], LASER)[0][0] for x, i in zip(pose, q)])
    z += noise * rng.standard_normal((n, 2)) * np.sqrt(np.diag(R_WHITE))
    first = np.r_[0, np.cumsum([len(p) for p in passes])[:-1]]
    laser = np.array([se2.compose(pose[k], LASER)[:2] for k in first])
    d = TREE - laser
    fields = {} if white else {
        "meas_pass": q,
        "pass_landmark": np.zeros(len(passes), np.int64),
        "pass_cov": pass_offset_cov(np.arctan2(d[:, 1], d[:, 0]), sd),
    }  # fmt: skip
    gaps = np.where(np.diff(q) > 0, 5.0, 0.2)
    return Problem(
        scan_t=np.r_[0.0, np.cumsum(gaps)],
        prior_pose=pose[0],
        prior_cov=np.zeros((3, 3)),
        odo_delta=delta,
        odo_cov=np.tile(1e-12 * np.eye(3), (n, 1, 1)),
        laser_pose=LASER,
        meas_scan=np.arange(n),
        meas_landmark=np.zeros(n, np.int64),
        meas_z=z,
        meas_R=np.tile(R_WHITE, (n, 1, 1)),
        meas_kind=np.zeros(n, np.int64),
        init_pose=pose,
        landmark_id=np.array([0]),
        init_landmark=TREE[None] + 0.3,
        **fields,
    )


def range_bearing(point, sensor, z) -> tuple[np.ndarray, np.ndarray]:
    """The residual h(point) - z of a range-bearing sighting from the laser at sensor
    [x, y, theta] (world) and its Jacobian (2, 2) with respect to the point."""
    d = point - sensor[:2]
    r2 = d @ d
    e = np.array([math.sqrt(r2), math.atan2(d[1], d[0]) - sensor[2]]) - z
    e[1] = se2.wrap_angle(e[1])
    return e, np.array([d / math.sqrt(r2), [-d[1] / r2, d[0] / r2]])


def oracle(p: Problem, cov_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, list]:
    """The exact model solved by Gauss-Newton in numpy, poses fixed: unknowns m and b_q,
    residuals R^-1/2 (h_j(m + b_q) - z_j) and Sigma_b^-1/2 b_q. Returns (m, its marginal
    covariance, the world-frame covariance C_q of each pass's white sightings at the solution)."""
    n_pass = cov_b.shape[0]
    theta = np.r_[p.init_landmark[0], np.zeros(2 * n_pass)]
    sensor = np.array([se2.compose(x, p.laser_pose) for x in p.init_pose])
    wr = np.linalg.cholesky(np.linalg.inv(R_WHITE)).T
    wb = [np.linalg.cholesky(np.linalg.inv(c)).T for c in cov_b]
    for _ in range(30):
        rows, jac = [], []
        info = [np.zeros((2, 2)) for _ in range(n_pass)]
        for j, q in enumerate(p.meas_pass):
            e, H = range_bearing(theta[:2] + theta[2 + 2 * q : 4 + 2 * q], sensor[j], p.meas_z[j])
            J = np.zeros((2, theta.size))
            J[:, :2] = J[:, 2 + 2 * q : 4 + 2 * q] = H
            rows.append(wr @ e)
            jac.append(wr @ J)
            info[q] += H.T @ np.linalg.solve(R_WHITE, H)
        for q in range(n_pass):
            J = np.zeros((2, theta.size))
            J[:, 2 + 2 * q : 4 + 2 * q] = wb[q]
            rows.append(wb[q] @ theta[2 + 2 * q : 4 + 2 * q])
            jac.append(J)
        A, r = np.vstack(jac), np.concatenate(rows)
        step = np.linalg.solve(A.T @ A, -A.T @ r)
        theta = theta + step
        if np.abs(step).max() < 1e-13:
            break
    cov = np.linalg.inv(A.T @ A)[:2, :2]
    return theta[:2], cov, [np.linalg.inv(i) for i in info]


def close(a, b, rel: float = 1e-6) -> None:
    """Covariances equal to `rel` of their largest entry: the poses are known to 1e-6 (the
    smoother's prior floor and the tests' odometry, 1e-12 m^2), which moves a 10 m sighting's
    point by 1e-5 m against sigmas of 1-10 cm; the oracle holds the poses fixed."""
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * np.abs(b).max())


def solve(p: Problem, **kw):
    return smooth(p, SmootherOptions(relative_error_tol=1e-12, **kw))


def test_one_pass_is_the_posterior_of_sightings_that_share_one_offset():
    """n sightings in one pass: the landmark's estimate and marginal are those of z_j = m + b +
    w_j (the exact model solved independently), to 1e-6; its covariance is the white
    sightings' C plus Sigma_b (b is not averaged away), far from the white model's."""
    rng = np.random.default_rng(1)
    p = one_tree([pass_poses(15, (0.0, 0.0), 0.2)], [np.array([0.04, -0.03])], rng)
    got = solve(p)
    m, cov, (C,) = oracle(p, p.pass_cov)
    np.testing.assert_allclose(got.landmark_xy[0], m, rtol=0, atol=1e-6)
    close(got.landmark_cov[0], cov)
    close(cov, C + p.pass_cov[0])
    assert got.pass_variables == 1 and got.dof == 2 * 15 - 2
    white = solve(dataclasses.replace(p, meas_pass=None, pass_landmark=None, pass_cov=None))
    assert white.pass_variables == 0
    close(white.landmark_cov[0], C, 1e-4)  # the white model's, at its own estimate
    assert np.trace(got.landmark_cov[0]) > 10 * np.trace(white.landmark_cov[0])


def test_two_passes_have_independent_offsets():
    """Two passes from different sides: each carries (C_q + Sigma_b,q)^-1 of information about
    the landmark (independent offsets), and the estimate weighs the two pass means so; the
    exact model solved independently agrees to 1e-6."""
    rng = np.random.default_rng(2)
    passes = [pass_poses(12, (0.0, 0.0), 0.3), pass_poses(20, (20.0, -8.0), 2.0)]
    offsets = [np.array([0.05, 0.02]), np.array([-0.03, 0.06])]
    p = one_tree(passes, offsets, rng)
    got = solve(p)
    m, cov, C = oracle(p, p.pass_cov)
    np.testing.assert_allclose(got.landmark_xy[0], m, rtol=0, atol=1e-6)
    close(got.landmark_cov[0], cov)
    info = sum(np.linalg.inv(c + b) for c, b in zip(C, p.pass_cov))
    close(cov, np.linalg.inv(info))
    # one offset shared by both passes would be another (and wrong) model: it is not this one
    shared = dataclasses.replace(p, meas_pass=np.zeros_like(p.meas_pass), pass_landmark=[0],
                                 pass_cov=p.pass_cov[:1])  # fmt: skip
    assert np.abs(solve(shared).landmark_cov[0] - cov).max() > 1e-4
    assert got.pass_variables == 2 and got.dof == 2 * 32 - 2


def test_isam2_solves_the_same_graph():
    rng = np.random.default_rng(3)
    passes = [pass_poses(12, (0.0, 0.0), 0.3), pass_poses(10, (20.0, -8.0), 2.0)]
    p = one_tree(passes, [np.array([0.05, 0.02]), np.array([-0.03, 0.06])], rng)
    batch, online = solve(p), solve(p, solver="isam2", polish=True)
    assert online.pass_variables == 2
    np.testing.assert_allclose(online.landmark_xy, batch.landmark_xy, atol=1e-6)
    close(online.landmark_cov[0], batch.landmark_cov[0])


def facing(n: int, los_rad: float, dist_m: float = 10.0) -> np.ndarray:
    """n poses driving at the tree along the line of sight `los_rad` (world), the laser on
    that line from `dist_m` to `dist_m` - 0.3 (n - 1) m away: every sighting along los_rad."""
    u = np.array([math.cos(los_rad), math.sin(los_rad)])
    laser = TREE - (dist_m - 0.3 * np.arange(n))[:, None] * u
    c, s = u
    mount = np.array([c * LASER[0] - s * LASER[1], s * LASER[0] + c * LASER[1]])
    return np.hstack([laser - mount, np.full((n, 1), los_rad)])


def test_an_across_offset_moves_the_landmark_only_across_the_line_of_sight():
    """sd = (0, s_a) (the range axis at the floor): the offset's covariance is turned onto the
    line of sight, so the landmark's marginal grows by s_a^2 across it and by nothing along
    it. Two passes seen along perpendicular lines of sight, each with an offset across its
    own: each pass pins the axis it sees along, so the landmark lands near the tree, where the
    white model averages the offsets in."""
    sd, los = (0.0, 0.1), 0.6
    rng = np.random.default_rng(4)
    p = one_tree([facing(8, los)], [np.zeros(2)], rng, noise=0.0, sd=sd)
    white = solve(dataclasses.replace(p, meas_pass=None, pass_landmark=None, pass_cov=None))
    grown = solve(p).landmark_cov[0] - white.landmark_cov[0]
    along = np.array([math.cos(los), math.sin(los)])
    across = np.array([-along[1], along[0]])
    assert along @ grown @ along == pytest.approx(PASS_FLOOR, rel=1e-3)
    assert across @ grown @ across == pytest.approx(sd[1] ** 2 + PASS_FLOOR, rel=1e-6)
    # two passes, lines of sight los and los + 90 deg, offsets of 0.1 m across each
    offsets = [0.1 * across, 0.1 * along]  # across the second line of sight: along the first
    p = one_tree([facing(10, los), facing(10, los + math.pi / 2)], offsets, rng, 0.0, sd)
    got = solve(p).landmark_xy[0]
    white = solve(dataclasses.replace(p, meas_pass=None, pass_landmark=None, pass_cov=None))
    np.testing.assert_allclose(got, oracle(p, p.pass_cov)[0], atol=1e-6)
    off = white.landmark_xy[0] - TREE  # the two offsets averaged in, weighed by the sightings
    assert min(off @ along, off @ across) > 0.03
    assert np.linalg.norm(got - TREE) < 0.1 * np.linalg.norm(off)


# ---- passes of a run's log ----------------------------------------------------------------------


def test_passes_are_the_filters_and_other_sightings_join_the_nearest():
    """The updates' passes are those the filter counts (`RunHistory.pass_index` over the
    updates, in time order); the initialising sighting and tentative ones join the pass of the
    nearest update within the gap, else form their own passes by the gap rule."""
    gap = 2.0
    t = np.array([0.0, 0.2, 0.4, 3.0, 3.2, 0.1, 0.3, 6.0, -0.2, 2.9, 9.0, 9.4])
    lm = np.array([1, 1, 1, 1, 1, 2, 2, 2, 1, 1, 1, 1])
    update = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0], bool)
    got = pass_numbers(t, lm, update, gap)
    h, index = RunHistory(np.zeros(1)), np.empty(t.size, np.int64)
    for i in np.flatnonzero(update)[np.argsort(t[update], kind="stable")]:
        index[i] = h.pass_index([lm[i]], float(t[i]), gap)[0]
    # the filter's passes: a new one where its index restarts at 1
    same = [(0, 1), (1, 2), (3, 4), (5, 6)]
    apart = [(2, 3), (0, 5), (6, 7)]
    assert index[[3, 7]].tolist() == [1, 1] and index[4] == 2
    for a, b in same:
        assert got[a] == got[b]
    for a, b in apart:
        assert got[a] != got[b]
    assert got[8] == got[0]  # 0.2 s before the first update
    assert got[9] == got[3]  # nearer the second pass
    assert got[10] == got[11] and got[10] not in got[:10]  # no update near: their own pass
    assert sorted(set(got.tolist())) == list(range(5))  # 2 + 2 passes of updates, 1 other
    assert np.array_equal(pass_sizes(t[update], lm[update], gap)[0], got[update])


def _state(log, sd=None, model="state"):
    """`log` as if its run had the pass offset `sd` (None: its own) under `model`."""
    cfg = {**log.config, "measurement": dict(log.config["measurement"])}
    cfg["measurement"]["pass_offset_model"] = model
    if sd is not None:
        cfg["measurement"]["pass_offset_sd_m"] = list(sd)
    return dataclasses.replace(log, config=cfg)


@pytest.mark.parametrize("gap", [2.0, 0.1])
def test_a_state_run_gives_each_pass_a_variable_along_its_line_of_sight(gap):
    """A run's log under the "state" model: the measurements keep their white covariance,
    the passes are `pass_numbers`' of the log, each pass's offset is turned onto the line of
    sight from the laser at its first sighting to its landmark (the EKF's), and the smoother
    adds one pass landmark per pass, with the white model's degrees of freedom."""
    from tests.slam.test_pass_offset import _run

    sd = (0.03, 0.05)
    log = _state(_run(sd, gap))
    p, white = problem_from_log(log, "all"), problem_from_log(_state(log, (0, 0)), "all")
    np.testing.assert_array_equal(p.meas_R, white.meas_R)  # no inflation
    assert p.pass_landmark.size == np.unique(p.meas_pass).size
    # each pass: the earliest of its sightings is where its line of sight is taken
    for q in range(p.pass_landmark.size):
        mine = np.flatnonzero(p.meas_pass == q)
        k = p.meas_scan[mine[np.argmin(p.scan_t[p.meas_scan[mine]])]]
        lm = log.landmark_xy[np.flatnonzero(log.landmark_id == p.pass_landmark[q])[0]]
        u = lm - se2.compose(log.pose[k], log.laser_pose)[:2]
        u /= np.linalg.norm(u)
        v = np.array([-u[1], u[0]])
        C = p.pass_cov[q]
        assert u @ C @ u == pytest.approx(sd[0] ** 2 + PASS_FLOOR, rel=1e-9)
        assert v @ C @ v == pytest.approx(sd[1] ** 2 + PASS_FLOOR, rel=1e-9)
        assert abs(u @ C @ v) < 1e-12
    n_lm = log.landmark_id.size
    if gap > 0.2:  # every landmark seen in every scan: one pass each
        assert p.pass_landmark.size == n_lm
    else:  # a pass per scan
        assert p.pass_landmark.size == p.n_measurements
    r, w = smooth(p), smooth(white)
    assert r.pass_variables == p.pass_landmark.size and r.dof == w.dof
    assert np.all(np.linalg.eigvalsh(r.landmark_cov - w.landmark_cov) > 0)  # less certain


def test_a_zero_offset_is_the_white_graph_whatever_the_model():
    """s = (0, 0) under "state": no pass fields, the same problem and the same solve, to the
    bit, as the white model's."""
    from tests.slam.test_pass_offset import _run

    log = _run((0.0, 0.0))
    p, white = problem_from_log(_state(log)), problem_from_log(_state(log, model="inflation"))
    assert p.meas_pass is None and p.pass_variables == 0
    assert p.arrays().keys() == white.arrays().keys()
    for k, a in p.arrays().items():
        np.testing.assert_array_equal(a, white.arrays()[k])
    r, w = smooth(p), smooth(white)
    assert r.pass_variables == 0
    for k in ("pose", "pose_cov", "landmark_xy", "landmark_cov"):
        np.testing.assert_array_equal(getattr(r, k), getattr(w, k))
    assert r.chi2 == w.chi2


def test_the_run_log_carries_the_passes_and_export_graph_refuses_them(tmp_path):
    """What `trunkslam smooth` reads back solves as the in-memory problem (both measurement
    sets), smoother.json counts the pass landmarks, and the g2o export says why it cannot
    write them."""
    from experiments.io.run_log import read_run_log, write_run_log
    from experiments.pipeline.smooth import smoother_summary
    from slam.graph import graph_of_problem
    from tests.slam.test_pass_offset import _run

    log = _state(_run((0.03, 0.05), 0.5))
    path = write_run_log(tmp_path / "run_log.npz", log)
    for which in ("all", "ekf"):
        back, _ = read_run_log(path, which)
        mem = problem_from_log(log, which)
        assert back.pass_variables == mem.pass_variables > 0
        a, b = smooth(back), smooth(mem)
        np.testing.assert_allclose(a.landmark_xy, b.landmark_xy, atol=1e-9)
        assert smoother_summary(back, a)["pass_variables"] == back.pass_variables
    with pytest.raises(SlamError, match="pass offset as a state.*trunkslam smooth"):
        graph_of_problem(back)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"pass_cov": None}, "pass_cov missing"),
        ({"meas_pass": np.array([0, 1])}, r"meas_pass: expected shape \(15\), got \(2,\)"),
        ({"meas_pass": np.full(15, 3)}, r"pass indices must lie in \[0, 1\)"),
        ({"pass_landmark": np.array([7])}, "pass 0 is of landmark 7"),
        ({"pass_cov": -np.eye(2)[None]}, r"pass_cov\[0\]: not a symmetric positive definite"),
        ({"pass_cov": np.full((1, 2, 2), np.nan)}, "pass_cov: contains NaN"),
    ],
)
def test_bad_pass_fields_name_the_field(change, message):
    p = one_tree([pass_poses(15, (0.0, 0.0), 0.2)], [np.zeros(2)], np.random.default_rng(5))
    with pytest.raises(SlamError, match=message):
        dataclasses.replace(p, **change)


def test_a_run_log_with_half_the_passes_is_refused(tmp_path):
    from experiments.errors import DataError
    from experiments.io.run_log import read_run_log, write_run_log
    from tests.slam.test_pass_offset import _run

    path = write_run_log(tmp_path / "run_log.npz", _state(_run((0.03, 0.05))))
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "pass_cov"}
    np.savez(tmp_path / "half.npz", **arrays)
    with pytest.raises(DataError, match="half.npz: Problem: pass_cov missing"):
        read_run_log(tmp_path / "half.npz")


@pytest.mark.slow
def test_trunkslam_smooth_counts_the_pass_variables_and_export_graph_says_why_not(tmp_path):
    """End to end: a run with the "state" model, `trunkslam smooth` (smoother.json counts
    the pass landmarks) and `trunkslam export-graph` (exit 1, the reason, no file)."""
    import json

    from typer.testing import CliRunner

    from experiments.cli import app

    runner = CliRunner()
    run = tmp_path / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "4", "--out", str(run)])
    assert res.exit_code == 0, res.output
    cfg = tmp_path / "state.toml"
    cfg.write_text('[measurement]\nnoise = "constant"\npass_offset_sd_m = [0.03, 0.05]\n'
                   'pass_offset_model = "state"\n')  # fmt: skip
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run), "--config", str(cfg), "--out", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["smooth", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "smoother.json").read_text())
    problem = read_back(out)
    assert summary["pass_variables"] == problem.pass_variables > 0
    res = runner.invoke(app, ["export-graph", str(out), "--out", str(tmp_path / "g.g2o")])
    assert res.exit_code == 1 and "pass offset as a state" in res.output
    assert not (tmp_path / "g.g2o").exists()


def read_back(run_dir):
    from experiments.io.run_log import read_run_log

    return read_run_log(run_dir)[0]
