"""Loop closure: recognise mapped territory after an excursion and merge the trees mapped twice.

The signature of a missed loop closure in EKF-SLAM: the vehicle is back among landmarks it
mapped long ago, their predictions lie in view, yet the per-scan association does not pair
them (the drift has grown past its gate), and new landmarks are mapped beside them. The
`LoopCloser` watches for it after each scan and, when it is there, matches the two maps:

1. Revisit detection (`LoopCloser.revisit`, before each scan's association): an *old*
   landmark (not seen for `old_s` seconds) whose prediction lies in view is hidden from the
   scan's association when its gate reaches half the distance to the nearest other tree in the
   map: the nearest landmark farther than `match_m`, and, within `SAME_TREE_M`, one the laser
   has seen in the same scan as this one (a landmark closer, or never seen with it, is this
   tree mapped again, and the association may take one for the other without harm). The
   trees of the way back are then mapped anew, as *recent* landmarks (joined the map in the
   last `recent_s` seconds).
   The second signature (`LoopCloser.passed_by`) needs no wide gate: a filter sure of a
   wrong pose passes mapped trees by and maps them again. Landmarks in view that no scan has
   updated for `recent_s` seconds, with recent landmarks within `max_offset_m` of them (the
   largest shift of the recent map's centroid that the match below allows), count as old
   for it.
2. Constellation match (`LoopCloser.close`, `hypotheses`): every `every_scans` scans while
   at least `min_pairs` old landmarks are hidden, or else passed by (the per-scan
   association pairs the rest), the recent landmarks within the laser's range against the
   old ones in view, at least `min_pairs` of each. Every pair of the `BASIS` most-seen
   recent landmarks at least `min_sep_m` apart and every pair of old ones at the same
   distance (within `match_m`) propose a rigid transform (rotation at most
   `max_rotation_deg`, moving the recent landmarks' centroid at most `max_offset_m`); a
   hypothesis scores the recent landmarks it puts within `match_m` of an old one. Trees in a
   park look alike, so the best hypothesis must explain `min_pairs` landmarks and `margin`
   more than the best hypothesis that differs from it (moves the centroid elsewhere by more
   than `match_m`).
3. Joint compatibility (`slam.rigid.same_landmarks_nis`): the filter's own covariance must allow
   all the matched pairs to be the same trees at once (chi-square at `jc_prob`, 2 x pairs
   degrees of freedom). An EKF's covariance is too small after a long excursion (its
   heading's linearisation; in the simulated park, without closure, fewer than half of the
   scans after a return have a pose NEES inside its 95% bounds), so a true closure often
   fails this test. With `re_register` (the default) such a match is checked without the
   filter's absolute covariance:
   - dead reckoning must allow the drift (`_drift_test`): the pose correction the match
     implies against the covariance of the odometry alone since the matched old landmarks
     were last seen (`dead_reckoned_cov`, the logged increments composed to first order; no
     landmark update shrinks it), chi-square with 3 dof at `jc_prob`, else "beyond dead
     reckoning". In an orchard a match one row over is as good as the right one; this is
     what refuses it;
   - the pairs must be the same trees up to one rigid motion (`slam.rigid.rigid_fit`): the NIS
     left by the least-squares rigid motion under the covariance of the centred residuals,
     with `tree_sd_m` added to each landmark (chi-square, 2 x pairs - 3 dof at `jc_prob`),
     else "not jointly compatible";
   - then the drift dead reckoning allows is given back to the filter (`_free_local_map`,
     `slam.rigid.free_rigid_motion`): the vehicle and every landmark mapped since the old
     landmarks were last seen may move together by a rigid motion of that covariance, grown
     as a random walk (a landmark mapped halfway through the excursion shares half of it), so
     that the pairs, not the filter's belief, place the excursion's map.
4. Applying it (`slam.rigid.merge_landmarks`): one update with "each pair differs by 0", then the
   recent duplicate is marginalised out; the log relabels its measurements with the old
   landmark's id (`RunHistory.merged`), so the smoother sees the closed loop as well. Then
   the other landmarks of the excursion (mapped since the old landmarks were last seen)
   mapped a second time are swept up (`LoopCloser._sweep`): each with a single old landmark
   near it, individually and jointly compatible, goes too. When the match passed the
   filter's own joint compatibility, the sweep covers the whole map and merges as above.
   After a re-registration it covers only the laser's range around the vehicle, where the
   match has just aligned the two maps, and a swept duplicate is only marginalised out (its
   measurements relabelled, no update): the sweep's tests use a covariance already known to
   be too small for what was mapped before the excursion's start, and an update through it
   can move the old map (on Victoria Park, merging the whole map's 14 such pairs moved the
   map of scans 1-2000 by a median 1.7 m, and its recall against the 2002 reference fell
   from 0.99 to 0.23; merging the local ones did the same). The re-registration's own merge
   can move the old map too, as one piece: the freed excursion and, where the whole map
   shares the start's uncertainty (first-estimates Jacobians keep it), the old map may both
   move. That is a motion of the world frame, which nothing observes, but it would move the
   map away from the path already logged; so the whole estimate is then moved back by the
   rigid motion that puts the old map where it was (`LoopCloser._hold_frame`,
   `slam.rigid.move_rigidly`), and held there at every scan after it (whenever it has moved by
   more than `HOLD_TOL_M`): under first-estimates Jacobians the re-registration leaves the
   linearisation points of the old map and of the vehicle metres apart, and the updates that
   follow observe the world frame through them (on Victoria Park they turned the whole map
   by 1.3 deg within 30 scans).
5. The duplicate sweep (`LoopCloser._sweep_duplicates`, every `every_scans` scans, whether a
   match is tried or not): two landmarks within the laser's range of the vehicle, closer
   than `match_m` to each other, that no scan has updated both of, are one tree mapped twice
   when the filter knows their relative position well enough (the pair's gate at
   `jc_prob`, with `tree_sd_m` on each, stops short of half the way to the nearest other
   tree, revisit detection's rule, so that no other tree could pass it) and their difference
   passes that gate. The one with fewer sightings is
   marginalised out and its measurements relabelled, with no update: nothing moves, and a
   pair the filter is unsure of (a return after drift) is left to the constellation match,
   which corrects the drift as it merges.

Every check that reaches step 2 is recorded as a `ClosureEvent` (accepted or why not).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from slam import rigid, se2
from slam.config import ClosureConfig
from slam.scan_candidates import revisit_spread, view_bounds
from slam.se2 import procrustes_2d

__all__ = [
    "BASIS",
    "HOLD_TOL_M",
    "OUTCOMES",
    "ClosureConfig",
    "ClosureDecision",
    "ClosureEvent",
    "LoopCloser",
    "Revisit",
    "closure_counts",
    "dead_reckoned_cov",
    "hypotheses",
]

OUTCOMES = ("accepted", "not jointly compatible", "beyond dead reckoning", "no margin", "too few")

# Landmarks searched around an old one for its nearest other tree (revisit detection): more
# than a tree is ever mapped over in a run
NEIGHBOURS = 16

# Two landmarks closer than this are one tree mapped twice unless the laser has seen both in
# one scan (the measure of trees mapped twice, `experiments.eval.map_quality`)
SAME_TREE_M = 1.5

# After a re-registration the old map is held in place at every scan once its rigid motion
# since the last hold moves it by more than this (RMS, m): the laser's range resolution
HOLD_TOL_M = 0.01

# Recent landmarks whose pairs propose transforms (the most-seen first): 10 give 90 ordered
# pairs; one right pair is enough, and the cost grows with the square of this.
BASIS = 10


@dataclass(frozen=True)
class ClosureEvent:
    """One constellation match: scan index, time, recent and old landmarks offered, the best
    and second-best hypotheses' landmark counts, the transform (rotation deg, centroid shift
    m), the outcome (`OUTCOMES`), the joint NIS and its bound; when the filter refuses and
    re_register is on, the dead-reckoning and rigid-fit NIS with their bounds and whether the
    local map was re-registered (NaN / False where not reached)."""

    scan: int
    t_s: float
    n_recent: int
    n_old: int
    best: int
    second: int
    rotation_deg: float
    shift_m: float
    outcome: str
    nis: float = math.nan
    nis_bound: float = math.nan
    drift_nis: float = math.nan
    drift_bound: float = math.nan
    shape_nis: float = math.nan
    shape_bound: float = math.nan
    re_registered: bool = False
    merged: list = field(default_factory=list)  # [(kept old id, dropped recent id)]

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True, eq=False)
class Revisit:
    """Revisit detection's answer for one scan (`LoopCloser.revisit`, module doc step 1):
    hidden (n,) bool over the state's landmarks, those the scan's association must not pair
    (None: none); n_hidden how many."""

    hidden: np.ndarray | None = None
    n_hidden: int = 0


@dataclass(frozen=True, eq=False)
class ClosureDecision:
    """What loop closure did after one scan (`LoopCloser.close`): the constellation match
    tried (None: none), and the duplicate sweep's merges [(kept id, dropped id, scan)]."""

    event: ClosureEvent | None = None
    duplicates: tuple = ()


