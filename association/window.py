"""K-scan sliding-window IHGR and the stateful wrapper the SLAM loop calls once per scan.

Which decisions are committed
-----------------------------
`SlidingWindowAssociator.step(...)` is called with the newest scan and returns that scan's
assignment, final at once: the EKF needs it for this scan's update. So the window commits the
**newest** scan (docs/method.md section 1 leaves oldest-or-newest open; committing the oldest would
delay every EKF update by K - 1 scans). A pairing with a map feature, once returned, is never
revisited, and hypotheses that contradict it are not built.

How the window uses earlier scans
---------------------------------
What stays undecided is the meaning of a -1: clutter, or the first sightings of a landmark that
is not in the map yet. Measurements of the last K - 1 scans that were returned as -1 (and that
the caller has not turned into map features, see `mark_mapped`) stay **open**. Each step solves
one set-partitioning problem over the current scan and the open measurements:

rows      every current measurement (exactly once), every gated map feature (at most once),
          every open measurement of the earlier scans (exactly once);
columns   (a) current measurement i <-> map feature j, cost as in the single scan
              c_ij = 1/2 d2 + 1/2 ln|2 pi S| - ln P_D + ln(1 - P_D);
          (a') an open earlier measurement <-> a map feature that its scan left unused, with
              the pair cost of that scan (rows (feature, scan) at most once). This is the
              K-scan map-feature tuple (j; i_1..i_K): its cost is a sum of per-scan terms, so it
              is carried by its per-scan pairings (the same LP). It lets the window explain a
              -1 that was a missed pairing instead of seeding a false new-landmark track;
          (b) new-landmark tracks: tuples of at most one measurement per scan, >= 2 members,
              drawn from the open measurements and the current scan, chronological. The first
              member places the landmark in the world (sensor pose + range-bearing, covariance
              from R and the pose covariance); every later scan of the window either adds a
              member, scored by its negative log-likelihood against the track so far (an EKF
              on the landmark point, gated by chi2_2(gate_prob)), or is a miss:
                  cost = -ln lambda_b                                      (birth)
                       + sum_members after the first [1/2 d2 + 1/2 ln|2 pi S| - ln P_D]
                       + sum_misses after the first  [-ln(1 - P_D)].
              A track whose landmark, predicted into the current scan, is compatible with a map
              feature's prediction (chi2_2 gate on the difference, covariance
              S_track + H_j P H_j^T) is not built: trunks do not overlap, so it would be that
              feature seen through a missed pairing (the usual rule against duplicate
              landmarks). Without this rule the window stole measurements of mapped trunks
              whose map estimate was a little off (tighter track prediction, smaller ln|S|);
          (c) singletons: a measurement explained by nothing else, seen in scan w with L later
              scans in the window: -ln(lambda_b (1 - P_D)^L + lambda_c) (a new landmark never
              seen again, or clutter).
All costs are negative log-likelihoods of the `CostModel`, so the window with K = 1 (or without
sensor poses) is exactly the single-scan problem. The earlier scans' committed pairings are
already in the filter's prediction and take no further part; map features are named across scans
by `feature_ids`.

The grouping of open measurements into tracks is re-decided at every step (it was never
returned to the caller). Tracks of >= 3 members make the problem a multi-dimensional assignment
whose LP can be fractional; IHGR's rounding then matters.

The answer for the current scan: map feature j, or -1. `last.sightings` says for each -1 how
many scans of the window saw its landmark (1 = only now); the SLAM loop can initialise a new
landmark when sightings >= 2 (clutter rarely repeats) and must then call `mark_mapped` so that
the track's earlier measurements leave the pool.

Track geometry needs the sensor pose in the world frame for every scan (`sensor_pose`); its
`sensor_pose_cov` is the uncertainty of that pose *relative to the other scans of the window*
(odometry drift over K scans), not the absolute SLAM covariance: an error common to all scans
moves every sighting together and does not change whether they agree. Without `sensor_pose`,
a scan takes no part in tracks.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from association.errors import AssociationError
from association.inputs import (
    Prepared,
    as_float_array,
    block_psd_ok,
    check_finite,
    chol2_solve,
    gate_threshold,
    prepare,
    wrap_angle,
)
from association.rounding import RoundingResult, check_rounding_options, ihgr_round
from association.single import CostModel, single_scan_problem

__all__ = ["SlidingWindowAssociator", "WindowDecision"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class WindowDecision:
    """What one `SlidingWindowAssociator.step` decided.

    assignment: (m,) int64, the current scan's map feature per measurement or -1 (committed).
    sightings: (m,) int64, 0 for a measurement paired with a map feature; otherwise the number
        of scans in the window that saw its landmark according to the chosen tracks (1 = only
        this scan: a new landmark or clutter).
    tracks: the chosen new-landmark tracks with a current member, as tuples of
        (scans_ago, measurement index) pairs, oldest first; scans_ago = 0 is the current scan.
    rounding: the IHGR result of this step's set-partitioning problem.
    n_tracks: number of track hypotheses built (columns of kind (b)).
    problem: (costs, A, exact) of the step's set-partitioning problem, for studies.
    """

    assignment: np.ndarray
    sightings: np.ndarray
    tracks: tuple
    rounding: RoundingResult
    n_tracks: int
    problem: tuple


@dataclass(eq=False)
class _PastScan:
    """One earlier scan in the window (mutable: `open` changes)."""

    pose: np.ndarray | None  # (3,) [x_m, y_m, heading_rad] of the sensor in the world
    pose_cov: np.ndarray  # (3, 3) relative pose covariance
    z: np.ndarray  # (m, 2)
    R: np.ndarray  # (m, 2, 2)
    open: np.ndarray  # (m,) bool: -1 and not mapped
    pair_i: np.ndarray  # (k,) gated pairings of open measurements with map features that
    pair_fid: np.ndarray  # (k,) the scan left unused: measurement, feature id,
    pair_cost: np.ndarray  # (k,) and the single-scan pair cost


class _ThisScan(NamedTuple):
    """The scan being associated, checked (`SlidingWindowAssociator.step`)."""

    prep: Prepared  # its measurements, the map features' predictions and the gated pairings
    pose: np.ndarray | None  # (3,) [x_m, y_m, heading_rad] of the sensor in the world, or None
    pose_cov: np.ndarray  # (3, 3) that pose's covariance relative to the window's other scans
    fids: np.ndarray  # (n,) int64 ids naming the map features across scans


class _WindowProblem(NamedTuple):
    """One step's set-partitioning problem (see the module doc) and what its columns mean.

    Columns: 0..n_single-1 the single-scan problem's (col_meas, col_feat: (n_single,) its
    measurement and map feature, -1 for a singleton), then the (a') pairings of earlier open
    measurements, then one column per track from first_track on, then the (c) singletons.
    """

    costs: np.ndarray  # (N,) column costs (negative log-likelihoods)
    A: sp.csc_array  # (rows, N) 0/1
    exact: np.ndarray  # (rows,) bool: covered exactly once, else at most once
    col_meas: np.ndarray  # (n_single,) int64
    col_feat: np.ndarray  # (n_single,) int64
    first_track: int
    tracks: list  # [(cost, [(w, i), ...]), ...] the new-landmark track hypotheses, `_tracks`
    W: int  # scans in the window, the current one included (window index W - 1)


class _Columns:
    """The columns of a 0/1 set-partitioning matrix, added one at a time."""

    def __init__(self, A0: sp.csc_array, costs0: np.ndarray) -> None:
        coo = A0.tocoo()
        self.rows, self.cols, self.costs = [coo.row], [coo.col], [costs0]
        self.n = A0.shape[1]

    def add(self, rows: list, cost: float) -> None:
        """A column covering `rows` at `cost`."""
        self.rows.append(np.asarray(rows, np.int64))
        self.cols.append(np.full(len(rows), self.n, np.int64))
        self.costs.append(np.array([cost]))
        self.n += 1

    def problem(self, n_rows: int) -> tuple[np.ndarray, sp.csc_array]:
        """(costs (N,), A (n_rows, N) CSC)."""
        rr, cc = np.concatenate(self.rows), np.concatenate(self.cols)
        A = sp.csc_array((np.ones(rr.size), (rr, cc)), shape=(n_rows, self.n))
        return np.concatenate(self.costs), A


def _point_from_measurement(pose, Q, z, R):
    """World point (m, 2) and covariance (m, 2, 2) of range-bearing measurements from `pose`."""
    phi = pose[2] + z[:, 1]
    c, s = np.cos(phi), np.sin(phi)
    r = z[:, 0]
    p = np.column_stack([pose[0] + r * c, pose[1] + r * s])
    Gz = np.empty((z.shape[0], 2, 2))
    Gz[:, 0, 0], Gz[:, 0, 1], Gz[:, 1, 0], Gz[:, 1, 1] = c, -r * s, s, r * c
    Gx = np.zeros((z.shape[0], 2, 3))
    Gx[:, 0, 0] = Gx[:, 1, 1] = 1.0
    Gx[:, 0, 2], Gx[:, 1, 2] = -r * s, r * c
    # einsum rather than batched matmul: tiny products, no BLAS threads
    cov = np.einsum("mab,mbc,mdc->mad", Gz, R, Gz) + np.einsum("mab,bc,mdc->mad", Gx, Q, Gx)
    return p, 0.5 * (cov + np.swapaxes(cov, 1, 2))


def _predict(pose, Q, p, Sigma):
    """Predicted range-bearing of point p from pose: z_hat (2,), H_p (2, 2), S_pred (2, 2)."""
    dx, dy = p[0] - pose[0], p[1] - pose[1]
    q = max(dx * dx + dy * dy, 1e-12)
    r = math.sqrt(q)
    z_hat = np.array([r, math.atan2(dy, dx) - pose[2]])
    Hp = np.array([[dx / r, dy / r], [-dy / q, dx / q]])
    Hx = np.array([[-dx / r, -dy / r, 0.0], [dy / q, -dx / q, -1.0]])
    S = Hp @ Sigma @ Hp.T + Hx @ Q @ Hx.T
    return z_hat, Hp, 0.5 * (S + S.T)


def _solve2(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """S^-1 B for a 2x2 symmetric positive-definite S (Cholesky; no LAPACK call for a 2x2)."""
    l11 = math.sqrt(S[0, 0])
    l21 = S[1, 0] / l11
    l22 = math.sqrt(S[1, 1] - l21 * l21)
    u0 = B[0] / l11  # forward: L u = B
    u1 = (B[1] - l21 * u0) / l22
    x1 = u1 / l22  # backward: L^T x = u
    x0 = (u0 - l21 * x1) / l11
    return np.stack([x0, x1])


def _add_missed_pairings(cols: _Columns, live, row_of_open: dict, first_row: int) -> int:
    """Columns (a'): each open measurement i of an earlier scan w (`live`: [(w, _PastScan)])
    with each map feature f that its scan left unused and gated with it, at that scan's pair
    cost, covering i's row and the row of (w, f), numbered from first_row in order of first use.
    Returns the number of (w, f) rows."""
    feat_row: dict[tuple[int, int], int] = {}
    for w, ps in live:
        keep = ps.open[ps.pair_i]
        for i, f, c in zip(ps.pair_i[keep], ps.pair_fid[keep], ps.pair_cost[keep]):
            r = feat_row.setdefault((w, int(f)), first_row + len(feat_row))
            cols.add([row_of_open[(w, int(i))], r], c)
    return len(feat_row)


def _decide(problem: _WindowProblem, res: RoundingResult, m: int):
    """The step's `WindowDecision` from the chosen columns, and the members of each chosen
    track with a current member, by that member's index: {i: [(w, i_w), ...]}."""
    W = problem.W
    out = np.full(m, -1, np.int64)
    sightings = np.ones(m, np.int64)
    chosen_tracks = []
    members_of: dict[int, list[tuple[int, int]]] = {}
    n_single, first_track = problem.col_meas.size, problem.first_track
    for h in res.selected:
        if h < n_single:
            out[problem.col_meas[h]] = problem.col_feat[h]
        elif first_track <= h < first_track + len(problem.tracks):
            members = problem.tracks[h - first_track][1]
            if members[-1][0] == W - 1:
                i_cur = members[-1][1]
                sightings[i_cur] = len(members)
                members_of[i_cur] = members
                chosen_tracks.append(tuple((W - 1 - w, i) for w, i in members))
    sightings[out >= 0] = 0
    decision = WindowDecision(
        assignment=out,
        sightings=sightings,
        tracks=tuple(chosen_tracks),
        rounding=res,
        n_tracks=len(problem.tracks),
        problem=(problem.costs, problem.A, problem.exact),
    )
    return decision, members_of


class SlidingWindowAssociator:
    """K-scan IHGR association for a SLAM loop; see the module docstring for the model.

    K: window length in scans (2..4 intended; 1 is the single-scan problem).
    gate_prob: chi-square gate probability (map pairings and track extensions, 2 dof).
    model: the `CostModel` (P_D, clutter and birth densities).
    max_tracks: cap on track hypotheses per step; beyond it the cheapest are kept (logged).
    rounding: options of `ihgr_round` (eps, fix_ones, presolve).
    """

    def __init__(
        self,
        K: int,
        gate_prob: float,
        model: CostModel | None = None,
        max_tracks: int = 20_000,
        **rounding,
    ) -> None:
        if not isinstance(K, (int, np.integer)) or not 1 <= K <= 8:
            raise AssociationError(f"K: must be an integer in 1..8, got {K!r}")
        if not 0.0 < float(gate_prob) < 1.0:
            raise AssociationError(f"gate_prob: must be in (0, 1), got {gate_prob!r}")
        if not isinstance(max_tracks, (int, np.integer)) or max_tracks < 0:
            raise AssociationError(
                f"max_tracks: must be a non-negative integer, got {max_tracks!r}"
            )
        rounding = check_rounding_options(rounding)
        self.K = int(K)
        self.gate_prob = float(gate_prob)
        self.model = model if model is not None else CostModel()
        if not isinstance(self.model, CostModel):
            raise AssociationError(f"model: expected a CostModel, got {type(model).__name__}")
        self.max_tracks = int(max_tracks)
        self.rounding = rounding
        self._past: list[_PastScan] = []
        self.last: WindowDecision | None = None
        self._last_track_members: dict[int, list[tuple[int, int]]] = {}
        self._last_drop = 0

    def reset(self) -> None:
        """Forget every earlier scan."""
        self._past = []
        self.last = None
        self._last_track_members = {}

    def step(
        self, z, R, z_hat, H, P, *, sensor_pose=None, sensor_pose_cov=None, feature_ids=None
    ) -> np.ndarray:
        """Associate the newest scan; returns its committed assignment (m,) int64.

        z, R, z_hat, H, P: as for `association.associate` (this scan's measurements and the map
        features' predictions for this scan); the answer indexes z_hat, as there.
        sensor_pose: (3,) [x_m, y_m, heading_rad], the sensor in the world frame; heading is the
            world direction of bearing 0. Needed for new-landmark tracks.
        sensor_pose_cov: (3, 3) uncertainty of that pose relative to the window's other scans
            (default zero).
        feature_ids: (n,) distinct integers naming the map features across scans (default
            0..n-1, right when the map only grows by appending, as an EKF-SLAM state does).
        """
        prep = prepare(z, R, z_hat, H, P, gate_prob=self.gate_prob)
        pose, Q = self._check_pose(sensor_pose, sensor_pose_cov)
        scan = _ThisScan(prep, pose, Q, self._check_ids(feature_ids, prep.n))
        past = self._past[-(self.K - 1) :] if self.K > 1 else []
        problem = self._problem(scan, past)
        res = ihgr_round(problem.costs, problem.A, problem.exact, **self.rounding)
        self.last, self._last_track_members = _decide(problem, res, prep.m)
        out = self.last.assignment
        if self.K > 1:
            self._past = (past + [self._remember(scan, out)])[-(self.K - 1) :]
        self._last_drop = problem.W - len(self._past)
        return out

    def _problem(self, scan: _ThisScan, past: list[_PastScan]) -> _WindowProblem:
        """Assemble the step's problem: (a) and the current singletons from the single-scan
        problem, (a') earlier open measurements with the map features free in their scan,
        (b) tracks, (c) singletons of the earlier open measurements. past: the window's earlier
        scans, oldest first (window indices 0..W-2; the current scan is W - 1)."""
        costs0, A0, exact0, col_meas, col_feat = single_scan_problem(scan.prep, self.model)
        n_rows0 = A0.shape[0]
        # the earlier scans that take part in (a'), (b), (c): with a sensor pose, as this one
        live = [
            (w, ps) for w, ps in enumerate(past) if ps.pose is not None and scan.pose is not None
        ]
        # (window index w, measurement index) of the open measurements, each a row
        open_nodes = [(w, int(i)) for w, ps in live for i in np.flatnonzero(ps.open)]
        row_of_open = {node: n_rows0 + k for k, node in enumerate(open_nodes)}
        tracks: list[tuple[float, list[tuple[int, int]]]] = []
        if open_nodes and self.model.birth_density > 0:
            tracks = self._tracks(past, open_nodes, scan)
        W = len(past) + 1
        cols = _Columns(A0, costs0)
        n_rows = n_rows0 + len(open_nodes)
        n_rows += _add_missed_pairings(cols, live, row_of_open, n_rows)  # (a')
        first_track = cols.n
        for cost, members in tracks:  # (b)
            cols.add([i if w == W - 1 else row_of_open[(w, i)] for w, i in members], cost)
        for w, i in open_nodes:  # (c)
            cols.add([row_of_open[(w, i)]], self.model.unexplained_cost(W - 1 - w))
        exact = np.zeros(n_rows, bool)
        exact[:n_rows0] = exact0
        exact[n_rows0 : n_rows0 + len(open_nodes)] = True
        costs, A = cols.problem(n_rows)
        return _WindowProblem(
            costs=costs,
            A=A,
            exact=exact,
            col_meas=col_meas,
            col_feat=col_feat,
            first_track=first_track,
            tracks=tracks,
            W=W,
        )

    def _remember(self, scan: _ThisScan, out: np.ndarray) -> _PastScan:
        """The current scan as an earlier one for the next steps: its -1s stay open (without a
        sensor pose none do); their gated pairings with map features that this scan left free
        can still explain them later."""
        prep = scan.prep
        is_open = (out < 0) if scan.pose is not None else np.zeros(prep.m, bool)
        used = np.zeros(prep.n, bool)
        used[out[out >= 0]] = True
        keep = is_open[prep.pair_i] & ~used[prep.pair_j]
        return _PastScan(
            pose=scan.pose,
            pose_cov=scan.pose_cov,
            z=prep.z,
            R=prep.R,
            open=is_open,
            pair_i=prep.pair_i[keep],
            pair_fid=scan.fids[prep.pair_j[keep]],
            pair_cost=self.model.pair_cost(prep.d2[keep], prep.logdet_S[keep]),
        )

    @staticmethod
    def _check_ids(ids, n: int) -> np.ndarray:
        if ids is None:
            return np.arange(n, dtype=np.int64)
        a = np.asarray(ids)
        if a.shape != (n,) or a.dtype.kind not in "iu":
            raise AssociationError(
                f"feature_ids: expected ({n},) integers, got {a.dtype} {a.shape}"
            )
        if np.unique(a).size != n:
            raise AssociationError("feature_ids: must be distinct")
        return a.astype(np.int64)

    def mark_mapped(self, indices) -> None:
        """The caller initialised map features from these measurements of the last scan: they and
        the earlier members of their tracks leave the pool of open measurements."""
        if self.last is None:
            raise AssociationError("mark_mapped: no scan has been associated yet")
        idx = np.atleast_1d(np.asarray(indices, dtype=np.int64))
        m = self.last.assignment.size
        if idx.ndim != 1 or ((idx < 0) | (idx >= m)).any():
            raise AssociationError(f"indices: must be in 0..{m - 1}, got {idx.tolist()}")
        if not self._past:
            return  # K = 1: nothing is kept
        for i in idx.tolist():
            self._past[-1].open[i] = False
            for w, j in self._last_track_members.get(i, []):
                wi = w - self._last_drop  # window index at the last step -> index in _past now
                if 0 <= wi < len(self._past):
                    self._past[wi].open[j] = False

    def _check_pose(self, pose, Q):
        if pose is None:
            if Q is not None:
                raise AssociationError("sensor_pose_cov: given without sensor_pose")
            return None, np.zeros((3, 3))
        pose = as_float_array("sensor_pose", pose, "(3,)")
        if pose.shape != (3,):
            raise AssociationError(
                f"sensor_pose: expected shape (3,) [x_m, y_m, heading_rad], got {pose.shape}"
            )
        check_finite("sensor_pose", pose)
        if Q is None:
            Q = np.zeros((3, 3))
        else:
            Q = as_float_array("sensor_pose_cov", Q, "(3, 3)")
            if Q.shape != (3, 3):
                raise AssociationError(f"sensor_pose_cov: expected shape (3, 3), got {Q.shape}")
            check_finite("sensor_pose_cov", Q)
            if np.abs(Q - Q.T).max() > 1e-8 * max(np.abs(Q).max(), 1e-300):
                raise AssociationError("sensor_pose_cov: not symmetric")
            if not block_psd_ok(Q, np.arange(3), 1e-9):
                raise AssociationError("sensor_pose_cov: not positive semi-definite")
        return pose, Q

    def _tracks(self, past, open_nodes, scan: _ThisScan):
        """Enumerate new-landmark track hypotheses: [(cost, [(w, i), ...]), ...]."""
        prep, pose_cur, Q_cur = scan.prep, scan.pose, scan.pose_cov
        z_cur, R_cur = prep.z, prep.R
        mdl = self.model
        gate = gate_threshold(self.gate_prob)
        W = len(past) + 1
        scans = [(ps.pose, ps.pose_cov, ps.z, ps.R, np.flatnonzero(ps.open)) for ps in past]
        scans.append((pose_cur, Q_cur, z_cur, R_cur, np.arange(z_cur.shape[0])))
        out: list[tuple[float, list[tuple[int, int]]]] = []
        init = {}
        for w, ps in enumerate(past):
            if ps.pose is not None and ps.open.any():
                p, cov = _point_from_measurement(ps.pose, ps.pose_cov, ps.z, ps.R)
                init[w] = (p, cov)
        budget = [self.max_tracks * 4 + 1000]  # enumeration guard before the cost-based cap

        def dfs(w, p, Sigma, cost, members):
            if budget[0] <= 0:
                return
            if w == W:
                if len(members) >= 2:
                    out.append((cost, members))
                    budget[0] -= 1
                return
            pose, Q, z, R, cand = scans[w]
            if w == W - 1 and prep.n:
                # A new landmark cannot sit on a mapped one: if the track's prediction for the
                # current scan is compatible with a map feature's, it is that feature.
                z_hat, Hp, S_pred = _predict(pose, Q, p, Sigma)
                dz = prep.z_hat - z_hat
                dz[:, 1] = wrap_angle(dz[:, 1])
                d2m, _, okm = chol2_solve(prep.S_feat + S_pred[None], dz)
                if (okm & (d2m <= gate)).any():
                    return
            if pose is not None and cand.size:
                z_hat, Hp, S_pred = _predict(pose, Q, p, Sigma)
                nu = z[cand] - z_hat
                nu[:, 1] = wrap_angle(nu[:, 1])
                S = S_pred[None] + R[cand]
                d2, logdet, ok = chol2_solve(S, nu)
                for k in np.flatnonzero(ok & (d2 <= gate)):
                    i = int(cand[k])
                    Sk = S[k]
                    K = _solve2(Sk, Hp @ Sigma).T  # Sigma Hp^T S^-1 (S, Sigma symmetric)
                    p_new = p + K @ nu[k]
                    IKH = np.eye(2) - K @ Hp
                    Sig_new = IKH @ Sigma @ IKH.T + K @ (Sk - Hp @ Sigma @ Hp.T) @ K.T  # Joseph
                    Sig_new = 0.5 * (Sig_new + Sig_new.T)
                    step_cost = float(mdl.nll(d2[k], logdet[k])) + mdl.detect_cost
                    dfs(w + 1, p_new, Sig_new, cost + step_cost, members + [(w, i)])
            dfs(w + 1, p, Sigma, cost + mdl.miss_cost, members)

        for w0, i0 in open_nodes:
            p, cov = init[w0]
            dfs(w0 + 1, p[i0], cov[i0], mdl.birth_cost, [(w0, i0)])
        if budget[0] <= 0 or len(out) > self.max_tracks:
            log.warning(
                "window association: %d track hypotheses, keeping the %d cheapest",
                len(out),
                self.max_tracks,
            )
            out.sort(key=lambda t: t[0])
            out = out[: self.max_tracks]
        return out
