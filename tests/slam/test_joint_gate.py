"""`[association] joint_check` (slam.joint_gate): the joint test of a scan's pairings in the
run loop."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slam import SlamConfig, SlamError, run_slam
from slam.config import AssociationConfig
from slam.ekf import Filter, initial_state
from slam.joint_gate import JointGate, NoJointGate, make_joint_gate
from slam.map_managers import ScanAssociation
from slam.sources import Measurements

from .test_run import LANDMARKS, TIGHT, drive_sequence, paper_noise, point_features

LASER = np.zeros(3)
LM = np.array([[10.0, 0.0], [0.0, 10.0], [0.0, -10.0]])
R = np.diag([1e-4, 1e-6])


def measured(xy: np.ndarray, pose_xy) -> np.ndarray:
    """(range, bearing) of landmarks xy (k, 2) from a laser at pose_xy, heading 0."""
    d = xy - np.asarray(pose_xy)
    return np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])], axis=1)


def filter_with_uncertain_pose() -> Filter:
    """Three landmarks mapped from the origin, then a step of the pose with 0.3 m sd per axis:
    their innovations share that uncertainty."""
    f = Filter(initial_state(np.zeros(3), np.diag([1e-6, 1e-6, 1e-8])))
    for lid, z in enumerate(measured(LM, (0.0, 0.0))):
        f.add_landmark(z, R, LASER, lid)
    f.predict(np.zeros(3), np.eye(3), np.diag([0.09, 0.09, 0.0]))
    return f


def scan(z: np.ndarray) -> tuple[Measurements, ScanAssociation]:
    k = z.shape[0]
    meas = Measurements(
        k=7, scan=None, features=None, z=z, R=np.repeat(R[None], k, 0), status=np.full(k, -1)
    )
    a = ScanAssociation(
        assign=np.arange(k),
        ambiguous=np.zeros(k, bool),
        lm_idx=np.arange(3),
        t_idx=np.zeros(0, int),
    )
    return meas, a


def test_two_pairings_each_in_its_gate_but_jointly_incompatible_drop_the_outlier():
    """Landmarks 0 and 1 are seen as from x = +0.6 m, landmark 2 as from x = -0.6 m: each
    pairing alone is at d2 of about 4 (gate 13.8), the scan together is not; the outlier
    (landmark 2's measurement) is dropped and marked ambiguous, and the run log's record names
    it."""
    f = filter_with_uncertain_pose()
    z = np.concatenate([measured(LM[:2], (0.6, 0.0)), measured(LM[2:], (-0.6, 0.0))])
    nu, S = f.innovation(np.arange(3), z, np.repeat(R[None], 3, 0), LASER)
    for j in range(3):
        b = slice(2 * j, 2 * j + 2)
        assert nu[j] @ np.linalg.solve(S[b, b], nu[j]) < chi2.ppf(0.999, 2)
    meas, a = scan(z)
    gate = JointGate(0.999, LASER)
    out = gate(f, meas, a)
    assert out.assign.tolist() == [0, 1, -1]
    assert out.ambiguous.tolist() == [False, False, True]
    assert gate.dropped == [[7, 2, 2]]
    assert out.to_map().tolist() == [0, 1]
    assert a.assign.tolist() == [0, 1, 2]  # the associator's record is not changed


def test_a_consistent_scan_is_untouched():
    f = filter_with_uncertain_pose()
    meas, a = scan(measured(LM, (0.6, -0.3)))
    gate = JointGate(0.999, LASER)
    assert gate(f, meas, a) is a and gate.dropped == []


def test_off_the_gate_passes_even_an_incompatible_scan_unchanged():
    """The gate is chosen once: off, `NoJointGate` returns the association itself (the scan
    the joint test would prune) and records nothing; on, the run's gate records its drops."""
    f = filter_with_uncertain_pose()
    z = np.concatenate([measured(LM[:2], (0.6, 0.0)), measured(LM[2:], (-0.6, 0.0))])
    meas, a = scan(z)
    off = make_joint_gate(False, 0.999, LASER)
    assert isinstance(off, NoJointGate)
    assert off(f, meas, a) is a and off.record() is None
    on = make_joint_gate(True, 0.999, LASER)
    assert isinstance(on, JointGate) and on(f, meas, a) is not a
    assert on.record() == [[7, 2, 2]]


def test_innovation_is_the_updates():
    """Filter.innovation gives the update's own innovation and S, to the bit."""
    f = filter_with_uncertain_pose()
    z = measured(LM, (0.6, -0.3))
    Rk = np.repeat(R[None], 3, 0)
    nu, S = f.innovation(np.arange(3), z, Rk, LASER)
    res = f.update(np.arange(3), z, Rk, LASER)
    assert np.array_equal(nu, res.innovation) and np.array_equal(S, res.S)


def test_off_by_default_and_a_clean_run_is_the_same_with_it_on():
    """The built-in setting is off (the run log has no record); on, a drive whose circles are
    its landmarks' drops nothing and gives the same poses and map to the bit."""
    assert SlamConfig().association.joint_check is False
    seq = drive_sequence(1.5, 0.05, n_scans=30)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(0))
    off = run_slam(seq, features=feats, config=paper_noise(TIGHT))
    on = run_slam(
        seq, features=feats, config=paper_noise(TIGHT, **{"association.joint_check": True})
    )
    assert off.joint_dropped is None and on.joint_dropped == []
    assert np.array_equal(off.pose, on.pose)
    assert np.array_equal(off.landmark_xy, on.landmark_xy)
    assert np.all(on.n_associated[5:] >= 2)  # the test had pairings to check
    from experiments.pipeline.slam import summarise

    assert "joint_check" not in summarise(off, seq, 0.0)
    assert summarise(on, seq, 0.0)["joint_check"] == {"dropped": 0, "scans": 0}


def test_a_non_boolean_is_refused():
    with pytest.raises(SlamError, match="association.joint_check"):
        AssociationConfig(joint_check="yes")
    with pytest.raises(SlamError, match="association.joint_check"):
        SlamConfig.from_dict({"association": {"joint_check": 1}})
