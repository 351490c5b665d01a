"""Loop closure (`slam.closure`): the merge update, the constellation match, the decision
(too few, no margin, beyond dead reckoning, not jointly compatible, accepted, re-registered)
and the log's relabelling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import SlamConfig, rigid, se2
from slam.closure import (
    HOLD_TOL_M,
    ClosureConfig,
    LoopCloser,
    Revisit,
    dead_reckoned_cov,
    hypotheses,
)
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.history import RunHistory
from slam.map_managers import View

LASER = np.array([0.0, 0.0, 0.0])
R_TINY = np.diag([1e-4, 1e-8])


def _stand(rng, n: int, spacing: float = 3.0) -> np.ndarray:
    """n points in a 40 m x 30 m block at least `spacing` apart."""
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform([0.0, -15.0], [40.0, 15.0])
        if all(np.hypot(*(p - q)) >= spacing for q in pts):
            pts.append(p)
    return np.array(pts)


def _add(f: Filter, true_pose, pts, first_id: int) -> list[int]:
    """Landmarks from exact measurements of pts taken at true_pose, initialised from the
    filter's pose estimate (so they carry its error)."""
    z, _ = se2.observe(np.asarray(true_pose, float), pts, LASER)
    ids = []
    for j, zj in enumerate(z):
        f.add_landmark(zj, R_TINY, LASER, first_id + j)
        ids.append(first_id + j)
    return ids


def test_merging_two_estimates_of_one_landmark_is_their_information_fusion():
    """Two uncorrelated estimates a, b (covariances A, B) of one point: the merge keeps
    (A^-1 + B^-1)^-1 (A^-1 a + B^-1 b) with covariance (A^-1 + B^-1)^-1, drops b, and its NIS
    is (a - b)^T (A + B)^-1 (a - b)."""
    f = Filter(initial_state(np.zeros(3), np.diag([1e-12, 1e-12, 1e-14])))
    f.add_landmark(np.array([10.0, 0.1]), np.diag([0.3**2, 0.02**2]), LASER, 7)
    f.add_landmark(np.array([10.4, 0.12]), np.diag([0.1**2, 0.05**2]), LASER, 9)
    a, b = f.landmarks_xy.copy()
    A, B = f.landmark_covs
    want_nis = float((a - b) @ np.linalg.solve(A + B, a - b))
    assert rigid.same_landmarks_nis(f, [7], [9]) == pytest.approx(want_nis, rel=1e-9)
    nis = rigid.merge_landmarks(f, [7], [9], sigma_m=1e-6)
    info = np.linalg.inv(A) + np.linalg.inv(B)
    want = np.linalg.solve(info, np.linalg.solve(A, a) + np.linalg.solve(B, b))
    assert nis == pytest.approx(want_nis, rel=1e-6)
    assert f.landmark_ids.tolist() == [7]
    np.testing.assert_allclose(f.landmarks_xy[0], want, atol=1e-6)
    np.testing.assert_allclose(f.landmark_covs[0], np.linalg.inv(info), atol=1e-9)
    with pytest.raises(SlamError, match="pair up"):
        rigid.merge_landmarks(f, [7], [])
    with pytest.raises(SlamError, match="twice"):
        rigid.merge_landmarks(f, [7], [7])


def test_the_constellation_match_finds_a_moved_copy_and_its_pairs():
    """10 of 25 trees seen again 4 m and 5 deg off: the best hypothesis explains all 10 with
    the right pairs and the inverse motion; no other placement explains more than 3."""
    rng = np.random.default_rng(3)
    old = _stand(rng, 25)
    pick = rng.choice(25, 10, replace=False)
    th = math.radians(5.0)
    Rm = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    recent = old[pick] @ Rm.T + [4.0, -1.0] + rng.normal(0, 0.03, (10, 2))
    best, second, rot, txy, pairs = hypotheses(recent, old, np.array([0.5, 3.0, 0.3, 15.0, 10]))
    assert best == 10 and second <= 3
    assert math.degrees(rot) == pytest.approx(-5.0, abs=0.5)
    assert sorted(map(tuple, pairs.tolist())) == sorted((i, int(pick[i])) for i in range(10))
    np.testing.assert_allclose(se2.rotate(rot, recent) + txy, old[pick], atol=0.15)


def _closer(state, cfg: ClosureConfig, hold_frame: bool = True) -> LoopCloser:
    history = RunHistory(np.arange(1000) * 0.2)
    for k in range(1000):  # the predictions the run loop logs before each scan's match
        history.predicted(k, np.zeros(3), np.zeros((3, 3)))
    for lid in state.landmark_ids:
        history.first_scan[int(lid)] = 0
    view = View(fov=(-math.pi, math.pi), max_range=80.0)
    return LoopCloser(cfg, view, LASER, history, gate_prob=0.9999, hold_frame=hold_frame)


