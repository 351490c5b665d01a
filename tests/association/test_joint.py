"""association.joint_check: the joint test of one scan's pairings and its greedy pruning."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from association.errors import AssociationError
from association.joint import joint_check

GATE_PROB = 0.999


def shared_pose(k: int, pose_var: float = 0.09, r_var: float = 1e-4) -> np.ndarray:
    """(2k, 2k) joint covariance of k pairings that share a translation of the pose (variance
    pose_var per axis) with white measurement noise r_var: pose_var 1 1^T (x) I + r_var I."""
    return np.kron(np.full((k, k), pose_var), np.eye(2)) + r_var * np.eye(2 * k)


def d2(nu: np.ndarray, S: np.ndarray) -> float:
    v = nu.reshape(-1)
    return float(v @ np.linalg.solve(S, v))


def test_each_pairing_passes_its_gate_but_the_outlier_is_dropped():
    """Two pairings agree on a 0.6 m shift of the pose, the third on -0.6 m: each alone is at
    d2 = 4 (gate 13.8), together they are incompatible; the third is dropped, and the two kept
    pass the joint gate of 4 dof."""
    S = shared_pose(3)
    nu = np.array([[0.6, 0.0], [0.6, 0.0], [-0.6, 0.0]])
    for j in range(3):
        assert d2(nu[j], S[2 * j : 2 * j + 2, 2 * j : 2 * j + 2]) < chi2.ppf(GATE_PROB, 2)
    assert d2(nu, S) > chi2.ppf(GATE_PROB, 6)
    c = joint_check(nu, S, GATE_PROB)
    assert c.keep.tolist() == [True, True, False]
    assert c.dropped == (2,)
    assert c.d2_before == pytest.approx(d2(nu, S), rel=1e-9)
    assert c.d2_after == pytest.approx(d2(nu[:2], S[:4, :4]), rel=1e-9)
    assert c.d2_after <= chi2.ppf(GATE_PROB, 4)


def test_a_consistent_scan_is_untouched():
    S = shared_pose(4)
    nu = np.tile([0.6, -0.3], (4, 1)) + 0.005 * np.arange(8).reshape(4, 2)
    c = joint_check(nu, S, GATE_PROB)
    assert c.keep.all() and c.dropped == ()
    assert c.d2_before == c.d2_after == pytest.approx(d2(nu, S), rel=1e-9)
    assert c.d2_before <= chi2.ppf(GATE_PROB, 8)


def without(nu: np.ndarray, S: np.ndarray, rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The innovations and joint covariance of the pairings `rows` only."""
    idx = (2 * np.array(rows, int)[:, None] + np.arange(2)).reshape(-1)
    return nu[rows], S[np.ix_(idx, idx)]


def test_each_pairing_dropped_is_the_one_whose_removal_lowers_the_joint_distance_most():
    """Against brute force, at every drop of every draw: the removal chosen leaves the smallest
    D2 of the pairings still kept (the Schur-complement fall used by joint_check is the direct
    recomputation's); the kept set failed the joint gate before each drop and passes it after
    the last. The innovations are drawn at 3 sd against an S whose diagonal is about 1.5, so
    every draw fails the joint gate at first and is checked."""
    rng = np.random.default_rng(5)
    k, draws, steps = 5, 20, 0
    for _ in range(draws):
        A = rng.standard_normal((2 * k, 2 * k))
        S = A @ A.T / (2 * k) + shared_pose(k, 0.5, 0.01)
        nu = rng.standard_normal((k, 2)) * 3.0
        c = joint_check(nu, S, GATE_PROB)
        assert c.d2_before > chi2.ppf(GATE_PROB, 2 * k) and c.dropped
        kept = list(range(k))
        for j in c.dropped:
            assert d2(*without(nu, S, kept)) > chi2.ppf(GATE_PROB, 2 * len(kept))
            left = [d2(*without(nu, S, [r for r in kept if r != i])) for i in kept]
            assert j == kept[int(np.argmin(left))]
            kept.remove(j)
            steps += 1
        assert c.keep.tolist() == [i in kept for i in range(k)]
        assert c.d2_after == pytest.approx(d2(*without(nu, S, kept)), rel=1e-9)
        assert c.d2_after <= chi2.ppf(GATE_PROB, 2 * len(kept))
    assert steps >= draws  # every draw dropped at least one pairing, each drop was checked


def test_a_single_pairing_outside_its_gate_is_dropped_and_nothing_is_left():
    S = shared_pose(1)
    c = joint_check(np.array([[1.5, 0.0]]), S, GATE_PROB)  # d2 25 > 13.8
    assert c.keep.tolist() == [False] and c.dropped == (0,) and c.d2_after == 0.0


def test_bad_inputs_are_named():
    with pytest.raises(AssociationError, match="nu must be"):
        joint_check(np.zeros((2, 2)), np.eye(2), GATE_PROB)
    with pytest.raises(AssociationError, match="gate_prob"):
        joint_check(np.zeros((1, 2)), np.eye(2), 1.0)
    with pytest.raises(AssociationError, match="finite"):
        joint_check(np.array([[np.nan, 0.0]]), np.eye(2), GATE_PROB)
    with pytest.raises(AssociationError, match="finite"):
        joint_check(np.zeros((1, 2)), np.diag([1.0, np.inf]), GATE_PROB)
    with pytest.raises(AssociationError, match="positive definite"):
        joint_check(np.ones((1, 2)), -np.eye(2), GATE_PROB)
