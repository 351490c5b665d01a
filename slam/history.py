"""`RunHistory`: what a run has done so far that a component needs from the past, kept by the
loop (`slam.loop.Slam`) and read by loop closure (`slam.closure`) and the log (`slam.log`).

Per scan: its time, the filter's pose and covariance after the prediction, the odometry
increment from the scan before (frame of that scan) and its covariance. Per landmark (by id):
the scan it joined the map, the scans it was associated in (its tentative sightings
included), the time it was last seen (kept by loop closure, `mark_seen`), and, after a loop
closure, the landmark it was merged into; and the pass each landmark's updates belong to
(`pass_index`, for `measurement.pass_offset_sd_m`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["RunHistory"]


class RunHistory:
    """The run's past, written by the loop as scans are predicted, landmarks join the map,
    are updated and are merged; read by the components that need it."""

    def __init__(self, scan_t: np.ndarray) -> None:
        n = scan_t.shape[0]
        self.scan_t = scan_t  # (N,) s
        self.pred_pose = np.empty((n, 3))  # (N, 3) world, after each scan's prediction
        self.pred_pose_cov = np.empty((n, 3, 3))
        self.odo_delta = np.zeros((n, 3))  # row k: scan k - 1 -> k, frame of k - 1 (row 0: 0)
        self.odo_cov = np.zeros((n, 3, 3))
        self.first_scan: dict[int, int] = {}  # landmark id -> scan it joined the map
        self.n_obs: dict[int, int] = {}  # landmark id -> scans it was associated in
        self.alias: dict[int, int] = {}  # a landmark merged into another: its id -> the other's
        self._seen = np.full(256, np.nan)  # by landmark id: the time it was last seen
        self._pass: dict[int, tuple[float, int]] = {}  # id -> (last update's time, index)

    def odometry(self, k: int, delta: np.ndarray, cov: np.ndarray) -> None:
        """The odometry increment from scan k - 1 to k (frame of k - 1) and its covariance."""
        self.odo_delta[k] = delta
        self.odo_cov[k] = cov

    def predicted(self, k: int, pose: np.ndarray, cov: np.ndarray) -> None:
        self.pred_pose[k] = pose
        self.pred_pose_cov[k] = cov

    def joined(self, landmark: int, k: int, n_obs: int) -> None:
        """Landmark `landmark` joined the map at scan k, seen in `n_obs` scans so far."""
        self.n_obs[landmark] = int(n_obs)
        self.first_scan[landmark] = k

    def observed(self, landmark: int) -> None:
        """Landmark `landmark` was used in an update."""
        self.n_obs[landmark] = self.n_obs.get(landmark, 0) + 1

    def pass_index(self, ids, t: float, gap_s: float) -> np.ndarray:
        """Landmarks `ids` are updated at time t: each one's index (1, 2, ...) within its
        current pass, a pass ending after more than `gap_s` without an update of it."""
        out = np.empty(len(ids), np.int64)
        for i, lid in enumerate(np.asarray(ids, dtype=np.int64).tolist()):
            last, k = self._pass.get(lid, (-np.inf, 0))
            k = k + 1 if t - last <= gap_s else 1
            self._pass[lid] = (t, k)
            out[i] = k
        return out

    def mark_seen(self, ids, t: float, only_new: bool = False) -> None:
        """Landmarks `ids` were seen (updated) at time t (only_new: those not seen before)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if ids.size and ids.max() >= self._seen.size:
            grown = np.full(max(2 * self._seen.size, int(ids.max()) + 1), np.nan)
            grown[: self._seen.size] = self._seen
            self._seen = grown
        if only_new:
            ids = ids[np.isnan(self._seen[ids])]
        self._seen[ids] = t

    def seen_at(self, ids, default: float) -> np.ndarray:
        """The time each landmark of `ids` was last seen (`default` if never)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if ids.size and ids.max() < self._seen.size:  # every id known (the loop's case)
            out = self._seen[ids]
        else:
            out = np.full(ids.size, default)
            known = ids < self._seen.size
            out[known] = self._seen[ids[known]]
        return np.where(np.isnan(out), default, out)

    def merged(self, drop: int, keep: int) -> None:
        """Landmark `drop` was found to be landmark `keep` (a loop closure): its sightings and
        measurements count as `keep`'s, in the log and in the smoother's problem."""
        self.alias[drop] = keep
        self.n_obs[keep] = self.n_obs.get(keep, 0) + self.n_obs.pop(drop, 0)
        self.first_scan[keep] = min(
            self.first_scan.get(keep, 1 << 62), self.first_scan.pop(drop, 1 << 62)
        )

    def resolved(self, ids: list) -> np.ndarray:
        """Landmark ids with every merged one replaced by the one it was merged into."""
        out = np.array(ids, np.int64)
        if self.alias:
            root = {}
            for a in self.alias:
                b = self.alias[a]
                while b in self.alias:
                    b = self.alias[b]
                root[a] = b
            out = np.array([root.get(int(v), int(v)) for v in out.tolist()], np.int64)
        return out
