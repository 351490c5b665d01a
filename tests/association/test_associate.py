"""`association.associate` (IHGR, JCBB, NN) and the K-scan `SlidingWindowAssociator`."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.stats import chi2
from support import two_landmarks_with_cross_term

from association import (
    AssociationError,
    CostModel,
    SlidingWindowAssociator,
    associate,
    associate_detailed,
    solve_set_partition,
    wrap_angle,
)
from association.inputs import (
    _project_cov_kernel,
    cross_cov,
    cross_cov_numpy,
    prepare,
    project_cov_numpy,
)
from association.single import single_scan_problem

METHODS = ("ihgr", "jcbb", "nn")
GATE = 0.99  # association has no default gate; these tests' cases were drawn for this one
R0 = np.diag([0.05**2, math.radians(0.5) ** 2])


def predict(pose, lm):
    """z_hat (n, 2), H (n, 2, 3 + 2n) for state [pose, lm...] (range-bearing)."""
    n = lm.shape[0]
    dx, dy = lm[:, 0] - pose[0], lm[:, 1] - pose[1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    z_hat = np.column_stack([r, wrap_angle(np.arctan2(dy, dx) - pose[2])])
    H = np.zeros((n, 2, 3 + 2 * n))
    H[:, 0, 0], H[:, 0, 1] = -dx / r, -dy / r
    H[:, 1, 0], H[:, 1, 1], H[:, 1, 2] = dy / q, -dx / q, -1.0
    j = np.arange(n)
    H[j, 0, 3 + 2 * j], H[j, 0, 4 + 2 * j] = dx / r, dy / r
    H[j, 1, 3 + 2 * j], H[j, 1, 4 + 2 * j] = -dy / q, dx / q
    return z_hat, H


SIGMA_TH0 = math.radians(0.3)
ORIGIN = np.zeros(3)
ORIGIN.setflags(write=False)


def scene(
    rng,
    lm,
    sigma_xy=0.05,
    sigma_th=SIGMA_TH0,
    sigma_lm=0.03,
    R=R0,
    n_clutter=0,
    pose=ORIGIN,
    p_detect=1.0,
    err_scale=1.0,
):
    """Measurements of the true landmarks `lm` from `pose`, predictions from estimates drawn
    from P; returns (z, R, z_hat, H, P, truth). err_scale < 1 draws the actual errors smaller
    than P and R say (a conservative filter), so that none falls outside the gates."""
    n = lm.shape[0]
    P = np.zeros((3 + 2 * n,) * 2)
    P[:3, :3] = np.diag([sigma_xy**2, sigma_xy**2, sigma_th**2])
    P[3:, 3:] = np.eye(2 * n) * sigma_lm**2
    err = err_scale * rng.multivariate_normal(np.zeros(3 + 2 * n), P)
    z_hat, H = predict(pose + err[:3], lm + err[3:].reshape(n, 2))
    z_true, _ = predict(pose, lm)
    seen = np.flatnonzero(rng.random(n) < p_detect)
    z = z_true[seen] + err_scale * rng.multivariate_normal(np.zeros(2), R, seen.size).reshape(-1, 2)
    zc = np.column_stack([rng.uniform(1, 30, n_clutter), rng.uniform(-np.pi, np.pi, n_clutter)])
    z = np.vstack([z, zc])
    z[:, 1] = wrap_angle(z[:, 1])
    truth = np.concatenate([seen, np.full(n_clutter, -1)])
    return z, R, z_hat, H, P, truth


def grid_landmarks(spacing=8.0, k=4):
    g = (np.arange(k) - (k - 1) / 2) * spacing
    lm = np.array([(x, y) for x in g for y in g])
    return lm[np.hypot(*lm.T) > 2.0]


# ---- known truth -------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_well_separated_landmarks_are_all_correct(method):
    rng = np.random.default_rng(11)
    lm = grid_landmarks()
    for _ in range(20):
        z, R, z_hat, H, P, truth = scene(rng, lm, p_detect=0.8, err_scale=0.3)
        np.testing.assert_array_equal(associate(z, R, z_hat, H, P, method, gate_prob=GATE), truth)


def test_well_separated_landmarks_window_all_correct():
    rng = np.random.default_rng(12)
    lm = grid_landmarks()
    win = SlidingWindowAssociator(K=3, gate_prob=GATE)
    for t in range(6):
        pose = np.array([0.5 * t, 0.0, 0.0])
        z, R, z_hat, H, P, truth = scene(rng, lm, pose=pose, p_detect=0.8, err_scale=0.3)
        a = win.step(z, R, z_hat, H, P, sensor_pose=pose, sensor_pose_cov=np.eye(3) * 1e-6)
        np.testing.assert_array_equal(a, truth)


@pytest.mark.parametrize("method", METHODS)
def test_bearing_wrap_around(method):
    # landmarks straight behind the sensor: predictions at +pi - eps, measurements at -pi + eps
    lm = np.array([[-10.0, 0.05], [-12.0, -0.1], [5.0, 5.0]])
    z_hat, H = predict(np.zeros(3), lm)
    assert z_hat[0, 1] > 3.1 and z_hat[1, 1] < -3.1
    z = z_hat.copy()
    z[0, 1] = -np.pi + 0.004  # true bearing is +pi - 0.005: 0.009 rad away across the cut
    z[1, 1] = np.pi - 0.005  # true bearing is -pi + 0.0083
    P = np.eye(H.shape[2]) * 1e-4
    R = np.diag([0.05**2, 0.01**2])
    np.testing.assert_array_equal(associate(z, R, z_hat, H, P, method, gate_prob=GATE), [0, 1, 2])
    # unwrapped angles (+- 2 pi k) in the inputs mean the same
    z2, zh2 = z.copy(), z_hat.copy()
    z2[:, 1] += 2 * np.pi
    zh2[:, 1] -= 4 * np.pi
    np.testing.assert_array_equal(associate(z2, R, zh2, H, P, method, gate_prob=GATE), [0, 1, 2])


def test_wrap_angle_range():
    a = wrap_angle(np.array([np.pi, -np.pi, 3 * np.pi, 0.0, -3 * np.pi / 2, 7.0]))
    np.testing.assert_allclose(a, [np.pi, np.pi, np.pi, 0.0, np.pi / 2, 7.0 - 2 * np.pi])
    assert np.all((a > -np.pi) & (a <= np.pi))


# ---- order invariance (hypothesis) ---------------------------------------------------------


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    n_lm=st.integers(1, 12),
    n_clutter=st.integers(0, 6),
    sigma_xy=st.sampled_from([0.05, 0.5, 1.5]),
    data=st.data(),
)
def test_result_does_not_depend_on_order(seed, n_lm, n_clutter, sigma_xy, data):
    rng = np.random.default_rng(seed)
    lm = rng.uniform(-15, 15, (n_lm, 2))
    lm = lm[np.hypot(*lm.T) > 1.0]
    if lm.shape[0] == 0:
        return
    z, R, z_hat, H, P, _ = scene(
        rng, lm, sigma_xy=sigma_xy, sigma_th=sigma_xy / 20, n_clutter=n_clutter, p_detect=0.8
    )
    m, n = z.shape[0], z_hat.shape[0]
    pm = np.array(data.draw(st.permutations(range(m)), label="measurement order"), dtype=int)
    pf = np.array(data.draw(st.permutations(range(n)), label="feature order"), dtype=int)
    Rm = np.broadcast_to(R, (m, 2, 2)) * rng.uniform(0.5, 2.0, (m, 1, 1))  # per-measurement R
    for method in METHODS:
        a = associate(z, Rm, z_hat, H, P, method, gate_prob=GATE)
        b = associate(z[pm], Rm[pm], z_hat[pf], H[pf], P, method, gate_prob=GATE)
        # b[k] is the answer for measurement pm[k], in the permuted feature numbering
        expect = np.where(a[pm] >= 0, np.argsort(pf)[np.maximum(a[pm], 0)], -1)
        np.testing.assert_array_equal(b, expect, err_msg=method)
        used = a[a >= 0]
        assert used.size == np.unique(used).size  # each feature at most once


@pytest.mark.slow
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n_clutter=st.integers(0, 8), data=st.data())
def test_window_does_not_depend_on_order(seed, n_clutter, data):
    rng = np.random.default_rng(seed)
    lm = rng.uniform(-12, 12, (10, 2))
    lm = lm[np.hypot(*lm.T) > 2.0]
    new = rng.uniform(-10, 10, (3, 2))  # unmapped landmarks: tracks across the window
    w_a, w_b = (
        SlidingWindowAssociator(K=3, gate_prob=GATE),
        SlidingWindowAssociator(K=3, gate_prob=GATE),
    )
    n = lm.shape[0]
    for t in range(4):
        pose = np.array([0.4 * t, 0.1 * t, 0.02 * t])
        z, R, z_hat, H, P, _ = scene(
            rng, lm, sigma_xy=0.3, sigma_th=0.01, pose=pose, n_clutter=n_clutter, p_detect=0.9
        )
        zn, _ = predict(pose, new)
        z = np.vstack([z, zn + rng.multivariate_normal(np.zeros(2), R0, len(new))])
        m = z.shape[0]
        pm = np.array(data.draw(st.permutations(range(m)), label=f"order {t}"), dtype=int)
        pf = np.array(data.draw(st.permutations(range(n)), label=f"features {t}"), dtype=int)
        kw = {"sensor_pose": pose, "sensor_pose_cov": np.eye(3) * 1e-4}
        a = w_a.step(z, R, z_hat, H, P, **kw)
        b = w_b.step(z[pm], R, z_hat[pf], H[pf], P, feature_ids=pf, **kw)
        expect = np.where(a[pm] >= 0, np.argsort(pf)[np.maximum(a[pm], 0)], -1)
        np.testing.assert_array_equal(b, expect)
        np.testing.assert_array_equal(w_b.last.sightings, w_a.last.sightings[pm])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    n_lm=st.integers(0, 12),
    n_clutter=st.integers(0, 6),
    sigma_xy=st.sampled_from([0.05, 0.5, 1.5]),
)
def test_trusted_path_gives_the_checked_answer(seed, n_lm, n_clutter, sigma_xy):
    """validate=False (the SLAM loop's path) skips the checks and answers as the checked path,
    to the bit: assignment, distances, cost and the method's statistics."""
    rng = np.random.default_rng(seed)
    lm = rng.uniform(-15, 15, (n_lm, 2))
    lm = lm[np.hypot(*lm.T) > 1.0]
    z, R, z_hat, H, P, _ = scene(
        rng, lm, sigma_xy=sigma_xy, sigma_th=sigma_xy / 20, n_clutter=n_clutter, p_detect=0.8
    )
    Rm = np.broadcast_to(R, (z.shape[0], 2, 2)) * rng.uniform(0.5, 2.0, (z.shape[0], 1, 1))
    for method in METHODS:
        for R_arg in (R, Rm):
            a = associate_detailed(z, R_arg, z_hat, H, P, method, gate_prob=0.999)
            b = associate_detailed(z, R_arg, z_hat, H, P, method, gate_prob=0.999, validate=False)
            np.testing.assert_array_equal(b.assignment, a.assignment)
            np.testing.assert_array_equal(b.d2, a.d2)
            stats = ("cost", "gated_pairs", "lp_solves", "fractional", "nodes", "budget_exhausted")
            np.testing.assert_equal([getattr(b, k) for k in stats], [getattr(a, k) for k in stats])


def test_trusted_path_skips_the_checks_only():
    """validate=False does not check the data (a P not PSD in its cross terms passes), but the
    method and its parameters are still checked."""
    z, z_hat, H, P = two_landmarks_with_cross_term(0.5)
    with pytest.raises(AssociationError, match="joint block"):
        associate(z, np.eye(2) * 0.01, z_hat, H, P, gate_prob=GATE)
    assert associate(z, np.eye(2) * 0.01, z_hat, H, P, validate=False, gate_prob=GATE).shape == (2,)
    with pytest.raises(AssociationError, match="not parameters"):
        associate(z, np.eye(2) * 0.01, z_hat, H, P, validate=False, max_nodes=3, gate_prob=GATE)


# ---- exactness and method-specific checks -------------------------------------------------


def test_single_scan_ihgr_equals_milp_on_contended_scenes():
    rng = np.random.default_rng(21)
    model = CostModel()
    for _ in range(40):
        lm = rng.uniform(-12, 12, (int(rng.integers(3, 15)), 2))
        z, R, z_hat, H, P, _ = scene(rng, lm, sigma_xy=0.8, sigma_th=0.04, n_clutter=4)
        det = associate_detailed(z, R, z_hat, H, P, "ihgr", gate_prob=GATE)
        costs, A, e, _, _ = single_scan_problem(prepare(z, R, z_hat, H, P, 0.99), model)
        opt = solve_set_partition(costs, A, e, method="milp")
        assert det.cost == pytest.approx(opt.cost, abs=1e-9)
        assert not det.fractional and det.lp_solves <= 1


def joint_d2(z, R, z_hat, H, P, pairs):
    if not pairs:
        return 0.0
    ii, jj = zip(*pairs)
    nu = z[list(ii)] - z_hat[list(jj)]
    nu[:, 1] = wrap_angle(nu[:, 1])
    Hs = H[list(jj)].reshape(-1, P.shape[0])
    S = Hs @ P @ Hs.T + np.kron(np.eye(len(pairs)), R)
    v = nu.ravel()
    return float(v @ np.linalg.solve(S, v))


def test_jcbb_matches_brute_force():
    rng = np.random.default_rng(31)
    for _ in range(25):
        lm = rng.uniform(-8, 8, (int(rng.integers(2, 5)), 2))
        lm = lm[np.hypot(*lm.T) > 1.0]
        z, R, z_hat, H, P, _ = scene(rng, lm, sigma_xy=0.6, sigma_th=0.05, n_clutter=1)
        m, n = z.shape[0], z_hat.shape[0]
        det = associate_detailed(z, R, z_hat, H, P, "jcbb", gate_prob=GATE)
        gate1 = chi2.ppf(0.99, 2)
        best = (0, 0.0)
        for labels in itertools.product(range(-1, n), repeat=m):
            used = [j for j in labels if j >= 0]
            if len(used) != len(set(used)):
                continue
            pairs = [(i, j) for i, j in enumerate(labels) if j >= 0]
            if any(joint_d2(z, R, z_hat, H, P, [p]) > gate1 for p in pairs):
                continue
            d2 = joint_d2(z, R, z_hat, H, P, pairs)
            if pairs and d2 > chi2.ppf(0.99, 2 * len(pairs)):
                continue
            if len(pairs) > best[0] or (len(pairs) == best[0] and d2 < best[1]):
                best = (len(pairs), d2)
        got = [(i, j) for i, j in enumerate(det.assignment) if j >= 0]
        assert len(got) == best[0]
        assert joint_d2(z, R, z_hat, H, P, got) == pytest.approx(best[1], rel=1e-6, abs=1e-9)
        assert det.cost == pytest.approx(best[1], rel=1e-6, abs=1e-9)


def test_jcbb_node_budget_falls_back_to_a_compatible_hypothesis():
    rng = np.random.default_rng(41)
    lm = rng.uniform(-6, 6, (14, 2))
    lm = lm[np.hypot(*lm.T) > 1.0]
    z, R, z_hat, H, P, _ = scene(rng, lm, sigma_xy=1.0, sigma_th=0.08, n_clutter=5)
    full = associate_detailed(z, R, z_hat, H, P, "jcbb", gate_prob=GATE)
    cut = associate_detailed(z, R, z_hat, H, P, "jcbb", max_nodes=5, gate_prob=GATE)
    assert cut.budget_exhausted and not full.budget_exhausted
    assert cut.nodes <= full.nodes
    pairs = [(i, j) for i, j in enumerate(cut.assignment) if j >= 0]
    assert pairs, "the fallback is the first leaf, never empty when pairings exist"
    assert joint_d2(z, R, z_hat, H, P, pairs) <= chi2.ppf(0.99, 2 * len(pairs))
    assert (full.assignment >= 0).sum() >= len(pairs)


def test_sparse_kernels_match_dense_twins():
    rng = np.random.default_rng(51)
    lm = rng.uniform(-10, 10, (9, 2))
    _, H = predict(np.array([0.3, -0.2, 0.1]), lm)
    A = rng.normal(size=(H.shape[2],) * 2)
    P = A @ A.T
    S, asym, ok = _project_cov_kernel(H, P, 1e-8, 1e-9, 16)
    np.testing.assert_allclose(S, project_cov_numpy(H, P), rtol=1e-10, atol=1e-10)
    assert ok.all() and asym.max() < 1e-12
    feats = np.array([4, 0, 7])
    np.testing.assert_allclose(
        cross_cov(H, P, feats), cross_cov_numpy(H, P, feats), rtol=1e-10, atol=1e-10
    )
    Hd = rng.normal(size=H.shape)  # dense Jacobians
    S, _, _ = _project_cov_kernel(Hd, P, 1e-8, 1e-9, 16)
    np.testing.assert_allclose(S, project_cov_numpy(Hd, P), rtol=1e-9)


def test_empty_inputs():
    _, H = predict(np.zeros(3), np.array([[5.0, 0.0]]))
    P = np.eye(5) * 0.01
    for method in METHODS:
        assert associate(
            np.zeros((0, 2)), R0, np.array([[5.0, 0.0]]), H, P, method, gate_prob=GATE
        ).shape == (0,)
        out = associate(
            np.array([[5.0, 0.0]]),
            R0,
            np.zeros((0, 2)),
            np.zeros((0, 2, 5)),
            P,
            method,
            gate_prob=GATE,
        )
        np.testing.assert_array_equal(out, [-1])


# ---- malformed inputs ----------------------------------------------------------------------


def good_inputs():
    lm = np.array([[5.0, 1.0], [6.0, -2.0]])
    z_hat, H = predict(np.zeros(3), lm)
    P = np.eye(7) * 0.01
    return {"z": z_hat + 0.01, "R": R0, "z_hat": z_hat, "H": H, "P": P}


def _bad(**kw):
    d = good_inputs()
    for k, v in kw.items():
        d[k] = v(d[k]) if callable(v) else v
    return d


def _set(a, idx, v):
    a = np.array(a, dtype=float)
    a[idx] = v
    return a


def _indefinite(P):
    P = P.copy()
    P[0, 1] = P[1, 0] = 0.02  # symmetric, positive diagonal, eigenvalue -0.01
    return P


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"z": lambda z: z[:, :1]}, r"^z: expected shape"),
        ({"z": lambda z: _set(z, (0, 0), np.nan)}, r"^z: contains NaN"),
        ({"z": lambda z: _set(z, (1, 0), -1.0)}, r"^z\[1\]: negative range"),
        ({"z": "abc"}, r"^z: "),
        ({"R": np.eye(3)}, r"^R: expected shape"),
        ({"R": np.zeros((5, 2, 2))}, r"^R: expected shape"),
        ({"R": np.diag([0.01, -1e-4])}, r"^R\[0\]: not positive definite"),
        ({"R": np.array([[0.01, 0.001], [0.0, 0.01]])}, r"^R\[0\]: not symmetric"),
        ({"R": lambda R: _set(R, (0, 0), np.inf)}, r"^R: contains NaN or inf"),
        ({"z_hat": lambda zh: zh[:1]}, r"^H: expected shape"),
        ({"z_hat": lambda zh: _set(zh, (1, 1), np.nan)}, r"^z_hat: contains NaN"),
        ({"H": lambda H: H[:, :, :5]}, r"^H: expected shape"),
        ({"H": lambda H: _set(H, (0, 0, 0), np.nan)}, r"^H: contains NaN"),
        ({"P": np.eye(7)[:, :6]}, r"^P: expected a square"),
        ({"P": lambda P: _set(P, (2, 2), -0.01)}, r"^P: negative variance"),
        ({"P": _indefinite}, r"^P: not positive semi-definite"),
        ({"P": lambda P: _set(P, (0, 1), 0.005)}, r"^P: not symmetric"),
        ({"P": lambda P: _set(P, (4, 4), np.nan)}, r"^P: contains NaN"),
    ],
)
def test_malformed_inputs_raise_naming_the_argument(kw, match):
    d = _bad(**kw)
    for method in METHODS:
        with pytest.raises(ValueError, match=match):
            associate(d["z"], d["R"], d["z_hat"], d["H"], d["P"], method, gate_prob=GATE)


