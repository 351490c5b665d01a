"""How good a map is, against a reference map and against the run's own detections.

- `reference_in_our_frame`: a reference map (the 2002 SLAM school's 145 trees of Victoria Park
  scans 1-2000) mapped into the run's frame by the rigid fit of the reference laser path to the
  run's laser path over the scans both have.
- `map_recall`: share of the reference trees with a landmark within `tol_m` (1 m).
- `seen_trees`: the reference trees a detector came within `tol_m` of: over part of the
  reference's span, recall is judged on them (the others were not in view).
- `map_precision`: share of the landmarks that joined the map in the reference's span of scans
  with a reference tree within `tol_m`; landmarks that joined later are outside what the
  reference covers and are not judged.
- `one_tree_pairs`: the landmarks mapped twice that a run leaves: pairs within 1.5 m
  (`slam.closure.SAME_TREE_M`, the radius loop closure's revisit detection uses), and of
  them those that are one tree by the reference (both within `tol_m` of the same reference
  tree) or by the laser (never both updated in one scan: the laser never saw them as two).
- `false_detection_rate`: the paper's Table 4 figure on real data, where no detection carries a
  truth label: the share of the circles the filter considered (within its range, in scans it
  used) that no landmark of the final map explains, i.e. whose track (the landmark or tentative
  it was paired with or started) is not a landmark at the end of the run. Ambiguous circles
  (gated to several, assigned to none) count as unexplained.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from slam import se2
from slam.closure import SAME_TREE_M
from slam.log import OUT_OF_RANGE, SKIPPED
from slam.se2 import procrustes_2d

__all__ = [
    "false_detection_rate",
    "map_precision",
    "map_recall",
    "one_tree_pairs",
    "reference_in_our_frame",
    "seen_trees",
]


def reference_in_our_frame(
    laser_xy: np.ndarray, ground: np.ndarray, trees: np.ndarray
) -> np.ndarray:
    """(T, 2) the reference `trees` (T, >= 2) in the run's frame. laser_xy (N, 2): the run's
    laser positions; ground (M, >= 2): the reference's laser path, scan for scan; fitted over
    the first min(N, M) scans."""
    n = min(ground.shape[0], laser_xy.shape[0])
    if n < 2:
        raise ValueError(f"reference_in_our_frame: {n} common scans, at least 2 needed")
    theta, t = procrustes_2d(ground[:n, :2], laser_xy[:n])
    return se2.rotate(theta, trees[:, :2]) + t


def _nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a),) distance from each point of a to the nearest of b (inf when b is empty)."""
    if b.shape[0] == 0:
        return np.full(a.shape[0], np.inf)
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1]).min(axis=1)


def map_recall(landmark_xy: np.ndarray, trees_xy: np.ndarray, tol_m: float = 1.0) -> float:
    """Share of the trees with a landmark within tol_m."""
    return float(np.mean(_nearest(trees_xy, landmark_xy) <= tol_m))


def seen_trees(points_xy: np.ndarray, trees_xy: np.ndarray, tol_m: float = 1.0) -> np.ndarray:
    """(T,) bool: the trees with a point of points_xy (K, 2) (detections placed in the world)
    within tol_m."""
    points = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    trees = np.asarray(trees_xy, dtype=np.float64)[:, :2]
    if not points.shape[0]:
        return np.zeros(trees.shape[0], bool)
    # the bound excludes a neighbour at exactly tol_m: the next float up includes it
    bound = float(np.nextafter(tol_m, np.inf))
    return cKDTree(points).query(trees, distance_upper_bound=bound)[0] <= tol_m


def map_precision(
    landmark_xy: np.ndarray,
    first_scan: np.ndarray,
    trees_xy: np.ndarray,
    n_scans: int,
    tol_m: float = 1.0,
    start: int = 0,
) -> float:
    """Share of the landmarks that joined the map in scans start .. n_scans - 1 (within the
    reference's span) with a tree within tol_m; NaN when no landmark joined in those scans."""
    first_scan = np.asarray(first_scan)
    judged = (first_scan >= start) & (first_scan < n_scans)
    if not judged.any():
        return float("nan")
    return float(np.mean(_nearest(landmark_xy[judged], trees_xy) <= tol_m))


def false_detection_rate(
    meas_status: np.ndarray, meas_track: np.ndarray, landmark_id: np.ndarray
) -> float:
    """Share of the considered circles (status not out of range, not in a skipped scan) whose
    track is not a landmark of the final map; NaN when no circle was considered."""
    considered = (meas_status != OUT_OF_RANGE) & (meas_status != SKIPPED)
    if not considered.any():
        return float("nan")
    explained = np.isin(meas_track[considered], landmark_id) & (meas_track[considered] >= 0)
    return float(1.0 - np.mean(explained))


def one_tree_pairs(
    landmark_xy: np.ndarray,
    landmark_id: np.ndarray,
    obs: tuple[np.ndarray, np.ndarray],
    trees_xy: np.ndarray,
    within_m: float = SAME_TREE_M,
    tol_m: float = 1.0,
) -> tuple[int, int]:
    """(pairs of landmarks within `within_m` of each other, of them those that are one tree):
    both within `tol_m` of the same tree of `trees_xy`, or never updated in the same scan.
    obs: (scan, landmark id) of every update's observation (the log's obs_scan, obs_landmark)."""
    xy = np.asarray(landmark_xy, dtype=np.float64).reshape(-1, 2)
    ids = np.asarray(landmark_id).reshape(-1)
    if ids.shape[0] != xy.shape[0]:
        raise ValueError(f"one_tree_pairs: {xy.shape[0]} landmark positions but {ids.shape[0]} ids")
    pairs = np.array(sorted(cKDTree(xy).query_pairs(within_m)), dtype=np.int64).reshape(-1, 2)
    if not pairs.size:
        return 0, 0
    tree_of = np.full(ids.size, -1)
    if trees_xy.shape[0]:
        d, j = cKDTree(trees_xy[:, :2]).query(xy)
        tree_of = np.where(d <= tol_m, j, -1)
    same_tree = (tree_of[pairs[:, 0]] >= 0) & (tree_of[pairs[:, 0]] == tree_of[pairs[:, 1]])
    scan, lid = (np.asarray(a).reshape(-1) for a in obs)
    seen = {int(i): set(scan[lid == i].tolist()) for i in np.unique(ids[pairs])}
    apart = np.array([not seen[int(ids[a])] & seen[int(ids[b])] for a, b in pairs])
    return int(pairs.shape[0]), int(np.sum(same_tree | apart))
