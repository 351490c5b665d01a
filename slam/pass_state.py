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

Loop closure's merges and rigid moves act on the landmarks' slots, so `slam.rigid` restores
every copy before it acts; a landmark seen again in the same pass afterwards begins a new pass
(a new, independent offset: on the cautious side). A landmark removed from the map takes its
copy with it (`Filter.remove_landmarks`).
"""

from __future__ import annotations

import math

import numpy as np

from slam.ekf import Filter

__all__ = ["PassOffsets", "offset_cov"]


def offset_cov(pose: np.ndarray, landmarks_xy: np.ndarray, laser: np.ndarray, sd) -> np.ndarray:
    """(k, 2, 2) world-frame covariances Rot(phi) diag(sd_range^2, sd_across^2) Rot(phi)^T of
    the offsets of landmarks at landmarks_xy (k, 2), phi the direction from the laser (mounted
    at `laser` [lx, ly, lth] on the vehicle at `pose`) to each landmark."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    at = pose[:2] + np.array([c * laser[0] - s * laser[1], s * laser[0] + c * laser[1]])
    d = np.asarray(landmarks_xy, dtype=np.float64).reshape(-1, 2) - at
    phi = np.arctan2(d[:, 1], d[:, 0])
    u = np.stack([np.cos(phi), np.sin(phi)], axis=1)  # along the line of sight
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)  # across it
    return sd[0] ** 2 * np.einsum("ki,kj->kij", u, u) + sd[1] ** 2 * np.einsum("ki,kj->kij", v, v)


class PassOffsets:
    """Which landmarks are in a pass, and when each pass ends; the loop calls `end_passes` at
    every scan (with the scan's time) before its association, `begin` before each update with
    the ids it updates, `joined` with the landmarks that join the map, and `end_all` at the
    end of the run."""

    def __init__(self, sd: tuple[float, float], gap_s: float, laser: np.ndarray) -> None:
        self.sd = (float(sd[0]), float(sd[1]))
        self.gap_s = float(gap_s)
        self.laser = np.asarray(laser, dtype=np.float64)
        self.last: dict[int, float] = {}  # landmark id in a pass -> time of its last update
        self.fresh: set[int] = set()  # in the pass they joined the map in, with no anchor yet
        self.n_passes = 0  # passes begun

    def joined(self, ids, t: float) -> None:
        """Landmarks `ids` joined the map at time t, initialised from a sighting of this pass."""
        for i in np.asarray(ids, dtype=np.int64).reshape(-1).tolist():
            self.last[i] = t
            self.fresh.add(i)

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
        state.restore_copies([i for i in ended if i in open_])

    def begin(self, state: Filter, ids: np.ndarray, t: float) -> None:
        """Landmarks `ids` (state order, before the update at time t): each one without an
        anchor takes one, Sigma_b added to the landmark (a new pass) or, in the pass it joined
        the map in, to the anchor (module doc); all are marked updated."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        new = ids[~np.isin(ids, state.copy_of)]
        if new.size:
            xy = state.landmarks_xy[state.positions_of(new)]
            fresh = np.array([i in self.fresh for i in new.tolist()], bool)
            cov = offset_cov(state.pose, xy, self.laser, self.sd)
            state.append_copies(new, cov, on_copy=fresh)
            self.n_passes += int(new.size)
        for i in ids.tolist():
            self.last[i] = t
            self.fresh.discard(i)

    def end_all(self, state: Filter) -> None:
        """The end of the run: every pass ends."""
        state.restore_copies()
        self.last.clear()
        self.fresh.clear()
