"""`slam.run`: EKF-SLAM over one `Sequence`, scan by scan.

Per scan k (times `scan_t[k]`), five steps, each a function below:
1. `_predict`: integrate the odometry from the previous scan (zero-order hold, `slam.vehicle`);
2. `_measure`: the scan's circles (a method name for `features.extract_features`, a callable
   (k, scan) -> Features, a list of precomputed Features, or the sequence's own detections) as
   range-bearing measurements of their centres in the laser frame (`slam.measurement`);
3. `_associate`: the landmarks and tentative features that can be in view are offered to
   `association.associate` (IHGR by default, JCBB or NN), on the sub-state [pose, those
   landmarks] (the Jacobians are zero elsewhere, so this is exact and keeps the cost down);
4. `_update`: all associated map measurements at once (Joseph form, `slam.ekf.update`);
5. `_manage` (`slam.mapping`): associated tentatives count a sighting and join the map after
   three scans (initialised from the current measurement with cross covariances); unassociated
   measurements that gate with no landmark or tentative start new tentatives; tentatives not
   associated are dropped.

A scan after which the odometry has moved the vehicle less than `SlamConfig.min_travel_m` since
the last scan used (0 by default: none) is predicted only: steps 3-5 are skipped and its
measurements logged with status SKIPPED.

With association "ihgr-window" steps 3 and 5 are `_associate_window` and `_manage_window`: the
K-scan `association.SlidingWindowAssociator` (K = `SlamConfig.window_scans`) replaces the
tentative features. Every scan it is offered the landmarks in view and the laser's world pose
with the odometry drift over the window (the sum of the last K - 1 prediction noises) as its
relative uncertainty; it commits the newest scan's pairings (fed to the update as they are) and
re-decides, over the window, which earlier unpaired measurements are first sightings of one new
landmark, which a mapped landmark missed by its own scan explains, and which are clutter. A
measurement whose track was seen in min(confirm_scans, K) scans of the window becomes a
landmark (initialised from the current measurement); the window is told (`mark_mapped`), and
the track's earlier sightings get its id in the log (the smoother's "all" measurements).

Before the timed loop, the five steps run over the first scans on a throwaway filter until one
update has been made (`_warm_up`, `run(warm_up=False)` to skip it): the first call of a step
compiles or loads numba kernels and imports lazily, seconds that would otherwise be timed as
scan 0's or 1's `timing_s`. The estimate does not depend on it.

The start pose is the truth at the first scan when the sequence has truth, else a fit of the
antenna track to the GPS fixes of the first `gps_start_fit_m` metres (`slam.start`; the track
dead-reckoned, or with `gps_start_track = "slam"` the path of a first pass of the filter from
the origin; the heading from `initial_heading_rad` when given), else the origin.
Everything the run did is returned as a `SlamLog` (`slam.log.LogBuilder` assembles it). The
optional visualiser is any object with the methods of `NullVisualiser` (which does nothing).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from features.types import Features
from slam import se2
from slam.config import OWN_COVARIANCE, SlamConfig
from slam.ekf import Filter, initial_state, landmark_columns
from slam.errors import SlamError
from slam.log import (
    AMBIGUOUS,
    CONFIRMED,
    NEW_TENTATIVE,
    OUT_OF_RANGE,
    SKIPPED,
    TENTATIVE_HIT,
    LogBuilder,
    SlamLog,
)
from slam.mapping import Tentatives, sighting
from slam.measurement import constant_noise, measurements_from_features
from slam.sequence import MAX_STEER_RAD, Sequence
from slam.start import fit_gps_start, fit_gps_start_to_track
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
    features: Callable  # (k, scan) -> (Features, z (m, 2), R (m, 2, 2))
    associate: Callable  # the signature of association.associate minus `method`
    model: AckermannModel
    odometry: Odometry
    laser: np.ndarray  # (3,) laser pose in the vehicle frame
    noise: tuple  # ("fit" | "constant", model), SlamConfig.noise_for
    floor: tuple[float, float]
    fov: tuple[float, float]  # first and last beam angle, rad, laser frame
    max_range: float
    gate_new: float  # chi2 (2 dof) of the gate outside which a measurement may be new
    window: int = 0  # K of the "ihgr-window" association, 0 for a single-scan method


@dataclass(frozen=True, eq=False)
class _Association:
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
    warm_up: bool = True,
) -> SlamLog:
    """EKF-SLAM over `sequence` (a `slam.Sequence`); returns the `SlamLog`.

    features: a `features.extract_features` method name ("paper", "geometric", "bailey"),
        "detections" (the sequence's precomputed detections), a callable (k, scan) -> Features,
        or a list of N precomputed Features (laser frame).
    association: "ihgr", "jcbb", "nn", "ihgr-window" (K-scan IHGR, K = config.window_scans;
        see the module docstring), or a callable with the signature of `association.associate`
        minus `method` (z, R, z_hat, H, P, gate_prob=..., **params).
    feature_params: keyword arguments for `extract_features` (method name only).
    visualiser: an object with the methods of `NullVisualiser` (default: nothing is logged).
    initial_heading_rad: overrides the start heading (needed for GPS starts without motion).
    progress: callback(done, total) after each scan.
    warm_up: first run the steps over the first scans on a throwaway filter (`_warm_up`), so
        that `SlamLog.timing_s` holds the steps' own times and not one-off compilation.
    Raises `SlamError` (a ValueError) for a run that cannot be made: not a `Sequence`, missing
    odometry or vehicle, odometry gaps, a mismatched list of features.
    """
    if initial_heading_rad is not None and (
        isinstance(initial_heading_rad, bool)
        or not isinstance(initial_heading_rad, (int, float, np.integer, np.floating))
        or not math.isfinite(initial_heading_rad)
    ):
        raise SlamError(
            f"initial_heading_rad: must be a finite number of radians, got {initial_heading_rad!r}"
        )
    s = _setup(sequence, features, association, config, feature_params)
    vis = visualiser or NullVisualiser()
    pose0, cov0, start = _start(s, initial_heading_rad)
    if warm_up:
        _warm_up(s, pose0, cov0)
    loop = _Run.start(s, pose0, cov0)
    N = sequence.n_scans
    for k in range(N):
        scan, f, z, status = loop.step(k)
        _visualise(vis, k, sequence, scan, f, loop.state, loop.tent, s.laser, z, status)
        if progress is not None:
            progress(k + 1, N)
    return loop.book.build(
        loop.state,
        start=start,
        features_method=getattr(s.features, "method", "custom"),
        association_method=getattr(s.associate, "method", "custom"),
        config=s.cfg.to_dict(),
        window_stats=loop.win.stats() if loop.win is not None else None,
    )


WARM_UP_SCANS = 10  # at most, see `_warm_up`


@dataclass(eq=False)
class _Run:
    """The state of one pass over the scans: the filter, the tentatives or the window, the log."""

    s: _Setup
    state: Filter
    tent: Tentatives
    win: _Window | None
    book: LogBuilder
    next_id: int = 0
    n_used: int = 0  # measurements used in the last scan's update
    n_pending: int = 0  # tentatives (or open window measurements) after the last scan
    travel_m: float = 0.0  # odometry distance since the last scan used
    Q_skipped: np.ndarray | None = None  # prediction noise of the scans skipped since then
    # landmark id -> [scans expected in view, scans associated] since it joined the map
    vis_count: dict[int, list[int]] = field(default_factory=dict)

    @classmethod
    def start(cls, s: _Setup, pose0: np.ndarray, cov0: np.ndarray) -> _Run:
        first = s.cfg.first_estimates_jacobians
        state = Filter(
            initial_state(pose0, np.array(cov0, dtype=np.float64)), first_estimates=first
        )
        book = LogBuilder(np.asarray(s.seq.scan_t, dtype=np.float64))
        book.started(pose0, cov0, s.laser)
        win = _Window.start(s) if s.window else None
        return cls(s, state, Tentatives.empty(), win, book)

    def step(self, k: int) -> tuple:
        """Scan k's five steps, timed and logged; returns (scan, features, z, status)."""
        s, state, book = self.s, self.state, self.book
        t = [time.perf_counter()]
        Q = _predict(s, state, k, book)
        book.predicted(k, state.pose, state.pose_cov)
        t.append(time.perf_counter())
        scan, f, z, R, status = _measure(s, k)
        t.append(time.perf_counter())
        if k > 0 and s.cfg.min_travel_m > 0:
            self.travel_m += _arc_length(s.odometry, s.seq.scan_t[k - 1], s.seq.scan_t[k], s.model)
        if k > 0 and self.travel_m < s.cfg.min_travel_m:
            # predicted only: the vehicle has not moved enough since the last scan used
            status[:] = SKIPPED
            book.skipped[k] = True
            self.Q_skipped = Q if self.Q_skipped is None else self.Q_skipped + Q
            t += [t[-1]] * 3
            radius = np.asarray(f.circle_params, float).reshape(-1, 3)[:, 2]
            track = np.full(z.shape[0], -1, np.int64)
            book.scan_done(k, state, self.n_pending, z, R, status, track, 0, math.nan, 0, t, radius)
            self.n_used = 0
            return scan, f, z, status
        self.travel_m = 0.0
        if self.Q_skipped is not None:  # the window's drift covers the skipped scans too
            Q, self.Q_skipped = Q + self.Q_skipped, None
        if self.win is None:
            a = _associate(s, state, self.tent, z, R, status != OUT_OF_RANGE)
        else:
            a = _associate_window(s, state, self.win, z, R, status != OUT_OF_RANGE, Q)
        t.append(time.perf_counter())
        nis, n_used = _update(s, state, z, R, a, status, book, k)
        t.append(time.perf_counter())
        track = np.where(status >= 0, status, -1)
        if self.win is None:
            self.tent, self.next_id = _manage(
                s, state, self.tent, z, R, a, status, track, book, k, self.next_id
            )
            n_pending = len(self.tent)
        else:
            self.next_id, n_pending = _manage_window(
                s, state, self.win, z, R, a, status, track, book, k, self.next_id
            )
        if s.cfg.map_policy.prunes:
            _prune(s, state, self.vis_count, status, k)
        t.append(time.perf_counter())
        radius = np.asarray(f.circle_params, float).reshape(-1, 3)[:, 2]
        book.scan_done(k, state, n_pending, z, R, status, track, n_used, nis, 2 * n_used, t, radius)
        self.n_used, self.n_pending = n_used, n_pending
        return scan, f, z, status


def _warm_up(s: _Setup, pose0: np.ndarray, cov0: np.ndarray) -> None:
    """Run the five steps over the first scans on a throwaway filter, until one update has
    been made (at most `WARM_UP_SCANS` scans), and forget it. The first call of each step pays
    one-off costs: numba compiling or loading its kernels from the cache (seconds for the
    extractor), lazy imports, first-use caches. Without this the timed loop would put them on
    scans 0-3 (`SlamLog.timing_s`: thousands of ms against a median of a few). Nothing is
    shared with the run (its own filter, tentatives, window and log), so the estimate is the
    same with or without it; only a features or association callable of the caller's sees the
    first scans twice."""
    loop = _Run.start(s, pose0, cov0)
    for k in range(min(WARM_UP_SCANS, s.seq.n_scans)):
        loop.step(k)
        if loop.n_used > 0:
            break


def _setup(seq, features, association, config, feature_params) -> _Setup:
    if not isinstance(seq, Sequence):
        raise SlamError(f"sequence: expected a slam.Sequence, got {type(seq).__name__}")
    cfg = config or SlamConfig()
    if not isinstance(cfg, SlamConfig):
        raise SlamError(f"config: expected a SlamConfig, got {type(cfg).__name__}")
    if features == "detections":
        if not seq.has_detections:
            raise SlamError(
                "features: 'detections' needs a sequence with precomputed detections (det_scan, "
                f"...); {seq.name or 'this sequence'!r} has none"
            )
        has_cov = seq.det_cov is not None
        noise = cfg.noise_for(seq.det_method, has_cov)
        if noise[0] == "fit" and not has_cov:
            raise SlamError("measurement_noise: 'fit' needs det_cov in the sequence's detections")
        feat_fn, n_pre = _detections_source(seq, noise, cfg), None
    else:
        if feature_params and not isinstance(features, str):
            raise SlamError("feature_params: only for a features method name")
        raw, n_pre = _resolve_features(features, dict(feature_params or {}))
        own = raw.method in OWN_COVARIANCE and getattr(raw, "has_cov", True)
        noise = cfg.noise_for(raw.method, own)
        floor = (cfg.fit_floor_range_m, cfg.fit_floor_bearing_rad)
        feat_fn = _from_features(raw, noise, floor, cfg.range_bias_for(raw.method))
        if isinstance(features, str) and not seq.has_ranges:
            raise SlamError(
                f"features: {features!r} extracts from raw scans, and this sequence has none; "
                "use features='detections'"
            )
    steer = cfg.steering.apply(seq.odo_steer) if seq.odo_steer is not None else None
    _check_runnable(seq, n_pre, cfg, steer)
    a0 = float(seq.scan_angle_min)
    window = cfg.window_scans if association == WINDOW else 0
    return _Setup(
        seq=seq,
        cfg=cfg,
        features=feat_fn,
        associate=_resolve_association(association),
        model=AckermannModel.from_vehicle(seq.vehicle),
        odometry=Odometry(seq.odo_t, seq.odo_speed, steer),
        laser=np.asarray(seq.laser_pose if cfg.laser_pose is None else cfg.laser_pose, float),
        noise=noise,
        floor=(cfg.fit_floor_range_m, cfg.fit_floor_bearing_rad),
        fov=(a0, a0 + float(seq.scan_angle_increment) * (seq.n_beams - 1)),
        max_range=min(float(seq.scan_max_range), cfg.max_feature_range_m),
        gate_new=-2.0 * math.log1p(-max(cfg.new_feature_gate_prob, cfg.gate_prob)),
        window=window,
    )


# ---- the five steps -----------------------------------------------------------------------------


def _predict(s: _Setup, state: Filter, k: int, book: LogBuilder) -> np.ndarray:
    """Step 1: the odometry from scan k - 1 to scan k (nothing before the first scan).

    The increment and its covariance in the frame of the pose at k - 1 go to the log (the
    smoother's odometry factors): the motion model is invariant to where the car is, so the
    world-frame Q is that covariance rotated by the heading. Returns Q (3, 3), world frame
    (zeros at k = 0)."""
    if k == 0:
        return np.zeros((3, 3))
    t = s.seq.scan_t
    p0 = state.pose.copy()
    p1, F, Q = integrate(s.model, p0, s.odometry, t[k - 1], t[k], s.cfg.odometry_noise)
    delta = se2.compose(se2.inverse(p0), p1)
    delta[2] = float(se2.wrap_angle(delta[2]))
    c, sn = math.cos(p0[2]), math.sin(p0[2])
    A = np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])  # world -> frame of p0
    book.odometry(k, delta, A @ Q @ A.T)
    state.predict(p1, F, Q)
    return Q


