"""`PassOffsets`: the pass offset as a state of the filter (`measurement.pass_offset_model =
"state"`), the exact model of a trunk's centre offset b shared by the sightings of one pass.

A landmark's sightings in one pass (no gap over `measurement.pass_gap_s` between its
updates) see m' = m + b, the tree's centre m plus an offset b ~ N(0, Sigma_b) constant over
the pass and independent between passes; Sigma_b = Rot(phi) diag(s_range^2, s_across^2)
Rot(phi)^T in the world frame, phi the line of sight from the laser to the landmark when the
pass begins (`measurement.pass_offset_sd_m`). While a pass lasts the filter carries two slots
for the landmark (`slam.ekf.Filter.append_copies`): its own, which the association, the map
and the log keep reading, holds m' and is updated with the white measurement covariance; a
hidden copy, the anchor, holds m (the copy taken before Sigma_b was added to the landmark, so
x_a = x_p, P_a* = P_p*, P_pa = P_pp). When the pass ends (the landmark's last update more than
pass_gap_s before a scan, or the end of the run) the landmark gets the anchor back and the
anchor goes (`Filter.restore_copies`): b = m' - m is marginalised out, exact for a Gaussian.

A landmark's first pass began before it joined the map: the measurement it was initialised
from (`Filter.add_landmark`, the white model) saw m' too. Its first update (within pass_gap_s
of its joining) therefore takes the anchor with Sigma_b added to the anchor instead
(m = m' - b: x_a = x_p, P_aa = P_pp + Sigma_b, P_pa = P_pp), so that the first pass's offset
does not stay in the tree's estimate with the white model's confidence.

With a finite correlation length L (`measurement.pass_offset_corr_rad`) the offset drifts as
the view turns, first-order Gauss-Markov in the view angle theta (the line of sight's bearing in
the world): before each update in a pass, b <- phi b + q, phi = exp(-|theta - theta_last| / L),
q ~ N(0, (1 - phi^2) Sigma_b) (`Filter.blend_copies`: landmark <- phi landmark + (1 - phi)
anchor), Sigma_b kept from the pass's first sighting so that the process is stationary (the
smoother's model, `slam.smoother`). L = inf: constant over the pass, nothing computed.

Loop closure's change of frame (`slam.rigid.move_rigidly`, which holds the map's frame after a
re-registration, possibly at every scan) moves the copies with the landmarks, and the passes go
on (with a drift, the kept Sigma_b and view angles stay in the old frame: the frame's turn is a
few millidegrees). Its merges and re-registrations (`merge_landmarks`, `free_rigid_motion`, a
few events in a run) restore every copy first: a landmark seen again in the same pass
afterwards begins a new pass with a new, independent offset, which counts that pass's offset
twice (over-confident by at most one pass's offset, once per such event). A landmark removed
from the map takes its copy with it (`Filter.remove_landmarks`).
"""

from __future__ import annotations

import math

import numpy as np

from slam.ekf import Filter
from slam.measurement import line_of_sight_cov
from slam.se2 import compose, wrap_angle

__all__ = ["PassOffsets", "offset_cov", "view_angle"]


def view_angle(pose: np.ndarray, landmarks_xy: np.ndarray, laser: np.ndarray) -> np.ndarray:
    """(k,) the world bearing of the line of sight from the laser (mounted at `laser` on the
    vehicle at `pose`) to each landmark at landmarks_xy (k, 2)."""
    d = np.asarray(landmarks_xy, dtype=np.float64).reshape(-1, 2) - compose(pose, laser)[:2]
    return np.arctan2(d[:, 1], d[:, 0])


def offset_cov(pose: np.ndarray, landmarks_xy: np.ndarray, laser: np.ndarray, sd) -> np.ndarray:
    """(k, 2, 2) world-frame covariances Rot(phi) diag(sd_range^2, sd_across^2) Rot(phi)^T of
    the offsets of landmarks at landmarks_xy (k, 2), phi the direction from the laser (mounted
    at `laser` [lx, ly, lth] on the vehicle at `pose`) to each landmark."""
    return line_of_sight_cov(view_angle(pose, landmarks_xy, laser), sd)


