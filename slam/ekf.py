"""EKF-SLAM state and steps: vehicle pose plus 2D landmarks (tree centres).

State x = [x_m, y_m, theta_rad, l0_x, l0_y, l1_x, l1_y, ...] in the world frame: the rear-axle
centre's pose followed by the landmarks' positions; P its covariance. Landmark i occupies
columns 3 + 2 i and 4 + 2 i and carries a stable integer id.

Observation (one circle centre seen by the laser): the laser sits at `laser_pose` [lx, ly, lth]
in the vehicle frame, so at p_L = p + R(theta) [lx, ly] with heading theta + lth. A landmark m
is measured as

    range_m = |m - p_L|,   bearing_rad = atan2((m - p_L)_y, (m - p_L)_x) - theta - lth

(laser frame, wrapped to (-pi, pi]); `slam.se2.observe` gives the prediction and its analytic
Jacobian with respect to the five state entries it touches, [x, y, theta, m_x, m_y].

The steps work in place on a `Filter` (the run loop's working state), so a scan costs no copy of
the d x d covariance:
- `predict`: the vehicle rows and columns only: P_vv <- F P_vv F^T + Q, P_vm <- F P_vm; the
  landmark block is untouched, so the cost is linear in the map size.
- `update`: all of a scan's associated measurements at once. With S = H P H^T + R = L L^T
  (Cholesky) and W = P H^T L^-T (d, q), the optimal gain is K = W L^-1, so x += W (L^-1 nu),
  NIS = |L^-1 nu|^2, ln|S| = 2 sum ln L_ii, and the Joseph form
  (I - K H) P (I - K H)^T + K R K^T, which for this gain equals P - K S K^T, is P - W W^T: a
  symmetric rank-q update (q = 2 x measurements) subtracted in place by BLAS `dsyrk` from P's
  lower triangle (`_subtract_gram`), with no d x d temporary. (The expanded Joseph form
  P + K A^T + A K^T, A = K S / 2 - P H^T, by `dsyr2k`, gave the same estimates up to rounding
  at twice the flops.) The filter leaves the upper triangle behind and mirrors it only when
  `Filter.P` is read (then symmetric to the last bit); the steps and the run loop read the
  blocks they need from the lower triangle (`cov`, `pose_cov`), so a scan does not pay the
  O(d^2) mirror, whose writes across the cold upper triangle cost more than the update.
- `add_landmark`: initialisation from one measurement with its cross covariances:
  m = g(pose, z), P_mm = Gx P_vv Gx^T + Gz R Gz^T, P_m* = Gx P_v* (this one grows P: a copy).

Hidden copies (`Filter.append_copies`, `Filter.restore_copies`): 2-D slots after the landmarks,
x = [pose, landmarks..., copies...], each a copy of one landmark taken before an extra error
was added to it (the pass offset's anchor, `slam.pass_state`). They take part in every step
(`predict` carries all rows after the pose, `update` all rows of P) but not in what the filter
shows: `landmarks_xy`, `landmark_ids`, `n_landmarks` and `snapshot` see the landmarks only, a
new landmark is inserted before the copies, and removing a landmark removes its copy with it.
The functions `predict`, `update` and `add_landmark` do the same on an immutable `EkfState`
(copying it), for callers that want values rather than a working state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.linalg import blas

from slam.errors import SlamError
from slam.se2 import inverse_observe, observe, observe_kernel, sensor_numbers, wrap_angle

_SE2_OBSERVE = observe  # `Filter.update` fuses this model; another one takes the numpy steps

__all__ = [
    "EkfState",
    "Filter",
    "UpdateResult",
    "add_landmark",
    "initial_state",
    "observe",
    "observe_jacobian_full",
    "predict",
    "update",
]


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


class _Estimate:
    """Read-only views shared by `EkfState` and `Filter` (both have x, P, landmark_ids).

    Covariances are read from the lower triangle of `_lower` (P itself for an `EkfState`; the
    filter's storage, whose upper triangle may lag, for a `Filter`)."""

    x: np.ndarray
    P: np.ndarray
    landmark_ids: np.ndarray

    @property
    def _lower(self) -> np.ndarray:
        return self.P

    @property
    def P_lower(self) -> np.ndarray:
        """The covariance's storage, whose lower triangle is current (a `Filter`'s upper one may
        lag): for kernels that read P[max(r, c), min(r, c)]. A view: do not write to it."""
        return self._lower

    @property
    def dim(self) -> int:
        return int(self.x.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.landmark_ids.size)

    @property
    def pose(self) -> np.ndarray:
        """(3,) [x_m, y_m, theta_rad] of the rear-axle centre."""
        return self.x[:3]

    @property
    def pose_cov(self) -> np.ndarray:
        """(3, 3) covariance of the pose (a copy), read from the lower triangle (the values of
        `cov([0, 1, 2])`, without a kernel call: it is read several times a scan)."""
        out = self._lower[:3, :3].copy()
        out[0, 1], out[0, 2], out[1, 2] = out[1, 0], out[2, 0], out[2, 1]
        return out

    @property
    def landmarks_xy(self) -> np.ndarray:
        """(n, 2) landmark positions, world frame, m."""
        return self.x[3 : 3 + 2 * self.n_landmarks].reshape(-1, 2)

    @property
    def landmark_covs(self) -> np.ndarray:
        """(n, 2, 2) marginal covariances of the landmarks."""
        P = self._lower
        diag, below = np.diagonal(P), np.diagonal(P, -1)  # views: P[j, j], P[j + 1, j]
        end = 3 + 2 * self.n_landmarks  # the landmarks' slots (a Filter's hidden copies after)
        out = np.empty((self.n_landmarks, 2, 2))
        out[:, 0, 0] = diag[3:end:2]
        out[:, 0, 1] = below[3:end:2]
        out[:, 1, 0] = below[3:end:2]
        out[:, 1, 1] = diag[4:end:2]
        return out

    def cov(self, idx) -> np.ndarray:
        """P[idx][:, idx]: the covariance of the state entries at positions idx (k,) as
        (k, k), or of each row of idx (n, k) as (n, k, k) (e.g. `landmark_columns`). A copy,
        read from the lower triangle (a `Filter` does not mirror P for it)."""
        idx = np.asarray(idx, dtype=np.int64)
        flat = np.ascontiguousarray(idx.reshape(math.prod(idx.shape[:-1]), idx.shape[-1]))
        return _sym_blocks(self._lower, flat).reshape(idx.shape + idx.shape[-1:])

    def rows(self, idx) -> np.ndarray:
        """P[idx, :] (k, d): whole rows of the covariance at state positions idx (k,), a copy
        (a `Filter` reads them from its lower triangle when the upper one lags, as `P` would
        after mirroring it, so the reading costs O(k d), not the O(d^2) mirror)."""
        return self.P[np.asarray(idx, dtype=np.int64).reshape(-1)]

    def index_of(self, landmark_id: int) -> int:
        """Position (0..n-1) of a landmark id in the state."""
        hits = np.flatnonzero(self.landmark_ids == landmark_id)
        if hits.size == 0:
            raise KeyError(f"landmark id {landmark_id} is not in the state")
        return int(hits[0])

    def positions_of(self, landmark_ids) -> np.ndarray:
        """`index_of` for many ids at once: (k,) positions, -1 where an id is not in the
        state (one sort, or for a few ids `_positions`)."""
        ids = np.ascontiguousarray(landmark_ids, dtype=np.int64).reshape(-1)
        if ids.size <= _FEW_IDS:  # a scan's few: a pass over the state per id
            return _positions(np.ascontiguousarray(self.landmark_ids, dtype=np.int64), ids)
        if not self.landmark_ids.size:
            return np.full(ids.size, -1, np.int64)
        order = np.argsort(self.landmark_ids, kind="stable")
        at = np.minimum(np.searchsorted(self.landmark_ids[order], ids), order.size - 1)
        pos = order[at]
        return np.where(self.landmark_ids[pos] == ids, pos, -1)


@dataclass(frozen=True, eq=False)
class EkfState(_Estimate):
    """The filter's estimate, immutable.

    x: (3 + 2 n,) [x_m, y_m, theta_rad, then n landmark positions x_m, y_m], world frame.
    P: (3 + 2 n, 3 + 2 n) covariance, symmetric positive semi-definite.
    landmark_ids: (n,) int64 stable ids of the landmarks, in state order.
    Arrays are stored read-only; the constructor validates and copies them.
    """

    x: np.ndarray
    P: np.ndarray
    landmark_ids: np.ndarray

    def __post_init__(self) -> None:
        x = np.array(self.x, dtype=np.float64)
        P = np.array(self.P, dtype=np.float64)
        ids = np.array(self.landmark_ids, dtype=np.int64).reshape(-1)
        if x.ndim != 1 or x.shape[0] < 3 or (x.shape[0] - 3) % 2:
            raise SlamError(f"EkfState.x: expected shape (3 + 2 n,), got {x.shape}")
        d = x.shape[0]
        if P.shape != (d, d):
            raise SlamError(f"EkfState.P: expected shape ({d}, {d}), got {P.shape}")
        if ids.shape[0] != (d - 3) // 2:
            raise SlamError(
                f"EkfState.landmark_ids: expected {(d - 3) // 2} ids, got {ids.shape[0]}"
            )
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise SlamError("EkfState.x, P: must be finite")
        object.__setattr__(self, "x", _readonly(x))
        object.__setattr__(self, "P", _readonly(P))
        object.__setattr__(self, "landmark_ids", _readonly(ids))


@dataclass(frozen=True, eq=False)
class UpdateResult:
    """What an update returns besides the new state.

    innovation: (k, 2) z - z_hat (bearing wrapped). S: (2 k, 2 k) joint innovation covariance.
    nis: nu^T S^-1 nu of the whole batch (chi-square with 2 k dof when consistent).
    logdet: ln |S| (with nis, the batch's Gaussian log-likelihood -1/2 (nis + ln|2 pi S|)).
    """

    innovation: np.ndarray
    S: np.ndarray
    nis: float
    logdet: float = math.nan


class Filter(_Estimate):
    """The working state of a run, changed in place by `predict`, `update`, `add_landmark`.

    Built from an `EkfState` (copied); `snapshot()` returns an immutable `EkfState`. Views such
    as `pose` or `P` change with the filter: copy what must be kept.

    The steps keep only P's lower triangle current (`update` subtracts W W^T from it alone):
    reading `P` mirrors it to the upper one first (O(d^2), once per update at most), which the
    run loop avoids by reading what it needs through `cov`, `pose_cov` and `landmark_covs`.
    """

    def __init__(self, state: EkfState, first_estimates: bool = False) -> None:
        self.x = np.array(state.x, dtype=np.float64)
        self._P = np.array(state.P, dtype=np.float64, order="C")
        self._mirrored = True  # whether the upper triangle of _P is current
        self.landmark_ids = np.array(state.landmark_ids, dtype=np.int64)
        self.first_estimates = bool(first_estimates)
        self.first_xy = self.landmarks_xy.copy()  # each landmark's first estimate
        self.prior_pose = self.x[:3].copy()  # the pose after the last prediction
        self.copy_of = np.zeros(0, np.int64)  # the hidden slots: the landmark each one copies

    @property
    def P(self) -> np.ndarray:
        """(d, d) covariance, symmetric (mirrored from the lower triangle when it lags)."""
        if not self._mirrored:
            _mirror_lower(self._P)
            self._mirrored = True
        return self._P

    @property
    def _lower(self) -> np.ndarray:
        return self._P

    def rows(self, idx) -> np.ndarray:
        idx = np.ascontiguousarray(idx, dtype=np.int64).reshape(-1)
        return self._P[idx] if self._mirrored else _sym_rows(self._P, idx)

    def snapshot(self) -> EkfState:
        """The landmarks' estimate (the hidden copies marginalised out), immutable."""
        d = 3 + 2 * self.n_landmarks
        return EkfState(self.x[:d], self.P[:d, :d], self.landmark_ids)

    def append_copies(self, landmark_ids, extra, on_copy=None) -> None:
        """Append a hidden copy of each of these landmarks, then add extra (k, 2, 2) to the
        landmark's own covariance block: the copy (a slot after the landmarks, which
        `landmarks_xy`, `landmark_ids`, `snapshot` and the steps' indices do not see) keeps
        the landmark's estimate and all its covariances, its cross-covariance with the
        landmark included (the landmark's block before the addition); the landmark becomes
        the copy plus an independent error of covariance extra, whose later updates reach the
        copy through that correlation. on_copy (k,) bool (default none): for these, extra
        goes to the copy's block instead (the landmark is the copy less an independent error:
        an estimate that already carries the error). `restore_copies` marginalises the error
        out. Cost O(d^2) (P grows: a copy), one copy for the whole batch."""
        ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
        extra = np.asarray(extra, dtype=np.float64).reshape(ids.size, 2, 2)
        on_copy = np.zeros(ids.size, bool) if on_copy is None else np.asarray(on_copy, bool)
        if not ids.size:
            return
        pos = self.positions_of(ids)
        if np.any(pos < 0) or np.unique(ids).size != ids.size or np.isin(ids, self.copy_of).any():
            raise SlamError(
                f"append_copies: landmark ids {ids.tolist()} must be distinct landmarks of the "
                "state without a copy"
            )
        cols = _pair_cols(pos)
        P = self.P  # mirrored: the new rows are read whole
        d, q = self.dim, cols.size
        out = np.empty((d + q, d + q))
        out[:d, :d] = P
        out[d:, :d] = P[cols]
        out[:d, d:] = out[d:, :d].T
        out[d:, d:] = P[np.ix_(cols, cols)]
        for j, (c, e) in enumerate(zip(cols[::2].tolist(), extra)):
            c = d + 2 * j if on_copy[j] else c
            out[c : c + 2, c : c + 2] += 0.5 * (e + e.T)
        self._P = out
        self._mirrored = True
        self.x = np.concatenate([self.x, self.x[cols]])
        self.copy_of = np.concatenate([self.copy_of, ids])

    def _copy_columns(self, ids: np.ndarray, who: str):
        """(slots of the copies (k,), the landmarks' columns (2 k,), the copies' columns (2 k,))
        of the distinct landmark ids (k,), each with a copy; `who` names the caller's error."""
        where = {i: j for j, i in enumerate(self.copy_of.tolist())}
        if np.unique(ids).size != ids.size or not all(i in where for i in ids.tolist()):
            raise SlamError(f"{who}: landmark ids {ids.tolist()} must each have a copy")
        slot = np.array([where[i] for i in ids.tolist()], np.int64)
        return slot, _pair_cols(self.positions_of(ids)), _pair_cols(self.n_landmarks + slot)

    def restore_copies(self, landmark_ids=None) -> None:
        """Give each of these landmarks (None: every landmark with a copy) its hidden copy's
        estimate back (x, its row and column of P, its own block) and drop the copy: the error
        `append_copies` added is marginalised out, exact for a Gaussian. Cost O(d^2)."""
        ids = self.copy_of.copy() if landmark_ids is None else landmark_ids
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if not ids.size:
            return
        slot, cols, hid = self._copy_columns(ids, "restore_copies")
        P = self.P
        P[cols, :] = P[hid, :]
        P[:, cols] = P[:, hid]  # the landmark's own block is now the copy's
        self.x[cols] = self.x[hid]
        keep = np.ones(self.dim, bool)
        keep[hid] = False
        self.x = self.x[keep]
        self._P = np.ascontiguousarray(P[np.ix_(keep, keep)])
        self.copy_of = np.delete(self.copy_of, slot)

    def blend_copies(self, landmark_ids, phi, extra) -> None:
        """A first-order Gauss-Markov step of the error `append_copies` added to each of these
        landmarks (each has a hidden copy): landmark <- phi landmark + (1 - phi) copy, then
        extra (k, 2, 2) added to the landmark's own block, i.e. the error e = landmark - copy
        becomes phi e plus an independent error of covariance extra. phi (k,) in [0, 1].
        x <- T x, P <- T P T^T + extra on the landmark's block. Cost O(d) per landmark."""
        ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
        if not ids.size:
            return
        phi = np.asarray(phi, dtype=np.float64).reshape(ids.size)
        extra = np.asarray(extra, dtype=np.float64).reshape(ids.size, 2, 2)
        _, cols, hid = self._copy_columns(ids, "blend_copies")
        if not np.all((phi >= 0.0) & (phi <= 1.0)):
            raise SlamError(f"blend_copies: phi must be in [0, 1], got {phi.tolist()}")
        f = np.repeat(phi, 2)
        P = self.P  # mirrored: rows, then columns (T P, then (T P) T^T)
        P[cols, :] = f[:, None] * P[cols, :] + (1.0 - f)[:, None] * P[hid, :]
        P[:, cols] = P[:, cols] * f[None, :] + P[:, hid] * (1.0 - f)[None, :]
        for c, e in zip(cols[::2].tolist(), extra):
            P[c : c + 2, c : c + 2] += 0.5 * (e + e.T)
        self.x[cols] = f * self.x[cols] + (1.0 - f) * self.x[hid]

    def predict(self, pose1: np.ndarray, F: np.ndarray, Q: np.ndarray) -> None:
        """Prediction with the motion's result `pose1`, Jacobian F (3, 3) and noise Q (3, 3).

        Only the vehicle rows and columns change (the landmarks are static): cost O(n).
        """
        if self.first_estimates:  # FEJ: the Jacobian from the prior poses (see the module doc)
            F = np.array(
                [
                    [1.0, 0.0, -(pose1[1] - self.prior_pose[1])],
                    [0.0, 1.0, pose1[0] - self.prior_pose[0]],
                    [0.0, 0.0, 1.0],
                ]
            )
            self.prior_pose = np.array(pose1, dtype=np.float64)
        P = self._P
        Pvv = F @ self.pose_cov @ F.T + Q
        P[:3, :3] = 0.5 * (Pvv + Pvv.T)
        if self.dim > 3:  # from the lower triangle's copy of P_vm, written to both
            P[:3, 3:] = F @ P[3:, :3].T
            P[3:, :3] = P[:3, 3:].T
        self.x[:3] = pose1
        self.x[2] = float(wrap_angle(self.x[2]))

    def update(
        self, idx: np.ndarray, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray
    ) -> UpdateResult:
        """Batch update with measurements z (k, 2) of the landmarks at state positions idx (k,).

        R: (k, 2, 2) measurement covariances (independent measurements). Joseph form with the
        optimal gain as a rank-q downdate P - W W^T (see the module doc); H touches only the
        pose and the observed landmarks' columns.
        """
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        if idx.size == 0:
            return UpdateResult(np.zeros((0, 2)), np.zeros((0, 0)), math.nan)
        nu, cols, Hc, R_blk = self._batch(idx, z, R, laser_pose, "update")
        P = self._P
        HP = Hc @ _sym_rows(P, cols)  # (q, d) = (P H^T)^T, from whole rows of P
        S = Hc @ HP[:, cols].T + R_blk
        S = 0.5 * (S + S.T)
        L = np.linalg.cholesky(S)  # S = L L^T
        # W = P H^T L^-T (d, q), in Fortran order for BLAS: K = W L^-1, K S K^T = W W^T.
        W = blas.dtrsm(1.0, L, HP.T, side=1, lower=1, trans_a=1, overwrite_b=1)
        v = blas.dtrsv(L, nu.reshape(-1), lower=1)  # L^-1 nu
        nis = float(v @ v)
        logdet = 2.0 * float(np.log(np.diag(L)).sum())
        self.x += W @ v  # K nu
        self.x[2] = float(wrap_angle(self.x[2]))
        # Joseph form with the optimal gain: P - K S K^T = P - W W^T (lower triangle only)
        _subtract_gram(P, W, mirror=False)
        self._mirrored = False
        return UpdateResult(nu, S, nis, logdet)

    def innovation(
        self, idx: np.ndarray, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(nu (k, 2), S (2 k, 2 k)): the innovations of measurements z (k, 2) of the landmarks
        at state positions idx (k,) and their joint covariance H P H^T + R (the pose's
        correlations included), as `update` computes them, without updating (a joint gate's)."""
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        if idx.size == 0:
            return np.zeros((0, 2)), np.zeros((0, 0))
        nu, cols, Hc, R_blk = self._batch(idx, z, R, laser_pose, "innovation")
        S = Hc @ (Hc @ _sym_rows(self._P, cols))[:, cols].T + R_blk
        return nu, 0.5 * (S + S.T)

    def _batch(self, idx: np.ndarray, z, R, laser_pose, who: str):
        """(nu, cols, Hc, R_blk) of a batch of measurements z (k, 2), R (k, 2, 2) of the
        landmarks at positions idx (k,), k >= 1, checked (`who`: the caller, for errors)."""
        k = idx.size
        n = self.landmarks_xy.shape[0]
        if idx.min() < 0 or idx.max() >= n:  # the kernel below reads idx unchecked
            raise SlamError(
                f"{who}.idx: landmark positions must be in [0, {n}), got {idx.tolist()}"
            )
        z = np.ascontiguousarray(z, dtype=np.float64).reshape(k, 2)
        R = np.ascontiguousarray(R, dtype=np.float64).reshape(k, 2, 2)
        # nu = z - z_hat (bearing wrapped), the columns the batch touches ([x, y, theta, then
        # each landmark's pair]) and H on them (FEJ: at the landmarks' first estimates)
        if observe is _SE2_OBSERVE:  # the sensor model, fused
            sensor = sensor_numbers(self.pose, laser_pose)
            nu, cols, Hc, R_blk, twice = _batch_inputs(
                self.landmarks_xy,
                self.first_xy,
                idx,
                z,
                R,
                sensor,
                (float(self.x[2]), float(laser_pose[2])),
                self.first_estimates,
            )
        else:  # another observation model put in its place (the closed-form tests' linear one)
            nu, cols, Hc, R_blk, twice = self._batch_inputs_of(observe, idx, z, R, laser_pose)
        if twice:
            raise SlamError(f"{who}.idx: a landmark appears twice in one batch")
        return nu, cols, Hc, R_blk

    def _batch_inputs_of(self, observe_fn, idx, z, R, laser_pose):
        """`_batch_inputs` by the numpy steps it fused, through `observe_fn` (an observation
        model other than `se2.observe`)."""
        z_hat, H5 = observe_fn(self.pose, self.landmarks_xy[idx], laser_pose)
        if self.first_estimates:  # FEJ: Jacobians at the landmarks' first estimates
            H5 = observe_fn(self.pose, self.first_xy[idx], laser_pose)[1]
        nu = z - z_hat
        nu[:, 1] = wrap_angle(nu[:, 1])
        cols, Hc, R_blk = _batch_blocks(idx, H5, R)
        return nu, cols, Hc, R_blk, len(set(idx.tolist())) != idx.size

    def add_landmark(
        self, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray, landmark_id: int
    ) -> None:
        """Append a landmark initialised from measurement z (2,) with covariance R (2, 2).

        Its cross covariances with the vehicle and every other landmark are Gx P_v*, its own
        covariance Gx P_vv Gx^T + Gz R Gz^T (cost O(d^2) for the copy, O(d) for the new rows).
        """
        if np.any(self.landmark_ids == landmark_id):
            raise SlamError(f"add_landmark.landmark_id: {landmark_id} is already in the state")
        m, Gx, Gz = inverse_observe(self.pose, z, laser_pose)
        d, e = self.dim, 3 + 2 * self.n_landmarks  # e: where it goes, before any hidden copy
        P = np.empty((d + 2, d + 2))  # every block is written below: no zeroing of d^2
        old = self._P  # the order of the rows is kept: the triangles stay where they were
        P[:e, :e] = old[:e, :e]  # its upper triangle lags as much as the old one did
        P[e + 2 :, :e] = old[e:, :e]
        P[:e, e + 2 :] = old[:e, e:]
        P[e + 2 :, e + 2 :] = old[e:, e:]
        cross = Gx @ _sym_rows(old, _POSE_COLS[0])  # (2, d)
        P[e : e + 2, :e] = cross[:, :e]
        P[:e, e : e + 2] = cross[:, :e].T
        P[e : e + 2, e + 2 :] = cross[:, e:]
        P[e + 2 :, e : e + 2] = cross[:, e:].T
        Pmm = Gx @ self.pose_cov @ Gx.T + Gz @ np.asarray(R) @ Gz.T
        P[e : e + 2, e : e + 2] = 0.5 * (Pmm + Pmm.T)
        self._P = P
        self.x = np.concatenate([self.x[:e], m, self.x[e:]])
        self.landmark_ids = np.concatenate([self.landmark_ids, np.array([landmark_id], np.int64)])
        self.first_xy = np.concatenate([self.first_xy, m[None, :]])

    def remove_landmarks(self, landmark_ids) -> None:
        """Remove these landmarks from the state: their rows and columns of x and P go
        (marginalisation, exact for a Gaussian); the others keep their order."""
        ids = np.asarray(landmark_ids, dtype=np.int64).reshape(-1)
        pos = np.flatnonzero(np.isin(self.landmark_ids, ids))
        if pos.size != np.unique(ids).size:
            missing = sorted(set(ids.tolist()) - set(self.landmark_ids[pos].tolist()))
            raise SlamError(f"remove_landmarks: landmark ids {missing} are not in the state")
        if not pos.size:
            return
        keep = np.ones(self.dim, bool)
        keep[3 + 2 * pos] = False
        keep[4 + 2 * pos] = False
        copies = np.flatnonzero(np.isin(self.copy_of, ids))  # their hidden copies go too
        keep[_pair_cols(self.n_landmarks + copies)] = False
        self.x = self.x[keep]
        self._P = np.ascontiguousarray(self._P[np.ix_(keep, keep)])  # keeps the triangles
        self.landmark_ids = np.delete(self.landmark_ids, pos)
        self.copy_of = np.delete(self.copy_of, copies)
        self.first_xy = np.delete(self.first_xy, pos, axis=0)


@njit(cache=True)
def _positions(landmark_ids: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The position of each of ids (k,) in landmark_ids (n,), distinct ids, -1 where absent:
    a pass over the state per id (k is a scan's few landmarks; the sort and search this
    replaced cost more than k passes over hundreds). Loops bounded by k and n."""
    out = np.full(ids.size, -1, np.int64)
    for a in range(ids.size):
        for i in range(landmark_ids.size):
            if landmark_ids[i] == ids[a]:
                out[a] = i
                break
    return out


@njit(cache=True)
def _batch_inputs(lm_xy, first_xy, idx, z, R, sensor, headings, first_estimates: bool):
    """`Filter.update`'s inputs in one call (its dozen array operations cost more than the
    arithmetic): (nu (k, 2), cols, Hc, R_blk (`_batch_blocks`), whether a landmark appears
    twice in idx) for measurements z (k, 2), R (k, 2, 2) of the landmarks at positions idx
    (k,) (lm_xy (n, 2); first_xy (n, 2) their first estimates, for the Jacobians when
    first_estimates); sensor: `se2.sensor_numbers`'s four numbers, headings: (the vehicle's,
    the sensor's yaw). The same operations as `se2.observe` and `se2.wrap_angle`, to the bit.
    Loops bounded by k."""
    k = idx.size
    twice = False
    seen = np.sort(idx)
    for j in range(1, k):
        twice = twice or seen[j] == seen[j - 1]
    m = np.empty((k, 2))
    for j in range(k):
        m[j, 0], m[j, 1] = lm_xy[idx[j], 0], lm_xy[idx[j], 1]
    px, py, dpx, dpy = sensor
    z_hat, H5 = observe_kernel(m, px, py, dpx, dpy, headings[0], headings[1])
    if first_estimates:
        for j in range(k):
            m[j, 0], m[j, 1] = first_xy[idx[j], 0], first_xy[idx[j], 1]
        H5 = observe_kernel(m, px, py, dpx, dpy, headings[0], headings[1])[1]
    nu = np.empty((k, 2))
    for j in range(k):
        nu[j, 0] = z[j, 0] - z_hat[j, 0]
        nu[j, 1] = np.pi - np.mod(np.pi - (z[j, 1] - z_hat[j, 1]), 2.0 * np.pi)  # wrap_angle
    cols, Hc, R_blk = _batch_blocks(idx, H5, R)
    return nu, cols, Hc, R_blk, twice


@njit(cache=True)
def _batch_blocks(idx: np.ndarray, H5: np.ndarray, R: np.ndarray):
    """The blocks of a batch update of the landmarks at positions idx (k,): the state columns
    it touches cols (3 + q,) = [x, y, theta, then each landmark's pair], H on them Hc (q, 3 + q)
    (pose columns, then landmark j's 2 x 2 block in row pair j) and the block-diagonal
    measurement covariance (q, q), q = 2 k; from the 5-column Jacobians H5 (k, 2, 5) and
    R (k, 2, 2)."""
    k = idx.size
    q = 2 * k
    cols = np.empty(3 + q, np.int64)
    cols[0], cols[1], cols[2] = 0, 1, 2
    Hc = np.zeros((q, 3 + q))
    R_blk = np.zeros((q, q))
    for j in range(k):
        cols[3 + 2 * j] = 3 + 2 * idx[j]
        cols[4 + 2 * j] = 4 + 2 * idx[j]
        for r in range(2):
            row = 2 * j + r
            for c in range(3):
                Hc[row, c] = H5[j, r, c]
            Hc[row, 3 + 2 * j] = H5[j, r, 3]
            Hc[row, 4 + 2 * j] = H5[j, r, 4]
            R_blk[row, 2 * j] = R[j, r, 0]
            R_blk[row, 2 * j + 1] = R[j, r, 1]
    return cols, Hc, R_blk


def _subtract_gram(P: np.ndarray, W: np.ndarray, mirror: bool = True) -> None:
    """P -= W W^T in place, P symmetric (d, d), W (d, r).

    BLAS `dsyrk` updates one triangle of P's Fortran view P^T (P's lower triangle) and
    `_mirror_lower` copies it to the other, so the result is symmetric to the last bit;
    mirror=False leaves the upper triangle as it was (only the lower one is current).
    A P that is not a C-contiguous float64 array takes the plain numpy route."""
    if P.dtype != np.float64 or not P.flags.c_contiguous:
        P -= W @ W.T
        return
    out = blas.dsyrk(-1.0, W, beta=1.0, c=P.T, lower=0, overwrite_c=1)
    if not np.shares_memory(out, P):  # BLAS made a copy after all: use it
        P[...] = out.T
    if mirror:
        _mirror_lower(P)


@njit(cache=True)
def _mirror_lower(P: np.ndarray) -> None:
    """P[j, i] = P[i, j] for j < i: row by row, contiguous reads and one write per row of the
    upper triangle (measured 2x faster at d = 450-900 than copying by 64 x 64 blocks)."""
    d = P.shape[0]
    for i in range(d):
        for j in range(i):
            P[j, i] = P[i, j]


_POSE_COLS = np.array([[0, 1, 2]], np.int64)

# `positions_of` looks up at most this many ids by passes over the state (k passes over n ids
# cost less than the sort and search up to a few dozen)
_FEW_IDS = 32


def _pair_cols(pos: np.ndarray) -> np.ndarray:
    """(2 k,) the state columns [3 + 2 i, 4 + 2 i, ...] of the 2-D slots at positions pos (k,)
    (landmarks, then the hidden copies after them)."""
    pos = np.asarray(pos, dtype=np.int64).reshape(-1)
    return ((3 + 2 * pos)[:, None] + np.arange(2)).reshape(-1)


@njit(cache=True)
def _sym_blocks(P: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """out[n, a, b] = P[idx[n, a], idx[n, b]] of a symmetric P, read from its lower triangle."""
    n, k = idx.shape
    out = np.empty((n, k, k))
    for t in range(n):
        for a in range(k):
            r = idx[t, a]
            for b in range(k):
                c = idx[t, b]
                out[t, a, b] = P[r, c] if r >= c else P[c, r]
    return out


@njit(cache=True)
def _sym_rows(P: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """P[rows, :] (k, d) of a symmetric P, read from its lower triangle."""
    d = P.shape[0]
    out = np.empty((rows.size, d))
    for a in range(rows.size):
        r = rows[a]
        for c in range(r + 1):
            out[a, c] = P[r, c]
        for c in range(r + 1, d):
            out[a, c] = P[c, r]
    return out


def initial_state(pose: np.ndarray, pose_cov: np.ndarray | None = None) -> EkfState:
    """A state with no landmarks at `pose` with covariance `pose_cov` (zeros when None)."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (3,):
        raise SlamError(f"initial_state.pose: expected shape (3,), got {pose.shape}")
    P = np.zeros((3, 3)) if pose_cov is None else np.asarray(pose_cov, dtype=np.float64)
    return EkfState(pose.copy(), P, np.zeros(0, np.int64))


def predict(state: EkfState, pose1: np.ndarray, F: np.ndarray, Q: np.ndarray) -> EkfState:
    """`Filter.predict` on a copy of `state`."""
    f = Filter(state)
    f.predict(pose1, F, Q)
    return f.snapshot()


def update(
    state: EkfState, idx: np.ndarray, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray
) -> tuple[EkfState, UpdateResult]:
    """`Filter.update` on a copy of `state`: (new state, UpdateResult)."""
    f = Filter(state)
    res = f.update(idx, z, R, laser_pose)
    return f.snapshot(), res


def add_landmark(
    state: EkfState, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray, landmark_id: int
) -> EkfState:
    """`Filter.add_landmark` on a copy of `state`."""
    f = Filter(state)
    f.add_landmark(z, R, laser_pose, landmark_id)
    return f.snapshot()


def landmark_columns(idx: np.ndarray) -> np.ndarray:
    """(k, 5) state columns [0, 1, 2, 3 + 2 i, 4 + 2 i] of landmarks at positions idx."""
    idx = np.asarray(idx, dtype=np.int64).reshape(-1)
    cols = np.empty((idx.size, 5), np.int64)
    cols[:, :3] = _POSE_COLS  # broadcast from an array: a list would be converted every call
    cols[:, 3] = 3 + 2 * idx
    cols[:, 4] = 4 + 2 * idx
    return cols


def observe_jacobian_full(
    state: _Estimate, idx: np.ndarray, laser_pose: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """z_hat (k, 2) and the dense Jacobians H (k, 2, d) of landmarks at positions idx."""
    idx = np.asarray(idx, dtype=np.int64).reshape(-1)
    z, H5 = observe(state.pose, state.landmarks_xy[idx], laser_pose)
    H = np.zeros((idx.size, 2, state.dim))
    cols = landmark_columns(idx)
    for j in range(idx.size):
        H[j][:, cols[j]] = H5[j]
    return z, H