def test_bad_method_gate_and_params():
    d = good_inputs()
    args = (d["z"], d["R"], d["z_hat"], d["H"], d["P"])
    with pytest.raises(ValueError, match="^method"):
        associate(*args, method="hungarian", gate_prob=GATE)
    with pytest.raises(ValueError, match="^gate_prob"):
        associate(*args, gate_prob=1.0)
    with pytest.raises(ValueError, match="max_nodes"):
        associate(*args, method="nn", max_nodes=3, gate_prob=GATE)
    with pytest.raises(ValueError, match="p_detect"):
        associate(*args, p_detect=1.5, gate_prob=GATE)
    with pytest.raises(ValueError, match="max_nodes"):
        associate(*args, method="jcbb", max_nodes=0, gate_prob=GATE)


# ---- sliding window ------------------------------------------------------------------------


def test_window_without_history_or_poses_is_the_single_scan():
    rng = np.random.default_rng(61)
    lm = rng.uniform(-12, 12, (12, 2))
    w1 = SlidingWindowAssociator(K=1, gate_prob=GATE)
    w3 = SlidingWindowAssociator(K=3, gate_prob=GATE)
    for _ in range(5):
        z, R, z_hat, H, P, _ = scene(rng, lm, sigma_xy=0.6, sigma_th=0.03, n_clutter=4)
        single = associate(z, R, z_hat, H, P, "ihgr", gate_prob=GATE)
        np.testing.assert_array_equal(w1.step(z, R, z_hat, H, P, sensor_pose=np.zeros(3)), single)
        np.testing.assert_array_equal(w3.step(z, R, z_hat, H, P), single)  # no sensor_pose