def _revisit(pts_old, pts_recent, drift, pose_sd=(1.5, 1.5, 0.03), start_sd=(1e-3, 1e-3, 1e-4)):
    """A filter that mapped pts_old from a pose known to start_sd (x, y, heading; exact at
    the truth), then drifted by `drift` (its pose covariance grown to pose_sd) and mapped
    pts_recent from the drifted estimate."""
    f = Filter(initial_state(np.zeros(3), np.diag(np.square(start_sd))))
    old_ids = _add(f, np.zeros(3), pts_old, 0)
    est = np.asarray(drift, float)
    F = np.eye(3)
    f.predict(est, F, np.diag(np.square(pose_sd)))
    recent_ids = _add(f, np.zeros(3), pts_recent, 100)
    return f, old_ids, recent_ids


def test_a_return_with_drift_is_closed_and_the_pose_corrected():
    """The trees of the stand mapped again 2.5 m and 2 deg off: the closure is accepted, each
    recent landmark is merged into its own tree, and the pose comes back to the truth."""
    rng = np.random.default_rng(11)
    pts = _stand(rng, 20)
    f, old_ids, recent_ids = _revisit(pts, pts[:12], (2.0, -1.5, math.radians(2.0)))
    closer = _closer(f, ClosureConfig(enabled=True))
    ev = closer.match(f, 50, np.arange(20, 32), np.arange(20))
    assert ev.outcome == "accepted" and ev.best == 12 and ev.nis <= ev.nis_bound
    assert sorted(ev.merged) == [(old_ids[j], recent_ids[j]) for j in range(12)]
    assert f.n_landmarks == 20
    np.testing.assert_allclose(f.pose, 0.0, atol=0.05)
    assert closer.history.alias == {recent_ids[j]: old_ids[j] for j in range(12)}


def test_an_old_landmark_is_hidden_by_another_tree_near_it_not_by_itself_mapped_again():
    """Revisit detection: trees 5 m apart seen from a pose known to 0.2 m (gate about 0.9 m,
    less than half the spacing) are left to the per-scan association. A landmark 0.3 m from
    an old one (within match_m) is that tree mapped again, which the association may take for
    it without harm: it hides nothing. So is one 1.2 m away (within SAME_TREE_M) that the
    laser never saw in the same scan as the old one. Once a scan has updated both, it is
    another tree inside twice the old one's gate, and the old one is hidden. (Counting a
    tree's own copies as neighbours hid, on Victoria Park, trees at each revisit and mapped
    them anew, up to 14 times.)"""
    rng = np.random.default_rng(4)
    pts = _stand(rng, 12, spacing=5.0)
    f = Filter(initial_state(np.zeros(3), np.diag([1e-6, 1e-6, 1e-8])))
    old_ids = _add(f, np.zeros(3), pts, 0)
    f.predict(np.zeros(3), np.eye(3), np.diag([0.04, 0.04, 1e-6]))
    _add(f, np.zeros(3), np.array([pts[0] + [0.3, 0.0], pts[1] + [0.0, 1.2]]), 100)
    closer = _closer(f, ClosureConfig(enabled=True, min_pairs=3))
    closer.history.mark_seen(old_ids, 0.0)
    closer.history.mark_seen([100, 101], 100.0)
    revisit = closer.revisit(f, 500)
    assert revisit.hidden is None and revisit.n_hidden == 0  # 100 s: the old ones old
    closer.seen_together(f, np.array([old_ids[1], 101, old_ids[5]]))
    revisit = closer.revisit(f, 500)
    assert revisit.hidden is not None and revisit.n_hidden == 1
    assert f.landmark_ids[revisit.hidden].tolist() == [old_ids[1]]


def test_too_few_and_no_margin_are_refused():
    """Four landmarks are too few (min_pairs 6); in an orchard grid every shift by one spacing
    explains almost as many, so the best has no margin and nothing is merged."""
    rng = np.random.default_rng(5)
    pts = _stand(rng, 20)
    f, _, _ = _revisit(pts, pts[:4], (2.0, -1.5, 0.0))
    ev = _closer(f, ClosureConfig(enabled=True)).match(f, 50, np.arange(20, 24), np.arange(20))
    assert ev.outcome == "too few" and f.n_landmarks == 24
    grid = np.array([[x, y] for x in np.arange(4.0, 44.0, 4.0) for y in (-9.0, -3.0, 3.0, 9.0)])
    f, _, _ = _revisit(grid, grid[10:30], (1.0, 0.5, 0.0))
    n = grid.shape[0]
    ev = _closer(f, ClosureConfig(enabled=True)).match(f, 50, np.arange(n, n + 20), np.arange(n))
    assert ev.outcome == "no margin" and ev.best - ev.second < 3
    assert f.n_landmarks == n + 20


