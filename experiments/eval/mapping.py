"""Association quality of a SLAM run: false pairings, duplicate landmarks, missed trees.

- `false_pairings(log, meas_object)`: updates whose measurement came from another object than
  the one its landmark stands for (the object most of the landmark's measurements came from).
- `duplicates_and_missed(landmark_xy, trees_xy, seen, tol_m)`: trees with two or more map
  landmarks within tol_m (duplicates: the extra landmarks), and trees seen by the sensor with
  no landmark within tol_m.
"""

from __future__ import annotations

import numpy as np

from slam import SlamLog
from slam.log import CONFIRMED

__all__ = ["duplicates_and_missed", "false_pairings", "landmark_objects"]


def landmark_objects(lg: SlamLog, meas_object) -> dict[int, int]:
    """landmark id -> the object (label) most of its measurements came from (its updates, its
    initialising measurement and its logged earlier sightings). meas_object(scan, feature) ->
    object label (any int; -1 for none)."""
    votes: dict[int, dict[int, int]] = {}
    used = (lg.meas_status >= 0) | (lg.meas_status == CONFIRMED)
    used |= np.isin(lg.meas_track, lg.landmark_id) & (lg.meas_status < 0)
    for k, i, lid in zip(lg.meas_scan[used], lg.meas_feature[used], lg.meas_track[used]):
        o = int(meas_object(int(k), int(i)))
        d = votes.setdefault(int(lid), {})
        d[o] = d.get(o, 0) + 1
    # ties go to the smaller label
    return {lid: min(d, key=lambda o: (-d[o], o)) for lid, d in votes.items()}


def false_pairings(lg: SlamLog, meas_object) -> tuple[int, int]:
    """(false, total) over the measurements used in the run's updates: false when the
    measurement's object (meas_object(scan, feature)) is not its landmark's object
    (`landmark_objects`)."""
    obj = landmark_objects(lg, meas_object)
    false = 0
    for k, i, lid in zip(lg.obs_scan, lg.obs_feature, lg.obs_landmark):
        false += int(meas_object(int(k), int(i)) != obj.get(int(lid), -1))
    return false, int(lg.obs_scan.size)


def duplicates_and_missed(
    landmark_xy: np.ndarray, trees_xy: np.ndarray, seen: np.ndarray | None = None, tol_m=1.0
) -> tuple[int, int]:
    """(duplicates, missed): duplicates = sum over trees of (landmarks within tol_m - 1) where
    positive; missed = trees with `seen` True and no landmark within tol_m (seen: (T,) bool,
    default every tree)."""
    trees_xy = np.asarray(trees_xy, float).reshape(-1, 2)
    lm = np.asarray(landmark_xy, float).reshape(-1, 2)
    seen = np.ones(trees_xy.shape[0], bool) if seen is None else np.asarray(seen, bool)
    if lm.shape[0] == 0:
        return 0, int(seen.sum())
    d = np.hypot(trees_xy[:, None, 0] - lm[None, :, 0], trees_xy[:, None, 1] - lm[None, :, 1])
    near = (d <= tol_m).sum(axis=1)
    return int(np.maximum(near - 1, 0).sum()), int(np.sum(seen & (near == 0)))
