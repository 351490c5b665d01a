"""Map management as the paper describes it (section 3, second experiment).

"A new feature is tentative until it has been associated in at least three scans, then joins
the map; tentative features not seen again are dropped" (the paper: features "not used for the
SLAM more than 3 times" are not drawn in the map).

Tentative features live outside the filter state, so a false feature (a bush that looked like a
trunk once) never moves the vehicle estimate: each keeps its world position and covariance from
its latest sighting (computed as a landmark initialisation would, `slam.se2.inverse_observe`), the
number of scans it was associated in, and the number of consecutive scans it was missed in.
With the existence policy and `existence_fuse_tentatives`, the position and covariance are
instead those of all its sightings fused (`fuse`).
For association they are offered alongside the map's landmarks with a covariance that ignores
their correlation with the vehicle (their first-sighting covariance already contains the
vehicle's uncertainty, so the gate is, if anything, too wide).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.config import MapPolicy
from slam.se2 import inverse_observe

__all__ = ["Tentatives", "fuse", "sighting"]


def sighting(
    pose: np.ndarray, pose_cov: np.ndarray, z: np.ndarray, R: np.ndarray, laser_pose: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World position (2,) and covariance (2, 2) of a feature seen as z (2,) with noise R."""
    m, Gx, Gz = inverse_observe(pose, z, laser_pose)
    C = Gx @ pose_cov @ Gx.T + Gz @ R @ Gz.T
    return m, 0.5 * (C + C.T)


def fuse(
    xy: np.ndarray, cov: np.ndarray, m: np.ndarray, C: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A tentative's position xy (2,) with covariance cov (2, 2) fused with a new sighting m (2,)
    of covariance C (2, 2), as a static point's Kalman update (information form): cov' =
    (cov^-1 + C^-1)^-1, xy' = cov' (cov^-1 xy + C^-1 m). Over its sightings this is their
    inverse-covariance-weighted mean (map policy `existence_fuse_tentatives`). The sightings'
    errors are taken as independent: the part of their covariance the vehicle's pose brings is
    shared by sightings close in time, so cov' is, if anything, too small."""
    K = np.linalg.solve((cov + C).T, cov.T).T  # cov (cov + C)^-1, the Kalman gain
    fused = xy + K @ (m - xy)
    P = cov - K @ cov
    return fused, 0.5 * (P + P.T)


@dataclass(frozen=True, eq=False)
class Tentatives:
    """The tentative features.

    xy: (t, 2) world position of each, m (latest sighting; fused over its sightings with
    `existence_fuse_tentatives`, `fuse`). cov: (t, 2, 2) its covariance.
    hits: (t,) scans it has been associated in. missed: (t,) consecutive scans without a hit.
    first_scan: (t,) scan index of the first sighting. ids: (t,) stable ids (the landmark id
    it keeps if it joins the map).
    """

    xy: np.ndarray
    cov: np.ndarray
    hits: np.ndarray
    missed: np.ndarray
    first_scan: np.ndarray
    ids: np.ndarray

    @classmethod
    def empty(cls) -> Tentatives:
        none = np.zeros(0, np.int64)
        return cls(
            xy=np.zeros((0, 2)),
            cov=np.zeros((0, 2, 2)),
            hits=none,
            missed=none,
            first_scan=none,
            ids=none,
        )

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def step(
        self,
        matched: dict[int, tuple[np.ndarray, np.ndarray]],
        new: list[tuple[np.ndarray, np.ndarray, int]],
        scan_index: int,
        policy: MapPolicy,
        join: np.ndarray | None = None,
        gone: np.ndarray | None = None,
    ) -> tuple[Tentatives, list[int]]:
        """One scan of bookkeeping.

        matched: tentative position -> (xy, cov) of this scan's sighting of it.
        new: [(xy, cov, id)] first sightings to add.
        join, gone: (t,) bool, the tentatives that join the map and those dropped, decided
        by the caller (map policy "existence"); None: by `policy.confirm_scans`, nothing more.
        A tentative unseen for `policy.drop_after_missed` scans is dropped too, unless the
        existence policy keeps tentatives through misses (`existence_keep_tentatives`).
        Returns the new set and the positions (in `self`) of the tentatives that reached
        `policy.confirm_scans` (or `join`) and must join the map (they are removed from the
        set).
        """
        t = len(self)
        hits = self.hits.copy()
        missed = self.missed + 1
        xy, cov = (self.xy.copy(), self.cov.copy()) if matched else (self.xy, self.cov)
        fusing = policy.by_existence and policy.existence_fuse_tentatives
        for i, (m, C) in matched.items():
            hits[i] += 1
            missed[i] = 0
            xy[i], cov[i] = fuse(xy[i], cov[i], m, C) if fusing else (m, C)
        if join is None:
            confirm = np.flatnonzero(hits >= policy.confirm_scans).tolist()
        else:
            confirm = np.flatnonzero(join).tolist()
        keep = np.ones(t, bool)
        keep[confirm] = False
        if not (policy.by_existence and policy.existence_keep_tentatives):
            keep &= missed < policy.drop_after_missed  # else: only its existence drops it
        if gone is not None:
            keep &= ~np.asarray(gone, bool)
        kept = xy[keep], cov[keep], hits[keep], missed[keep], self.first_scan[keep], self.ids[keep]
        if new:  # the first sightings after the tentatives kept
            n_new = len(new)
            added = (
                np.array([m for m, _, _ in new]).reshape(n_new, 2),
                np.array([C for _, C, _ in new]).reshape(n_new, 2, 2),
                np.ones(n_new, np.int64),
                np.zeros(n_new, np.int64),
                np.full(n_new, scan_index),
                np.array([i for _, _, i in new], np.int64),
            )
            kept = tuple(np.concatenate([a, b]) for a, b in zip(kept, added))
        return Tentatives(*kept), confirm
