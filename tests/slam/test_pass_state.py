"""The pass offset as a state (`measurement.pass_offset_model = "state"`, `slam.pass_state`):
the filter's hidden copies (`Filter.append_copies`, `Filter.restore_copies`), the exact
constant-per-pass model against its batch posterior, and the runs that carry it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import slam.ekf
import slam.pass_state
import slam.se2
from slam import SlamError, run_slam
from slam import rigid as rigid_ops
from slam.config import ClosureConfig
from slam.ekf import EkfState, Filter, initial_state
from slam.pass_state import PassOffsets, offset_cov
from tests.slam.test_closure import _closer, _revisit, _stand
from tests.slam.test_run import LANDMARKS, TIGHT, drive_sequence, paper_noise, point_features

LASER = np.array([0.5, 0.2, 0.1])
POSE = np.array([1.0, -2.0, 0.4])


def _linear_observe(pose, m, laser):
    """A linear observation z = m - (x, y) (world frame), in `slam.se2.observe`'s form: the
    EKF is then the Kalman filter, whose posterior the batch form gives exactly."""
    m = np.asarray(m, dtype=np.float64).reshape(-1, 2)
    H5 = np.zeros((m.shape[0], 2, 5))
    H5[:, 0, 0] = H5[:, 1, 1] = -1.0
    H5[:, 0, 3] = H5[:, 1, 4] = 1.0
    return m - np.asarray(pose)[:2], H5


def _filter(m0, P0, ids, pose_cov=None) -> Filter:
    """A filter at POSE (covariance pose_cov, default 0: a known vehicle) with landmarks m0
    (n, 2), joint covariance P0 (2 n, 2 n)."""
    m0 = np.asarray(m0, dtype=np.float64).reshape(-1, 2)
    d = 3 + m0.size
    P = np.zeros((d, d))
    P[:3, :3] = 0.0 if pose_cov is None else pose_cov
    P[3:, 3:] = P0
    return Filter(EkfState(np.concatenate([POSE, m0.reshape(-1)]), P, ids))


def _rot_cov(phi: float, sd) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    rot = np.array([[c, -s], [s, c]])
    return rot @ np.diag([sd[0] ** 2, sd[1] ** 2]) @ rot.T


def _spd(rng, scale: float) -> np.ndarray:
    a = rng.standard_normal((2, 2)) * scale
    return a @ a.T + scale**2 * np.eye(2)


def test_the_offset_is_along_and_across_the_line_of_sight():
    sd = (0.05, 0.02)
    pose = np.array([0.0, 0.0, 0.7])
    laser = np.array([0.0, 0.0, 0.0])
    C = offset_cov(pose, np.array([[10.0, 0.0], [0.0, -4.0], [3.0, 3.0]]), laser, sd)
    np.testing.assert_allclose(C[0], np.diag([0.05**2, 0.02**2]), atol=1e-18)
    np.testing.assert_allclose(C[1], np.diag([0.02**2, 0.05**2]), atol=1e-18)
    np.testing.assert_allclose(C[2], _rot_cov(math.pi / 4, sd), atol=1e-18)
    # the laser's mounting moves where the line of sight starts
    C = offset_cov(np.array([0.0, 0.0, math.pi / 2]), [[-1.0, 5.0]], np.array([2.0, 1.0, 0.3]), sd)
    np.testing.assert_allclose(C[0], np.diag([0.02**2, 0.05**2]), atol=1e-18)


def _batch(m0, P0, passes):
    """The posterior of m under z_j = m + b_p + w_j (w_j ~ N(0, R_j), b_p ~ N(0, Sigma_p)
    independent per pass p), prior N(m0, P0) (None: none), fixed vehicle at POSE: each pass's
    stacked sightings have covariance blockdiag(R_j) + 1 1^T (x) Sigma_p."""
    info = np.zeros((2, 2)) if P0 is None else np.linalg.inv(P0)
    vec = np.zeros(2) if P0 is None else info @ m0
    for zs, Rs, Sig in passes:
        n = len(zs)
        C = np.kron(np.ones((n, n)), Sig)
        for j, R in enumerate(Rs):
            C[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] += R
        H = np.kron(np.ones((n, 1)), np.eye(2))
        Ci = np.linalg.inv(C)
        info += H.T @ Ci @ H
        vec += H.T @ Ci @ (np.concatenate(zs) + np.tile(POSE[:2], n))
    cov = np.linalg.inv(info)
    return cov @ vec, cov


@pytest.mark.parametrize("n_passes", [1, 2, 3])
def test_the_state_model_is_the_batch_posterior_of_a_constant_offset_per_pass(
    monkeypatch, n_passes
):
    """One landmark, a known vehicle, passes of 5-12 sightings with white R: after each pass
    has ended the filter's landmark and its covariance are the closed-form posterior of
    z_j = m + b_p + w_j with an independent b_p per pass (to 1e-9)."""
    monkeypatch.setattr(slam.ekf, "observe", _linear_observe)
    rng = np.random.default_rng(11)
    sd = (0.06, 0.03)
    m0, P0 = np.array([12.0, 5.0]), _spd(rng, 0.3)
    f = _filter(m0, P0, [4])
    po = PassOffsets(sd, 2.0, LASER)
    passes, t = [], 0.0
    for _ in range(n_passes):
        zs, Rs = [], []
        for j in range(int(rng.integers(5, 13))):
            po.end_passes(f, t)
            if j == 0:  # the pass's offset is along the line of sight when it begins
                at = POSE[:2] + _rot2(POSE[2]) @ LASER[:2]
                d = f.landmarks_xy[0] - at
                Sig = _rot_cov(math.atan2(d[1], d[0]), sd)
            z = m0 - POSE[:2] + rng.normal(0.0, 0.2, 2)
            R = _spd(rng, 0.02)
            po.begin(f, np.array([4]), t)
            assert f.copy_of.tolist() == [4] and f.dim == 7
            f.update(np.array([0]), z[None], R[None], LASER)
            zs.append(z)
            Rs.append(R)
            t += 0.2
        passes.append((zs, Rs, Sig))
        t += 2.5  # a gap: the pass ends at the next scan
    po.end_passes(f, t)
    assert f.copy_of.size == 0 and f.dim == 5 and po.n_passes == n_passes
    want_m, want_P = _batch(m0, P0, passes)
    np.testing.assert_allclose(f.landmarks_xy[0], want_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(f.P[3:, 3:], want_P, rtol=0, atol=1e-9)


def _linear_inverse(pose, z, laser):
    """`slam.se2.inverse_observe` of `_linear_observe`: m = (x, y) + z."""
    Gx = np.zeros((2, 3))
    Gx[0, 0] = Gx[1, 1] = 1.0
    return np.asarray(pose)[:2] + np.asarray(z), Gx, np.eye(2)


def test_a_landmark_initialised_in_its_first_pass_carries_that_pass_offset(monkeypatch):
    """A landmark initialised from a sighting (no prior), seen again in the same pass, then
    in a second pass: the filter ends at the batch posterior of z_j = m + b_p + w_j in which
    the initialising sighting shares the first pass's offset (to 1e-9)."""
    monkeypatch.setattr(slam.ekf, "observe", _linear_observe)
    monkeypatch.setattr(slam.ekf, "inverse_observe", _linear_inverse)
    rng = np.random.default_rng(4)
    sd = (0.07, 0.02)
    f = Filter(initial_state(POSE, np.zeros((3, 3))))
    po = PassOffsets(sd, 2.0, LASER)
    z0, R0 = np.array([9.0, -4.0]) + rng.normal(0.0, 0.1, 2), _spd(rng, 0.02)
    f.add_landmark(z0, R0, LASER, 6)
    po.joined([6], 0.0)
    passes, t, zs, Rs = [], 0.2, [z0], [R0]
    for n in (7, 4):
        for j in range(n):
            po.end_passes(f, t)
            if j == 0:
                d = f.landmarks_xy[0] - (POSE[:2] + _rot2(POSE[2]) @ LASER[:2])
                Sig = _rot_cov(math.atan2(d[1], d[0]), sd)
            po.begin(f, np.array([6]), t)
            z, R = np.array([9.0, -4.0]) + rng.normal(0.0, 0.1, 2), _spd(rng, 0.02)
            f.update(np.array([0]), z[None], R[None], LASER)
            zs.append(z)
            Rs.append(R)
            t += 0.2
        passes.append((zs, Rs, Sig))
        zs, Rs, t = [], [], t + 3.0
    po.end_all(f)
    assert f.copy_of.size == 0 and not po.fresh and not po.last
    want_m, want_P = _batch(None, None, passes)
    np.testing.assert_allclose(f.landmarks_xy[0], want_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(f.P[3:, 3:], want_P, rtol=0, atol=1e-9)


def _rot2(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _busy_filter(rng) -> Filter:
    """A filter with an uncertain pose and three correlated landmarks (ids 3, 8, 5)."""
    A = rng.standard_normal((9, 9))
    P = A @ A.T * 0.01 + 0.01 * np.eye(9)
    x = np.concatenate([POSE, [10.0, 2.0, -3.0, 7.0, 4.0, -6.0]])
    return Filter(EkfState(x, P, [3, 8, 5]))


def test_restoring_a_copy_is_the_marginal_of_the_augmented_state():
    """After updates with open copies, restoring them gives exactly the augmented state's
    marginal over [pose, landmarks with each copy in its landmark's place]; appending then
    restoring at once gives the filter back."""
    rng = np.random.default_rng(5)
    f = _busy_filter(rng)
    x0, P0 = f.x.copy(), f.P.copy()
    f.append_copies([5, 3], offset_cov(f.pose, f.landmarks_xy[[2, 0]], LASER, (0.05, 0.03)))
    assert f.copy_of.tolist() == [5, 3] and f.dim == 13
    np.testing.assert_array_equal(f.x[9:], x0[[7, 8, 3, 4]])  # the copies' slots
    np.testing.assert_array_equal(f.P[9:11, :9], P0[7:9])  # a copy keeps every covariance
    np.testing.assert_array_equal(f.P[9:11, 9:11], P0[7:9, 7:9])
    assert f.P[7, 7] > P0[7, 7]  # the landmark got the offset
    g = Filter(f.snapshot())
    g.restore_copies()  # (no copies: nothing)
    f2 = Filter(EkfState(x0, P0, [3, 8, 5]))
    f2.append_copies([8], np.eye(2) * 0.01)
    f2.restore_copies([8])
    np.testing.assert_allclose(f2.x, x0, atol=0)
    np.testing.assert_allclose(f2.P, P0, rtol=0, atol=1e-15)
    z, _ = slam.se2.observe(f.pose, f.landmarks_xy, LASER)
    f.update(np.array([0, 2]), z[[0, 2]] + 0.05, np.tile(np.diag([1e-3, 1e-5]), (2, 1, 1)), LASER)
    x, P = f.x.copy(), f.P.copy()
    f.restore_copies([3])  # one, then the other
    assert f.copy_of.tolist() == [5]
    f.restore_copies()
    order = np.array([0, 1, 2, 11, 12, 5, 6, 9, 10])  # landmark 3 <- copy 2, landmark 5 <- copy 1
    np.testing.assert_array_equal(f.x, x[order])
    np.testing.assert_allclose(f.P, P[np.ix_(order, order)], rtol=0, atol=1e-15)
    with pytest.raises(SlamError, match="must each have a copy"):
        f.restore_copies([8])
    with pytest.raises(SlamError, match="without a copy"):
        f.append_copies([8, 8], np.zeros((2, 2, 2)))


def test_copies_are_invisible_to_the_map_and_follow_its_changes():
    """With open copies: landmarks_xy, landmark_ids, n_landmarks, landmark_covs and snapshot
    see the landmarks only; a new landmark goes before the copies, with the same cross
    covariances as when the copy is taken after it; removing a landmark removes its copy."""
    rng = np.random.default_rng(7)
    f, g = _busy_filter(rng), _busy_filter(np.random.default_rng(7))
    extra = np.array([[[0.004, 0.001], [0.001, 0.002]]])
    f.append_copies([8], extra)
    assert f.n_landmarks == 3 and f.landmarks_xy.shape == (3, 2)
    np.testing.assert_array_equal(f.landmarks_xy, g.landmarks_xy)
    np.testing.assert_array_equal(f.landmark_ids, [3, 8, 5])
    assert f.landmark_covs.shape == (3, 2, 2)
    snap = f.snapshot()
    assert snap.x.shape == (9,) and snap.P.shape == (9, 9) and snap.n_landmarks == 3
    np.testing.assert_array_equal(snap.P, f.P[:9, :9])
    z, R = np.array([8.0, 0.3]), np.diag([0.01, 1e-4])
    f.add_landmark(z, R, LASER, 11)
    g.add_landmark(z, R, LASER, 11)
    g.append_copies([8], extra)
    np.testing.assert_array_equal(f.landmark_ids, [3, 8, 5, 11])
    assert f.copy_of.tolist() == [8] and f.dim == 13
    np.testing.assert_allclose(f.x, g.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(f.P, g.P, rtol=0, atol=1e-15)
    f.remove_landmarks([8])
    assert f.copy_of.size == 0 and f.dim == 9
    h = _busy_filter(np.random.default_rng(7))
    h.add_landmark(z, R, LASER, 11)
    h.remove_landmarks([8])
    np.testing.assert_allclose(f.P, h.P, rtol=0, atol=1e-15)
    np.testing.assert_allclose(f.x, h.x, rtol=0, atol=0)


def _busy_with_copies():
    f = _busy_filter(np.random.default_rng(3))
    f.append_copies([3, 8], np.tile(np.eye(2) * 1e-3, (2, 1, 1)))
    f.update(
        np.array([0, 1]),
        np.array([[9.0, 0.2], [8.0, -0.9]]),
        np.tile(np.eye(2) * 1e-3, (2, 1, 1)),
        LASER,
    )
    return f


def test_a_change_of_frame_moves_the_copies_and_the_passes_go_on():
    """Loop closure's change of frame (`move_rigidly`, possibly at every scan after a
    re-registration) keeps the copies, moved with the landmarks: moving then restoring is
    restoring then moving (to 1e-12), and an identity move changes nothing."""
    f, g = _busy_with_copies(), _busy_with_copies()
    rigid_ops.move_rigidly(f, 0.01, np.array([0.2, -0.1]))
    assert f.copy_of.tolist() == [3, 8]
    f.restore_copies()
    g.restore_copies()
    rigid_ops.move_rigidly(g, 0.01, np.array([0.2, -0.1]))
    np.testing.assert_allclose(f.x, g.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f.P, g.P, rtol=0, atol=1e-12)
    f, g = _busy_with_copies(), _busy_with_copies()
    rigid_ops.move_rigidly(f, 0.0, np.zeros(2))
    np.testing.assert_array_equal(f.x, g.x)
    np.testing.assert_array_equal(f.P, g.P)
    assert f.copy_of.tolist() == [3, 8]


def test_loop_closure_restores_the_copies_before_a_merge_or_a_re_registration():
    """A merge and freeing a rigid motion change what the filter knows of the landmarks'
    slots: each first restores every copy, so it acts on the filter without them."""
    for act in (
        lambda s: rigid_ops.merge_landmarks(s, [3], [5]),
        lambda s: rigid_ops.free_rigid_motion(s, [8, 5], s.pose[:2].copy(), np.eye(3) * 1e-4),
    ):
        f, g = _busy_with_copies(), _busy_with_copies()
        g.restore_copies()
        act(f)
        act(g)
        assert f.copy_of.size == 0
        np.testing.assert_array_equal(f.x, g.x)
        np.testing.assert_array_equal(f.P, g.P)


def _run(sd, model="state", closure=False, monkeypatch=None, seen=None, n_scans=40, **kw):
    seq = drive_sequence(1.5, 0.05, n_scans=n_scans)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(3))
    settings = {
        "measurement.pass_offset_sd_m": sd,
        "measurement.pass_offset_model": model,
        "closure.enabled": closure,
        **kw,
    }
    cfg = paper_noise(TIGHT, **settings)
    if monkeypatch is not None:
        update = Filter.update

        def spy(self, pos, z, R, laser):
            seen.append((self.landmark_ids[pos].copy(), R.copy(), self.copy_of.copy()))
            return update(self, pos, z, R, laser)

        monkeypatch.setattr(Filter, "update", spy)
    return run_slam(seq, cfg, features=feats, warm_up=False)


def test_a_zero_offset_with_the_state_model_runs_as_before_to_the_bit(monkeypatch):
    """At (0, 0) the state model computes nothing (no pass bookkeeping, no copy): the run is
    the white one to the bit."""

    def never(*args, **kwargs):
        raise AssertionError("the pass-offset state was computed at (0, 0)")

    white = _run((0.0, 0.0), model="inflation")
    monkeypatch.setattr(slam.pass_state.PassOffsets, "__init__", never)
    monkeypatch.setattr(Filter, "append_copies", never)
    run = _run((0.0, 0.0))
    for name in ("pose", "pose_cov", "landmark_xy", "final_x", "final_P", "scan_nis"):
        np.testing.assert_array_equal(getattr(run, name), getattr(white, name))


def test_the_state_model_updates_with_white_noise_and_ends_every_pass(monkeypatch):
    """Each update uses the measured covariance (the offset is in the state, not in R); the
    landmarks in a pass carry their anchors during it (a landmark seen every scan keeps its
    copy), and after the run no copy is left: the log sees the landmarks only."""
    white = _run((0.0, 0.0))
    seen: list = []
    log = _run((0.03, 0.05), monkeypatch=monkeypatch, seen=seen)
    assert len(seen) > 20
    for ids, R, copies in seen:
        assert set(ids.tolist()) <= set(copies.tolist())  # every updated landmark in a pass
        assert np.all(R[:, 0, 0] == R[0, 0, 0])  # the constant white model, not inflated
    assert R[0, 0, 0] == pytest.approx(0.01**2)
    assert log.final_x.shape == (3 + 2 * log.landmark_id.size,)
    assert log.final_P.shape == (log.final_x.size,) * 2
    assert log.landmark_id.size == white.landmark_id.size == len(LANDMARKS)
    # the offset of a pass is not averaged away: every landmark ends less certain than white
    gain = np.trace(log.landmark_cov, axis1=1, axis2=2) - np.trace(
        white.landmark_cov, axis1=1, axis2=2
    )
    assert np.all(gain > 0)


def test_short_gaps_give_one_pass_per_sighting_with_the_state_model(monkeypatch):
    """A gap shorter than a scan: every update begins a pass (and the one before it ended)."""
    seen: list = []
    _run((0.03, 0.05), monkeypatch=monkeypatch, seen=seen, **{"measurement.pass_gap_s": 0.1})
    for ids, _, copies in seen:
        assert sorted(copies.tolist()) == sorted(ids.tolist())


def test_a_closure_run_with_the_state_model_keeps_its_invariants():
    """A run with loop closure on (its per-scan calls: revisit detection, the duplicate sweep,
    seen-together bookkeeping; the drive does not return, so no match is tried: the test
    below has one) and the state model: the run ends with no copy left, one landmark per
    tree, and the map near the truth."""
    log = _run((0.03, 0.05), closure=True, n_scans=60)
    white = _run((0.0, 0.0), closure=True, n_scans=60)
    assert log.closures is not None
    assert log.final_x.shape == (3 + 2 * log.landmark_id.size,)
    assert np.all(np.isfinite(log.final_P))
    assert np.all(np.linalg.eigvalsh(log.final_P) > -1e-12)
    assert log.landmark_id.size == white.landmark_id.size
    err = np.linalg.norm(log.landmark_xy[:, None] - LANDMARKS[None], axis=2).min(axis=1)
    assert err.max() < 0.5


def test_a_closure_with_passes_open_is_accepted_and_ends_them():
    """The return of test_closure (the stand mapped again 2.5 m and 2 deg off) with the recent
    landmarks in a pass (their anchors open): the closure is accepted with the same pairs,
    its merge restores every anchor first, and the pose comes back to the truth."""
    rng = np.random.default_rng(11)
    pts = _stand(rng, 20)
    f, old_ids, recent_ids = _revisit(pts, pts[:12], (2.0, -1.5, math.radians(2.0)))
    xy = f.landmarks_xy[f.positions_of(recent_ids[:6])]
    f.append_copies(recent_ids[:6], offset_cov(f.pose, xy, LASER, (0.0546, 0.0385)))
    assert f.n_landmarks == 32 and f.dim == 3 + 2 * 38
    closer = _closer(f, ClosureConfig(enabled=True))
    ev = closer.match(f, 50, np.arange(20, 32), np.arange(20))
    assert ev.outcome == "accepted" and ev.best == 12
    assert sorted(ev.merged) == [(old_ids[j], recent_ids[j]) for j in range(12)]
    assert f.copy_of.size == 0 and f.n_landmarks == 20 and f.dim == 43
    np.testing.assert_allclose(f.pose, 0.0, atol=0.05)


def _batch_drift(m0, P0, passes, corr_rad):
    """The posterior of m under z_j + (x_j, y_j) = m + b_j + w_j with b first-order
    Gauss-Markov in the view angle within a pass (Cov(b_j, b_k) = Sigma_p exp(-|path from
    theta_j to theta_k| / L)), independent between passes, prior N(m0, P0); passes hold
    (z_j + pose_j, R_j, theta_j, Sigma_p)."""
    info, vec = np.linalg.inv(P0), np.linalg.inv(P0) @ m0
    for ys, Rs, thetas, Sig in passes:
        n = len(ys)
        steps = np.abs([float(slam.se2.wrap_angle(b - a)) for a, b in zip(thetas, thetas[1:])])
        path = np.concatenate([[0.0], np.cumsum(steps)])
        corr = np.exp(-np.abs(path[:, None] - path[None, :]) / corr_rad)
        C = np.kron(corr, Sig)
        for j, R in enumerate(Rs):
            C[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] += R
        H = np.kron(np.ones((n, 1)), np.eye(2))
        Ci = np.linalg.inv(C)
        info += H.T @ Ci @ H
        vec += H.T @ Ci @ np.concatenate(ys)
    cov = np.linalg.inv(info)
    return cov @ vec, cov


@pytest.mark.parametrize("corr_rad", [0.05, 0.4, 3.0])
def test_a_drifting_offset_is_the_batch_posterior_of_a_gauss_markov_offset(monkeypatch, corr_rad):
    """One landmark, a known vehicle driving past it (the view angle turns by up to a few
    degrees a sighting, back and forth in the second pass), two passes: with a finite
    correlation length the filter's landmark and covariance after the passes are the
    closed-form posterior of an offset first-order Gauss-Markov in the view angle (to 1e-9)."""
    monkeypatch.setattr(slam.ekf, "observe", _linear_observe)
    rng = np.random.default_rng(5)
    sd = (0.06, 0.03)
    m0, P0 = np.array([12.0, 5.0]), _spd(rng, 0.3)
    f = _filter(m0, P0, [4])
    po = PassOffsets(sd, 2.0, LASER, corr_rad)
    passes, t = [], 0.0
    for p in range(2):
        ys, Rs, thetas = [], [], []
        xs = np.linspace(0.0, 9.0, 8) if p == 0 else np.array([9.0, 7.0, 8.0, 3.0, 4.0, 1.0])
        for j, x in enumerate(xs):
            po.end_passes(f, t)
            f.x[:3] = [x, -2.0 + 0.1 * j, 0.3 - 0.05 * j]
            theta = float(slam.pass_state.view_angle(f.x[:3], f.landmarks_xy[:1], LASER)[0])
            if j == 0:
                Sig = _rot_cov(theta, sd)
            z = m0 - f.x[:2] + rng.normal(0.0, 0.2, 2)
            R = _spd(rng, 0.02)
            po.begin(f, np.array([4]), t)
            f.update(np.array([0]), z[None], R[None], LASER)
            ys.append(z + f.x[:2])
            Rs.append(R)
            thetas.append(theta)
            t += 0.2
        passes.append((ys, Rs, thetas, Sig))
        t += 2.5
    po.end_passes(f, t)
    assert f.copy_of.size == 0 and not po.view and not po.cov
    want_m, want_P = _batch_drift(m0, P0, passes, corr_rad)
    np.testing.assert_allclose(f.landmarks_xy[0], want_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(f.P[3:, 3:], want_P, rtol=0, atol=1e-9)


def test_an_infinite_correlation_length_takes_no_drift_step(monkeypatch):
    """corr_rad = inf is the constant offset: `blend_copies` is never called."""
    calls = []
    monkeypatch.setattr(Filter, "blend_copies", lambda *a, **k: calls.append(a))
    f = _filter([12.0, 5.0], 0.1 * np.eye(2), [4])
    po = PassOffsets((0.05, 0.03), 2.0, LASER, math.inf)
    for j in range(4):
        f.x[:3] = [float(j), -2.0, 0.3]
        po.begin(f, np.array([4]), 0.2 * j)
    assert calls == [] and not po.view


def test_blend_copies_refuses_what_it_cannot_do():
    f = _filter([12.0, 5.0], 0.1 * np.eye(2), [4])
    with pytest.raises(SlamError, match="blend_copies: landmark ids \\[4\\] must each have"):
        f.blend_copies([4], [0.5], np.zeros((1, 2, 2)))
    f.append_copies([4], 0.01 * np.eye(2)[None])
    with pytest.raises(SlamError, match="phi must be in \\[0, 1\\]"):
        f.blend_copies([4], [1.5], np.zeros((1, 2, 2)))