def test_pairs_with_two_old_landmarks_near_are_left_out():
    """Every old tree mapped twice 0.7 m apart: each recent landmark lands within match_m of
    one and within 2 x match_m of both, so which one it is stays unclear; with the unclear
    pairs left out too few remain, and nothing is merged."""
    rng = np.random.default_rng(11)
    pts = _stand(rng, 12, spacing=4.0)
    twice = np.vstack([pts, pts + [0.7, 0.0]])
    f, _, _ = _revisit(twice, pts[:10] + [0.1, 0.0], (2.0, -1.5, 0.0))
    ev = _closer(f, ClosureConfig(enabled=True)).match(f, 50, np.arange(24, 34), np.arange(24))
    assert ev.best >= 6 and ev.outcome in ("too few", "no margin")
    assert f.n_landmarks == 34


def _overconfident_revisit(
    drift_sd, shape_error=None, start_sd=(1e-3, 1e-3, 1e-4), hold_frame=True
):
    """The stand of `test_a_return_with_drift_is_closed_and_the_pose_corrected` 2.5 m and
    2 deg off, but the filter believes its pose to 5 cm and 0.06 deg; the log's odometry
    (500 scans, 100 s, since the old landmarks were last seen) has dead-reckoned sds
    `drift_sd` (x, y, heading) at the match, scan 500. shape_error: moved to the recent
    landmarks (12, 2)."""
    rng = np.random.default_rng(11)
    pts = _stand(rng, 20)
    drift = (2.0, -1.5, math.radians(2.0))
    recent_pts = pts[:12] if shape_error is None else pts[:12] + shape_error
    f, old_ids, recent_ids = _revisit(
        pts, recent_pts, drift, pose_sd=(0.05, 0.05, 0.001), start_sd=start_sd
    )
    closer = _closer(f, ClosureConfig(enabled=True), hold_frame)
    closer.history.mark_seen(old_ids, 0.0)  # the old trees: mapped and last seen at 0 s
    closer.history.first_scan.update({i: 450 for i in recent_ids})  # the recent: at 90 s
    closer.history.odo_delta[1:501] = [0.5, 0.0, 0.0]
    closer.history.odo_cov[1:501] = np.diag(np.square(drift_sd) / 500.0)
    return f, old_ids, recent_ids, closer


