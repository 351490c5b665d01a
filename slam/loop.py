"""`slam.run_slam`: EKF-SLAM over one `Sequence`, scan by scan, as its configuration says.

`Slam.step(k)` is the loop's body, five named steps; each returns what it produced and the
scan's record (`ScanResult`) collects it for the log and the visualiser:
1. predict: integrate the odometry from the previous scan (zero-order hold, `slam.vehicle`);
2. measure: the scan's circles as range-bearing measurements of their centres (the source,
   `slam.sources`: an extractor, the sequence's detections, or given features), each
   NEW_TENTATIVE or OUT_OF_RANGE;
3. associate, 5. manage: the map manager (`slam.map_managers`: tentatives with a single-scan
   associator, or the K-scan IHGR window; one contract) pairs measurements with landmarks
   (`ScanAssociation`; with `[association] joint_check` the pairings the joint test refuses
   are dropped, `slam.joint_gate`) and decides what joins the map (`MapDecisions`: every
   measurement's final status and track, the landmarks that joined, earlier measurements
   re-tracked);
4. update: all measurements paired with landmarks at once (Joseph form, `slam.ekf.Filter`);
   returns the landmark each measurement updated.
A scan after which the odometry has moved the vehicle less than `vehicle.min_travel_m` since
the last scan used is predicted only (`RestGate`): its measurements are logged SKIPPED.
With map policy "existence" every landmark's and tentative's existence is updated after the
association, on the predicted state (`slam.existence_map`), and the landmarks the map manager
removes for it are marginalised out. Pruning (`slam.map_managers.Pruner`) follows map
management when the map policy asks for it, and loop closure (`slam.closure.LoopCloser`)
when `[closure] enabled`: before the association it says which old landmarks the scan must
not pair (`Revisit`), after map management what it matched and merged (`ClosureDecision`).

The loop's roles: the source, the motion, the laser (mounting and view), the filter, the
map manager, pruning, loop closure, the rest gate, the run's history (`slam.history`: what
the past scans did that closure and the log read) and the log (`slam.log.LogBuilder`).
The components come from the configuration once (`slam.components`); `run_slam` builds one
`Slam` and starts it from a prior (`Slam.start`): for the first pass a GPS start fits to
(`slam.start.first_pass_wanted`), for the warm-up, and for the run. The warm-up runs the
steps over the first scans until one update has been made: the first call of a step
compiles or loads numba kernels and imports lazily, seconds that would otherwise be timed as
the first scans'. The estimate does not depend on it. Everything the run did is returned as
a `SlamLog`; the optional visualiser is any object with the methods of `NullVisualiser`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from slam import se2
from slam.checks import check_noise
from slam.closure import ClosureDecision, LoopCloser, Revisit
from slam.components import Components, components
from slam.config import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.existence_map import LandmarkExistence
from slam.history import RunHistory
from slam.joint_gate import make_joint_gate
from slam.log import NEW_TENTATIVE, OUT_OF_RANGE, SKIPPED, LogBuilder, SlamLog
from slam.map_managers import MapDecisions, Pruner, ScanAssociation, make_map_manager
from slam.measurement import pass_inflation
from slam.pass_state import PassOffsets
from slam.sequence import Sequence
from slam.sources import Measurements
from slam.start import first_pass_wanted, initial_pose
from slam.visual import NullVisualiser, show_scan

__all__ = ["Slam", "run_slam"]

WARM_UP_SCANS = 10  # at most, see `warm_up`


@dataclass
class _Clock:
    """perf_counter at the start and after each of the five steps."""

    marks: list = field(default_factory=lambda: [time.perf_counter()])

    def lap(self) -> None:
        self.marks.append(time.perf_counter())

    def skip(self, n: int) -> None:
        """n steps not run: zero time each."""
        self.marks += [self.marks[-1]] * n


@dataclass(frozen=True, eq=False)
class ScanResult:
    """What one scan's steps produced (`Slam.step`), the record the log and the visualiser
    read: the measurements (as measured), each one's final status (`slam.log` codes) and
    track, the update's figures (batch NIS or NaN, measurements used), the tentatives pending
    after the scan and where they are, the association (None for a skipped scan), the map
    manager's decisions and loop closure's (None when not run)."""

    meas: Measurements
    status: np.ndarray
    track: np.ndarray
    nis: float
    n_used: int
    n_pending: int
    tentative_xy: np.ndarray
    association: ScanAssociation | None = None
    decisions: MapDecisions | None = None
    closure: ClosureDecision | None = None
    existence: np.ndarray | None = None  # map policy "existence": the map's, after the scan
    departed_existence: tuple = ()  # and that of each landmark the decisions removed


class RestGate:
    """`vehicle.min_travel_m`: a scan after which the odometry has moved the vehicle less than
    that since the last scan used is predicted only; its prediction noise joins the next used
    scan's drift."""

    def __init__(self, motion, scan_t: np.ndarray, min_travel_m: float) -> None:
        self.motion, self.scan_t, self.min_travel_m = motion, scan_t, min_travel_m
        self.travel_m = 0.0  # odometry distance since the last scan used
        self.Q_skipped = None  # prediction noise of the scans skipped since then

    def __call__(self, k: int, Q: np.ndarray) -> np.ndarray | None:
        """The drift (3, 3) scan k's association works with: its prediction noise Q and that
        of the scans skipped before it; None when scan k is at rest (skipped)."""
        min_travel = self.min_travel_m
        if k > 0 and min_travel > 0:
            self.travel_m += self.motion.distance(self.scan_t[k - 1], self.scan_t[k])
        if k > 0 and self.travel_m < min_travel:
            self.Q_skipped = Q if self.Q_skipped is None else self.Q_skipped + Q
            return None
        self.travel_m = 0.0
        if self.Q_skipped is not None:
            Q, self.Q_skipped = Q + self.Q_skipped, None
        return Q


