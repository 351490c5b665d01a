"""`slam.run`: EKF-SLAM over one `Sequence`, scan by scan.

Per scan k (times `scan_t[k]`), five steps, each a function below:
1. `_predict`: integrate the odometry from the previous scan (zero-order hold, `slam.vehicle`);
2. `_measure`: the scan's circles (a method name for `features.extract_features`, a callable
   (k, scan) -> Features, or a list of precomputed Features) as range-bearing measurements of
   their centres in the laser frame (`slam.measurement`);
3. `_associate`: the landmarks and tentative features that can be in view are offered to
   `association.associate` (IHGR by default, JCBB or NN), on the sub-state [pose, those
   landmarks] (the Jacobians are zero elsewhere, so this is exact and keeps the cost down);
4. `_update`: all associated map measurements at once (Joseph form, `slam.ekf.update`);
5. `_manage` (`slam.mapping`): associated tentatives count a sighting and join the map after
   three scans (initialised from the current measurement with cross covariances); unassociated
   measurements that gate with no landmark or tentative start new tentatives; tentatives not
   associated are dropped.

The start pose is the truth at the first scan when the sequence has truth, else the first GPS
fix (antenna offset removed; heading from `initial_heading_rad` or the first GPS motion of at
least 2 m), else the origin. Everything the run did is returned as a `SlamLog`
(`slam.log.LogBuilder` assembles it). The optional visualiser is any object with the methods of
`NullVisualiser` (which does nothing).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slam import se2
from slam.config import SlamConfig
from slam.ekf import EkfState, add_landmark, initial_state, predict, update
from slam.errors import SlamError
from slam.log import (
    AMBIGUOUS,
    CONFIRMED,
    NEW_TENTATIVE,
    OUT_OF_RANGE,
    TENTATIVE_HIT,
    LogBuilder,
    SlamLog,
)
from slam.mapping import Tentatives, sighting
from slam.measurement import measurements_from_features
from slam.sequence import Sequence
from slam.vehicle import AckermannModel, Odometry, integrate

__all__ = ["NullVisualiser", "run"]

log = logging.getLogger(__name__)


class NullVisualiser:
    """The visualiser interface; does nothing (kiss-icp's StubVisualizer).

    Poses are world [x, y, theta]; `pose` of log_scan/log_features is the laser's world pose.
    """

    def set_scan(self, k: int, stamp_s: float | None = None) -> None: ...
    def log_scan(self, scan, pose=None, path: str = "world/scan") -> None: ...
    def log_features(self, scan, features, pose=None, path: str = "world/features") -> None: ...
    def log_vehicle(self, pose, cov) -> None: ...
    def log_landmarks(self, xy, cov, ids) -> None: ...
    def log_tentatives(self, xy) -> None: ...
    def log_associations(self, from_xy, to_xy) -> None: ...
    def log_truth(self, pose) -> None: ...


@dataclass(frozen=True, eq=False)
class _Setup:
    """What stays fixed during a run."""

    seq: Sequence
    cfg: SlamConfig
    features: Callable  # (k, scan) -> Features
    associate: Callable  # the signature of association.associate minus `method`
    model: AckermannModel
    odometry: Odometry
    laser: np.ndarray  # (3,) laser pose in the vehicle frame
    noise: tuple  # ("fit" | "constant", model), SlamConfig.noise_for
    floor: tuple[float, float]
    fov: tuple[float, float]  # first and last beam angle, rad, laser frame
    max_range: float
    gate_new: float  # chi2 (2 dof) of the gate outside which a measurement may be new


@dataclass(frozen=True, eq=False)
class _Association:
    """One scan's association: assign (m,) is an index into [landmarks in view, tentatives in
    view] or -1; ambiguous (m,) marks unassigned measurements inside the wider gate of something;
    lm_idx, t_idx: state positions of the landmarks in view and indices of the tentatives."""

    assign: np.ndarray
    ambiguous: np.ndarray
    lm_idx: np.ndarray
    t_idx: np.ndarray


def run(
    sequence: Sequence,
    features="paper",
    association="ihgr",
    config: SlamConfig | None = None,
    *,
    feature_params: dict | None = None,
    visualiser=None,
    initial_heading_rad: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> SlamLog:
    """EKF-SLAM over `sequence` (a `slam.Sequence`); returns the `SlamLog`.

    features: a `features.extract_features` method name ("paper", "geometric", "bailey"), a
        callable (k, scan) -> Features, or a list of N precomputed Features (laser frame).
    association: "ihgr", "jcbb", "nn", or a callable with the signature of
        `association.associate` minus `method` (z, R, z_hat, H, P, gate_prob=..., **params).
    feature_params: keyword arguments for `extract_features` (method name only).
    visualiser: an object with the methods of `NullVisualiser` (default: nothing is logged).
    initial_heading_rad: overrides the start heading (needed for GPS starts without motion).
    progress: callback(done, total) after each scan.
    Raises `SlamError` (a ValueError) for a run that cannot be made: not a `Sequence`, missing
    odometry or vehicle, odometry gaps, a mismatched list of features.
    """
    s = _setup(sequence, features, association, config, feature_params)
    vis = visualiser or NullVisualiser()
    pose0, cov0, start = _start(sequence, s.cfg, initial_heading_rad)
    state = initial_state(pose0, cov0)
    tent = Tentatives.empty()
    next_id = 0
    book = LogBuilder(np.asarray(sequence.scan_t, dtype=np.float64))
    N = sequence.n_scans
    for k in range(N):
        t = [time.perf_counter()]
        state = _predict(s, state, k)
        book.predicted(k, state.pose, state.pose_cov)
        t.append(time.perf_counter())
        scan, f, z, R, status = _measure(s, k)
        t.append(time.perf_counter())
        a = _associate(s, state, tent, z, R, status != OUT_OF_RANGE)
        t.append(time.perf_counter())
        state, nis, n_used = _update(s, state, z, R, a, status, book, k)
        t.append(time.perf_counter())
        state, tent, next_id = _manage(s, state, tent, z, R, a, status, book, k, next_id)
        t.append(time.perf_counter())
        book.scan_done(k, state, len(tent), z, R, status, n_used, nis, 2 * n_used, t)
        _visualise(vis, k, sequence, scan, f, state, tent, s.laser, z, status)
        if progress is not None:
            progress(k + 1, N)
    return book.build(
        state,
        start=start,
        features_method=getattr(s.features, "method", "custom"),
        association_method=getattr(s.associate, "method", "custom"),
        config=s.cfg.to_dict(),
    )


def _setup(seq, features, association, config, feature_params) -> _Setup:
    if not isinstance(seq, Sequence):
        raise SlamError(f"sequence: expected a slam.Sequence, got {type(seq).__name__}")
    cfg = config or SlamConfig()
    if not isinstance(cfg, SlamConfig):
        raise SlamError(f"config: expected a SlamConfig, got {type(cfg).__name__}")
    feat_fn, n_pre = _resolve_features(features, dict(feature_params or {}))
    _check_runnable(seq, n_pre, cfg)
    a0 = float(seq.scan_angle_min)
    return _Setup(
        seq=seq,
        cfg=cfg,
        features=feat_fn,
        associate=_resolve_association(association),
        model=AckermannModel.from_vehicle(seq.vehicle),
        odometry=Odometry(seq.odo_t, seq.odo_speed, seq.odo_steer),
        laser=np.asarray(seq.laser_pose, dtype=np.float64),
        noise=cfg.noise_for(feat_fn.method),
        floor=(cfg.fit_floor_range_m, cfg.fit_floor_bearing_rad),
        fov=(a0, a0 + float(seq.scan_angle_increment) * (seq.n_beams - 1)),
        max_range=min(float(seq.scan_max_range), cfg.max_feature_range_m),
        gate_new=-2.0 * math.log1p(-max(cfg.new_feature_gate_prob, cfg.gate_prob)),
    )


# ---- the five steps -----------------------------------------------------------------------------


def _predict(s: _Setup, state: EkfState, k: int) -> EkfState:
    """Step 1: the odometry from scan k - 1 to scan k (nothing before the first scan)."""
    if k == 0:
        return state
    t = s.seq.scan_t
    p1, F, Q = integrate(s.model, state.pose, s.odometry, t[k - 1], t[k], s.cfg.odometry_noise)
    return predict(state, p1, F, Q)


def _measure(s: _Setup, k: int):
    """Step 2: scan k, its features, their measurements z (m, 2), R (m, 2, 2), and the status of
    each (NEW_TENTATIVE until decided; OUT_OF_RANGE beyond the usable range or not finite)."""
    scan = s.seq.scan(k)
    f = s.features(k, scan)
    z, R = measurements_from_features(f, s.noise, s.floor)
    status = np.full(z.shape[0], NEW_TENTATIVE, np.int64)
    usable = (z[:, 0] <= s.max_range) & np.all(np.isfinite(z), axis=1)
    status[~usable] = OUT_OF_RANGE
    return scan, f, z, R, status


def _associate(s: _Setup, state: EkfState, tent: Tentatives, z, R, usable) -> _Association:
    """Step 3: the usable measurements against the landmarks and tentatives that can be in view,
    on the sub-state [pose, landmarks in view] (tentatives with their own covariance)."""
    cfg = s.cfg
    z_lm, H_lm = se2.observe(state.pose, state.landmarks_xy, s.laser)
    vis_lm = _in_view(z_lm, s.max_range, s.fov, cfg)
    z_t, H_t = se2.observe(state.pose, tent.xy, s.laser)
    vis_t = _in_view(z_t, s.max_range, s.fov, cfg)
    lm_idx = np.arange(state.n_landmarks)[vis_lm]
    t_idx = np.flatnonzero(vis_t)
    n = lm_idx.size + t_idx.size
    m = z.shape[0]
    assign = np.full(m, -1, np.int64)
    ambiguous = np.zeros(m, bool)
    use = np.flatnonzero(usable)
    if use.size and n:
        zh = np.concatenate([z_lm[vis_lm], z_t[vis_t]])
        d_sub = 3 + 2 * n
        Hv = np.concatenate([H_lm[vis_lm], H_t[vis_t]])  # (n, 2, 5)
        H = np.zeros((n, 2, d_sub))
        H[:, :, :3] = Hv[:, :, :3]
        for j in range(n):
            H[j, :, 3 + 2 * j : 5 + 2 * j] = Hv[j, :, 3:5]
        cols = np.concatenate(
            [[0, 1, 2], np.stack([3 + 2 * lm_idx, 4 + 2 * lm_idx], 1).reshape(-1)]
        ).astype(np.int64)
        P_sub = np.zeros((d_sub, d_sub))
        nc = cols.size
        P_sub[:nc, :nc] = state.P[np.ix_(cols, cols)]
        for j, ti in enumerate(t_idx):
            a = nc + 2 * j
            P_sub[a : a + 2, a : a + 2] = tent.cov[ti]
        a_use = s.associate(
            z[use], R[use], zh, H, P_sub, gate_prob=cfg.gate_prob, **cfg.association_params
        )
        assign[use] = np.asarray(a_use, dtype=np.int64)
        ambiguous[use] = (assign[use] < 0) & _gated_any(z[use], R[use], zh, H, P_sub, s.gate_new)
    return _Association(assign, ambiguous, lm_idx, t_idx)


def _update(s: _Setup, state: EkfState, z, R, a: _Association, status, book: LogBuilder, k: int):
    """Step 4: one batch update with the measurements paired with map landmarks.

    Returns the new state, the batch NIS (NaN without an update) and the number of
    measurements used; sets their status to the landmark id and logs them."""
    n_l = a.lm_idx.size
    to_map = np.flatnonzero(a.assign >= 0)
    to_map = to_map[a.assign[to_map] < n_l]
    if not to_map.size:
        return state, math.nan, 0
    pos = a.lm_idx[a.assign[to_map]]
    state, res = update(state, pos, z[to_map], R[to_map], s.laser)
    for j, i in enumerate(to_map):
        lid = int(state.landmark_ids[pos[j]])
        status[i] = lid
        S_j = res.S[2 * j : 2 * j + 2, 2 * j : 2 * j + 2]
        book.observation(k, int(i), lid, z[i], res.innovation[j], S_j)
    return state, res.nis, int(to_map.size)


def _manage(s: _Setup, state, tent: Tentatives, z, R, a: _Association, status, book, k, next_id):
    """Step 5: tentatives seen again count a sighting (and join the map at the policy's count),
    new measurements start tentatives, ambiguous ones are ignored, unseen tentatives drop out.

    Returns the new state, tentatives and next free landmark id; sets each measurement's status.
    """
    policy = s.cfg.map_policy
    n_l = a.lm_idx.size
    matched: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    matched_meas: dict[int, int] = {}
    new: list[tuple[np.ndarray, np.ndarray, int]] = []
    new_meas: list[int] = []
    for i in np.flatnonzero(a.assign >= n_l):
        ti = int(a.t_idx[a.assign[i] - n_l])
        matched[ti] = sighting(state.pose, state.pose_cov, z[i], R[i], s.laser)
        matched_meas[ti] = int(i)
        status[i] = TENTATIVE_HIT
    for i in np.flatnonzero((a.assign < 0) & (status != OUT_OF_RANGE)):
        if a.ambiguous[i]:
            status[i] = AMBIGUOUS
            continue
        mxy, C = sighting(state.pose, state.pose_cov, z[i], R[i], s.laser)
        new.append((mxy, C, next_id))
        new_meas.append(int(i))
        next_id += 1
    if policy.confirm_scans == 1:  # every sighting joins the map at once
        for (_, _, lid), i in zip(new, new_meas):
            state = add_landmark(state, z[i], R[i], s.laser, lid)
            status[i] = CONFIRMED
            book.n_obs[lid] = 1
            book.first_scan[lid] = k
        new = []
    tent_new, confirm = tent.step(matched, new, k, policy)
    for ti in confirm:
        i = matched_meas[ti]
        lid = int(tent.ids[ti])
        state = add_landmark(state, z[i], R[i], s.laser, lid)
        status[i] = CONFIRMED
        book.n_obs[lid] = int(tent.hits[ti]) + 1
        book.first_scan[lid] = k
    return state, tent_new, next_id


# ---- helpers ------------------------------------------------------------------------------------


def _in_view(z_hat: np.ndarray, max_range: float, fov: tuple[float, float], cfg: SlamConfig):
    """(n,) bool: predictions within range and field of view, plus margins."""
    if z_hat.shape[0] == 0:
        return np.zeros(0, bool)
    fov0, fov1 = fov
    b = z_hat[:, 1]
    in_fov = (b >= fov0 - cfg.view_margin_rad) & (b <= fov1 + cfg.view_margin_rad)
    if fov1 - fov0 + 2 * cfg.view_margin_rad >= 2 * math.pi:
        in_fov[:] = True
    return in_fov & (z_hat[:, 0] <= max_range + cfg.view_margin_m)


def _gated_any(z, R, z_hat, H, P, gate: float) -> np.ndarray:
    """(m,) bool: measurement i passes the individual gate with at least one prediction."""
    HPH = np.einsum("nad,de,nbe->nab", H, P, H)  # (n, 2, 2)
    nu = z[:, None, :] - z_hat[None, :, :]
    nu[..., 1] = se2.wrap_angle(nu[..., 1])
    S = HPH[None, :, :, :] + R[:, None, :, :]
    d2 = np.einsum("mna,mna->mn", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return np.any(d2 <= gate, axis=1)


def _check_runnable(seq: Sequence, n_features: int | None, cfg: SlamConfig) -> None:
    """What a run needs beyond a valid Sequence: odometry, a vehicle, no long odometry gaps."""
    if seq.odo_t is None:
        raise SlamError(
            "sequence: missing odometry (odo_t, odo_speed, odo_steer); EKF-SLAM needs it"
        )
    if seq.vehicle is None:
        raise SlamError("sequence.vehicle: missing vehicle model (needed to use the odometry)")
    scan_t, odo_t = seq.scan_t, seq.odo_t
    veh = seq.vehicle
    k = float(veh.get("encoder_offset_m", 0.0)) / float(veh["wheelbase_m"])
    den = 1.0 - k * np.tan(seq.odo_steer)
    if np.any(den <= 0):  # v_c = v_e / (1 - (H/L) tan(alpha)) would be infinite or negative
        i = int(np.flatnonzero(den <= 0)[0])
        raise SlamError(
            f"sequence.vehicle: encoder_offset_m / wheelbase_m = {k:.3g} with odo_steer[{i}] = "
            f"{float(seq.odo_steer[i]):.3g} rad makes the encoder-to-axle speed correction "
            "infinite or negative; check the vehicle parameters and the steering units"
        )
    # The longest stretch of the run [scan_t[0], scan_t[-1]] on stale (held) odometry.
    lead = max(0.0, float(odo_t[0] - scan_t[0]))
    tail = max(0.0, float(scan_t[-1] - odo_t[-1]))
    clipped = np.clip(odo_t, scan_t[0], scan_t[-1])
    steps = np.diff(clipped)
    inner = float(steps.max()) if steps.size else 0.0
    if max(lead, tail, inner) > cfg.max_odometry_gap_s:
        if lead > cfg.max_odometry_gap_s:
            where = f"odometry starts at {odo_t[0]:.3f} s, {lead:.3f} s after the first scan"
        elif tail > cfg.max_odometry_gap_s:
            where = f"odometry ends at {odo_t[-1]:.3f} s, {tail:.3f} s before the last scan"
        else:
            i = int(np.argmax(steps))
            where = f"no odometry from {clipped[i]:.3f} s to {clipped[i + 1]:.3f} s"
        raise SlamError(
            f"sequence.odo_t: missing odometry: {where} (max_odometry_gap_s = "
            f"{cfg.max_odometry_gap_s} s)"
        )
    if n_features is not None and n_features != scan_t.shape[0]:
        raise SlamError(
            f"features: {n_features} precomputed feature sets for {scan_t.shape[0]} scans"
        )


def _start(seq: Sequence, cfg: SlamConfig, initial_heading_rad: float | None):
    """(pose (3,), covariance (3, 3), "truth" | "gps" | "origin") of the first scan."""
    t0 = float(seq.scan_t[0])
    truth_t = seq.truth_t
    if truth_t is not None and not truth_t[0] <= t0 <= truth_t[-1]:
        log.warning(
            "the truth (%.3f .. %.3f s) does not cover the first scan (%.3f s); "
            "not starting from it",
            truth_t[0],
            truth_t[-1],
            t0,
        )
        truth_t = None
    if truth_t is not None:
        pose = se2.interpolate_poses(t0, seq.truth_t, seq.truth_pose)[0]
        if initial_heading_rad is not None:
            log.warning("initial_heading_rad ignored: the run starts from the truth")
        return pose, np.diag(np.square(cfg.initial_pose_sigma)), "truth"
    if seq.gps_t is not None:
        xy = seq.gps_xy
        if initial_heading_rad is not None:
            th = float(initial_heading_rad)
        else:
            far = np.flatnonzero(np.hypot(*(xy - xy[0]).T) >= 2.0)
            if far.size == 0:
                raise SlamError(
                    "initial_heading_rad: the GPS never moves 2 m from its first fix, so the "
                    "start heading is unknown; give --initial-heading"
                )
            d = xy[far[0]] - xy[0]
            th = math.atan2(d[1], d[0])
        ant = seq.gps_pose if seq.gps_pose is not None else seq.laser_pose
        p = xy[0] - se2.rotate(th, ant[:2])
        if abs(float(seq.gps_t[0]) - t0) > 1.0:
            log.warning(
                "first GPS fix at %.3f s is %.3f s from the first scan",
                float(seq.gps_t[0]),
                float(seq.gps_t[0]) - t0,
            )
        cov = np.diag([cfg.gps_sigma_m**2, cfg.gps_sigma_m**2, cfg.initial_heading_sigma_rad**2])
        return np.array([p[0], p[1], th]), cov, "gps"
    th = 0.0 if initial_heading_rad is None else float(initial_heading_rad)
    return np.array([0.0, 0.0, th]), np.diag(np.square(cfg.initial_pose_sigma)), "origin"


def _resolve_association(association) -> Callable:
    """A callable with `associate`'s signature minus `method`, carrying `.method` (its name)."""
    if callable(association):
        name = getattr(association, "__name__", "custom")

        def custom(*args, **kwargs):
            return association(*args, **kwargs)

        custom.method = name
        return custom
    from association import METHODS, associate

    if not isinstance(association, str):
        raise SlamError(f"association: expected a method name or a callable, got {association!r}")
    if association not in METHODS:
        raise SlamError(f"association: unknown method {association!r}; known: {list(METHODS)}")
    method = association

    def call(z, R, z_hat, H, P, gate_prob=0.99, **params):
        return associate(z, R, z_hat, H, P, method=method, gate_prob=gate_prob, **params)

    call.method = method
    return call


def _resolve_features(features, feature_params: dict) -> tuple[Callable, int | None]:
    """(callable (k, scan) -> Features carrying `.method`, number of precomputed sets or None)."""
    if isinstance(features, str):
        from features import extract_features

        method = features

        def extract(k, scan):
            return extract_features(scan, method, **feature_params)

        extract.method = method
        return extract, None
    if callable(features):

        def call(k, scan):
            return features(k, scan)

        call.method = getattr(features, "method", "custom")
        return call, None
    feats = list(features)

    def given(k, scan):
        return feats[k]

    given.method = feats[0].method if feats and hasattr(feats[0], "method") else "custom"
    return given, len(feats)


def _visualise(
    vis, k, seq: Sequence, scan, f, state: EkfState, tent: Tentatives, laser, z, status
) -> None:
    if type(vis) is NullVisualiser:
        return
    vis.set_scan(k, float(seq.scan_t[k]))
    pose = state.pose
    lpose = se2.compose(pose, laser)
    vis.log_scan(scan, lpose)
    vis.log_features(scan, f, lpose)
    vis.log_vehicle(pose, state.pose_cov)
    vis.log_landmarks(state.landmarks_xy, state.landmark_covs, state.landmark_ids)
    vis.log_tentatives(tent.xy)
    used = np.flatnonzero(status >= 0)
    if used.size:
        ang = lpose[2] + z[used, 1]
        frm = lpose[:2] + z[used, 0:1] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        to = np.array([state.landmarks_xy[state.index_of(int(i))] for i in status[used]])
        vis.log_associations(frm, to)
    else:
        vis.log_associations(np.zeros((0, 2)), np.zeros((0, 2)))
    if seq.truth_t is not None:
        vis.log_truth(se2.interpolate_poses(seq.scan_t[k], seq.truth_t, seq.truth_pose)[0])