def test_window_tracks_an_unmapped_landmark_and_forgets_it_when_mapped():
    rng = np.random.default_rng(71)
    mapped = grid_landmarks()
    new_lm = np.array([[3.0, 4.5]])  # not in the map
    win = SlidingWindowAssociator(K=3, gate_prob=GATE)
    seen = []
    for t in range(5):
        pose = np.array([0.3 * t, 0.0, 0.0])
        z, R, z_hat, H, P, truth = scene(rng, mapped, pose=pose, err_scale=0.3)
        zn, _ = predict(pose, new_lm)
        zn = zn + 0.3 * rng.multivariate_normal(np.zeros(2), R0, 1)
        z = np.vstack([z, zn])
        a = win.step(z, R, z_hat, H, P, sensor_pose=pose, sensor_pose_cov=np.eye(3) * 1e-6)
        np.testing.assert_array_equal(a, np.append(truth, -1))
        seen.append(int(win.last.sightings[-1]))
        assert (win.last.sightings[:-1] == 0).all()
        if t == 3:
            win.mark_mapped([z.shape[0] - 1])
    assert seen == [1, 2, 3, 3, 1]  # K = 3 caps the count; after mark_mapped it starts again
    assert win.last.tracks == ()


def test_window_rejects_bad_arguments():
    with pytest.raises(ValueError, match="^K"):
        SlidingWindowAssociator(K=0, gate_prob=GATE)
    with pytest.raises(ValueError, match="not options"):
        SlidingWindowAssociator(fix=True, K=3, gate_prob=GATE)
    d = good_inputs()
    win = SlidingWindowAssociator(K=3, gate_prob=GATE)
    args = (d["z"], d["R"], d["z_hat"], d["H"], d["P"])
    with pytest.raises(ValueError, match="^sensor_pose:"):
        win.step(*args, sensor_pose=np.zeros(2))
    with pytest.raises(ValueError, match="^sensor_pose_cov: not positive"):
        win.step(*args, sensor_pose=np.zeros(3), sensor_pose_cov=-np.eye(3))
    with pytest.raises(ValueError, match="^feature_ids"):
        win.step(*args, sensor_pose=np.zeros(3), feature_ids=[3, 3])
    with pytest.raises(ValueError, match="mark_mapped"):
        win.mark_mapped([0])
