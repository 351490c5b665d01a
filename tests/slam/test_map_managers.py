"""The map managers' one contract (`slam.map_managers.MapManager`): the single-scan manager and
the K-scan window are interchangeable behind it, and `manage` returns its decisions without
changing the measurements it was given."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.log import CONFIRMED, NEW_TENTATIVE, OUT_OF_RANGE
from slam.map_managers import MapDecisions, MapManager, View, make_map_manager
from slam.sources import Measurements

LASER = np.zeros(3)


def _manager(method: str, confirm_scans: int = 1) -> MapManager:
    cfg = SlamConfig().with_(
        **{"association.method": method, "map_policy.confirm_scans": confirm_scans}
    )
    view = View(fov=(-math.pi / 2, math.pi / 2), max_range=50.0)

    def nearest(z, R, z_hat, H, P, gate_prob=0.99, **params):  # the single-scan associator
        return np.full(z.shape[0], -1, np.int64)

    return make_map_manager(LASER, view, cfg.association, cfg.map_policy, nearest)


def _scan(k: int) -> Measurements:
    z = np.array([[10.0, 0.1], [20.0, -0.3], [80.0, 0.0]])
    status = np.array([NEW_TENTATIVE, NEW_TENTATIVE, OUT_OF_RANGE])
    return Measurements(k, None, None, z, np.tile(np.diag([1e-2, 1e-4]), (3, 1, 1)), status)


@pytest.mark.parametrize("method", ["ihgr", "ihgr-window"])
def test_both_managers_keep_the_contract_and_leave_the_measurements_alone(method):
    """With nothing mapped and every new measurement confirmed at once (the window: in
    min(confirm_scans, K) = 1 scan), both managers map the two usable measurements in the
    first scan, say so in their decisions (status CONFIRMED, the joined ids, their tracks),
    keep the out-of-range one out, and leave `meas.status` as the measure step made it."""
    manager = _manager(method)
    assert isinstance(manager, MapManager)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-4))
    meas = _scan(0)
    before = meas.status.copy()
    a = manager.associate(state, meas, np.eye(3) * 1e-6, None)
    decisions = manager.manage(state, meas, a, np.full(3, -1, np.int64))
    assert isinstance(decisions, MapDecisions)
    np.testing.assert_array_equal(meas.status, before)
    assert decisions.status.tolist() == [CONFIRMED, CONFIRMED, OUT_OF_RANGE]
    joined = [lid for lid, _ in decisions.joined]
    assert state.landmark_ids.tolist() == joined and len(joined) == 2
    assert decisions.track[:2].tolist() == joined and decisions.track[2] == -1
    assert decisions.n_pending == manager.n_pending == 0 and decisions.retracks == []
    np.testing.assert_allclose(state.landmarks_xy[0], [10 * math.cos(0.1), 10 * math.sin(0.1)])


# map policy "existence" (slam.existence_map): joins and removals by probability


def _existence_manager(method: str, **policy):
    from slam.existence_map import LandmarkExistence

    changes = {"association.method": method, "map_policy.policy": "existence"}
    changes |= {f"map_policy.{k}": v for k, v in policy.items()}
    cfg = SlamConfig().with_(**changes)
    view = View(fov=(-math.pi / 2, math.pi / 2), max_range=50.0)

    def nearest(z, R, z_hat, H, P, gate_prob=0.99, **params):  # within 1 m of range-bearing
        d = np.hypot(z[:, None, 0] - z_hat[None, :, 0], 10 * (z[:, None, 1] - z_hat[None, :, 1]))
        return np.where(d.min(axis=1) < 1.0, d.argmin(axis=1), -1).astype(np.int64)

    book = LandmarkExistence(cfg.map_policy, view, LASER)
    manager = make_map_manager(
        LASER, view, cfg.association, cfg.map_policy, nearest, existence=book
    )
    return manager, book


def _trunk_scan(k: int, seen: bool = True) -> Measurements:
    z = np.array([[10.0, 0.1]]) if seen else np.zeros((0, 2))
    R = np.tile(np.diag([1e-2, 1e-4]), (z.shape[0], 1, 1))
    return Measurements(k, None, None, z, R, np.full(z.shape[0], NEW_TENTATIVE, np.int64))


def _existence_scan(manager, book, state, meas):
    a = manager.associate(state, meas, np.eye(3) * 1e-6, None)
    book.update(state, meas, a, getattr(manager, "tent", None))
    paired = np.full(meas.z.shape[0], -1, np.int64)
    to_map = a.to_map()
    paired[to_map] = state.landmark_ids[a.lm_idx[a.assign[to_map]]]
    d = manager.manage(state, meas, a, paired)
    if d.removed:
        state.remove_landmarks([lid for lid, _ in d.removed])
    return d


def _map_the_trunk(manager, book, state, max_scans: int = 50) -> tuple[int, int]:
    """Scans of the trunk seen every scan until it joins the map: (its id, the scans run)."""
    for k in range(max_scans):
        _existence_scan(manager, book, state, _trunk_scan(k))
        if state.n_landmarks:
            return int(state.landmark_ids[0]), k + 1
    raise AssertionError(f"the trunk did not join the map in {max_scans} scans")


@pytest.mark.parametrize("method", ["ihgr", "ihgr-window"])
def test_existence_joins_a_trunk_at_join_prob_not_at_a_count(method):
    """A trunk seen every scan joins the map in the first scan its existence reaches
    join_prob (confirm_scans 10 plays no part), and not before; its existence rose with each
    sighting."""
    manager, book = _existence_manager(method, confirm_scans=10)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    history = []
    for k in range(6):
        d = _existence_scan(manager, book, state, _trunk_scan(k))
        if d.joined:
            break
        assert state.n_landmarks == 0
        if method == "ihgr":  # the tentative's existence, below join_prob until it joins
            history.append(book.r[0])
            assert history[-1] < book.cfg.join_prob
    assert d.joined and state.n_landmarks == 1 and k + 1 < 10
    lid = d.joined[0][0]
    assert book.r[lid] >= book.cfg.join_prob
    assert all(b > a for a, b in zip(history, history[1:]))
    if method == "ihgr-window":  # the window's rule: the existence of its sightings
        R = _trunk_scan(0).R[0]
        assert book.track_existence(k + 1, R) >= book.cfg.join_prob
        assert book.track_existence(k, R) < book.cfg.join_prob
    else:
        assert len(history) == k >= 1


def test_a_circle_no_likelier_than_clutter_never_joins_and_is_dropped():
    """With a clutter density that explains a sighting better than a trunk does, the tentative's
    existence falls with each sighting: it never joins and leaves below remove_prob."""
    manager, book = _existence_manager("ihgr", existence_false_per_scan=1e5)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    rs = []
    for k in range(10):
        d = _existence_scan(manager, book, state, _trunk_scan(k))
        assert not d.joined
        rs.append(book.r[0])
    assert rs[0] == book.birth and rs[1] < rs[0] and rs[-1] < book.cfg.remove_prob
    assert state.n_landmarks == 0 and 0 not in manager.tent.ids.tolist()


@pytest.mark.parametrize("method", ["ihgr", "ihgr-window"])
def test_a_landmark_missed_in_view_leaves_when_its_existence_falls_below_remove_prob(method):
    """Once mapped, a landmark in view and no longer reported loses odds by (1 - pd_max) per
    scan (no beams given: Pd = pd_max in view); the map manager reports it removed, reason
    "existence", in the first scan its existence falls below remove_prob, not before."""
    manager, book = _existence_manager(method)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    lid, k = _map_the_trunk(manager, book, state)
    odds = book.r[lid] / (1 - book.r[lid])
    misses = 0
    while odds / (1 + odds) >= book.cfg.remove_prob:
        odds *= 1 - book.cfg.pd_max
        misses += 1
    for i in range(misses):
        d = _existence_scan(manager, book, state, _trunk_scan(k + i, seen=False))
        assert d.removed == ([(lid, "existence")] if i == misses - 1 else [])
    assert state.n_landmarks == 0 and book.r[lid] < book.cfg.remove_prob


def test_a_landmark_out_of_view_keeps_its_existence():
    manager, book = _existence_manager("ihgr")
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    lid, k = _map_the_trunk(manager, book, state)
    r = book.r[lid]
    state.x[2] = math.pi  # turned round: the landmark is behind the laser
    for i in range(5):
        assert _existence_scan(manager, book, state, _trunk_scan(k + i, seen=False)).removed == []
    assert book.r[lid] == r and state.n_landmarks == 1


@pytest.mark.parametrize("method", ["ihgr"])
def test_against_persistent_clutter_a_trunk_joins_after_the_sightings_pd_over_repeat_needs(method):
    """With persistent clutter (repeat_prob 0.3, no shape spread) a trunk seen every scan gains
    odds pd_max / repeat_prob a scan after its birth, so it joins in the first scan where
    birth odds times that ratio to the (scans - 1) reaches join_prob, where the uniform clutter
    maps it after two sightings. (The window's tracks hold at most window_scans sightings: with
    these settings they never reach join_prob, `LandmarkExistence.track_existence`.)"""
    policy = {"existence_clutter": "persistent", "existence_repeat_prob": 0.3}
    manager, book = _existence_manager(method, confirm_scans=30, **policy)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6))
    _, scans = _map_the_trunk(manager, book, state)
    lo = math.log(book.birth / (1 - book.birth))
    step = math.log(book.cfg.pd_max / 0.3)
    want = 1 + math.ceil((math.log(book.cfg.join_prob / (1 - book.cfg.join_prob)) - lo) / step)
    assert scans == want and scans > 2
    manager, book = _existence_manager(method, confirm_scans=30)
    assert (
        _map_the_trunk(manager, book, Filter(initial_state(np.zeros(3), np.eye(3) * 1e-6)))[1] == 2
    )


@pytest.mark.parametrize(
    ("z", "R", "status"),
    [
        (np.zeros((2, 2)), np.zeros((2, 2, 2)), np.zeros(3, np.int64)),  # status too long
        (np.zeros((2, 2)), np.zeros((1, 2, 2)), np.zeros(2, np.int64)),  # R too short
        (np.zeros((2, 3)), np.zeros((2, 2, 2)), np.zeros(2, np.int64)),  # z not (m, 2)
    ],
)
def test_measurements_of_mismatched_lengths_are_refused(z, R, status):
    """The map managers' kernels read z, R and status by one index, unchecked: a record whose
    arrays disagree is a SlamError naming the shapes, not a read out of bounds."""
    with pytest.raises(SlamError, match=r"Measurements: needs z \(m, 2\)"):
        Measurements(0, None, None, z, R, status)