def test_landmarks_passed_by_while_their_trees_are_mapped_again_start_a_match():
    """Revisit detection's second signature: the filter is sure of its pose (nothing hidden)
    and the old landmarks were seen 50 s ago (not old at old_s 60 s), but they lie in view,
    no scan has updated them for recent_s, and landmarks joined the map near them: the match
    runs and closes the loop. A stale landmark out of view, or farther than max_offset_m from
    every new one, is not passed by; the sweep after the match counts every landmark seen by
    the time the excursion began as old."""
    f, old_ids, recent_ids, closer = _overconfident_revisit((1.5, 1.5, 0.03))
    closer.view = View(fov=(-math.pi / 2, math.pi / 2), max_range=80.0)  # the half ahead
    f.add_landmark(np.array([75.0, 0.0]), R_TINY, LASER, 50)  # ahead, past the stand
    f.add_landmark(np.array([3.0, math.pi]), R_TINY, LASER, 51)  # behind, by the stand
    closer.history.mark_seen([*old_ids, 50, 51], 50.0)
    assert closer.revisit(f, 500).hidden is None
    passed = closer.passed_by(f, 100.0)
    xy = f.landmarks_xy
    recent_xy = xy[f.positions_of(np.array(recent_ids))]
    gap = np.hypot(*(xy[:, None, :] - recent_xy[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    z, _ = se2.observe(f.pose, xy, LASER)
    ahead = np.abs(z[:, 1]) <= math.pi / 2
    far, behind = f.positions_of(np.array([50, 51]))
    assert ahead[far] and gap[far] > closer.cfg.max_offset_m  # in view, nothing new near it
    assert not ahead[behind] and gap[behind] <= closer.cfg.max_offset_m  # out of view
    want = [i for i in range(xy.shape[0]) if f.landmark_ids[i] < 100 and ahead[i]]
    want = [i for i in want if gap[i] <= closer.cfg.max_offset_m]
    assert passed.tolist() == want and len(want) >= closer.cfg.min_pairs
    _, old = closer.candidates(f, 100.0, in_view=False)
    assert old.size == 0  # by old_s alone, nothing is old
    _, old = closer.candidates(f, 100.0, in_view=False, since=50.0)
    assert sorted(f.landmark_ids[old].tolist()) == sorted([*old_ids, 50, 51])
    ev = closer.close(f, 500, np.zeros(0, np.int64), Revisit()).event
    assert ev is not None and ev.outcome == "accepted" and ev.re_registered
    assert sorted(ev.merged) == [(old_ids[j], recent_ids[j]) for j in range(12)]
    np.testing.assert_allclose(f.pose, 0.0, atol=0.02)
    # the new landmarks farther than max_offset_m from every stale one: nothing is tried
    f, old_ids, _, closer = _overconfident_revisit((1.5, 1.5, 0.03))
    closer.cfg = ClosureConfig(enabled=True, max_offset_m=1.0)
    closer.history.mark_seen(old_ids, 50.0)
    assert closer.passed_by(f, 100.0).size == 0
    assert closer.candidates(f, 100.0)[0].size >= closer.cfg.min_pairs  # recent ones there
    assert closer.close(f, 500, np.zeros(0, np.int64), Revisit()).event is None
    assert not closer.events


def test_a_closure_the_filter_cannot_explain_is_refused_without_re_registration():
    """The pairs are not jointly compatible with the filter's covariance: with re_register
    off nothing is merged."""
    f, _, _, closer = _overconfident_revisit((1.5, 1.5, 0.03))
    closer.cfg = ClosureConfig(enabled=True, re_register=False)
    ev = closer.match(f, 500, np.arange(20, 32), np.arange(20))
    assert ev.outcome == "not jointly compatible" and ev.nis > ev.nis_bound
    assert math.isnan(ev.shape_nis) and not ev.re_registered
    assert f.n_landmarks == 32


def test_re_registration_closes_what_the_filter_is_too_sure_to_allow():
    """Same overconfident filter, dead reckoning allowing 1.5 m: the drift is within it, the
    shape of the pairs fits one rigid motion, so the drift is given back to the vehicle and
    the landmarks mapped since the old ones were seen, and they are moved onto the old trees:
    every recent landmark merged into its own tree and the pose back at the truth."""
    f, old_ids, recent_ids, closer = _overconfident_revisit((1.5, 1.5, 0.03))
    ev = closer.match(f, 500, np.arange(20, 32), np.arange(20))
    assert ev.nis > ev.nis_bound and ev.drift_nis <= ev.drift_bound
    assert ev.shape_nis <= ev.shape_bound and ev.shape_nis < 1.0  # exact measurements
    assert ev.outcome == "accepted" and ev.re_registered
    assert sorted(ev.merged) == [(old_ids[j], recent_ids[j]) for j in range(12)]
    np.testing.assert_allclose(f.pose, 0.0, atol=0.02)
    assert f.n_landmarks == 20


def test_a_re_registration_leaves_the_old_map_where_it_was():
    """The same closure in a filter whose whole map shares the start's uncertainty (1 m,
    2 deg, as first-estimates Jacobians keep it): the merge could move the old map as one
    piece, a change of the world frame nothing observes; the closure moves the estimate back
    so that the old trees stay where they were (to 1 cm: the merge still bends the old map a
    little), while the pose still comes back to the truth. Without that step the old map
    moves by 0.69 m."""
    start_sd = (1.0, 1.0, math.radians(2.0))

    def old_map_shift(hold_frame=True):
        f, old_ids, _, closer = _overconfident_revisit(
            (1.5, 1.5, 0.03), start_sd=start_sd, hold_frame=hold_frame
        )
        pos = [f.index_of(i) for i in old_ids]
        before = f.landmarks_xy[pos].copy()
        ev = closer.match(f, 500, np.arange(20, 32), np.arange(20))
        assert ev.outcome == "accepted" and ev.re_registered
        pos = [f.index_of(i) for i in old_ids]
        return np.hypot(*(f.landmarks_xy[pos] - before).T).max(), f.pose.copy()

    moved, pose = old_map_shift()
    assert moved < 0.01
    np.testing.assert_allclose(pose, 0.0, atol=0.05)
    moved_free, _ = old_map_shift(hold_frame=False)
    assert moved_free > 0.3


def test_after_a_re_registration_the_old_map_is_held_at_every_scan():
    """Once a re-registration is accepted, each later scan moves the estimate back whenever
    the old map has moved as one piece by more than HOLD_TOL_M (RMS): a turn of the whole
    estimate by 0.5 deg is undone (the vehicle's pose with it), a shift of 5 mm is left. A
    closer that never re-registered holds nothing."""
    f, old_ids, _, closer = _overconfident_revisit(
        (1.5, 1.5, 0.03), start_sd=(1.0, 1.0, math.radians(2.0))
    )
    assert closer.match(f, 500, np.arange(20, 32), np.arange(20)).re_registered
    pos = [f.index_of(i) for i in old_ids]
    held, pose = f.landmarks_xy[pos].copy(), f.pose.copy()
    no_measurements = np.zeros(0, dtype=np.int64)
    rigid.move_rigidly(f, math.radians(0.5), np.array([0.3, -0.2]))
    assert np.hypot(*(f.landmarks_xy[pos] - held).T).max() > 0.1
    closer.close(f, 501, no_measurements, Revisit())
    np.testing.assert_allclose(f.landmarks_xy[pos], held, atol=1e-9)
    np.testing.assert_allclose(f.pose, pose, atol=1e-9)
    rigid.move_rigidly(f, 0.0, np.array([0.005, 0.0]))
    closer.close(f, 502, no_measurements, Revisit())
    np.testing.assert_allclose(f.landmarks_xy[pos], held + [0.005, 0.0], atol=1e-9)
    assert HOLD_TOL_M == 0.01
    g, _, _, fresh = _overconfident_revisit((1.5, 1.5, 0.03))
    x0 = g.x.copy()
    rigid.move_rigidly(g, math.radians(0.5), np.zeros(2))
    moved = g.x.copy()
    fresh.close(g, 501, no_measurements, Revisit())
    np.testing.assert_array_equal(g.x, moved)
    assert not np.allclose(moved, x0)


def test_the_duplicate_sweep_marginalises_a_tree_mapped_twice_and_nothing_else():
    """Five trees, each mapped twice. Copies mapped from the well-known start pose (relative
    sds of millimetres): 10 cm off and never updated with its tree, it is marginalised out
    (the one with fewer sightings goes, its measurements are relabelled, nothing else
    moves); 10 cm off but updated with it in one scan (two stems), or 40 cm off (beyond the
    5 cm trunk error), it stays. Copies mapped after the pose's sd grew: to 0.3 m, the
    pair's gate (1.15 m) is wider than match_m but stops short of half the way to the
    nearest other tree (30 m), and the copy goes; to 1.5 m, the gate (5.7 m) reaches past
    half the way to a tree 4.2 m off, and the pair is left to the constellation match."""
    f = Filter(initial_state(np.zeros(3), np.diag([1e-6, 1e-6, 1e-8])))
    trees = np.array([[10.0, 3.0], [12.0, -6.0], [20.0, 8.0], [23.0, 5.0], [40.0, -20.0]])
    off = np.array([[0.1, 0.0], [0.0, 0.1], [0.4, 0.0], [0.1, 0.0], [0.0, -0.1]])
    _add(f, np.zeros(3), trees, 0)
    _add(f, np.zeros(3), trees[:3] + off[:3], 10)
    f.predict(np.zeros(3), np.eye(3), np.diag([0.3**2, 0.3**2, 1e-8]))
    _add(f, np.zeros(3), trees[4:] + off[4:], 14)
    f.predict(np.zeros(3), np.eye(3), np.diag([1.5**2 - 0.3**2, 1.5**2 - 0.3**2, 1e-4]))
    _add(f, np.zeros(3), trees[3:4] + off[3:4], 13)
    closer = _closer(f, ClosureConfig(enabled=True))
    closer.history.n_obs.update({i: 40 for i in range(5)} | {i: 3 for i in range(10, 15)})
    closer.close(
        f, 3, np.array([1, 11]), Revisit()
    )  # k = 3: the pair 1, 11 seen in one scan; no sweep yet
    x_before, ids_before = f.x.copy(), f.landmark_ids.copy()
    decision = closer.close(f, 5, np.zeros(0, dtype=np.int64), Revisit())  # k = 5: the sweep
    assert sorted(decision.duplicates) == [(0, 10, 5), (4, 14, 5)] and decision.event is None
    assert sorted(closer.duplicates) == [(0, 10, 5), (4, 14, 5)]
    assert sorted(f.landmark_ids.tolist()) == [0, 1, 2, 3, 4, 11, 12, 13]
    assert closer.history.alias == {10: 0, 14: 4}
    kept = ~np.isin(ids_before, [10, 14])  # the others' rows, unchanged
    np.testing.assert_array_equal(f.x, x_before[np.concatenate([[True] * 3, np.repeat(kept, 2)])])


def test_positions_of_finds_many_ids_at_once_and_marks_the_missing():
    """`Filter.positions_of` is `index_of` for many ids (in any order), -1 for an id not in the
    state, also after a landmark left it."""
    f, ids, recent = _revisit(_stand(np.random.default_rng(3), 5), np.zeros((0, 2)), np.zeros(3))
    got = f.positions_of([ids[3], 999, ids[0], ids[4]])
    assert got.tolist() == [f.index_of(ids[3]), -1, f.index_of(ids[0]), f.index_of(ids[4])]
    f.remove_landmarks([ids[1]])
    assert f.positions_of(ids).tolist() == [0, -1, 1, 2, 3]


def test_moving_the_estimate_rigidly_changes_only_the_frame():
    """`slam.rigid.move_rigidly`: every position moved by the same rotation and translation, the
    heading turned, the covariance rotated with them (J P J^T); distances, the joint NIS of a
    pair and the first estimates' geometry are unchanged."""
    rng = np.random.default_rng(2)
    pts = _stand(rng, 6)
    f, ids, _ = _revisit(pts, pts[:3], (0.5, 0.2, 0.01), start_sd=(0.3, 0.2, 0.02))
    th, t = 0.4, np.array([3.0, -2.0])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    x0, P0, first0 = f.x.copy(), f.P.copy(), f.first_xy.copy()
    nis0 = rigid.same_landmarks_nis(f, [ids[0]], [100])
    rigid.move_rigidly(f, th, t)
    np.testing.assert_allclose(f.landmarks_xy, f_xy := x0[3:].reshape(-1, 2) @ R.T + t)
    np.testing.assert_allclose(f.pose[:2], R @ x0[:2] + t)
    assert f.pose[2] == pytest.approx(se2.wrap_angle(x0[2] + th))
    J = np.eye(f.dim)
    for a in [0, *range(3, f.dim, 2)]:
        J[a : a + 2, a : a + 2] = R
    np.testing.assert_allclose(f.P, J @ P0 @ J.T, atol=1e-12)
    assert rigid.same_landmarks_nis(f, [ids[0]], [100]) == pytest.approx(nis0)
    np.testing.assert_allclose(f.first_xy, first0 @ R.T + t)
    assert f_xy.shape == (9, 2)


def test_a_drift_dead_reckoning_cannot_explain_is_refused():
    """Dead reckoning allowing 10 cm and 0.1 deg cannot have drifted 2.5 m: "beyond dead
    reckoning", nothing merged (in an orchard, a match one row over looks as good)."""
    f, _, _, closer = _overconfident_revisit((0.1, 0.1, 0.002))
    ev = closer.match(f, 500, np.arange(20, 32), np.arange(20))
    assert ev.outcome == "beyond dead reckoning" and ev.drift_nis > ev.drift_bound
    assert f.n_landmarks == 32


@pytest.mark.parametrize(("tree_sd_m", "scale"), [(0.0, 1.0), (0.05, 1.6)])
def test_a_map_that_no_rigid_motion_fits_is_refused(tree_sd_m, scale):
    """The recent landmarks bent (each moved by up to 0.21 m x scale, within the
    constellation's match_m, by the bearing from the centre of the stand): no rigid motion
    puts them on the old trees within their (1 cm) precision and the trunks' own error
    (tree_sd_m: none, as for circles; 5 cm, about the default, against a bend 1.6 times larger),
    so the closure is refused."""
    rng = np.random.default_rng(11)
    pts = _stand(rng, 20)[:12]
    bend = scale * 0.3 * (pts - pts.mean(axis=0))[:, ::-1] / 20.0 * [1.0, -1.0] * [1.0, 0.0]
    assert 0.2 * scale < np.abs(bend).max() < 0.22 * scale < 0.5  # 0.5: match_m
    f, _, _, closer = _overconfident_revisit((1.5, 1.5, 0.03), shape_error=bend)
    closer.cfg = ClosureConfig(enabled=True, tree_sd_m=tree_sd_m)
    ev = closer.match(f, 500, np.arange(20, 32), np.arange(20))
    assert ev.best >= 6 and ev.shape_nis > ev.shape_bound
    assert ev.outcome == "not jointly compatible" and f.n_landmarks == 32


def test_freeing_with_shares_is_a_random_walk_of_the_motion():
    """Shares f: a landmark gets f cov, two landmarks min(f, g) cov between them, each
    landmark f cov with the vehicle (share 1); shares outside [0, 1] or of the wrong length
    are refused by name."""
    f = Filter(initial_state(np.zeros(3), np.diag([0.01, 0.01, 1e-4])))
    for j, p in enumerate([[5.0, 2.0], [8.0, -1.0], [3.0, 6.0]]):
        z, _ = se2.observe(f.pose, np.array([p]), LASER)
        f.add_landmark(z[0], np.diag([0.01, 1e-4]), LASER, 10 + j)
    P0 = f.P.copy()
    T = np.diag([0.5, 0.2, 0.0])
    rigid.free_rigid_motion(f, [10, 11, 12], np.zeros(2), T, shares=[0.25, 1.0, 0.5])
    dP = f.P - P0
    x_rows = {"vehicle": 0, 10: 3, 11: 5, 12: 7}
    share = {"vehicle": 1.0, 10: 0.25, 11: 1.0, 12: 0.5}
    for a, ra in x_rows.items():
        for b, rb in x_rows.items():
            want = min(share[a], share[b]) * T[:2, :2]
            np.testing.assert_allclose(dP[ra : ra + 2, rb : rb + 2], want, atol=1e-12)
    with pytest.raises(SlamError, match="shares"):
        rigid.free_rigid_motion(f, [10], np.zeros(2), T, shares=[1.5])
    with pytest.raises(SlamError, match="shares"):
        rigid.free_rigid_motion(f, [10, 11], np.zeros(2), T, shares=[0.5])


@pytest.mark.slow
def test_dead_reckoned_cov_is_the_composed_odometry_noise():
    """Straight increments of 1 m with independent noise: after n steps the along-track
    variance is n q_x, the heading's n q_theta, and the cross-track variance
    q_y n + q_theta (1^2 + ... + (n-1)^2) (each heading error swings the later steps);
    a Monte Carlo of the composition agrees."""
    n = 40
    q = np.array([0.01, 0.004, 1e-4])
    delta = np.zeros((n + 1, 3))
    delta[1:] = [1.0, 0.0, 0.0]
    cov = np.zeros((n + 1, 3, 3))
    cov[1:] = np.diag(q)
    C = dead_reckoned_cov(delta, cov, 0, n)
    assert C[0, 0] == pytest.approx(n * q[0], rel=1e-9)
    assert C[2, 2] == pytest.approx(n * q[2], rel=1e-9)
    assert C[1, 1] == pytest.approx(n * q[1] + q[2] * sum(j * j for j in range(n)), rel=1e-9)
    rng = np.random.default_rng(0)
    ends = []
    for _ in range(4000):
        T = np.zeros(3)
        for k in range(1, n + 1):
            T = se2.compose(T, delta[k] + rng.normal(0.0, np.sqrt(q)))
        ends.append(T)
    sd = np.sqrt(np.diag(C))  # compared as correlations-scaled entries (sampling error ~0.02)
    np.testing.assert_allclose(
        np.cov(np.array(ends).T) / np.outer(sd, sd), C / np.outer(sd, sd), atol=0.07
    )
    assert dead_reckoned_cov(delta, cov, 5, 5).tolist() == np.zeros((3, 3)).tolist()


def test_rigid_fit_recovers_the_motion_and_measures_what_it_leaves():
    """Landmarks of one stand and their copy moved by 3 deg and (2, -1) m: the fit returns
    the motion and a NIS near 0; moving one copy by 20 cm (landmark sd 1 cm) makes it large,
    about (0.2 / 0.01)^2 x (1 - 1/n) x (its share once the rotation is fitted)."""
    rng = np.random.default_rng(4)
    pts = _stand(rng, 8)
    th = math.radians(3.0)
    copy = se2.rotate(-th, pts - pts.mean(axis=0)) + pts.mean(axis=0) - [2.0, -1.0]
    f = Filter(initial_state(np.zeros(3), np.diag([1e-12, 1e-12, 1e-14])))
    for j, p in enumerate(np.vstack([pts, copy])):
        z, _ = se2.observe(np.zeros(3), p[None, :], LASER)
        f.add_landmark(z[0], np.diag([1e-4, 1e-4 / max(float(z[0, 0]), 1.0) ** 2]), LASER, j)
    nis, motion, centre = rigid.rigid_fit(f, list(range(8)), list(range(8, 16)))
    assert nis < 1e-6
    np.testing.assert_allclose(centre, copy.mean(axis=0), atol=1e-9)
    np.testing.assert_allclose(motion, [2.0, -1.0, th], atol=1e-9)
    f2 = Filter(initial_state(np.zeros(3), np.diag([1e-12, 1e-12, 1e-14])))
    copy[3] += [0.2, 0.0]
    for j, p in enumerate(np.vstack([pts, copy])):
        z, _ = se2.observe(np.zeros(3), p[None, :], LASER)
        f2.add_landmark(z[0], np.diag([1e-4, 1e-4 / max(float(z[0, 0]), 1.0) ** 2]), LASER, j)
    nis2, _, _ = rigid.rigid_fit(f2, list(range(8)), list(range(8, 16)))
    assert 50.0 < nis2 < 400.0
    # tree_sd_m is an independent error of each landmark: the same NIS as with it added to
    # P's landmark blocks, and a 20 cm error against 5 cm of it is no longer far out
    nis3, _, _ = rigid.rigid_fit(f2, list(range(8)), list(range(8, 16)), tree_sd_m=0.05)
    for j in range(16):
        f2.P[3 + 2 * j : 5 + 2 * j, 3 + 2 * j : 5 + 2 * j] += 0.05**2 * np.eye(2)
    assert nis3 == pytest.approx(
        rigid.rigid_fit(f2, list(range(8)), list(range(8, 16)))[0], rel=1e-9
    )
    assert 2.0 < nis3 < nis2 / 10.0
    with pytest.raises(SlamError, match="two pairs"):
        rigid.rigid_fit(f, [0], [8])


def test_freeing_a_rigid_motion_moves_the_vehicle_and_those_landmarks_together():
    """P += B cov B^T: a translation-only cov adds the same cov to the vehicle's position,
    to each freed landmark and to their cross covariances (they move together); the other
    landmarks' rows do not change; the rotation part adds J (p - centre) terms."""
    f = Filter(initial_state(np.array([1.0, 2.0, 0.3]), np.diag([0.01, 0.01, 1e-4])))
    for j, p in enumerate([[5.0, 2.0], [8.0, -1.0], [3.0, 6.0]]):
        z, _ = se2.observe(f.pose, np.array([p]), LASER)
        f.add_landmark(z[0], np.diag([0.01, 1e-4]), LASER, 10 + j)
    P0 = f.P.copy()
    T = np.diag([0.5, 0.2, 0.0])
    rigid.free_rigid_motion(f, [10, 12], np.zeros(2), T)
    dP = f.P - P0
    freed = [0, 1, 3, 4, 7, 8]
    np.testing.assert_allclose(dP[np.ix_(freed, freed)], np.kron(np.ones((3, 3)), T[:2, :2]))
    assert np.all(dP[5:7] == 0) and np.all(dP[:, 5:7] == 0) and np.all(dP[2] == 0)
    f = Filter(initial_state(np.zeros(3), np.diag([0.01, 0.01, 1e-4])))
    f.add_landmark(np.array([10.0, 0.0]), np.diag([0.01, 1e-4]), LASER, 1)
    P0 = f.P.copy()
    rigid.free_rigid_motion(f, [1], np.zeros(2), np.diag([0.0, 0.0, 0.01]))
    dP = f.P - P0  # a rotation about the vehicle moves the landmark 10 m away along y
    assert dP[4, 4] == pytest.approx(100 * 0.01) and dP[2, 4] == pytest.approx(10 * 0.01)
    assert dP[0, 0] == 0.0 and dP[2, 2] == pytest.approx(0.01)


def test_the_history_counts_a_merged_landmarks_measurements_as_the_kept_ones():
    history = RunHistory(np.arange(3) * 0.2)
    history.n_obs.update({1: 5, 2: 3, 5: 2})
    history.first_scan.update({1: 1, 2: 2, 5: 0})
    history.merged(drop=2, keep=1)
    assert history.n_obs == {1: 8, 5: 2} and history.first_scan == {1: 1, 5: 0}
    history.merged(drop=1, keep=5)  # a later closure: 2 -> 1 -> 5
    assert history.n_obs == {5: 10} and history.first_scan == {5: 0}
    assert history.resolved([2, 1, 5, -1, 4]).tolist() == [5, 5, 5, -1, 4]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"closure": {"min_pairs": 2}}, r"closure\.min_pairs"),
        ({"closure": {"jc_prob": 1.0}}, r"closure\.jc_prob"),
        ({"closure": {"match_m": -1.0}}, r"closure\.match_m"),
        ({"closure": {"enabled": "yes"}}, r"closure\.enabled"),
        ({"closure": {"re_register": 1}}, r"closure\.re_register"),
        ({"closure": {"tree_sd_m": -0.05}}, r"closure\.tree_sd_m: must be >= 0"),
        ({"closure": {"old_s": 20.0}}, r"closure\.old_s: must be >= recent_s"),
        ({"closure": {"every": 3}}, r"closure\.every.*did you mean 'every_scans'"),
    ],
)
def test_bad_closure_settings_name_the_key(data, message):
    with pytest.raises(SlamError, match=message):
        SlamConfig.from_dict(data)


def test_a_closure_setting_that_may_be_zero_is_accepted_at_zero():
    assert SlamConfig.from_dict({"closure": {"tree_sd_m": 0.0}}).closure.tree_sd_m == 0.0