def _arc_length(odometry: Odometry, t0: float, t1: float, model: AckermannModel) -> float:
    """Distance the rear-axle centre drove from t0 to t1 by the odometry (m)."""
    dt, v, a = odometry.pieces(t0, t1)
    k = model.encoder_offset_m / model.wheelbase_m
    return float(np.sum(np.abs(v / (1.0 - k * np.tan(a))) * dt))


def _measure(s: _Setup, k: int):
    """Step 2: scan k, its features, their measurements z (m, 2), R (m, 2, 2), and the status of
    each (NEW_TENTATIVE until decided; OUT_OF_RANGE beyond the usable range or not finite)."""
    scan = s.seq.scan(k)
    f, z, R = s.features(k, scan)
    status = np.full(z.shape[0], NEW_TENTATIVE, np.int64)
    usable = (z[:, 0] <= s.max_range) & np.all(np.isfinite(z), axis=1)
    status[~usable] = OUT_OF_RANGE
    _check_noise(k, R, usable, s.cfg.measurement_noise)
    return scan, f, z, R, status


def _check_noise(k: int, R: np.ndarray, usable: np.ndarray, model: str) -> None:
    """Every usable measurement's R is finite and positive definite. The association gets the
    loop's inputs unchecked (its trusted path), so a degenerate R (the "fit" model of a
    degenerate fit with no floors) is named here rather than failing inside the solver."""
    a, b, c = R[:, 0, 0], 0.5 * (R[:, 0, 1] + R[:, 1, 0]), R[:, 1, 1]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(R).all(axis=(1, 2)) & (a > 0) & (c > 0) & (a * c - b * b > 0)
    bad = np.flatnonzero(usable & ~ok)
    if bad.size:
        i = int(bad[0])
        raise SlamError(
            f"measurement noise: scan {k}, feature {i} has a covariance R that is not positive "
            f"definite ({R[i].tolist()}; noise model {model!r}); give the fit floors "
            "(fit_floor_range_m, fit_floor_bearing_rad) or a constant noise model"
        )