class PassOffsets:
    """Which landmarks are in a pass, and when each pass ends; the loop calls `end_passes` at
    every scan (with the scan's time) before its association, `begin` before each update with
    the ids it updates, `joined` with the landmarks that join the map, and `end_all` at the
    end of the run."""

    def __init__(
        self, sd: tuple[float, float], gap_s: float, laser: np.ndarray, corr_rad: float = math.inf
    ) -> None:
        self.sd = (float(sd[0]), float(sd[1]))
        self.gap_s = float(gap_s)
        self.laser = np.asarray(laser, dtype=np.float64)
        self.corr_rad = float(corr_rad)
        self.drift = math.isfinite(self.corr_rad)  # Gauss-Markov steps (else constant)
        self.view: dict[int, float] = {}  # drift: landmark in a pass -> its last view angle
        self.cov: dict[int, np.ndarray] = {}  # drift: landmark in a pass -> its Sigma_b
        self.last: dict[int, float] = {}  # landmark id in a pass -> time of its last update
        self.fresh: set[int] = set()  # in the pass they joined the map in, with no anchor yet
        self.n_passes = 0  # passes begun

    def joined(self, ids, t: float, state: Filter | None = None) -> None:
        """Landmarks `ids` joined the map at time t, initialised from a sighting of this pass
        (drift: `state` gives the view angle of that sighting; without it the drift's first
        step counts from the first update)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        for i in ids.tolist():
            self.last[i] = t
            self.fresh.add(i)
        if self.drift and state is not None and ids.size:
            theta = view_angle(state.pose, state.landmarks_xy[state.positions_of(ids)], self.laser)
            self.view.update(zip(ids.tolist(), theta.tolist()))

    def end_passes(self, state: Filter, t: float) -> None:
        """At a scan at time t: the passes whose landmark's last update is more than gap_s
        before t end (each landmark gets its anchor back); bookkeeping for landmarks whose
        copy is gone (removed from the map, or restored by loop closure) is dropped."""
        open_ = set(state.copy_of.tolist())
        ended = [
            i
            for i, last in self.last.items()
            if t - last > self.gap_s or (i not in open_ and i not in self.fresh)
        ]
        for i in ended:
            del self.last[i]
            self.fresh.discard(i)
            self.view.pop(i, None)
            self.cov.pop(i, None)
        state.restore_copies([i for i in ended if i in open_])

    def begin(self, state: Filter, ids: np.ndarray, t: float) -> None:
        """Landmarks `ids` (state order, before the update at time t): each one without an
        anchor takes one, Sigma_b added to the landmark (a new pass) or, in the pass it joined
        the map in, to the anchor (module doc); with a drift, each one whose sighting before
        this one was in the same pass takes a Gauss-Markov step (module doc); all are marked
        updated."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        new = ids[~np.isin(ids, state.copy_of)]
        if new.size:
            xy = state.landmarks_xy[state.positions_of(new)]
            fresh = np.array([i in self.fresh for i in new.tolist()], bool)
            cov = offset_cov(state.pose, xy, self.laser, self.sd)
            state.append_copies(new, cov, on_copy=fresh)
            self.n_passes += int(new.size)
            if self.drift:
                for i, c, f in zip(new.tolist(), cov, fresh.tolist()):
                    self.cov[i] = c
                    if not f:  # a new pass: its first sighting is this one
                        self.view.pop(i, None)
        if self.drift:
            self._drift(state, ids)
        for i in ids.tolist():
            self.last[i] = t
            self.fresh.discard(i)

    def _drift(self, state: Filter, ids: np.ndarray) -> None:
        """The Gauss-Markov step of each of `ids` (all with an anchor) from its last view angle
        to this one, and the view angles kept."""
        theta = view_angle(state.pose, state.landmarks_xy[state.positions_of(ids)], self.laser)
        step = [
            (i, math.exp(-abs(float(wrap_angle(th - self.view[i]))) / self.corr_rad))
            for i, th in zip(ids.tolist(), theta.tolist())
            if i in self.view
        ]
        self.view.update(zip(ids.tolist(), theta.tolist()))
        if step:
            moved = np.array([i for i, _ in step], np.int64)
            phi = np.array([f for _, f in step])
            extra = np.stack([(1.0 - f * f) * self.cov[i] for i, f in step])
            state.blend_copies(moved, phi, extra)

    def end_all(self, state: Filter) -> None:
        """The end of the run: every pass ends."""
        state.restore_copies()
        self.last.clear()
        self.fresh.clear()
        self.view.clear()
        self.cov.clear()
