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

import numpy as np
import scipy.sparse as sp

from association.errors import AssociationError
from association.inputs import (
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
        K: int = 3,
        gate_prob: float = 0.99,
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
        prep = prepare(z, R, z_hat, H, P, self.gate_prob)
        pose, Q = self._check_pose(sensor_pose, sensor_pose_cov)
        fids = self._check_ids(feature_ids, prep.n)
        m = prep.m
        costs0, A0, exact0, col_meas, col_feat = single_scan_problem(prep, self.model)
        n_rows0 = A0.shape[0]

        past = self._past[-(self.K - 1) :] if self.K > 1 else []
        open_nodes: list[tuple[int, int]] = []  # (window index w, measurement index)
        if pose is not None:
            for w, ps in enumerate(past):
                if ps.pose is not None:
                    open_nodes += [(w, int(i)) for i in np.flatnonzero(ps.open)]
        W = len(past) + 1
        row_of_open = {node: n_rows0 + k for k, node in enumerate(open_nodes)}
        tracks: list[tuple[float, list[tuple[int, int]]]] = []
        if open_nodes and self.model.birth_density > 0:
            tracks = self._tracks(past, open_nodes, prep, pose, Q)

        # Assemble: (a) + current singletons from the single-scan problem, (a') earlier open
        # measurements with the map features free in their scan, (b) tracks, (c) singletons.
        coo = A0.tocoo()
        rows, cols, cost_parts = [coo.row], [coo.col], [costs0]
        n_cols = A0.shape[1]
        n_rows = n_rows0 + len(open_nodes)
        feat_row: dict[tuple[int, int], int] = {}
        for w, ps in enumerate(past):
            if pose is None or ps.pose is None:
                continue
            keep = ps.open[ps.pair_i]
            for i, f, c in zip(ps.pair_i[keep], ps.pair_fid[keep], ps.pair_cost[keep]):
                r = feat_row.setdefault((w, int(f)), n_rows + len(feat_row))
                rows.append(np.array([row_of_open[(w, int(i))], r], np.int64))
                cols.append(np.array([n_cols, n_cols], np.int64))
                cost_parts.append(np.array([c]))
                n_cols += 1
        n_rows += len(feat_row)
        k_tracks0 = n_cols
        for cost, members in tracks:
            r = [i if w == W - 1 else row_of_open[(w, i)] for w, i in members]
            rows.append(np.asarray(r, np.int64))
            cols.append(np.full(len(r), n_cols, np.int64))
            cost_parts.append(np.array([cost]))
            n_cols += 1
        for w, i in open_nodes:
            rows.append(np.array([row_of_open[(w, i)]], np.int64))
            cols.append(np.array([n_cols], np.int64))
            cost_parts.append(np.array([self.model.unexplained_cost(W - 1 - w)]))
            n_cols += 1
        rr, cc = np.concatenate(rows), np.concatenate(cols)
        A = sp.csc_array((np.ones(rr.size), (rr, cc)), shape=(n_rows, n_cols))
        exact = np.zeros(n_rows, bool)
        exact[:n_rows0] = exact0
        exact[n_rows0 : n_rows0 + len(open_nodes)] = True
        costs = np.concatenate(cost_parts)
        res = ihgr_round(costs, A, exact, **self.rounding)

        out = np.full(m, -1, np.int64)
        sightings = np.ones(m, np.int64)
        chosen_tracks = []
        self._last_track_members = {}
        for h in res.selected:
            if h < A0.shape[1]:
                out[col_meas[h]] = col_feat[h]
            elif k_tracks0 <= h < k_tracks0 + len(tracks):
                members = tracks[h - k_tracks0][1]
                if members[-1][0] == W - 1:
                    i_cur = members[-1][1]
                    sightings[i_cur] = len(members)
                    self._last_track_members[i_cur] = members
                    chosen_tracks.append(tuple((W - 1 - w, i) for w, i in members))
        sightings[out >= 0] = 0
        self.last = WindowDecision(
            out, sightings, tuple(chosen_tracks), res, len(tracks), (costs, A, exact)
        )
        if self.K > 1:
            # Remember this scan: its -1s stay open; their gated pairings with map features
            # that this scan left free can still explain them later.
            is_open = (out < 0) if pose is not None else np.zeros(m, bool)
            used = np.zeros(prep.n, bool)
            used[out[out >= 0]] = True
            keep = is_open[prep.pair_i] & ~used[prep.pair_j]
            pc = self.model.pair_cost(prep.d2[keep], prep.logdet_S[keep])
            this = _PastScan(
                pose, Q, prep.z, prep.R, is_open, prep.pair_i[keep], fids[prep.pair_j[keep]], pc
            )
            self._past = (past + [this])[-(self.K - 1) :]
        self._last_drop = W - len(self._past)
        return out

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

    def _tracks(self, past, open_nodes, prep, pose_cur, Q_cur):
        """Enumerate new-landmark track hypotheses: [(cost, [(w, i), ...]), ...]."""
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