def _associate(s: _Setup, state: Filter, tent: Tentatives, z, R, usable) -> _Association:
    """Step 3: the usable measurements against the landmarks and tentatives that can be in view.

    Each candidate's innovation covariance comes from its 5 x 5 block [pose, point] (tentatives
    with their own covariance and no correlation with the pose). Candidates that gate with no
    measurement, even at the wider new-feature gate, cannot be paired and do not make anything
    ambiguous, so only the others are offered to the associator, on the sub-state [pose,
    those landmarks, those tentatives]: exact, and the cost no longer grows with the map.
    """
    cfg = s.cfg
    z_lm, H_lm = se2.observe(state.pose, state.landmarks_xy, s.laser)
    z_t, H_t = se2.observe(state.pose, tent.xy, s.laser)
    lm_idx = np.flatnonzero(_in_view(z_lm, s.max_range, s.fov, cfg))
    t_idx = np.flatnonzero(_in_view(z_t, s.max_range, s.fov, cfg))
    n_l, n = lm_idx.size, lm_idx.size + t_idx.size
    m = z.shape[0]
    assign = np.full(m, -1, np.int64)
    ambiguous = np.zeros(m, bool)
    use = np.flatnonzero(usable)
    if not (use.size and n):
        return _Association(assign, ambiguous, lm_idx, t_idx)
    zh = np.concatenate([z_lm[lm_idx], z_t[t_idx]])
    H5 = np.concatenate([H_lm[lm_idx], H_t[t_idx]])  # (n, 2, 5)
    C5 = np.zeros((n, 5, 5))  # covariance of [pose, point] of each candidate
    cols = landmark_columns(lm_idx)
    C5[:n_l] = state.cov(cols)
    C5[n_l:, :3, :3] = state.pose_cov
    C5[n_l:, 3:, 3:] = tent.cov[t_idx]
    z_use, R_use = z[use], R[use]
    gated = _gates_kernel(z_use, R_use, zh, H5, C5, s.gate_new)  # (m_use, n)
    ambiguous[use] = gated.any(axis=1)
    cand = np.flatnonzero(gated.any(axis=0))
    if cand.size:
        c_lm = cand[cand < n_l]
        sub = np.concatenate([_POSE, landmark_columns(lm_idx[c_lm])[:, 3:].ravel()])
        c_t = t_idx[cand[cand >= n_l] - n_l]  # the tentatives, after the landmarks
        H, P_sub = _sub_problem(H5, cand, state.cov(sub), tent.cov[c_t])
        a_use = s.associate(
            z_use, R_use, zh[cand], H, P_sub, gate_prob=cfg.gate_prob, **cfg.association_params
        )
        a_use = np.asarray(a_use, dtype=np.int64)
        assign[use] = np.where(a_use >= 0, cand[np.maximum(a_use, 0)], -1)
    ambiguous &= assign < 0
    return _Association(assign, ambiguous, lm_idx, t_idx)