def closure_counts(events: list[dict], duplicates: list | None = None) -> dict:
    """A run's matches (`ClosureEvent.to_dict()` each): how many were tried, how many ended in
    each outcome (keys with "_" for " "), and the landmarks they merged; duplicates: the
    duplicate sweep's merges (`SlamLog.closure_duplicates`), counted as duplicates_merged."""
    out = {"tried": len(events)}
    for outcome in OUTCOMES:
        out[outcome.replace(" ", "_")] = sum(e["outcome"] == outcome for e in events)
    out["landmarks_merged"] = sum(len(e["merged"]) for e in events)
    out["duplicates_merged"] = len(duplicates or [])
    return out


class LoopCloser:
    """Loop closure as one component with two calls per scan (see the module doc): before
    the scan's association, `revisit(state, k)` says which old landmarks it must not pair
    (the predicted pose's view); after the scan's map management, `close(state, k, updated,
    revisit)` tries a match and sweeps duplicates, and says what it did. `events` and
    `duplicates` hold the run's decisions so far."""

    def __init__(
        self, cfg: ClosureConfig, view, laser, history, *, gate_prob: float, hold_frame=True
    ) -> None:
        """history: the run's `slam.history.RunHistory` (scan times, odometry, first scans,
        sightings; merges go to it); gate_prob: the new-feature gate's probability (revisit
        detection's gate); hold_frame False: leave the world frame free after a
        re-registration (module doc, step 4, without holding the old map; to measure what
        holding it does)."""
        self.cfg, self.view, self.laser, self.history = cfg, view, laser, history
        self.hold_frame = bool(hold_frame)
        self.scan_t = history.scan_t
        self.gate_radius = math.sqrt(_chi2_ppf(gate_prob, 2))  # in sds, 2 dof
        # (None: a closer used without a view, by its parts' tests; the steps that need it ask)
        self._view_bounds = None if view is None else view_bounds(view)
        self.events: list[ClosureEvent] = []
        self._together: dict[int, set] = {}  # id -> ids within SAME_TREE_M seen in one scan
        self._frame = None  # after a re-registration: (ids, positions) of the old map held
        self.duplicates: list[tuple[int, int, int]] = []  # (kept id, dropped id, scan)

    def close(self, state, k: int, updated: np.ndarray, revisit: Revisit) -> ClosureDecision:
        """After scan k's map management: `updated` the ids of the landmarks the scan updated,
        `revisit` what `revisit(state, k)` said before its association. Returns the match tried
        (if any) and the duplicates merged."""
        n_dup = len(self.duplicates)
        event = self._close(state, k, updated, revisit.n_hidden)
        return ClosureDecision(event, tuple(self.duplicates[n_dup:]))

    def _close(self, state, k: int, updated: np.ndarray, n_hidden: int) -> ClosureEvent | None:
        t = float(self.scan_t[k])
        self.history.mark_seen(updated, t)
        self.history.mark_seen(state.landmark_ids, t, only_new=True)  # joined this scan: seen now
        self.seen_together(state, updated)
        if self._frame is not None:
            self._hold_frame(state, self._frame, tol_m=HOLD_TOL_M)
        if k % self.cfg.every_scans:
            return None
        self._sweep_duplicates(state, k)
        passed_by = None
        if n_hidden < self.cfg.min_pairs:
            passed_by = self.passed_by(state, t)
            if passed_by.size < self.cfg.min_pairs:
                return None  # the per-scan association can still pair what is in view
        recent, old = self.candidates(state, t, passed_by=passed_by)
        if recent.size < self.cfg.min_pairs or old.size < self.cfg.min_pairs:
            return None
        event = self.match(state, k, recent, old)
        self.events.append(event)
        return event

    def revisit(self, state, k: int) -> Revisit:
        """Revisit detection (module doc, step 1): the landmarks the scan's association must
        not pair, a mask over the state's landmarks (`Revisit`). An old landmark in view is
        hidden when its gate at the new-feature level (radius sqrt(chi2_2) x the largest
        metric sd of its predicted measurement, range and range x bearing) reaches half the
        distance to the nearest other tree in the map (the nearest landmark farther than
        match_m, and within SAME_TREE_M one seen in the same scan as this one,
        `seen_together`): a measurement of that tree could then fall in its gate, and the
        per-scan association cannot tell them apart. Those are left to the constellation
        match, which pairs many at once."""
        t = float(self.scan_t[k])
        ids = state.landmark_ids
        if ids.size < 2:
            return Revisit()
        cand, sd = revisit_spread(  # the old landmarks in view, their predictions' sds
            state.P_lower,
            state.landmarks_xy,
            self.history.seen_at(ids, t),
            t - self.cfg.old_s,
            se2.sensor_numbers(state.pose, self.laser),
            float(self.laser[2]),
            float(state.pose[2]),
            self._view_bounds,
        )
        if not cand.size:
            return Revisit()
        out = np.zeros(ids.size, bool)
        out[cand] = self.gate_radius * sd >= 0.5 * self._nearest_other_tree(state, cand)
        n_hidden = int(out.sum())
        return Revisit(out, n_hidden) if n_hidden else Revisit()

    def _nearest_other_tree(self, state, pos: np.ndarray) -> np.ndarray:
        """(len(pos),) the distance from each landmark at state positions `pos` to the
        nearest other tree in the map (inf if none): the nearest landmark farther than
        match_m, and within SAME_TREE_M only one the laser has seen in the same scan as this
        one (`seen_together`); a landmark closer, or never seen with it, is this tree mapped
        again."""
        xy, ids = state.landmarks_xy, state.landmark_ids
        out, close, d, j = _nearest_far(
            np.ascontiguousarray(xy), pos, min(NEIGHBOURS, ids.size), self.cfg.match_m
        )
        for r in np.flatnonzero(close.any(axis=1)).tolist():
            together = self._together.get(int(ids[pos[r]]), ())
            for q, dq in zip(j[r, close[r]].tolist(), d[r, close[r]].tolist()):
                if int(ids[q]) in together:  # seen in one scan with it: another tree
                    out[r] = dq
                    break
        return out

    def seen_together(self, state, updated: np.ndarray) -> None:
        """Record the pairs of landmarks within SAME_TREE_M of each other that this scan
        updated both of: the laser saw them as two trees."""
        if updated.size < 2:
            return
        xy = state.landmarks_xy[state.positions_of(updated)]
        for a, b in _pairs_within(xy, SAME_TREE_M).tolist():
            ia, ib = int(updated[a]), int(updated[b])
            self._together.setdefault(ia, set()).add(ib)
            self._together.setdefault(ib, set()).add(ia)

    def passed_by(self, state, t: float) -> np.ndarray:
        """Revisit detection's second signature (module doc, step 1): the positions of the
        landmarks in view that no scan has updated for recent_s seconds while landmarks joined
        the map within max_offset_m of them (the largest shift of the recent map's centroid
        that the constellation match allows): the per-scan association passes them by and
        maps their trees again."""
        cfg, ids, xy = self.cfg, state.landmark_ids, state.landmarks_xy
        stale = np.flatnonzero(self.history.seen_at(ids, t) < t - cfg.recent_s)
        young = np.flatnonzero(self._joined_at(ids) >= t - cfg.recent_s)
        if stale.size < cfg.min_pairs or young.size < cfg.min_pairs:
            return np.zeros(0, np.int64)
        z_hat, _ = se2.observe(state.pose, xy[stale], self.laser)
        stale = stale[self.view.contains(z_hat, margins=False)]
        if not stale.size:
            return stale
        d, _ = cKDTree(xy[young]).query(xy[stale], distance_upper_bound=cfg.max_offset_m)
        return stale[np.isfinite(d)]

    def candidates(
        self,
        state,
        t: float,
        in_view: bool = True,
        since: float | None = None,
        passed_by: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(positions of recent landmarks within range, of old landmarks in view; with
        in_view False, every recent and old landmark). since: the excursion began then:
        recent means joined after it, and a landmark last seen by then is old too (a match on
        passed-by landmarks, `passed_by`, begins its excursion less than old_s ago);
        passed_by: positions that count as old too."""
        cfg, ids = self.cfg, state.landmark_ids
        t_joined = self._joined_at(ids)
        seen = self.history.seen_at(ids, t)
        old = seen < t - cfg.old_s
        if since is not None:
            old |= seen <= since
        if passed_by is not None:
            old[passed_by] = True
        recent = (t_joined >= t - cfg.recent_s if since is None else t_joined > since) & ~old
        if in_view:
            z_hat, _ = se2.observe(state.pose, state.landmarks_xy, self.laser)
            recent &= z_hat[:, 0] <= self.view.max_range
            old &= self.view.contains(z_hat, margins=False)
        return np.flatnonzero(recent), np.flatnonzero(old)

    def match(self, state, k: int, recent: np.ndarray, old: np.ndarray) -> ClosureEvent:
        """The constellation match of scan k (module doc, steps 2-4) between the recent and
        the old landmarks at state positions `recent` and `old` (`candidates`), and, when it
        is accepted, the merges and the sweep: the decision as a `ClosureEvent`."""
        cfg = self.cfg
        xy = state.landmarks_xy
        # the most-seen recent landmarks first: they propose the hypotheses (BASIS of them)
        seen = np.array([self.history.n_obs.get(int(i), 0) for i in state.landmark_ids[recent]])
        recent = recent[np.argsort(-seen, kind="stable")]
        centroid = xy[recent].mean(axis=0)
        best, second, rot, txy, pairs = hypotheses(
            np.ascontiguousarray(xy[recent]),
            np.ascontiguousarray(xy[old]),
            np.array(
                [
                    cfg.match_m,
                    cfg.min_sep_m,
                    math.radians(cfg.max_rotation_deg),
                    cfg.max_offset_m,
                    BASIS,
                ]
            ),
        )
        common = dict(
            re_registered=False,
            scan=k,
            t_s=float(self.scan_t[k]),
            n_recent=int(recent.size),
            n_old=int(old.size),
            best=int(best),
            second=int(second),
            rotation_deg=math.degrees(rot),
            shift_m=float(np.hypot(*(se2.rotate(rot, centroid) + txy - centroid))),
        )
        if best < cfg.min_pairs:
            return ClosureEvent(**common, outcome="too few")
        if best - second < cfg.margin:
            return ClosureEvent(**common, outcome="no margin")
        if pairs.shape[0] < cfg.min_pairs:  # too few left once the unclear pairs are out
            return ClosureEvent(**common, outcome="too few")
        keep = state.landmark_ids[old[pairs[:, 1]]].copy()
        drop = state.landmark_ids[recent[pairs[:, 0]]].copy()
        t_from = float(self.history.seen_at(keep, math.nan).max())  # the excursion began
        common["nis"] = rigid.same_landmarks_nis(state, keep, drop)
        common["nis_bound"] = float(_chi2_ppf(cfg.jc_prob, 2 * keep.size))
        if not common["nis"] <= common["nis_bound"]:
            if not cfg.re_register:
                return ClosureEvent(**common, outcome="not jointly compatible")
            C = self._dead_reckoning(k, t_from)
            common |= self._drift_test(state, C, (rot, txy))
            if not common["drift_nis"] <= common["drift_bound"]:
                return ClosureEvent(**common, outcome="beyond dead reckoning")
            shape, _, _ = rigid.rigid_fit(state, keep, drop, cfg.tree_sd_m)
            common |= {
                "shape_nis": shape,
                "shape_bound": float(_chi2_ppf(cfg.jc_prob, 2 * keep.size - 3)),
            }
            if not shape <= common["shape_bound"]:
                return ClosureEvent(**common, outcome="not jointly compatible")
            self._free_local_map(state, k, t_from, C)
            common["re_registered"] = True
        anchor = self._anchor(state, t_from) if common["re_registered"] else None
        merged = self.merge(state, keep, drop, common["t_s"])
        if anchor is not None and self.hold_frame:
            self._hold_frame(state, anchor)
            self._frame = anchor
        merged += self._sweep(state, common["t_s"], t_from, local=common["re_registered"])
        return ClosureEvent(**common, outcome="accepted", merged=merged)

    def _drift_test(self, state, C: np.ndarray, motion: tuple) -> dict:
        """Whether dead reckoning could have drifted as far as the match says (module doc,
        step 3): the correction the motion (rotation about the origin, then translation) makes
        to the vehicle's pose, d, against the covariance C of the odometry alone since the
        matched old landmarks were last seen (`dead_reckoned_cov` over the logged increments,
        plus the filter's pose covariance then; `_dead_reckoning`): d^T C^-1 d within
        chi-square(3) at jc_prob."""
        rot, txy = motion
        p = state.pose
        d = np.array([*(se2.rotate(rot, p[:2]) + txy - p[:2]), rot])
        try:
            v = np.linalg.solve(np.linalg.cholesky(C), d)
        except np.linalg.LinAlgError:  # no odometry noise: dead reckoning allows no drift
            v = np.full(3, np.inf)
        return {"drift_nis": float(v @ v), "drift_bound": float(_chi2_ppf(self.cfg.jc_prob, 3))}

    def _dead_reckoning(self, k: int, t_from: float) -> np.ndarray:
        """(3, 3) the world-frame covariance of the vehicle's pose at scan k from the odometry
        alone since time t_from (`dead_reckoned_cov`), plus the filter's pose covariance
        then."""
        a = int(np.searchsorted(self.scan_t, t_from))
        C = dead_reckoned_cov(self.history.odo_delta, self.history.odo_cov, a, k)
        c, s = math.cos(self.history.pred_pose[a][2]), math.sin(self.history.pred_pose[a][2])
        A = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # frame of scan a -> world
        return A @ C @ A.T + self.history.pred_pose_cov[a]

    def _joined_at(self, ids) -> np.ndarray:
        """The time each landmark joined the map (-inf if unknown)."""
        get, ids = self.history.first_scan.get, np.asarray(ids, np.int64).reshape(-1)
        joined = np.fromiter((get(i, -1) for i in ids.tolist()), np.int64, ids.size)
        return np.where(joined >= 0, self.scan_t[np.maximum(joined, 0)], -np.inf)

    def _free_local_map(self, state, k: int, t_from: float, cov: np.ndarray) -> None:
        """Re-registration (module doc, step 3): the drift dead reckoning allows since t_from
        (when the matched old landmarks were last seen; cov from `_dead_reckoning`, a covariance
        of the vehicle's pose, so a rigid motion about the vehicle) is added to the vehicle and to
        every landmark mapped since, grown as a random walk: a landmark mapped at t_join
        shares (t_join - t_from) / (t - t_from) of it (`slam.rigid.free_rigid_motion`)."""
        t = float(self.scan_t[k])
        ids = state.landmark_ids
        t_joined = self._joined_at(ids)
        sel = np.flatnonzero(t_joined > t_from)
        shares = np.clip((t_joined[sel] - t_from) / max(t - t_from, 1e-9), 0.0, 1.0)
        rigid.free_rigid_motion(state, ids[sel], state.pose[:2].copy(), cov, shares)

    def _anchor(self, state, t_from: float) -> tuple[np.ndarray, np.ndarray] | None:
        """(ids, positions) of the landmarks mapped before t_from (the old map the excursion's
        freed landmarks are merged into), or None when fewer than two."""
        ids = state.landmark_ids
        old = np.flatnonzero(self._joined_at(ids) <= t_from)
        return (ids[old].copy(), state.landmarks_xy[old].copy()) if old.size >= 2 else None

    def _hold_frame(self, state, anchor: tuple[np.ndarray, np.ndarray], tol_m: float = 0.0) -> None:
        """After a re-registration's merge, and at every scan after it (module doc, step 4):
        move the whole estimate by the rigid motion that puts the old map back where it was
        (least squares over `anchor`, from `_anchor` before the merge; its landmarks no longer
        in the map are left out), unless that motion moves the old map by at most tol_m
        (RMS). The freed excursion's covariance lets the merge move the old map as one piece
        too, a motion of the world frame that nothing observes and that would shift the map
        away from the path already logged; and under first-estimates Jacobians, whose
        linearisation points the re-registration has left metres apart, the updates after it
        keep moving it (on Victoria Park, by 1.3 deg within 30 scans)."""
        ids, before = anchor
        pos = state.positions_of(ids)
        there = pos >= 0
        if there.sum() < 2:
            return
        now, before = state.landmarks_xy[pos[there]], before[there]
        theta, t = procrustes_2d(now, before)
        shift = se2.rotate(theta, now) + t - now
        if tol_m > 0.0 and math.sqrt(np.mean(np.sum(shift**2, axis=1))) <= tol_m:
            return
        rigid.move_rigidly(state, theta, t)

    def merge(self, state, keep, drop, t: float, update: bool = True) -> list[tuple[int, int]]:
        """Landmarks `drop` are landmarks `keep` (ids, pair by pair), found at time t: merged by
        an update (`slam.rigid.merge_landmarks`), or with update False only marginalised out;
        the history relabels them. Returns the pairs [(kept, dropped)]."""
        if update:
            rigid.merge_landmarks(state, keep, drop)
        else:
            state.remove_landmarks(drop)
        merged = [(int(a), int(b)) for a, b in zip(keep, drop)]
        for a, b in merged:
            self.history.merged(drop=b, keep=a)
            self.history.mark_seen([a], t)
        return merged

    def _in_range(self, state) -> np.ndarray:
        """(n,) bool: the landmarks within the laser's range of the vehicle."""
        return np.hypot(*(state.landmarks_xy - state.pose[:2]).T) <= self.view.max_range

    def _sweep_duplicates(self, state, k: int) -> None:
        """The duplicate sweep (module doc, step 5): pairs of landmarks within the laser's
        range of the vehicle, closer than match_m to each other, that no scan has updated
        both of (`seen_together`), whose gate (2 dof at jc_prob, tree_sd_m added to each)
        stops short of half the way to the nearest other tree (`_nearest_other_tree`) and
        whose difference passes it: the one with fewer sightings is marginalised out and its
        measurements relabelled (no update). Nearest pairs first, each landmark in one pair
        at most."""
        xy, ids = state.landmarks_xy, state.landmark_ids
        near = np.flatnonzero(self._in_range(state))
        if near.size < 2:
            return
        pairs = np.array(sorted(cKDTree(xy[near]).query_pairs(self.cfg.match_m)), np.int64)
        if not pairs.size:
            return
        pairs = near[pairs]
        order = np.argsort(np.hypot(*(xy[pairs[:, 0]] - xy[pairs[:, 1]]).T), kind="stable")
        pairs = pairs[order]
        d_nn = self._nearest_other_tree(state, pairs.reshape(-1)).reshape(-1, 2).min(axis=1)
        gate = _chi2_quantile(self.cfg.jc_prob, 2)
        keep, drop, used = [], [], set()
        for (a, b), reach in zip(pairs, 0.5 * d_nn):
            ia, ib = int(ids[a]), int(ids[b])
            if ia in used or ib in used or ib in self._together.get(ia, ()):
                continue
            d, S = rigid.pair_difference(state, [ia], [ib], self.cfg.tree_sd_m)
            # only a pair whose gate stops short of half the way to the nearest other tree
            # (revisit detection's rule): no other tree could pass it
            if gate * np.linalg.eigvalsh(S)[-1] >= reach**2:
                continue
            if d @ np.linalg.solve(S, d) > gate:
                continue
            n_a, n_b = self.history.n_obs.get(ia, 0), self.history.n_obs.get(ib, 0)
            kept, dropped = (ia, ib) if (n_a, -ia) >= (n_b, -ib) else (ib, ia)
            keep.append(kept)
            drop.append(dropped)
            used |= {ia, ib}
        if keep:
            self.merge(state, keep, drop, float(self.scan_t[k]), update=False)
            self.duplicates += [(a, b, k) for a, b in zip(keep, drop)]

    def _sweep(self, state, t: float, since: float, local: bool) -> list[tuple[int, int]]:
        """After a closure, the other trees mapped twice (module doc, step 4): each landmark
        mapped since `since` (not old) with exactly one old landmark (`candidates`: unseen
        for old_s or since `since`) within 2 x match_m, closer than match_m and individually
        compatible with it (2 dof at jc_prob), merged in one batch if the batch is jointly
        compatible too. local (after a re-registration): only landmarks within the laser's
        range of the vehicle, and the duplicates are marginalised out instead of merged by an
        update."""
        recent, old = self.candidates(state, t, in_view=False, since=since)
        if local:
            inside = self._in_range(state)
            recent, old = recent[inside[recent]], old[inside[old]]
        if not (recent.size and old.size):
            return []
        xy, ids = state.landmarks_xy, state.landmark_ids
        d = np.hypot(*(xy[recent][:, None, :] - xy[old][None, :, :]).transpose(2, 0, 1))
        gate = _chi2_quantile(self.cfg.jc_prob, 2)
        keep, drop = [], []
        for i in range(recent.size):
            near = np.flatnonzero(d[i] < 2.0 * self.cfg.match_m)
            if near.size != 1 or d[i, near[0]] >= self.cfg.match_m:
                continue
            a, b = int(ids[old[near[0]]]), int(ids[recent[i]])
            if a in keep or rigid.same_landmarks_nis(state, [a], [b]) > gate:
                continue
            keep.append(a)
            drop.append(b)
        if not keep:
            return []
        if rigid.same_landmarks_nis(state, keep, drop) > _chi2_ppf(self.cfg.jc_prob, 2 * len(keep)):
            return []
        return self.merge(state, keep, drop, t, update=not local)


@njit(cache=True)
def _pairs_within(xy: np.ndarray, r: float) -> np.ndarray:
    """(p, 2) the pairs [a, b], a < b, in row order, of the points xy (n, 2) at most r apart
    (np.hypot's distance): one pass, where the n x n distance matrix cost more than the few
    points it holds."""
    n = xy.shape[0]
    out = np.empty((n * (n - 1) // 2, 2), np.int64)
    p = 0
    for a in range(n):
        for b in range(a + 1, n):
            if np.hypot(xy[a, 0] - xy[b, 0], xy[a, 1] - xy[b, 1]) <= r:
                out[p, 0], out[p, 1] = a, b
                p += 1
    return out[:p]


def _chi2_ppf(prob: float, dof: int):
    """scipy's `chi2.ppf(prob, dof)`, scipy.stats imported on first use: its import costs
    about a second of CPU, and every command that imports the run loop imports this module,
    while only a run with closure asks for a quantile."""
    from scipy.stats import chi2

    return chi2.ppf(prob, dof)


@functools.lru_cache(maxsize=32)
def _chi2_quantile(prob: float, dof: int) -> float:
    """float(chi2.ppf(prob, dof)), kept: the duplicate sweep asks for the same one at every
    sweep, and scipy's ppf costs more than the sweep's own arithmetic."""
    return float(_chi2_ppf(prob, dof))


@njit(cache=True)
def _nearest_far(xy: np.ndarray, pos: np.ndarray, k: int, match_m: float):
    """`LoopCloser._nearest_other_tree`'s search: for each landmark xy[pos[r]], its k nearest
    (`_k_nearest`: d, j (q, k), nearest first), the nearest farther than SAME_TREE_M (and
    than match_m), inf if none (q,), and which of the k are closer, but farther than match_m
    (close (q, k)): d ascends along each row, so the first such entry is the answer unless a
    close one is another tree."""
    q = pos.size
    query = np.empty((q, 2))
    for r in range(q):
        query[r, 0], query[r, 1] = xy[pos[r], 0], xy[pos[r], 1]
    d, j = _k_nearest(xy, query, k)
    out = np.full(q, np.inf)
    close = np.zeros((q, k), np.bool_)
    for r in range(q):
        found = False
        for c in range(k):
            if d[r, c] > match_m:
                if d[r, c] <= SAME_TREE_M:
                    close[r, c] = True
                elif not found:
                    out[r], found = d[r, c], True
    return out, close, d, j


@njit(cache=True)
def _k_nearest(xy: np.ndarray, query: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(d (q, k), j (q, k)): the k points of xy (n, 2) nearest each of query (q, 2), nearest
    first (equal distances in index order), their Euclidean distances and indices; k <= n.
    A brute-force pass over the n points (the map holds hundreds) in place of building a k-d
    tree every scan: the squared distance is summed as `scipy.spatial.cKDTree` sums it
    (0 + dx^2, + dy^2), so the distances are its own to the bit."""
    q, n = query.shape[0], xy.shape[0]
    d2 = np.full((q, k), np.inf)
    j = np.zeros((q, k), np.int64)
    for r in range(q):
        for i in range(n):
            dx = query[r, 0] - xy[i, 0]
            dy = query[r, 1] - xy[i, 1]
            s = dx * dx + dy * dy
            if not s < d2[r, k - 1]:
                continue
            p = k - 1  # insertion into the sorted k nearest, after equal ones
            for _ in range(k - 1):
                if d2[r, p - 1] <= s:
                    break
                d2[r, p], j[r, p] = d2[r, p - 1], j[r, p - 1]
                p -= 1
            d2[r, p], j[r, p] = s, i
    return np.sqrt(d2), j


@njit(cache=True, nogil=True)
def dead_reckoned_cov(delta: np.ndarray, cov: np.ndarray, a: int, b: int) -> np.ndarray:
    """(3, 3) the covariance of the pose at scan b relative to the pose at scan a (frame of a)
    from the odometry alone: the increments delta[k] (N, 3) with covariances cov[k] (N, 3, 3),
    k = a + 1 .. b, each in the frame of scan k - 1, composed to first order."""
    x = y = th = 0.0
    S = np.zeros((3, 3))
    J1 = np.eye(3)
    J2 = np.eye(3)
    for k in range(a + 1, b + 1):
        c, s = math.cos(th), math.sin(th)
        dx, dy = delta[k, 0], delta[k, 1]
        J1[0, 2] = -(s * dx + c * dy)
        J1[1, 2] = c * dx - s * dy
        J2[0, 0], J2[0, 1], J2[1, 0], J2[1, 1] = c, -s, s, c
        S = J1 @ S @ J1.T + J2 @ cov[k] @ J2.T
        x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, th + delta[k, 2]
    return S


@njit(cache=True, nogil=True)
def hypotheses(recent, old, prm):
    """The constellation match of the module doc, step 2. recent (n, 2), old (m, 2); prm:
    [match_m, min_sep_m, max_rotation_rad, max_offset_m, basis]: pairs of the first `basis`
    recent landmarks propose the transforms, every recent one scores them. Returns (best
    count, second-best count, the best motion: rotation phi (rad) about the origin then
    translation (tx, ty) (2,), pairs (k, 2): [recent index, old index], each landmark at most
    once, nearest first)."""
    match, min_sep, max_rot, max_off, basis = prm
    nb = min(recent.shape[0], int(basis))
    cx, cy = recent[:, 0].mean(), recent[:, 1].mean()
    # every hypothesis's count and where it puts the recent centroid
    cap = 4096
    counts = np.zeros(cap, np.int64)
    where = np.zeros((cap, 2))
    params = np.zeros((cap, 3))
    pa, pb, pd, start, orig = _pairs_by_length(old, match)
    n_pairs = pd.size
    key = np.zeros(cap, np.int64)
    h = 0
    for i in range(nb):
        for j in range(nb):
            if i == j:
                continue
            dx, dy = recent[j, 0] - recent[i, 0], recent[j, 1] - recent[i, 1]
            d = math.hypot(dx, dy)
            if d < min_sep:
                continue
            ang_r = math.atan2(dy, dx)
            lo = min(int((d - match) / match), start.size - 1)
            hi = min(int((d + match) / match) + 1, start.size - 1)
            for q in range(start[max(lo, 0)], start[hi]):
                if abs(pd[q] - d) > match:
                    continue
                a, b = pa[q], pb[q]
                ex, ey = old[b, 0] - old[a, 0], old[b, 1] - old[a, 1]
                phi = math.atan2(ey, ex) - ang_r
                phi = math.atan2(math.sin(phi), math.cos(phi))
                if abs(phi) > max_rot:
                    continue
                c, s = math.cos(phi), math.sin(phi)
                tx = old[a, 0] - (c * recent[i, 0] - s * recent[i, 1])
                ty = old[a, 1] - (s * recent[i, 0] + c * recent[i, 1])
                px, py = c * cx - s * cy + tx, s * cx + c * cy + ty
                if math.hypot(px - cx, py - cy) > max_off:
                    continue
                if h == cap:  # grow
                    counts = np.concatenate((counts, np.zeros(cap, np.int64)))
                    where = np.concatenate((where, np.zeros((cap, 2))))
                    params = np.concatenate((params, np.zeros((cap, 3))))
                    key = np.concatenate((key, np.zeros(cap, np.int64)))
                    cap *= 2
                counts[h] = _inliers(recent, old, c, s, tx, ty, match)
                where[h, 0], where[h, 1] = px, py
                params[h, 0], params[h, 1], params[h, 2] = phi, tx, ty
                key[h] = (i * nb + j) * n_pairs + orig[q]  # the order of an (a, b) scan
                h += 1
    if h == 0:
        return 0, 0, 0.0, np.zeros(2), np.zeros((0, 2), np.int64)
    kbest = 0  # the most landmarks; of equals, the first in (i, j, a, b) order
    for q in range(1, h):
        if counts[q] > counts[kbest] or (counts[q] == counts[kbest] and key[q] < key[kbest]):
            kbest = q
    second = 0
    for q in range(h):
        far = math.hypot(where[q, 0] - where[kbest, 0], where[q, 1] - where[kbest, 1]) > match
        if far and counts[q] > second:
            second = counts[q]
    phi, tx, ty = params[kbest, 0], params[kbest, 1], params[kbest, 2]
    pairs = _pairs(recent, old, math.cos(phi), math.sin(phi), tx, ty, match)
    return counts[kbest], second, phi, params[kbest, 1:].copy(), pairs


@njit(cache=True, nogil=True)
def _pairs_by_length(old, width):
    """Every ordered pair (a, b), a != b, of the old landmarks with its length, sorted into
    bins of `width` by length (a counting sort): (a (P,), b (P,), length (P,), start (bins +
    1,)); the pairs of bin k are start[k]:start[k + 1]."""
    m = old.shape[0]
    n = m * (m - 1)
    pa = np.empty(n, np.int64)
    pb = np.empty(n, np.int64)
    pd = np.empty(n)
    q = 0
    for a in range(m):
        for b in range(m):
            if a != b:
                pa[q], pb[q] = a, b
                pd[q] = math.hypot(old[b, 0] - old[a, 0], old[b, 1] - old[a, 1])
                q += 1
    bins = (pd / width).astype(np.int64) if n else np.zeros(0, np.int64)
    nbins = (bins.max() + 2) if n else 1
    start = np.zeros(nbins + 1, np.int64)
    for k in bins:
        start[k + 1] += 1
    start = np.cumsum(start)
    order = np.empty(n, np.int64)
    fill = start[:-1].copy()
    for q in range(n):
        order[fill[bins[q]]] = q
        fill[bins[q]] += 1
    return pa[order], pb[order], pd[order], start, order


@njit(cache=True, nogil=True)
def _inliers(recent, old, c, s, tx, ty, match):
    """How many recent landmarks the transform puts within `match` of an old one."""
    cnt = 0
    m2 = match * match
    for i in range(recent.shape[0]):
        px = c * recent[i, 0] - s * recent[i, 1] + tx
        py = s * recent[i, 0] + c * recent[i, 1] + ty
        for a in range(old.shape[0]):
            ex, ey = old[a, 0] - px, old[a, 1] - py
            if ex * ex + ey * ey < m2:
                cnt += 1
                break
    return cnt


@njit(cache=True, nogil=True)
def _pairs(recent, old, c, s, tx, ty, match):
    """One-to-one pairs [recent, old] within `match` under the transform, nearest first; a
    recent landmark with two old ones within 2 x match is left out (which one is unclear)."""
    n, m = recent.shape[0], old.shape[0]
    cand_d = []
    cand_i = []
    cand_a = []
    for i in range(n):
        px = c * recent[i, 0] - s * recent[i, 1] + tx
        py = s * recent[i, 0] + c * recent[i, 1] + ty
        best, best_a, near = math.inf, -1, 0
        for a in range(m):
            dd = math.hypot(old[a, 0] - px, old[a, 1] - py)
            if dd < 2.0 * match:
                near += 1
            if dd < best:
                best, best_a = dd, a
        if best < match and near == 1:
            cand_d.append(best)
            cand_i.append(i)
            cand_a.append(best_a)
    order = np.argsort(np.array(cand_d)) if len(cand_d) else np.zeros(0, np.int64)
    used_r = np.zeros(n, np.bool_)
    used_o = np.zeros(m, np.bool_)
    out = np.zeros((len(cand_d), 2), np.int64)
    k = 0
    for q in order:
        i, a = cand_i[q], cand_a[q]
        if used_r[i] or used_o[a]:
            continue
        used_r[i] = True
        used_o[a] = True
        out[k, 0], out[k, 1] = i, a
        k += 1
    return out[:k]
