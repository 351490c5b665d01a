"""Map managers: who associates a scan's measurements and decides what joins the map. One per
run, chosen once from the `[association]` and `[map_policy]` sections (`make_map_manager`),
interchangeable behind one contract (`MapManager`):

- `associate(state, meas, drift, hidden)`: which landmark (or tentative) each measurement
  belongs to (`ScanAssociation`); `hidden`: landmarks it must not pair (loop closure's);
- `manage(state, meas, a, paired)`: tentatives seen again count a sighting, new measurements
  start landmarks-to-be, confirmed ones join the filter's state; returns its decisions
  (`MapDecisions`) and changes no array of the loop's or the log's;
- `n_pending`, `tentative_xy`, `stats()`: what is pending, where, and the run's figures.

`TentativeMap` (association "ihgr", "jcbb", "nn") keeps new features as tentatives outside the
state until they have been associated in `MapPolicy.confirm_scans` scans (`slam.tentatives`).
`WindowMap` ("ihgr-window") gives that job to the K-scan `association.SlidingWindowAssociator`:
every scan it is offered the landmarks in view and the laser's world pose with the odometry
drift over the window as its relative uncertainty; it commits the newest scan's pairings and
re-decides, over the window, which earlier unpaired measurements are first sightings of one new
landmark, which a mapped landmark missed by its own scan explains, and which are clutter.
`Pruner` removes landmarks the laser should see and does not (`MapPolicy.prunes`).
With map policy "existence" (`slam.existence_map`) both join by existence instead of counts
and report the landmarks whose existence fell below remove_prob (`MapDecisions.removed`).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from association import gate_matrix
from slam import se2
from slam.ekf import Filter, landmark_columns
from slam.errors import SlamError
from slam.existence_map import LandmarkExistence, radii
from slam.log import AMBIGUOUS, CONFIRMED, OUT_OF_RANGE, TENTATIVE_HIT
from slam.scan_candidates import project_blocks, scan_candidates, view_bounds
from slam.sources import Measurements
from slam.tentatives import MapPolicy, Tentatives, sighting

log = logging.getLogger(__name__)

__all__ = [
    "MapDecisions",
    "MapManager",
    "ScanAssociation",
    "Pruner",
    "TentativeMap",
    "View",
    "WindowMap",
    "make_map_manager",
]

_POSE = np.array([0, 1, 2], np.int64)


@dataclass(frozen=True)
class View:
    """What the laser can see: fov (first, last beam angle, rad, laser frame), max_range (m),
    and the margins (m, rad) within which a landmark outside is still offered."""

    fov: tuple[float, float]
    max_range: float
    margin_m: float = 0.0
    margin_rad: float = 0.0

    def contains(self, z_hat: np.ndarray, margins: bool = True, max_range: float | None = None):
        """(n,) bool: predictions z_hat (n, 2) within range and field of view (plus the margins
        when `margins`; `max_range` below the view's own when given)."""
        if z_hat.shape[0] == 0:
            return np.zeros(0, bool)
        m_rad, m_m = (self.margin_rad, self.margin_m) if margins else (0.0, 0.0)
        fov0, fov1 = self.fov
        b = z_hat[:, 1]
        in_fov = (b >= fov0 - m_rad) & (b <= fov1 + m_rad)
        if fov1 - fov0 + 2 * m_rad >= 2 * math.pi:
            in_fov[:] = True
        r = self.max_range if max_range is None else min(self.max_range, max_range)
        return in_fov & (z_hat[:, 0] <= r + m_m)


@dataclass(frozen=True, eq=False)
class ScanAssociation:
    """One scan's association: assign (m,) is an index into [landmarks in view, tentatives in
    view] or -1; ambiguous (m,) marks unassigned measurements inside the wider gate of something;
    lm_idx, t_idx: state positions of the landmarks in view and indices of the tentatives.
    Window only: sightings (m,) scans of the window that saw an unpaired measurement's landmark
    (`WindowDecision.sightings`); tracks: measurement -> [(scans_ago, measurement)] of its
    chosen new-landmark track (indices into each scan's full measurement list)."""

    assign: np.ndarray
    ambiguous: np.ndarray
    lm_idx: np.ndarray
    t_idx: np.ndarray
    sightings: np.ndarray | None = None
    tracks: dict | None = None

    def to_map(self) -> np.ndarray:
        """The measurements paired with map landmarks (not tentatives)."""
        i = np.flatnonzero(self.assign >= 0)
        return i[self.assign[i] < self.lm_idx.size]


@dataclass(frozen=True, eq=False)
class MapDecisions:
    """What a map manager decided for one scan (`manage`): status (m,) of each measurement
    (`slam.log` codes: the landmark id it updated, or tentative seen again, confirmed,
    ambiguous, new, out of range); track (m,) the landmark or tentative id it was paired with or
    started (-1: none); joined [(landmark id, n_obs)] the landmarks that joined the map in this
    scan and the scans each was seen in; retracks [(scan, measurement, landmark id)] earlier
    measurements now known to be a new landmark's (the window's); n_pending tentatives (or open
    window measurements) after the scan; removed [(landmark id, reason)] landmarks of the map
    that must leave it (map_policy "existence": reason "existence"), for the loop to
    marginalise."""

    status: np.ndarray
    track: np.ndarray
    joined: list
    retracks: list
    n_pending: int
    removed: list = field(default_factory=list)


@runtime_checkable
class MapManager(Protocol):
    """The contract of a map manager (module doc): `TentativeMap` and `WindowMap`."""

    n_pending: int
    tentative_xy: np.ndarray

    def associate(self, state, meas, drift, hidden=None) -> ScanAssociation: ...
    def manage(self, state, meas, a: ScanAssociation, paired) -> MapDecisions: ...
    def stats(self) -> dict | None: ...


@dataclass(eq=False)
class _Context:
    """What a map manager is made of: the laser's mounting, the view, the association and map
    policy settings, the next free landmark id; and, while it manages a scan, the decisions."""

    laser: np.ndarray
    view: View
    gate_new: float
    gate_prob: float
    params: dict
    policy: MapPolicy
    next_id: int = 0
    existence: LandmarkExistence | None = None  # map_policy "existence" only

    @functools.cached_property
    def view_bounds(self) -> tuple:
        """The view's bounds as the association's kernel compares them (`view_bounds`)."""
        return view_bounds(self.view)

    def new_id(self) -> int:
        self.next_id += 1
        return self.next_id - 1


@dataclass(eq=False)
class _Deciding:
    """A scan's decisions as a map manager makes them (`manage`), from the update's: status
    and track start as the measure step's status with the landmark ids the update paired
    (`paired` (m,): landmark id or -1)."""

    meas: Measurements
    laser: np.ndarray
    status: np.ndarray
    track: np.ndarray
    joined: list = field(default_factory=list)
    retracks: list = field(default_factory=list)
    removed: list = field(default_factory=list)

    @classmethod
    def after_update(cls, meas: Measurements, laser, paired: np.ndarray) -> _Deciding:
        status = np.where(paired >= 0, paired, meas.status)
        return cls(meas, laser, status, np.where(status >= 0, status, -1))

    def map_landmark(self, state: Filter, i: int, lid: int, n_obs: int) -> None:
        """Measurement i of the scan initialises landmark `lid` (seen in `n_obs` scans)."""
        state.add_landmark(self.meas.z[i], self.meas.R[i], self.laser, lid)
        self.status[i] = CONFIRMED
        self.joined.append((lid, int(n_obs)))

    def remove_unlikely(self, state: Filter, book: LandmarkExistence | None) -> None:
        """Map policy "existence": the landmarks of the map whose existence fell below
        remove_prob leave it (reported, `MapDecisions.removed`)."""
        if book is None:
            return
        ids = state.landmark_ids
        for lid in ids[book.leaves(ids)].tolist():
            self.removed.append((int(lid), "existence"))

    def done(self, n_pending: int) -> MapDecisions:
        return MapDecisions(
            self.status, self.track, self.joined, self.retracks, n_pending, removed=self.removed
        )


class TentativeMap:
    """Single-scan association (`associator`: `association.associate`'s signature minus
    `method`) against the landmarks and tentatives in view; tentatives outside the state."""

    def __init__(self, ctx: _Context, associator) -> None:
        self.ctx = ctx
        self.associator = associator
        self.tent = Tentatives.empty()

    @property
    def tentative_xy(self) -> np.ndarray:
        return self.tent.xy

    @property
    def n_pending(self) -> int:
        """Tentatives after the last scan managed."""
        return len(self.tent)

    def stats(self) -> None:
        return None

    def associate(
        self, state: Filter, meas: Measurements, drift: np.ndarray, hidden=None
    ) -> ScanAssociation:
        """The usable measurements against the landmarks and tentatives that can be in view.

        Each candidate's innovation covariance comes from its 5 x 5 block [pose, point]
        (tentatives with their own covariance and no correlation with the pose). Candidates
        that gate with no measurement, even at the wider new-feature gate, cannot be paired and
        do not make anything ambiguous, so only the others are offered to the associator, on
        the sub-state [pose, those landmarks, those tentatives]: exact, and the cost no longer
        grows with the map."""
        ctx, tent = self.ctx, self.tent
        lm_xy = state.landmarks_xy
        hidden = np.zeros(lm_xy.shape[0], bool) if hidden is None else np.asarray(hidden, bool)
        lm_idx, t_idx, use, ambiguous, cand, zh_cand, H, P_sub = scan_candidates(
            state.P_lower,
            state.pose,
            lm_xy,
            hidden,
            tent.xy,
            tent.cov,
            se2.sensor_numbers(state.pose, ctx.laser),
            float(ctx.laser[2]),
            meas.z,
            meas.R,
            meas.status != OUT_OF_RANGE,
            ctx.view_bounds,
            ctx.gate_new,
        )
        assign = np.full(meas.z.shape[0], -1, np.int64)
        if cand.size:
            z_use, R_use = meas.z[use], meas.R[use]
            a_use = self.associator(
                z_use, R_use, zh_cand, H, P_sub, gate_prob=ctx.gate_prob, **ctx.params
            )
            a_use = np.asarray(a_use, dtype=np.int64)
            assign[use] = np.where(a_use >= 0, cand[np.maximum(a_use, 0)], -1)
        ambiguous &= assign < 0
        return ScanAssociation(assign, ambiguous, lm_idx, t_idx)

    def manage(
        self, state: Filter, meas: Measurements, a: ScanAssociation, paired: np.ndarray
    ) -> MapDecisions:
        """Tentatives seen again count a sighting (and join the map at the policy's count), new
        measurements start tentatives, ambiguous ones are ignored, unseen tentatives drop out.
        paired (m,): the landmark id each measurement updated (-1: none). Returns each
        measurement's status and track (the id of the tentative it was paired with or
        started), the landmarks that joined the map and the number of tentatives."""
        ctx, tent, z, R, book = self.ctx, self.tent, meas.z, meas.R, self.ctx.existence
        out = _Deciding.after_update(meas, ctx.laser, paired)
        status, track, policy = out.status, out.track, ctx.policy
        n_l = a.lm_idx.size
        matched, matched_meas, new, new_meas = {}, {}, [], []
        pose, pose_cov = state.pose, state.pose_cov  # the state changes only after the loops
        for i in np.flatnonzero(a.assign >= n_l):
            ti = int(a.t_idx[a.assign[i] - n_l])
            matched[ti] = sighting(pose, pose_cov, z[i], R[i], ctx.laser)
            matched_meas[ti] = int(i)
            status[i] = TENTATIVE_HIT
            track[i] = int(tent.ids[ti])
        for i in np.flatnonzero((a.assign < 0) & (status != OUT_OF_RANGE)):
            if a.ambiguous[i]:
                status[i] = AMBIGUOUS
                continue
            mxy, C = sighting(pose, pose_cov, z[i], R[i], ctx.laser)
            lid = ctx.new_id()
            if book is not None:
                book.born(lid, float(radii(meas)[i]), float(z[i, 0]))
            new.append((mxy, C, lid))
            new_meas.append(int(i))
            track[i] = lid
        if policy.confirm_scans == 1 and book is None:  # every sighting joins the map at once
            for (_, _, lid), i in zip(new, new_meas):
                out.map_landmark(state, i, lid, 1)
            new = []
        join = gone = None
        if book is not None:  # existence decides: joins in a scan it was seen in
            seen = np.zeros(len(tent), bool)
            seen[list(matched)] = True
            join, gone = book.joins(tent.ids) & seen, book.leaves(tent.ids)
            gone |= book.unreached(tent.ids) & ~seen
        out.remove_unlikely(state, book)
        self.tent, confirm = tent.step(matched, new, meas.k, policy, join=join, gone=gone)
        for ti in confirm:
            out.map_landmark(state, matched_meas[ti], int(tent.ids[ti]), tent.hits[ti] + 1)
        return out.done(len(self.tent))


class WindowMap:
    """The K-scan IHGR window (association "ihgr-window") in place of the tentatives; it
    remembers, for each of the last K - 1 scans, the positions of its usable measurements (the
    associator numbers only those) and the process noise of its prediction."""

    def __init__(self, ctx: _Context, window_scans: int) -> None:
        from association import CostModel, SlidingWindowAssociator
        from association.rounding import ROUNDING_OPTIONS

        params = ctx.params
        cost_keys = {f.name for f in dataclasses.fields(CostModel)}
        unknown = set(params) - cost_keys - set(ROUNDING_OPTIONS)
        if unknown:
            raise SlamError(
                f"association.params: {sorted(unknown)} are not parameters of 'ihgr-window' "
                f"(allowed: {sorted(cost_keys | set(ROUNDING_OPTIONS))})"
            )
        model = CostModel(**{k: v for k, v in params.items() if k in cost_keys})
        rounding = {k: v for k, v in params.items() if k in ROUNDING_OPTIONS}
        self.ctx = ctx
        self.assoc = SlidingWindowAssociator(window_scans, ctx.gate_prob, model, **rounding)
        if ctx.policy.confirm_scans > self.assoc.K:  # `manage` takes the smaller
            log.warning(
                "map_policy.confirm_scans = %d but the 'ihgr-window' association holds %d "
                "scans (association.window_scans): new landmarks join after %d sightings",
                ctx.policy.confirm_scans,
                self.assoc.K,
                self.assoc.K,
            )
        self.scans: list = []  # [(use (m_use,) int, Q (3, 3))], oldest first
        self.ranges: list = []  # [(m,) each scan's measured ranges], aligned with self.scans
        self.first_range = np.zeros(0)  # (m,) this scan's: its track's first sighting's range
        self.counts = dict.fromkeys(
            ("steps", "fractional_lps", "rounded_steps", "lp_solves", "track_hypotheses"), 0
        )

    tentative_xy = np.zeros((0, 2))
    n_pending = 0  # open measurements after the last scan managed

    def stats(self) -> dict:
        """Window figures of the run: steps, how many first LPs were fractional, how many steps
        the rounding changed (more than one LP solve), LP solves, track hypotheses built."""
        return {"K": self.assoc.K, **self.counts}

    def associate(
        self, state: Filter, meas: Measurements, drift: np.ndarray, hidden=None
    ) -> ScanAssociation:
        """Every landmark in view is offered (a track is not built where it could be a mapped
        landmark, so the window must see them all), on the sub-state [pose, those landmarks];
        the laser's world pose goes with the odometry drift over the window as its relative
        covariance. drift: this scan's prediction noise (3, 3), world frame."""
        ctx, K = self.ctx, self.assoc.K
        z_lm, H_lm = se2.observe(state.pose, state.landmarks_xy, ctx.laser)
        lm_idx = np.flatnonzero(ctx.view.contains(z_lm) & _shown(hidden, z_lm.shape[0]))
        n, m = lm_idx.size, meas.z.shape[0]
        ambiguous = np.zeros(m, bool)
        use = np.flatnonzero(meas.status != OUT_OF_RANGE)
        cols = landmark_columns(lm_idx)  # (n, 5)
        if use.size and n:
            S = _project(H_lm[lm_idx], state.cov(cols))
            gate = ctx.gate_new
            ambiguous[use] = gate_matrix(meas.z[use], meas.R[use], z_lm[lm_idx], S, gate).any(1)
        H = np.zeros((n, 2, 3 + 2 * n))
        H[:, :, :3] = H_lm[lm_idx, :, :3]
        for j in range(n):
            H[j, :, 3 + 2 * j : 5 + 2 * j] = H_lm[lm_idx[j], :, 3:5]
        P_sub = state.cov(np.concatenate([_POSE, cols[:, 3:].ravel()]).astype(np.int64))
        # the odometry drift over the window: this scan's prediction noise and the last K - 2's
        window_drift = drift + sum((q for _, q in self.scans[len(self.scans) - (K - 2) :]), 0.0)
        if K < 2:
            window_drift = np.zeros((3, 3))
        p_laser, dp = se2.sensor_position(state.pose, ctx.laser)
        J = np.array([[1.0, 0.0, dp[0]], [0.0, 1.0, dp[1]], [0.0, 0.0, 1.0]])
        out = self.assoc.step(
            meas.z[use],
            meas.R[use],
            z_lm[lm_idx],
            H,
            0.5 * (P_sub + P_sub.T),
            sensor_pose=np.array([p_laser[0], p_laser[1], state.pose[2] + ctx.laser[2]]),
            sensor_pose_cov=0.5 * (J @ window_drift @ J.T + (J @ window_drift @ J.T).T),
            feature_ids=state.landmark_ids[lm_idx].astype(np.int64),
        )
        self._count(self.assoc.last)
        assign = np.full(m, -1, np.int64)
        assign[use] = out
        sightings = np.zeros(m, np.int64)
        sightings[use] = self.assoc.last.sightings
        tracks = self._tracks(self.assoc.last, use)
        self.first_range = self._first_ranges(meas, tracks)
        self.scans = (self.scans + [(use, drift)])[-(K - 1) :] if K > 1 else []
        self.ranges = (self.ranges + [meas.z[:, 0].copy()])[-(K - 1) :] if K > 1 else []
        ambiguous &= assign < 0
        return ScanAssociation(
            assign=assign,
            ambiguous=ambiguous,
            lm_idx=lm_idx,
            t_idx=np.zeros(0, np.int64),
            sightings=sightings,
            tracks=tracks,
        )

    def _count(self, dec) -> None:
        c = self.counts
        c["steps"] += 1
        c["fractional_lps"] += int(dec.rounding.fractional)
        c["rounded_steps"] += int(dec.rounding.lp_solves > 1)
        c["lp_solves"] += int(dec.rounding.lp_solves)
        c["track_hypotheses"] += int(dec.n_tracks)

    def _tracks(self, dec, use: np.ndarray) -> dict:
        """The chosen new-landmark tracks ending in this scan, in the scans' own numbering."""
        past = {ago: u for ago, (u, _) in enumerate(reversed(self.scans), start=1)}
        past[0] = use
        tracks = {}
        for members in dec.tracks:
            ago_last, i_last = members[-1]
            if ago_last == 0:
                tracks[int(use[i_last])] = [
                    (ago, int(past[ago][i])) for ago, i in members if ago in past
                ]
        return tracks

    def _first_ranges(self, meas: Measurements, tracks: dict) -> np.ndarray:
        """(m,) each measurement's track's first (oldest) sighting's range in the window, its
        own where it has no earlier one: the circle that starts the track (its birth's range
        bin, as `existence_rates.derive_birth_by_range` bins a track)."""
        first = meas.z[:, 0].astype(np.float64, copy=True)
        for i, members in tracks.items():
            ago, j = max(members)
            if ago > 0:
                first[i] = self.ranges[-ago][j]
        return first

    def manage(
        self, state: Filter, meas: Measurements, a: ScanAssociation, paired: np.ndarray
    ) -> MapDecisions:
        """An unpaired measurement whose track was seen in min(confirm_scans, K) scans of the
        window joins the map, and its track's earlier measurements are re-tracked to it;
        ambiguous ones are ignored and leave the window's pool like the mapped ones; the rest
        stay open (status NEW_TENTATIVE). paired: as `TentativeMap.manage`."""
        ctx, book = self.ctx, self.ctx.existence
        out = _Deciding.after_update(meas, ctx.laser, paired)
        out.remove_unlikely(state, book)
        status, track = out.status, out.track
        need = min(ctx.policy.confirm_scans, self.assoc.K)
        use = self.scans[-1][0] if self.scans else np.flatnonzero(status != OUT_OF_RANGE)
        use_pos = {int(i): j for j, i in enumerate(use)}
        closed, n_open = [], 0
        for i in np.flatnonzero((a.assign < 0) & (status != OUT_OF_RANGE)):
            if a.ambiguous[i]:
                status[i] = AMBIGUOUS
                closed.append(use_pos[int(i)])
                continue
            r = (
                None
                if book is None
                else book.track_existence(
                    int(a.sightings[i]), meas.R[i], meas.z[i, 0], self.first_range[i]
                )
            )
            if (a.sightings[i] < need) if r is None else (r < book.cfg.join_prob):
                n_open += 1
                continue
            lid = ctx.new_id()
            if book is not None:
                book.track(lid, r, float(radii(meas)[i]))
            out.map_landmark(state, int(i), lid, max(int(a.sightings[i]), 1))
            track[i] = lid
            for ago, j in a.tracks.get(int(i), []):
                if ago > 0:
                    out.retracks.append((meas.k - ago, j, lid))
            closed.append(use_pos[int(i)])
        if closed:
            self.assoc.mark_mapped(closed)
        self.n_pending = n_open
        return out.done(n_open)


@dataclass(eq=False)
class Pruner:
    """Map policy's pruning, after the scan's update and map management: count for every
    landmark already in the map before this scan whether it was expected (predicted inside the
    field of view, no margins, and within the pruning and usable range) and whether it was
    associated; remove those expected often enough and seen too rarely (`MapPolicy`)."""

    policy: MapPolicy
    view: View
    laser: np.ndarray
    # landmark id -> [scans expected in view, scans associated] since it joined the map
    count: dict[int, list[int]] = field(default_factory=dict)

    def __call__(self, state: Filter, status: np.ndarray) -> list[int]:
        """Returns the ids removed."""
        ids = state.landmark_ids
        if not ids.size:
            return []
        z_hat, _ = se2.observe(state.pose, state.landmarks_xy, self.laser)
        expected = self.view.contains(z_hat, margins=False, max_range=self.policy.prune_range_m)
        seen = set(status[status >= 0].tolist())
        drop = []
        for lid, e in zip(ids.tolist(), expected.tolist()):
            c = self.count.get(lid)
            if c is None:  # joined the map in this scan: counted from the next one
                self.count[lid] = [0, 0]
                continue
            if e:
                c[0] += 1
                c[1] += lid in seen
                policy = self.policy
                if c[0] >= policy.prune_after_expected and c[1] < policy.prune_hit_ratio * c[0]:
                    drop.append(lid)
        if drop:
            state.remove_landmarks(drop)
            for lid in drop:
                del self.count[lid]
        return drop


def _shown(hidden, n: int) -> np.ndarray:
    """The landmarks (n,) a scan's association may pair: all but `hidden` (a mask or None;
    the loop closure's landmarks that the per-scan gate cannot tell apart)."""
    return np.ones(n, bool) if hidden is None else ~np.asarray(hidden, bool)


def make_map_manager(
    laser, view: View, association, policy: MapPolicy, associator, existence=None
) -> MapManager:
    """The run's map manager from the `[association]` and `[map_policy]` sections: `WindowMap`
    for "ihgr-window" (which associates by itself), else `TentativeMap` around the associator
    callable. Both are used the same way (module doc). existence: the run's
    `slam.existence_map.LandmarkExistence` (map policy "existence"; None: confirm_scans)."""
    ctx = _Context(
        laser,
        view,
        gate_new=association.gate_new,
        gate_prob=association.gate_prob,
        params=association.params,
        policy=policy,
        existence=existence,
    )
    if association.windowed:
        return WindowMap(ctx, association.window_scans)
    return TentativeMap(ctx, associator)


def _project(H5: np.ndarray, C5: np.ndarray) -> np.ndarray:
    """(n, 2, 2) H5_j C5_j H5_j^T of each candidate's [pose, point] block."""
    return project_blocks(np.ascontiguousarray(H5), np.ascontiguousarray(C5))