def _update(s: _Setup, state: Filter, z, R, a: _Association, status, book: LogBuilder, k: int):
    """Step 4: one batch update with the measurements paired with map landmarks.

    Returns the batch NIS (NaN without an update) and the number of measurements used; sets
    their status to the landmark id and logs them."""
    n_l = a.lm_idx.size
    to_map = np.flatnonzero(a.assign >= 0)
    to_map = to_map[a.assign[to_map] < n_l]
    if not to_map.size:
        return math.nan, 0
    pos = a.lm_idx[a.assign[to_map]]
    res = state.update(pos, z[to_map], R[to_map], s.laser)
    book.logdet[k] = res.logdet
    for j, i in enumerate(to_map):
        lid = int(state.landmark_ids[pos[j]])
        status[i] = lid
        S_j = res.S[2 * j : 2 * j + 2, 2 * j : 2 * j + 2]
        book.observation(k, int(i), lid, z[i], res.innovation[j], S_j)
    return res.nis, int(to_map.size)


def _manage(s: _Setup, state: Filter, tent, z, R, a: _Association, status, track, book, k, next_id):
    """Step 5: tentatives seen again count a sighting (and join the map at the policy's count),
    new measurements start tentatives, ambiguous ones are ignored, unseen tentatives drop out.

    Returns the new tentatives and next free landmark id; sets each measurement's status and
    track (the id of the tentative it was paired with or started).
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
        track[i] = int(tent.ids[ti])
    for i in np.flatnonzero((a.assign < 0) & (status != OUT_OF_RANGE)):
        if a.ambiguous[i]:
            status[i] = AMBIGUOUS
            continue
        mxy, C = sighting(state.pose, state.pose_cov, z[i], R[i], s.laser)
        new.append((mxy, C, next_id))
        new_meas.append(int(i))
        track[i] = next_id
        next_id += 1
    if policy.confirm_scans == 1:  # every sighting joins the map at once
        for (_, _, lid), i in zip(new, new_meas):
            state.add_landmark(z[i], R[i], s.laser, lid)
            status[i] = CONFIRMED
            book.n_obs[lid] = 1
            book.first_scan[lid] = k
        new = []
    tent_new, confirm = tent.step(matched, new, k, policy)
    for ti in confirm:
        i = matched_meas[ti]
        lid = int(tent.ids[ti])
        state.add_landmark(z[i], R[i], s.laser, lid)
        status[i] = CONFIRMED
        book.n_obs[lid] = int(tent.hits[ti]) + 1
        book.first_scan[lid] = k
    return tent_new, next_id


# ---- the K-scan window (association "ihgr-window") ----------------------------------------------

WINDOW = "ihgr-window"


@dataclass(eq=False)
class _Window:
    """The run's `SlidingWindowAssociator` and what the loop remembers of the window's scans:
    for each of the last K - 1 scans its index k, the positions of its usable measurements
    (the associator numbers only those) and the process noise of its prediction."""

    assoc: object  # association.SlidingWindowAssociator
    scans: list  # [(k, use (m_use,) int, Q (3, 3))], oldest first
    n_steps: int = 0
    n_fractional: int = 0
    n_rounded: int = 0  # steps whose rounding needed more than one LP
    n_lp_solves: int = 0
    n_tracks: int = 0

    @classmethod
    def start(cls, s: _Setup) -> _Window:
        from association import CostModel, SlidingWindowAssociator
        from association.rounding import ROUNDING_OPTIONS

        params = dict(s.cfg.association_params)
        cost_keys = {f.name for f in dataclasses.fields(CostModel)}
        unknown = set(params) - cost_keys - set(ROUNDING_OPTIONS)
        if unknown:
            raise SlamError(
                f"association_params: {sorted(unknown)} are not parameters of {WINDOW!r} "
                f"(allowed: {sorted(cost_keys | set(ROUNDING_OPTIONS))})"
            )
        model = CostModel(**{k: v for k, v in params.items() if k in cost_keys})
        rounding = {k: v for k, v in params.items() if k in ROUNDING_OPTIONS}
        assoc = SlidingWindowAssociator(s.window, s.cfg.gate_prob, model, **rounding)
        return cls(assoc, [])

    def stats(self) -> dict:
        """Window figures of the run: steps, how many first LPs were fractional, how many steps
        the rounding changed (more than one LP solve: a fractional LP was rounded and
        re-solved), LP solves, track hypotheses built."""
        return {
            "K": self.assoc.K,
            "steps": self.n_steps,
            "fractional_lps": self.n_fractional,
            "rounded_steps": self.n_rounded,
            "lp_solves": self.n_lp_solves,
            "track_hypotheses": self.n_tracks,
        }


def _associate_window(
    s: _Setup, state: Filter, win: _Window, z, R, usable, Q: np.ndarray
) -> _Association:
    """Step 3 with the K-scan window: every landmark in view is offered (a track is not built
    where it could be a mapped landmark, so the window must see them all), on the sub-state
    [pose, those landmarks]; the laser's world pose goes with the odometry drift over the window
    as its relative covariance."""
    cfg = s.cfg
    K = win.assoc.K
    z_lm, H_lm = se2.observe(state.pose, state.landmarks_xy, s.laser)
    lm_idx = np.flatnonzero(_in_view(z_lm, s.max_range, s.fov, cfg))
    n = lm_idx.size
    m = z.shape[0]
    ambiguous = np.zeros(m, bool)
    use = np.flatnonzero(usable)
    cols = landmark_columns(lm_idx)  # (n, 5)
    if use.size and n:
        C5 = state.cov(cols)
        ambiguous[use] = _gates(z[use], R[use], z_lm[lm_idx], H_lm[lm_idx], C5, s.gate_new).any(1)
    H = np.zeros((n, 2, 3 + 2 * n))
    H[:, :, :3] = H_lm[lm_idx, :, :3]
    for j in range(n):
        H[j, :, 3 + 2 * j : 5 + 2 * j] = H_lm[lm_idx[j], :, 3:5]
    sub = np.concatenate([[0, 1, 2], cols[:, 3:].ravel()]).astype(np.int64)
    P_sub = state.cov(sub)
    drift = Q + sum((q for _, _, q in win.scans[len(win.scans) - (K - 2) :]), np.zeros((3, 3)))
    if K < 2:
        drift = np.zeros((3, 3))
    pose = state.pose
    p_laser, dp = se2.sensor_position(pose, s.laser)
    J = np.array([[1.0, 0.0, dp[0]], [0.0, 1.0, dp[1]], [0.0, 0.0, 1.0]])
    laser_world = np.array([p_laser[0], p_laser[1], pose[2] + s.laser[2]])
    out = win.assoc.step(
        z[use],
        R[use],
        z_lm[lm_idx],
        H,
        0.5 * (P_sub + P_sub.T),
        sensor_pose=laser_world,
        sensor_pose_cov=0.5 * (J @ drift @ J.T + (J @ drift @ J.T).T),
        feature_ids=state.landmark_ids[lm_idx].astype(np.int64),
    )
    dec = win.assoc.last
    win.n_steps += 1
    win.n_fractional += int(dec.rounding.fractional)
    win.n_rounded += int(dec.rounding.lp_solves > 1)
    win.n_lp_solves += int(dec.rounding.lp_solves)
    win.n_tracks += int(dec.n_tracks)
    assign = np.full(m, -1, np.int64)
    assign[use] = out
    sightings = np.zeros(m, np.int64)
    sightings[use] = dec.sightings
    # the chosen tracks in the scans' own measurement numbering
    past = {ago: u for ago, (_, u, _) in enumerate(reversed(win.scans), start=1)}
    past[0] = use
    tracks = {}
    for members in dec.tracks:
        ago_last, i_last = members[-1]
        if ago_last == 0:
            tracks[int(use[i_last])] = [
                (ago, int(past[ago][i])) for ago, i in members if ago in past
            ]
    win.scans = (win.scans + [(None, use, Q)])[-(K - 1) :] if K > 1 else []
    ambiguous &= assign < 0
    return _Association(assign, ambiguous, lm_idx, np.zeros(0, np.int64), sightings, tracks)


def _manage_window(
    s: _Setup, state: Filter, win: _Window, z, R, a: _Association, status, track, book, k, next_id
):
    """Step 5 with the window: an unpaired measurement whose track was seen in
    min(confirm_scans, K) scans of the window joins the map; ambiguous ones (inside the wider
    gate of a landmark) are ignored and leave the window's pool like the mapped ones; the rest
    stay open in the window (status NEW_TENTATIVE). Returns (next free id, open measurements)."""
    need = min(s.cfg.map_policy.confirm_scans, win.assoc.K)
    use_pos = {int(i): j for j, i in enumerate(win.scans[-1][1])} if win.scans else None
    if use_pos is None:  # K = 1 keeps no scans: number this scan's usable measurements here
        use_pos = {int(i): j for j, i in enumerate(np.flatnonzero(status != OUT_OF_RANGE))}
    closed = []
    n_open = 0
    for i in np.flatnonzero((a.assign < 0) & (status != OUT_OF_RANGE)):
        if a.ambiguous[i]:
            status[i] = AMBIGUOUS
            closed.append(use_pos[int(i)])
            continue
        if a.sightings[i] < need:
            n_open += 1
            continue
        lid = next_id
        next_id += 1
        state.add_landmark(z[i], R[i], s.laser, lid)
        status[i] = CONFIRMED
        track[i] = lid
        members = a.tracks.get(int(i), [])
        for ago, j in members:
            if ago > 0:
                book.retrack(k - ago, j, lid)
        book.n_obs[lid] = max(int(a.sightings[i]), 1)
        book.first_scan[lid] = k
        closed.append(use_pos[int(i)])
    if closed:
        win.assoc.mark_mapped(closed)
    return next_id, n_open


def _prune(s: _Setup, state: Filter, count: dict[int, list[int]], status, k: int) -> None:
    """Map policy's pruning, after the scan's update and map management: count for every
    landmark already in the map before this scan whether it was expected (predicted inside the
    field of view, no margins, and within the pruning and usable range) and whether it was
    associated; remove those expected often enough and seen too rarely (`MapPolicy`)."""
    policy = s.cfg.map_policy
    ids = state.landmark_ids
    if not ids.size:
        return
    z_hat, _ = se2.observe(state.pose, state.landmarks_xy, s.laser)
    expected = _in_view(z_hat, min(s.max_range, policy.prune_range_m), s.fov)
    seen = set(status[status >= 0].tolist())
    drop = []
    for lid, e in zip(ids.tolist(), expected.tolist()):
        c = count.get(lid)
        if c is None:  # joined the map in this scan: counted from the next one
            count[lid] = [0, 0]
            continue
        if e:
            c[0] += 1
            c[1] += lid in seen
            if c[0] >= policy.prune_after_expected and c[1] < policy.prune_hit_ratio * c[0]:
                drop.append(lid)
    if drop:
        state.remove_landmarks(drop)
        for lid in drop:
            del count[lid]


# ---- helpers ------------------------------------------------------------------------------------


def _in_view(
    z_hat: np.ndarray, max_range: float, fov: tuple[float, float], cfg: SlamConfig | None = None
):
    """(n,) bool: predictions within range and field of view, plus the margins of `cfg`
    (`view_margin_rad`, `view_margin_m`; None: no margins)."""
    if z_hat.shape[0] == 0:
        return np.zeros(0, bool)
    m_rad, m_m = (cfg.view_margin_rad, cfg.view_margin_m) if cfg is not None else (0.0, 0.0)
    fov0, fov1 = fov
    b = z_hat[:, 1]
    in_fov = (b >= fov0 - m_rad) & (b <= fov1 + m_rad)
    if fov1 - fov0 + 2 * m_rad >= 2 * math.pi:
        in_fov[:] = True
    return in_fov & (z_hat[:, 0] <= max_range + m_m)


_POSE = np.array([0, 1, 2], np.int64)


def _gates(z, R, z_hat, H5, C5, gate: float) -> np.ndarray:
    """(m, n) bool: measurement i passes the individual gate of candidate j, with
    S_ij = H5_j C5_j H5_j^T + R_i (2 x 2, solved in closed form)."""
    HPH = np.einsum("nij,njk,nlk->nil", H5, C5, H5)  # (n, 2, 2)
    S = HPH[None, :, :, :] + R[:, None, :, :]  # (m, n, 2, 2)
    nu = z[:, None, :] - z_hat[None, :, :]
    nu[..., 1] = se2.wrap_angle(nu[..., 1])
    a, b, c = S[..., 0, 0], 0.5 * (S[..., 0, 1] + S[..., 1, 0]), S[..., 1, 1]
    d2 = (c * nu[..., 0] ** 2 - 2.0 * b * nu[..., 0] * nu[..., 1] + a * nu[..., 1] ** 2) / (
        a * c - b * b
    )
    return d2 <= gate


@njit(cache=True)
def _gates_kernel(z, R, z_hat, H5, C5, gate: float) -> np.ndarray:
    """`_gates` in one pass (its twin and test oracle): the scan loop's every-scan gating of all
    candidates, where the dozen array operations of the vectorised form cost more than the
    arithmetic. The same formulas; H5 C5 H5^T is summed in its own order, so d2 may differ
    from `_gates`' in the last bits."""
    m, n = z.shape[0], z_hat.shape[0]
    out = np.zeros((m, n), np.bool_)
    HPH = np.zeros((n, 2, 2))
    for t in range(n):
        for i in range(2):
            for u in range(2):
                acc = 0.0
                for j in range(5):
                    hij = H5[t, i, j]
                    for k in range(5):
                        acc += hij * C5[t, j, k] * H5[t, u, k]
                HPH[t, i, u] = acc
    for i in range(m):
        for t in range(n):
            a = HPH[t, 0, 0] + R[i, 0, 0]
            b = 0.5 * ((HPH[t, 0, 1] + R[i, 0, 1]) + (HPH[t, 1, 0] + R[i, 1, 0]))
            c = HPH[t, 1, 1] + R[i, 1, 1]
            n0 = z[i, 0] - z_hat[t, 0]
            n1 = np.pi - np.mod(np.pi - (z[i, 1] - z_hat[t, 1]), 2.0 * np.pi)  # `wrap_angle`
            d2 = (c * (n0 * n0) - 2.0 * b * n0 * n1 + a * (n1 * n1)) / (a * c - b * b)
            out[i, t] = d2 <= gate
    return out