class Slam:
    """The run loop over a run's components (`slam.components.Components`), built once;
    `start(pose, cov)` begins a pass over the scans from that prior at the first scan (the
    filter, the history, the log, and the map manager, pruning and loop closure made anew),
    `step(k)` runs scan k's five steps."""

    def __init__(self, parts: Components) -> None:
        self.parts = parts
        self.seq, self.source, self.motion = parts.seq, parts.source, parts.motion
        self.laser, self.view = parts.T_vehicle_laser, parts.view
        self.scan_t = np.asarray(parts.seq.scan_t, dtype=np.float64)

    def start(self, pose0: np.ndarray, cov0: np.ndarray) -> None:
        """A new pass from the prior (pose0 (3,), cov0 (3, 3)) at the first scan."""
        p = self.parts
        self.state = Filter(
            initial_state(pose0, np.array(cov0, dtype=np.float64)),
            first_estimates=p.first_estimates,
        )
        self.history = RunHistory(self.scan_t)
        self.log = LogBuilder(self.scan_t)
        self.log.started(pose0, cov0, self.laser, p.T_vehicle_antenna)
        self.existence = (
            LandmarkExistence(p.map_policy, self.view, self.laser)
            if p.map_policy.by_existence
            else None
        )
        self.map_manager = make_map_manager(
            self.laser,
            self.view,
            p.association,
            p.map_policy,
            p.associator,
            existence=self.existence,
        )
        prunes = p.map_policy.prunes
        self.pruner = Pruner(p.map_policy, self.view, self.laser) if prunes else None
        self.closer = (
            LoopCloser(
                p.closure,
                self.view,
                self.laser,
                self.history,
                gate_prob=p.association.new_feature_gate_prob,
            )
            if p.closure.enabled
            else None
        )
        self.rest = RestGate(self.motion, self.scan_t, p.min_travel_m)
        joint = p.association.joint_check
        self.joint = make_joint_gate(joint, p.association.gate_prob, self.laser)
        sd = p.pass_offset_sd_m
        by_state = p.pass_offset_model == "state" and (sd[0] != 0.0 or sd[1] != 0.0)
        self.passes = (
            PassOffsets(sd, p.pass_gap_s, self.laser, p.pass_offset_corr_rad) if by_state else None
        )

    def step(self, k: int) -> ScanResult:
        """Scan k's five steps, timed and logged; returns what they produced."""
        clock = _Clock()
        Q = self.predict(k)
        if self.passes is not None:  # the passes that ended before this scan
            self.passes.end_passes(self.state, float(self.scan_t[k]))
        clock.lap()
        meas = self.measure(k)
        clock.lap()
        drift = self.rest(k, Q)
        if drift is None:
            clock.skip(3)
            return self._skipped(meas, clock)
        revisit = Revisit() if self.closer is None else self.closer.revisit(self.state, k)
        a = self.map_manager.associate(self.state, meas, drift, revisit.hidden)
        a = self.joint(self.state, meas, a)  # `[association] joint_check`, else unchanged
        if self.existence is not None:  # on the predicted state, before the update
            tent = getattr(self.map_manager, "tent", None)
            self.existence.update(self.state, meas, a, tent, revisit.hidden)
        clock.lap()
        nis, paired = self.update(meas, a)
        clock.lap()
        decisions = self.map_manager.manage(self.state, meas, a, paired)
        self._record(k, decisions)
        if self.pruner is not None:
            for lid in self.pruner(self.state, decisions.status):
                self.log.departed(k, lid, "pruned", math.nan)
        closure = None
        if self.closer is not None:
            updated = decisions.status[decisions.status >= 0]
            closure = self.closer.close(self.state, k, updated, revisit)
        clock.lap()
        result = ScanResult(
            meas=meas,
            status=decisions.status,
            track=decisions.track,
            nis=nis,
            n_used=int(np.count_nonzero(paired >= 0)),
            n_pending=decisions.n_pending,
            tentative_xy=self.map_manager.tentative_xy,
            association=a,
            decisions=decisions,
            closure=closure,
            **self._existence_after(decisions.removed),
        )
        self.log.scan_done(result, self.state, clock.marks)
        return result

    def _existence_after(self, removed: list) -> dict:
        """Map policy "existence": the ScanResult's existence fields (removed: the decisions'
        [(landmark id, reason)]), else none."""
        if self.existence is None:
            return {}
        return {
            "existence": self.existence.of(self.state.landmark_ids),
            "departed_existence": tuple(self.existence.of([i for i, _ in removed])),
        }

    def predict(self, k: int) -> np.ndarray:
        """Step 1: the odometry from scan k - 1 to scan k (nothing before the first scan).

        The increment and its covariance in the frame of the pose at k - 1 go to the history
        (the smoother's odometry factors): the motion model is invariant to where the car is,
        so the world-frame Q is that covariance rotated by the heading. Returns Q (3, 3), world
        frame (zeros at k = 0)."""
        if k > 0:
            t = self.scan_t
            T_world_prev = self.state.pose.copy()
            T_world_next, F, Q = self.motion.integrate(T_world_prev, t[k - 1], t[k])
            delta = se2.compose(se2.inverse(T_world_prev), T_world_next)
            delta[2] = float(se2.wrap_angle(delta[2]))
            c, s = math.cos(T_world_prev[2]), math.sin(T_world_prev[2])
            A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world -> frame at k - 1
            self.history.odometry(k, delta, A @ Q @ A.T)
            self.state.predict(T_world_next, F, Q)
        else:
            Q = np.zeros((3, 3))
        self.history.predicted(k, self.state.pose, self.state.pose_cov)
        return Q

    def measure(self, k: int) -> Measurements:
        """Step 2: scan k's circles as measurements, each NEW_TENTATIVE until decided, or
        OUT_OF_RANGE beyond the usable range or not finite."""
        # the raw scan: for the extractor, and for existence's beams whatever the source
        wanted = self.source.needs_scan or self.existence is not None
        scan = self.seq.scan(k) if wanted else None
        f, z, R = self.source(k, scan)
        status = np.full(z.shape[0], NEW_TENTATIVE, np.int64)
        usable = (z[:, 0] <= self.view.max_range) & np.all(np.isfinite(z), axis=1)
        status[~usable] = OUT_OF_RANGE
        check_noise(k, R, usable, self.source.model.kind)
        return Measurements(k=k, scan=scan, features=f, z=z, R=R, status=status)

    def update(self, meas: Measurements, a: ScanAssociation) -> tuple[float, np.ndarray]:
        """Step 4: one batch update with the measurements paired with map landmarks. Returns
        (batch NIS or NaN, the landmark id each measurement updated (m,), -1 for none)."""
        paired = np.full(meas.z.shape[0], -1, np.int64)
        to_map = a.to_map()
        if not to_map.size:
            return math.nan, paired
        pos = a.lm_idx[a.assign[to_map]]
        ids = self.state.landmark_ids[pos]
        if self.passes is not None:  # pass offset "state": anchors for the passes begun
            self.passes.begin(self.state, ids, float(self.scan_t[meas.k]))
        res = self.state.update(pos, meas.z[to_map], self._update_R(meas, to_map, ids), self.laser)
        self.log.logdet[meas.k] = res.logdet
        paired[to_map] = ids
        for lid in ids.tolist():
            self.history.observed(lid)
        self.log.observations(meas.k, to_map, ids, z=meas.z[to_map], innov=res.innovation, S=res.S)
        return res.nis, paired

    def _update_R(self, meas: Measurements, rows: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The covariances the update uses for measurements `rows` of landmarks `ids`: as
        measured, plus the pass offset (`slam.measurement.pass_inflation`) when one is set
        as "inflation" (gating and new landmarks keep the white model; "state" carries it in
        the filter, `slam.pass_state`)."""
        sd = self.parts.pass_offset_sd_m
        if (sd[0] == 0.0 and sd[1] == 0.0) or self.passes is not None:
            return meas.R[rows]
        k = self.history.pass_index(ids, float(self.scan_t[meas.k]), self.parts.pass_gap_s)
        return pass_inflation(meas.z[rows], meas.R[rows], k, sd)

    def _record(self, k: int, decisions: MapDecisions) -> None:
        """The map manager's decisions into the history and the log: the landmarks that
        joined the map, the earlier measurements re-tracked to a new landmark."""
        for lid, n_obs in decisions.joined:
            self.history.joined(lid, k, n_obs)
        if self.passes is not None:  # their first pass began before they joined
            self.passes.joined(
                [lid for lid, _ in decisions.joined], float(self.scan_t[k]), self.state
            )
        for scan, feature, lid in decisions.retracks:
            self.log.retrack(scan, feature, lid)
        if decisions.removed:  # map policy "existence": marginalised out
            ids = [lid for lid, _ in decisions.removed]
            self.state.remove_landmarks(ids)
            r = self.existence.of(ids)
            for (lid, why), r_lid in zip(decisions.removed, r.tolist()):
                self.log.departed(k, lid, why, r_lid)

    def _skipped(self, meas: Measurements, clock: _Clock) -> ScanResult:
        """A scan at rest (`RestGate`): predicted only, its measurements SKIPPED."""
        self.log.skipped[meas.k] = True
        m = meas.z.shape[0]
        result = ScanResult(
            meas=meas,
            status=np.full(m, SKIPPED, np.int64),
            track=np.full(m, -1, np.int64),
            nis=math.nan,
            n_used=0,
            n_pending=self.map_manager.n_pending,
            tentative_xy=self.map_manager.tentative_xy,
            **self._existence_after([]),
        )
        self.log.scan_done(result, self.state, clock.marks)
        return result


def run_slam(
    sequence: Sequence,
    config: SlamConfig | None = None,
    *,
    features=None,
    association=None,
    visualiser=None,
    progress=None,
    warm_up: bool = True,
    prior=None,
) -> SlamLog:
    """EKF-SLAM over `sequence` as `config` (default `SlamConfig()`) says; returns the `SlamLog`,
    whose `config` is the whole configuration of the run.

    features: a method name (replaces `config.features.method`), or features the caller made:
        a list of N `Features` or a callable (k, scan) -> Features.
    association: a method name (replaces `config.association.method`), or a callable with the
        signature of `association.associate` minus `method`.
    visualiser: an object with the methods of `NullVisualiser` (default: nothing is logged).
    progress: callback(done, total) after each scan.
    warm_up: first run the steps over the first scans on a throwaway filter, so that
        `SlamLog.timing_s` holds the steps' own times and not one-off compilation.
    prior: (pose (3,), covariance (3, 3)) of the filter at the first scan, given by the caller
        (a published protocol's fixed start; `SlamLog.start` "given"); None: as the
        configuration's start says (`slam.start.initial_pose`).
    Raises `SlamError` (a ValueError) for a run that cannot be made.
    """
    cfg = _resolve(config, features, association)
    sequence = _at_measurement_times(sequence, cfg)
    if cfg.features.file is not None and (features is None or isinstance(features, str)):
        raise SlamError(
            f"features.file {cfg.features.file!r}: read it and pass its features (the "
            "command line does: experiments.io.features_json.load_features_json)"
        )
    parts = components(
        sequence,
        cfg,
        None if isinstance(features, str) else features,
        None if isinstance(association, str) else association,
    )
    loop = Slam(parts)
    if prior is None:
        wanted = first_pass_wanted(sequence, cfg)
        track = None if wanted is None else _first_pass(loop, *wanted)
        pose0, cov0, start = initial_pose(sequence, cfg, parts.motion, loop.laser, track)
    else:
        pose0, cov0, start = _given_prior(prior)
    if warm_up:
        _warm_up(loop, pose0, cov0)
    loop.start(pose0, cov0)
    vis = visualiser or NullVisualiser()
    for k in range(sequence.n_scans):
        result = loop.step(k)
        if type(vis) is not NullVisualiser:
            show_scan(vis, sequence, loop.laser, loop.state, result)
        if progress is not None:
            progress(k + 1, sequence.n_scans)
    if loop.passes is not None:  # the passes still open end with the run
        loop.passes.end_all(loop.state)
    closer = loop.closer
    return loop.log.build(
        loop.state,
        loop.history,
        start=start,
        features_method=parts.source.method,
        association_method=parts.associator.method,
        config=cfg.to_dict(),
        window_stats=loop.map_manager.stats(),
        existence=loop.existence,
        closures=None if closer is None else [e.to_dict() for e in closer.events],
        closure_duplicates=None if closer is None else [list(d) for d in closer.duplicates],
        joint_dropped=loop.joint.record(),
    )


def _at_measurement_times(seq: Sequence, cfg: SlamConfig) -> Sequence:
    """`seq` with each scan at its measurement time, its stamp minus
    `vehicle.laser_latency_s` (the sequence itself when that is 0: the run is then the same
    to the bit)."""
    latency = cfg.vehicle.laser_latency_s
    if latency == 0:
        return seq
    return dataclasses.replace(seq, scan_t=np.asarray(seq.scan_t, np.float64) - latency)


def _given_prior(prior) -> tuple[np.ndarray, np.ndarray, str]:
    """(pose, covariance, "given") of a caller's prior, checked."""
    pose = np.asarray(prior[0], dtype=np.float64)
    cov = np.asarray(prior[1], dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise SlamError(f"prior: expected a finite pose of shape (3,), got {pose!r}")
    if cov.shape != (3, 3) or not np.all(np.isfinite(cov)) or not np.allclose(cov, cov.T):
        raise SlamError("prior: expected a finite symmetric (3, 3) covariance")
    return pose.copy(), cov.copy(), "given"


def _resolve(config, features, association) -> SlamConfig:
    cfg = SlamConfig() if config is None else config
    if not isinstance(cfg, SlamConfig):
        raise SlamError(f"config: expected a SlamConfig, got {type(cfg).__name__}")
    changes = {}
    if isinstance(features, str):
        changes["features.method"] = features
    if isinstance(association, str):
        changes["association.method"] = association
    return cfg.with_(**changes) if changes else cfg


def _warm_up(loop: Slam, pose0: np.ndarray, cov0: np.ndarray) -> None:
    """The steps over the first scans from the prior, until one update has been made (at most
    `WARM_UP_SCANS`), in a pass that is then forgotten (`Slam.start` begins the run anew):
    numba compiling or loading its kernels, lazy imports and first-use caches are paid here,
    not in the timed loop. Only a features or association callable sees the first scans
    twice."""
    loop.start(pose0, cov0)
    for k in range(min(WARM_UP_SCANS, loop.seq.n_scans)):
        if loop.step(k).n_used > 0:
            break


def _first_pass(loop: Slam, cov0: np.ndarray, fit_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(scan times, poses) of a pass of the filter from the origin (covariance cov0) over the
    scans until its antenna track has covered `fit_m` metres (and one scan more), for
    `slam.start.initial_pose`'s fit to GPS along a path whose shape the landmarks kept
    (`first_pass_wanted`). The estimate of a run is the same up to rounding in any frame, so
    the pass's frame only names where the track starts."""
    loop.start(np.zeros(3), cov0)
    seq, ant = loop.seq, loop.parts.T_vehicle_antenna
    loop.step(0)
    poses = [np.zeros(3)]  # the track starts at the prior: the start is the prior's mean
    dist, last = 0.0, ant[:2].copy()
    for k in range(1, seq.n_scans):
        loop.step(k)
        poses.append(loop.state.pose.copy())
        a = se2.compose(poses[-1], ant)[:2]
        dist, last = dist + float(np.hypot(*(a - last))), a
        if dist > fit_m:
            break
    return np.asarray(seq.scan_t[: len(poses)], dtype=np.float64), np.array(poses)
