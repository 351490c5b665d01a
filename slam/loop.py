"""`slam.run_slam`: EKF-SLAM over one `Sequence`, scan by scan, as its configuration says.

`Slam.step(k)` is the loop's body, five named steps with a record passed between them:
1. predict: integrate the odometry from the previous scan (zero-order hold, `slam.vehicle`);
2. measure: the scan's circles as range-bearing measurements of their centres (the source,
   `slam.sources`: an extractor, the sequence's detections, or given features);
3. associate, 5. manage: the map manager (`slam.maps`: tentatives with a single-scan
   associator, or the K-scan IHGR window) pairs measurements with landmarks and decides what
   joins the map;
4. update: all measurements paired with landmarks at once (Joseph form, `slam.ekf.Filter`).
A scan after which the odometry has moved the vehicle less than `vehicle.min_travel_m` since
the last scan used is predicted only: its measurements are logged with status SKIPPED.
Pruning (`slam.maps.Pruner`) follows map management when the map policy asks for it, and
loop closure (`slam.closure.LoopCloser`) when `[closure] enabled`.

The components are built once from the configuration (`Slam.__init__`); the start pose comes
from `slam.start.initial_pose` and the run's checks from `slam.checks`. Before the timed loop
the steps run over the first scans on a throwaway filter until one update has been made
(`warm_up`): the first call of a step compiles or loads numba kernels and imports lazily,
seconds that would otherwise be timed as the first scans'. The estimate does not depend on it.
Everything the run did is returned as a `SlamLog`; the optional visualiser is any object with
the methods of `NullVisualiser`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from slam import se2
from slam.checks import check_noise
from slam.closure import LoopCloser
from slam.components import Components, components
from slam.config import SlamConfig
from slam.ekf import Filter, initial_state
from slam.errors import SlamError
from slam.log import NEW_TENTATIVE, OUT_OF_RANGE, SKIPPED, LogBuilder, ScanCounts, SlamLog
from slam.maps import Association, Pruner, make_map_manager
from slam.sequence import Sequence
from slam.sources import Measurements
from slam.start import antenna_of, initial_pose
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


class Slam:
    """One pass over a run's scans from a prior (pose, covariance) at the first scan: the
    filter, the map manager and the log, on the run's components."""

    def __init__(self, c: Components, pose0: np.ndarray, cov0: np.ndarray) -> None:
        self.c, self.seq, self.cfg = c, c.seq, c.cfg
        self.laser, self.view = c.T_vehicle_laser, c.view
        self.state = Filter(
            initial_state(pose0, np.array(cov0, dtype=np.float64)),
            first_estimates=c.cfg.filter.first_estimates_jacobians,
        )
        self.book = LogBuilder(np.asarray(c.seq.scan_t, dtype=np.float64))
        self.book.started(pose0, cov0, self.laser, antenna_of(c.seq, c.cfg, self.laser))
        self.maps = make_map_manager(c.cfg, self.laser, self.view, self.book, c.associator)
        policy = c.cfg.map_policy
        self.prune = Pruner(policy, self.view, self.laser) if policy.prunes else None
        closure = c.cfg.closure
        self.closer = (
            LoopCloser(
                closure,
                self.view,
                self.laser,
                self.book,
                gate_prob=c.cfg.association.new_feature_gate_prob,
            )
            if closure.enabled
            else None
        )
        self.travel_m = 0.0  # odometry distance since the last scan used
        self.Q_skipped = None  # prediction noise of the scans skipped since then
        self.n_used = self.n_pending = 0

    def step(self, k: int) -> Measurements:
        """Scan k's five steps, timed and logged; returns its measurements (status set)."""
        clock = _Clock()
        Q = self.predict(k)
        clock.lap()
        meas = self.measure(k)
        clock.lap()
        if self._at_rest(k, Q):
            meas.status[:] = SKIPPED
            self.book.skipped[k] = True
            clock.skip(3)
            self._log(meas, np.full(meas.z.shape[0], -1, np.int64), (math.nan, 0), clock)
            return meas
        hidden = None if self.closer is None else self.closer.hidden(self.state, k)
        a = self.maps.associate(self.state, meas, self._drift(Q), hidden)
        clock.lap()
        nis_used = self.update(meas, a)
        clock.lap()
        track = np.where(meas.status >= 0, meas.status, -1)
        self.n_pending = self.maps.manage(self.state, meas, a, track)
        if self.prune is not None:
            self.prune(self.state, meas.status)
        if self.closer is not None:
            self.closer(self.state, meas.k, meas.status)
        clock.lap()
        self._log(meas, track, nis_used, clock)
        return meas

    def predict(self, k: int) -> np.ndarray:
        """Step 1: the odometry from scan k - 1 to scan k (nothing before the first scan).

        The increment and its covariance in the frame of the pose at k - 1 go to the log (the
        smoother's odometry factors): the motion model is invariant to where the car is, so
        the world-frame Q is that covariance rotated by the heading. Returns Q (3, 3), world
        frame (zeros at k = 0)."""
        if k > 0:
            t = self.seq.scan_t
            T_world_prev = self.state.pose.copy()
            T_world_next, F, Q = self.c.motion.integrate(T_world_prev, t[k - 1], t[k])
            delta = se2.compose(se2.inverse(T_world_prev), T_world_next)
            delta[2] = float(se2.wrap_angle(delta[2]))
            c, s = math.cos(T_world_prev[2]), math.sin(T_world_prev[2])
            A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world -> frame at k - 1
            self.book.odometry(k, delta, A @ Q @ A.T)
            self.state.predict(T_world_next, F, Q)
        else:
            Q = np.zeros((3, 3))
        self.book.predicted(k, self.state.pose, self.state.pose_cov)
        return Q

    def measure(self, k: int) -> Measurements:
        """Step 2: scan k's circles as measurements, each NEW_TENTATIVE until decided, or
        OUT_OF_RANGE beyond the usable range or not finite."""
        scan = self.seq.scan(k)
        f, z, R = self.c.source(k, scan)
        status = np.full(z.shape[0], NEW_TENTATIVE, np.int64)
        usable = (z[:, 0] <= self.view.max_range) & np.all(np.isfinite(z), axis=1)
        status[~usable] = OUT_OF_RANGE
        check_noise(k, R, usable, self.c.source.model.kind)
        return Measurements(k=k, scan=scan, features=f, z=z, R=R, status=status)

    def update(self, meas: Measurements, a: Association) -> tuple[float, int]:
        """Step 4: one batch update with the measurements paired with map landmarks; their
        status becomes the landmark id. Returns (batch NIS or NaN, measurements used)."""
        to_map = a.to_map()
        if not to_map.size:
            return math.nan, 0
        pos = a.lm_idx[a.assign[to_map]]
        res = self.state.update(pos, meas.z[to_map], meas.R[to_map], self.laser)
        self.book.logdet[meas.k] = res.logdet
        for j, i in enumerate(to_map):
            lid = int(self.state.landmark_ids[pos[j]])
            meas.status[i] = lid
            S_j = res.S[2 * j : 2 * j + 2, 2 * j : 2 * j + 2]
            self.book.observation(meas.k, int(i), lid, z=meas.z[i], innov=res.innovation[j], S=S_j)
        return res.nis, int(to_map.size)

    def _at_rest(self, k: int, Q: np.ndarray) -> bool:
        """Whether scan k is predicted only: the vehicle has not moved `min_travel_m` since the
        last scan used (its Q then joins the next used scan's drift)."""
        min_travel = self.cfg.vehicle.min_travel_m
        if k > 0 and min_travel > 0:
            self.travel_m += self.c.motion.distance(self.seq.scan_t[k - 1], self.seq.scan_t[k])
        if k > 0 and self.travel_m < min_travel:
            self.Q_skipped = Q if self.Q_skipped is None else self.Q_skipped + Q
            return True
        self.travel_m = 0.0
        return False

    def _drift(self, Q: np.ndarray) -> np.ndarray:
        """This scan's prediction noise, with that of the scans skipped before it."""
        if self.Q_skipped is not None:
            Q, self.Q_skipped = Q + self.Q_skipped, None
        return Q

    def _log(self, meas: Measurements, track: np.ndarray, nis_used, clock: _Clock) -> None:
        nis, n_used = nis_used
        counts = ScanCounts(nis, n_used, self.n_pending)
        self.book.scan_done(meas, self.state, track, counts, clock.marks)
        self.n_used = n_used


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
    c = components(
        sequence,
        cfg,
        None if isinstance(features, str) else features,
        None if isinstance(association, str) else association,
    )
    if prior is None:
        pose0, cov0, start = initial_pose(
            sequence, cfg, c.motion, c.T_vehicle_laser, _first_pass(c)
        )
    else:
        pose0, cov0, start = _given_prior(prior)
    if warm_up:
        _warm_up(Slam(c, pose0, cov0))
    loop = Slam(c, pose0, cov0)
    vis = visualiser or NullVisualiser()
    for k in range(sequence.n_scans):
        meas = loop.step(k)
        if type(vis) is not NullVisualiser:
            show_scan(vis, loop, meas)
        if progress is not None:
            progress(k + 1, sequence.n_scans)
    return loop.book.build(
        loop.state,
        start=start,
        features_method=c.source.method,
        association_method=c.associator.method,
        config=cfg.to_dict(),
        window_stats=loop.maps.stats(),
        closures=None if loop.closer is None else [e.to_dict() for e in loop.closer.events],
        closure_duplicates=None
        if loop.closer is None
        else [list(d) for d in loop.closer.duplicates],
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


def _warm_up(loop: Slam) -> None:
    """The steps over the first scans, until one update has been made (at most
    `WARM_UP_SCANS`), on a filter that is then forgotten: numba compiling or loading its
    kernels, lazy imports and first-use caches are paid here, not in the timed loop. Nothing
    is shared with the run; only a features or association callable sees the first scans
    twice."""
    for k in range(min(WARM_UP_SCANS, loop.seq.n_scans)):
        loop.step(k)
        if loop.n_used > 0:
            break


def _first_pass(c: Components):
    """first_pass(cov0, fit_m) -> (scan times, poses) of the filter from the origin over the
    scans until its antenna track has covered `fit_m` metres (and one scan more), for
    `fit_gps_start_to_track`: the start's rigid fit to GPS along a path whose shape the
    landmarks kept. The estimate of a run is the same up to rounding in any frame, so the
    pass's frame only names where the track starts."""

    def first_pass(cov0: np.ndarray, fit_m: float) -> tuple[np.ndarray, np.ndarray]:
        loop = Slam(c, np.zeros(3), cov0)
        seq, ant = c.seq, antenna_of(c.seq, c.cfg, c.T_vehicle_laser)
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

    return first_pass