@njit(cache=True)
def _sub_problem(H5, cand, P_lm, cov_t):
    """The association's sub-problem on the state [pose, candidate landmarks, candidate
    tentatives]: H (nc, 2, 3 + 2 nc), candidate j's point in columns 3 + 2 j, 4 + 2 j, and its
    covariance P_sub, which is P_lm (the pose and the candidate landmarks, from the filter)
    followed by the tentatives' own 2 x 2 blocks cov_t (no correlation with anything). The
    candidates `cand` index H5, landmarks first."""
    nc = cand.size
    d = 3 + 2 * nc
    H = np.zeros((nc, 2, d))
    for j in range(nc):
        c = cand[j]
        for r in range(2):
            for q in range(3):
                H[j, r, q] = H5[c, r, q]
            H[j, r, 3 + 2 * j] = H5[c, r, 3]
            H[j, r, 4 + 2 * j] = H5[c, r, 4]
    P_sub = np.zeros((d, d))
    n_sub = P_lm.shape[0]
    P_sub[:n_sub, :n_sub] = P_lm
    for t in range(cov_t.shape[0]):
        a = n_sub + 2 * t
        P_sub[a : a + 2, a : a + 2] = cov_t[t]
    return H, P_sub


def _check_runnable(seq: Sequence, n_features: int | None, cfg: SlamConfig, steer) -> None:
    """What a run needs beyond a valid Sequence: odometry, a vehicle, no long odometry gaps.
    steer: the steering readings through `cfg.steering` (None without odometry)."""
    if seq.odo_t is None:
        raise SlamError(
            "sequence: missing odometry (odo_t, odo_speed, odo_steer); EKF-SLAM needs it"
        )
    if seq.vehicle is None:
        raise SlamError("sequence.vehicle: missing vehicle model (needed to use the odometry)")
    scan_t, odo_t = seq.scan_t, seq.odo_t
    veh = seq.vehicle
    if not cfg.steering.is_identity and np.any(np.abs(steer) > MAX_STEER_RAD):
        i = int(np.argmax(np.abs(steer)))
        raise SlamError(
            f"SlamConfig.steering: turns odo_steer[{i}] = {float(seq.odo_steer[i]):.6g} rad into "
            f"{float(steer[i]):.6g} rad, beyond +-{MAX_STEER_RAD} rad; check the calibration"
        )
    k = float(veh.get("encoder_offset_m", 0.0)) / float(veh["wheelbase_m"])
    den = 1.0 - k * np.tan(steer)
    if np.any(den <= 0):  # v_c = v_e / (1 - (H/L) tan(alpha)) would be infinite or negative
        i = int(np.flatnonzero(den <= 0)[0])
        raise SlamError(
            f"sequence.vehicle: encoder_offset_m / wheelbase_m = {k:.3g} with odo_steer[{i}] = "
            f"{float(seq.odo_steer[i]):.3g} rad (calibrated: {float(steer[i]):.3g} rad) makes "
            "the encoder-to-axle speed correction infinite or negative; check the vehicle "
            "parameters and the steering units"
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


def _start(s: _Setup, initial_heading_rad: float | None):
    """(pose (3,), covariance (3, 3), how) of the first scan: "truth", "gps" or "origin"."""
    seq, cfg = s.seq, s.cfg
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
        if float(seq.gps_t[0]) - t0 > 1.0:
            log.warning(
                "first GPS fix at %.3f s is %.3f s after the first scan",
                float(seq.gps_t[0]),
                float(seq.gps_t[0]) - t0,
            )
        ant = seq.gps_pose if seq.gps_pose is not None else s.laser
        floors = np.array([cfg.gps_sigma_m, cfg.gps_sigma_m, cfg.initial_heading_sigma_rad]) ** 2
        if cfg.gps_start_track == "slam":
            track_t, track_pose = _first_pass(s, np.diag(floors), cfg.gps_start_fit_m)
            fit = fit_gps_start_to_track(
                track_t,
                track_pose,
                seq.gps_t,
                seq.gps_xy,
                ant,
                cfg.gps_start_fit_m,
                initial_heading_rad,
            )
            how = f"a first pass over {track_t.size} scans"
        else:
            fit = fit_gps_start(
                t0,
                seq.gps_t,
                seq.gps_xy,
                ant,
                s.model,
                s.odometry,
                cfg.gps_start_fit_m,
                initial_heading_rad,
            )
            how = "dead reckoning"
        cov = fit.cov + np.diag(np.maximum(floors - np.diag(fit.cov), 0.0))
        log.info(
            "start from GPS (%s): %d fixes over %.1f m (%d rejected), rms %.2f m, heading %.2f deg",
            how,
            fit.n_fixes,
            fit.distance_m,
            fit.n_rejected,
            fit.rms_m,
            math.degrees(fit.pose[2]),
        )
        return fit.pose, cov, "gps"
    th = 0.0 if initial_heading_rad is None else float(initial_heading_rad)
    return np.array([0.0, 0.0, th]), np.diag(np.square(cfg.initial_pose_sigma)), "origin"


def _first_pass(s: _Setup, cov0: np.ndarray, fit_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(scan times, poses) of the filter run from the origin over the scans until its antenna
    track has covered `fit_m` metres (and one scan more), for `fit_gps_start_to_track`: the
    start's rigid fit to GPS along a path whose shape the landmarks kept. The estimate of a
    run is the same up to rounding in any frame, so the pass's frame (the origin, covariance
    `cov0`: the start's floors) only names where the track starts. Nothing is shared with the
    run."""
    seq = s.seq
    ant = np.asarray(seq.gps_pose if seq.gps_pose is not None else s.laser, dtype=np.float64)
    loop = _Run.start(s, np.zeros(3), cov0)
    loop.step(0)
    poses = [np.zeros(3)]  # the track starts at the prior: the start pose is the prior's mean
    dist, last = 0.0, ant[:2].copy()
    for k in range(1, seq.n_scans):
        loop.step(k)
        poses.append(loop.state.pose.copy())
        a = se2.compose(poses[-1], ant)[:2]
        dist, last = dist + float(np.hypot(*(a - last))), a
        if dist > fit_m:
            break
    return np.asarray(seq.scan_t[: len(poses)], dtype=np.float64), np.array(poses)


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
    if association == WINDOW:
        call = _resolve_association("ihgr")  # not called: the window has its own step
        call.method = WINDOW
        return call
    if association not in METHODS:
        raise SlamError(f"association: unknown method {association!r}; known: {[*METHODS, WINDOW]}")
    method = association

    def call(z, R, z_hat, H, P, gate_prob=0.99, **params):
        # The loop's inputs are valid by construction (finite, P symmetric PSD as the filter
        # keeps it): the trusted path, without the checks that would cost more than the solve.
        return associate(
            z, R, z_hat, H, P, method=method, gate_prob=gate_prob, validate=False, **params
        )

    call.method = method
    return call


def _from_features(feat_fn: Callable, noise, floor, range_bias=(0.0, 0.0)) -> Callable:
    """(k, scan) -> (Features, z, R) from a features callable; `range_bias` (a_m, b_per_m), the
    extractor's known mean range error a + b r, is taken off the ranges."""

    def measure(k, scan):
        f = feat_fn(k, scan)
        if not isinstance(f, Features):
            raise SlamError(
                f"features: scan {k} gave {type(f).__name__}, expected a features.Features"
            )
        z, R = measurements_from_features(f, noise, floor, range_bias)
        return f, z, R

    measure.method = feat_fn.method
    return measure


def _detections_source(seq: Sequence, noise, cfg: SlamConfig) -> Callable:
    """(k, scan) -> (Features, z, R) from the sequence's precomputed detections: z as stored less
    the known range bias of their method, R their covariance (plus the fit floor) or the
    constant model of their method; the Features (circles at the detections, as stored) are for
    the visualiser."""
    kind, model = noise
    floor = np.diag([cfg.fit_floor_range_m**2, cfg.fit_floor_bearing_rad**2])
    bias = cfg.range_bias_for(seq.det_method)
    # the arrays of no lines, edges or segments, shared by every scan's Features (read-only)
    empty = Features.empty(0.0, seq.det_method, seq.n_beams)

    def measure(k, scan):
        stored, radius, cov = seq.detections(k)
        z = stored.copy()
        z[:, 0] -= bias[0] + bias[1] * stored[:, 0]
        R = cov + floor if kind == "fit" else constant_noise(z, model)
        n = z.shape[0]
        c, s_ = np.cos(z[:, 1]), np.sin(z[:, 1])
        f = dataclasses.replace(
            empty,
            stamp_s=float(seq.scan_t[k]),
            circle_params=np.column_stack([stored[:, 0] * c, stored[:, 0] * s_, radius]),
            circle_cov=np.zeros((n, 3, 3)),
            circle_beams=np.zeros((n, 2), np.int64),
            circle_rms_m=np.full(n, np.nan),
        )
        return f, z, R

    measure.method = seq.det_method
    return measure


def _resolve_features(features, feature_params: dict) -> tuple[Callable, int | None]:
    """(callable (k, scan) -> Features carrying `.method` (and, for precomputed sets,
    `.has_cov`: whether any circle has a non-zero covariance), number of precomputed sets or
    None)."""
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
    if not isinstance(features, (list, tuple)):
        raise SlamError(
            "features: expected a method name, 'detections', a callable (k, scan) -> Features "
            f"or a list of Features, got {type(features).__name__}"
        )
    feats = list(features)
    bad = [k for k, f in enumerate(feats) if not isinstance(f, Features)]
    if bad:
        raise SlamError(
            f"features: item {bad[0]} is {type(feats[bad[0]]).__name__}, expected a "
            "features.Features"
        )

    def given(k, scan):
        return feats[k]

    given.method = feats[0].method if feats and hasattr(feats[0], "method") else "custom"
    # circles whose covariance is zero throughout carry none of their own ("auto" noise then
    # takes the constant model, not the fit floors alone)
    given.has_cov = any(np.any(np.asarray(f.circle_cov)) for f in feats if f.n_circles)
    return given, len(feats)


def _visualise(
    vis, k, seq: Sequence, scan, f, state: Filter, tent: Tentatives, laser, z, status
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
